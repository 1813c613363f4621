//! Shared helpers.

use std::path::{Path, PathBuf};

use cloud_io::{CloudInfo, FileInfo, IntensitySource, LasInfo};
use splat::PointCloud;
pub use test_support::{data_dir, workspace_root as root};

/// A temporary folder unique to this process and name.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cloud-io-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A committed cloud file written by another program (fixtures/clouds).
pub fn fixture(name: &str) -> PathBuf {
    root().join("fixtures/clouds").join(name)
}

/// A LAS/LAZ file's cloud, header and intensity source.
pub fn read_las(
    path: impl AsRef<Path>,
) -> Result<(PointCloud, LasInfo, IntensitySource), cloud_io::CloudIoError> {
    let (cloud, info, source) = cloud_io::read_cloud(path)?;
    Ok((cloud, las_info(info), source))
}

/// The LAS part of what was read.
pub fn las_info(info: CloudInfo) -> LasInfo {
    match info.file {
        FileInfo::Las(las) => las,
        other => panic!("not a LAS file: {other:?}"),
    }
}
