//! The CSV files through the one codec (`bench_conv::csv_io`): each reads back what it
//! wrote, and writes the bytes it always has (header, column order, number formats).

use std::path::PathBuf;

use bench_conv::report::{DomainPoint, RunRecord, read_domain_csv, write_domain_csv};
use bench_conv::tracking::FrameRecord;

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bench-conv-csv-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A run whose numbers survive their formats exactly.
fn run(run_id: usize) -> RunRecord {
    RunRecord {
        run_id,
        scene: "city-1".into(),
        desired: 0,
        offset_scale: 0.5,
        initial: run_id,
        config: "rule2/convolved".into(),
        method: vvs::Method::Rule2,
        final_position_error_m: 0.03,
        final_rotation_error_deg: 0.1,
        iterations_step1: 10,
        iterations_step2: 20,
        stop: vvs::StopReason::Stalled,
        lambda: 1.0,
        cost: 0.5,
        wall_time_s: 1.25,
        success: false,
    }
}

fn frame(k: usize) -> FrameRecord {
    FrameRecord {
        method: vvs::Method::Povs,
        frame_step: 10,
        frame: k,
        time_s: 0.5,
        true_pose: [1.0, -2.0, 3.0, 0.25, -0.125, 0.0],
        estimated_pose: [1.5, -2.0, 3.0, 0.25, -0.125, 0.0625],
        position_error_m: 0.5,
        rotation_error_deg: 3.5,
        iterations: [7, 8],
        stop: vvs::StopReason::Converged,
        recovered: true,
        wall_time_s: 0.75,
    }
}

#[test]
fn runs_csv_round_trips_and_keeps_its_bytes() {
    let dir = temp("runs");
    let path = dir.join("runs.csv");
    let mut records = vec![run(0), run(1)];
    records[1].scene = "a,b \"c\".las".into();
    records[1].offset_scale = 1.0;
    records[1].cost = f64::NAN;
    records[1].lambda = 0.3;
    records[1].success = true;
    bench_conv::report::write_csv(&path, &records).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(
        text,
        "run_id,scene,desired,offset_scale,initial,config,method,final_position_error_m,\
         final_rotation_error_deg,iterations_step1,iterations_step2,stop,lambda,cost,\
         wall_time_s,success\n\
         0,city-1,0,0.5,0,rule2/convolved,rule2,3.000000e-2,1.000000e-1,10,20,stalled,1,\
         5.000000e-1,1.250,false\n\
         1,\"a,b \"\"c\"\".las\",0,1,1,rule2/convolved,rule2,3.000000e-2,1.000000e-1,10,20,\
         stalled,0.3,NaN,1.250,true\n"
    );
    let back = bench_conv::report::read_csv(&path).unwrap();
    assert_eq!(back[0], records[0]);
    // NaN is not equal to itself: compared as text.
    assert_eq!(format!("{:?}", back[1]), format!("{:?}", records[1]));
    // No run: the header alone, which reads back as no run.
    bench_conv::report::write_csv(&path, &[]).unwrap();
    assert_eq!(
        std::fs::read_to_string(&path).unwrap().lines().count(),
        1,
        "the header alone"
    );
    assert!(bench_conv::report::read_csv(&path).unwrap().is_empty());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Errors name the file, the line, the column and its text.
#[test]
fn csv_errors_name_the_file_line_and_field() {
    let dir = temp("errors");
    let path = dir.join("runs.csv");
    bench_conv::report::write_csv(&path, &[run(0), run(1)]).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    // (the file, the field refused and the line of its first bad row)
    for (bad, field, line) in [
        (
            text.replace(",rule2,", ",rule9,"),
            "field method: `rule9`",
            2,
        ),
        (
            text.replace(",stalled,1,", ",stalled,x,"),
            "field lambda: `x`",
            2,
        ),
        (
            text.replace("1,city-1,0,", "1,city-1,-1,"),
            "field desired: `-1`",
            3,
        ),
        (
            text.replace(",1.250,false", ",1.250,no"),
            "field success: `no`",
            2,
        ),
        (
            text.replace("0,city-1,0,0.5", "0,city-1,0,0"),
            "field offset_scale: `0`",
            2,
        ),
    ] {
        std::fs::write(&path, bad).unwrap();
        let message = format!("{:#}", bench_conv::report::read_csv(&path).unwrap_err());
        let at = format!("{}:{line}: {field}", path.display());
        assert!(message.contains(&at), "expected `{at}` in: {message}");
    }
    std::fs::write(&path, text.replace("wall_time_s", "time_s")).unwrap();
    let message = format!("{:#}", bench_conv::report::read_csv(&path).unwrap_err());
    assert!(message.contains("unexpected header"), "{message}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn frames_csv_round_trips_and_keeps_its_bytes() {
    let dir = temp("frames");
    let path = dir.join("frames.csv");
    let records = vec![frame(0), frame(10)];
    bench_conv::tracking::write_csv(&path, &records).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "method,frame_step,frame,time_s,true_tx,true_ty,true_tz,true_wx,true_wy,true_wz,\
         est_tx,est_ty,est_tz,est_wx,est_wy,est_wz,position_error_m,rotation_error_deg,\
         iterations_step1,iterations_step2,stop,recovered,wall_time_s"
    );
    assert_eq!(
        lines.next().unwrap(),
        "povs,10,0,0.500000,1.000000000,-2.000000000,3.000000000,0.250000000,-0.125000000,\
         0.000000000,1.500000000,-2.000000000,3.000000000,0.250000000,-0.125000000,\
         0.062500000,0.500000000,3.500000,7,8,converged,true,0.750000"
    );
    assert_eq!(bench_conv::tracking::read_csv(&path).unwrap(), records);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn domain_csv_round_trips_and_keeps_its_bytes() {
    let dir = temp("domain");
    let path = dir.join("domain.csv");
    let points = vec![
        DomainPoint {
            config: "povs".into(),
            offset_scale: 0.25,
            runs: 3,
            successes: 2,
        },
        DomainPoint {
            config: "rule2/convolved".into(),
            offset_scale: 1.0,
            runs: 2,
            successes: 2,
        },
    ];
    write_domain_csv(&path, &points).unwrap();
    assert_eq!(
        std::fs::read_to_string(&path).unwrap(),
        "config,offset_scale,runs,successes,success_percent\n\
         povs,0.25,3,2,66.67\n\
         rule2/convolved,1,2,2,100.00\n"
    );
    assert_eq!(read_domain_csv(&path).unwrap(), points);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A table nothing reads back (the real benchmark's): its header is its rows' field
/// names, the `csv` crate's own number format, and no row makes an empty file.
#[test]
fn write_only_tables_take_their_header_from_their_rows() {
    #[derive(serde::Serialize)]
    struct Row {
        name: &'static str,
        value: f64,
        missing: Option<f64>,
    }
    let dir = temp("table");
    let path = dir.join("table.csv");
    let rows = [Row {
        name: "a",
        value: 1.0,
        missing: None,
    }];
    bench_conv::csv_io::write_table(&path, &rows).unwrap();
    assert_eq!(
        std::fs::read_to_string(&path).unwrap(),
        "name,value,missing\na,1.0,\n"
    );
    bench_conv::csv_io::write_table::<Row>(&path, &[]).unwrap();
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "");
    std::fs::remove_dir_all(&dir).unwrap();
}
