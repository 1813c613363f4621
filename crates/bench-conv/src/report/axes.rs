//! The basin along each axis alone (protocols with `sampling = "axes"`).

use std::fmt::Write as _;

use super::RunRecord;

/// The basin along each axis (protocols with `sampling = "axes"`): per method and
/// axis, the largest scale `s` such that every run along that axis (both signs, every
/// desired pose) converged at `s` and at every smaller scale run (a scale with no run
/// along the axis ends the basin); 0 if none, `None` for an axis with no run at all.
pub fn axis_basins(records: &[RunRecord]) -> Vec<(String, [Option<f64>; 6])> {
    let mut methods: Vec<&str> = records.iter().map(|r| r.config.as_str()).collect();
    methods.sort_unstable();
    methods.dedup();
    let mut scales: Vec<f64> = records.iter().map(|r| r.offset_scale).collect();
    scales.sort_by(f64::total_cmp);
    scales.dedup();
    let along = |r: &RunRecord, method: &str, axis: usize| {
        r.config == method && crate::protocol::Protocol::axis_of(r.initial) == axis
    };
    methods
        .into_iter()
        .map(|method| {
            let basin = std::array::from_fn(|axis| {
                if !records.iter().any(|r| along(r, method, axis)) {
                    return None;
                }
                let mut largest = 0.0;
                for &scale in &scales {
                    let mut runs = records
                        .iter()
                        .filter(|r| along(r, method, axis) && r.offset_scale == scale);
                    let mut any = false;
                    let all = runs.all(|r| {
                        any = true;
                        r.success
                    });
                    if !(any && all) {
                        break;
                    }
                    largest = scale;
                }
                Some(largest)
            });
            (method.to_string(), basin)
        })
        .collect()
}

/// [`axis_basins`] as a Markdown table in metres and degrees (`magnitudes`: the
/// protocol's offsets at scale 1, `tX, tY, tZ` in metres then `θwX, θwY, θwZ` in
/// degrees). A basin that reaches `top_scale`, the largest scale of the protocol, is
/// written `≥` it (the ladder found no end); an axis with no run `—`.
pub fn axis_basins_markdown(
    basins: &[(String, [Option<f64>; 6])],
    magnitudes: [f64; 6],
    top_scale: f64,
) -> String {
    let mut s = String::from(
        "| method | tX (m) | tY (m) | tZ (m) | θwX (°) | θwY (°) | θwZ (°) |\n|---|---:|---:|---:|---:|---:|---:|\n",
    );
    for (method, basin) in basins {
        let _ = write!(s, "| {method} |");
        for k in 0..6 {
            match basin[k] {
                Some(scale) => {
                    let at_least = if scale >= top_scale { "≥ " } else { "" };
                    let _ = write!(s, " {at_least}{:.2} |", scale * magnitudes[k]);
                }
                None => s.push_str(" — |"),
            }
        }
        s.push('\n');
    }
    s
}
