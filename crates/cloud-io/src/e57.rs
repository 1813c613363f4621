//! E57 (ASTM E2807, the exchange format of terrestrial scanners) through the `e57`
//! crate.
//!
//! Every scan of the file is read, structured (a row × column grid) or not, with
//! cartesian or spherical coordinates (converted to cartesian), and brought into the
//! file's frame by its pose; the scans are merged in the file's order. Points whose
//! coordinates are invalid (a scanner's missed returns, directions without a range)
//! are left out and counted. Colours are scaled by the scan's colour limits: 8-bit
//! when every coloured scan's limits are within `0..=255`, 16-bit otherwise; a scan
//! without colour, in a file where others have it, is grey at its intensity.
//! Intensities are normalised by the scan's intensity limits. Writing makes one
//! unstructured scan of `double` cartesian coordinates, colour at its depth (8- or
//! 16-bit integers) and `float` intensity.

use std::path::Path;

use glam::DVec3;

use crate::{CloudIoError, ColorScale, Colors, Points};

/// What was found in an E57 file.
#[derive(Clone, Debug, PartialEq)]
pub struct E57Info {
    /// Number of scans (E57 `data3D` entries).
    pub scans: usize,
    /// Points each scan's header announces.
    pub scan_point_counts: Vec<u64>,
    /// Scans stored as a row × column grid.
    pub structured_scans: usize,
    /// Scans whose coordinates are spherical.
    pub spherical_scans: usize,
    /// Points left out for invalid coordinates.
    pub invalid_points: u64,
}

fn e57_error(path: &Path) -> impl Fn(e57::Error) -> CloudIoError + '_ {
    move |source| CloudIoError::E57 {
        path: path.to_owned(),
        source: Box::new(source),
    }
}

/// Whether every colour channel of a scan fits 8 bits: its limit's maximum (an
/// integer), or without one its record's integer type (the range `e57` normalises by).
fn eight_bit(scan: &e57::PointCloud) -> bool {
    let record_fits = |name: &e57::RecordName| {
        scan.prototype.iter().filter(|r| r.name == *name).all(|r| {
            matches!(r.data_type, e57::RecordDataType::Integer { min, max } if min >= 0 && max <= 255)
        })
    };
    let limits = scan.color_limits.as_ref();
    [
        (
            limits.and_then(|l| l.red_max.as_ref()),
            e57::RecordName::ColorRed,
        ),
        (
            limits.and_then(|l| l.green_max.as_ref()),
            e57::RecordName::ColorGreen,
        ),
        (
            limits.and_then(|l| l.blue_max.as_ref()),
            e57::RecordName::ColorBlue,
        ),
    ]
    .iter()
    .all(|(max, name)| match max {
        Some(e57::RecordValue::Integer(i)) => *i <= 255,
        Some(_) => false,
        None => record_fits(name),
    })
}

/// Read every scan of an E57 file.
pub(crate) fn read(path: &Path) -> Result<(Points, E57Info), CloudIoError> {
    let err = e57_error(path);
    let mut reader = e57::E57Reader::from_file(path).map_err(&err)?;
    let scans = reader.pointclouds();
    let any_color = scans.iter().any(|s| s.has_color());
    let any_intensity = scans.iter().any(|s| s.has_intensity());
    let scale = if scans.iter().filter(|s| s.has_color()).all(eight_bit) {
        ColorScale::EightBit
    } else {
        ColorScale::SixteenBit
    };
    let top = f32::from(scale.max_value());
    let mut info = E57Info {
        scans: scans.len(),
        scan_point_counts: scans.iter().map(|s| s.records).collect(),
        structured_scans: scans.iter().filter(|s| s.has_row_column()).count(),
        spherical_scans: scans.iter().filter(|s| s.has_spherical()).count(),
        invalid_points: 0,
    };
    let mut positions = Vec::new();
    let mut colors = Vec::new();
    let mut intensities = Vec::new();
    for scan in &scans {
        let mut points = reader.pointcloud_simple(scan).map_err(&err)?;
        points.spherical_to_cartesian(true);
        points.intensity_to_color(false);
        points.normalize_color(true);
        points.normalize_intensity(true);
        points.apply_pose(true);
        for point in points {
            let point = point.map_err(&err)?;
            let e57::CartesianCoordinate::Valid { x, y, z } = point.cartesian else {
                info.invalid_points += 1;
                continue;
            };
            positions.push(DVec3::new(x, y, z));
            let intensity = point.intensity.filter(|i| i.is_finite());
            if any_color {
                let rgb = match (&point.color, intensity) {
                    (Some(c), _) => [c.red, c.green, c.blue],
                    (None, Some(i)) => [i; 3],
                    (None, None) => [0.0; 3],
                };
                colors.push(rgb.map(|v| {
                    let v = if v.is_finite() { v } else { 0.0 };
                    (v.clamp(0.0, 1.0) * top).round() as u16
                }));
            }
            if any_intensity {
                intensities.push(intensity.unwrap_or(0.0).max(0.0));
            }
        }
    }
    let points = Points {
        positions_m: positions,
        colors: any_color.then_some(Colors {
            values: colors,
            scale,
        }),
        intensities: any_intensity.then_some(intensities),
    };
    Ok((points, info))
}

/// Write points as an E57 file of one unstructured scan.
pub(crate) fn write(points: &Points, path: &Path) -> Result<(), CloudIoError> {
    let err = e57_error(path);
    let mut writer =
        e57::E57Writer::from_file(path, "{pgm-omni-vvs-cloud-io-file}").map_err(&err)?;
    let mut prototype = vec![
        e57::Record::CARTESIAN_X_F64,
        e57::Record::CARTESIAN_Y_F64,
        e57::Record::CARTESIAN_Z_F64,
    ];
    if let Some(c) = &points.colors {
        let data_type = match c.scale {
            ColorScale::EightBit => e57::RecordDataType::U8,
            ColorScale::SixteenBit => e57::RecordDataType::U16,
        };
        for name in [
            e57::RecordName::ColorRed,
            e57::RecordName::ColorGreen,
            e57::RecordName::ColorBlue,
        ] {
            prototype.push(e57::Record {
                name,
                data_type: data_type.clone(),
            });
        }
    }
    let intensity_max = points.intensities.as_ref().map(|v| {
        v.iter()
            .copied()
            .filter(|i| i.is_finite())
            .fold(0.0f32, f32::max)
    });
    if intensity_max.is_some() {
        prototype.push(e57::Record {
            name: e57::RecordName::Intensity,
            data_type: e57::RecordDataType::Single {
                min: Some(0.0),
                max: None,
            },
        });
    }
    let mut scan = writer
        .add_pointcloud("{pgm-omni-vvs-cloud-io-scan}", prototype)
        .map_err(&err)?;
    if let Some(max) = intensity_max {
        scan.set_intensity_limits(Some(e57::IntensityLimits {
            intensity_min: Some(e57::RecordValue::Single(0.0)),
            intensity_max: Some(e57::RecordValue::Single(if max > 0.0 { max } else { 1.0 })),
        }));
    }
    for (i, p) in points.positions_m.iter().enumerate() {
        // `add_point` takes the values: one vector a point.
        let mut values = Vec::with_capacity(7);
        values.extend([p.x, p.y, p.z].map(e57::RecordValue::Double));
        if let Some(c) = &points.colors {
            let top = c.scale.max_value();
            values.extend(c.values[i].map(|v| e57::RecordValue::Integer(i64::from(v.min(top)))));
        }
        if let Some(intensities) = &points.intensities {
            let v = intensities[i];
            values.push(e57::RecordValue::Single(if v.is_finite() {
                v.max(0.0)
            } else {
                0.0
            }));
        }
        scan.add_point(values).map_err(&err)?;
    }
    scan.finalize().map_err(&err)?;
    writer.finalize().map_err(&err)?;
    Ok(())
}
