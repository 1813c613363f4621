//! The real-data benchmark: real photographs localised and tracked in clouds fused from
//! RGB-D frames (`bench-conv real BENCH.toml --data DIR --out DIR`,
//! `cargo xtask reproduce-real`).
//!
//! A benchmark file names a dataset (an [`rgbd::RgbdDataset`] description), how its
//! frames split into clouds and queries, where each query's localisation starts, the
//! methods, and optionally a global search, tracking, and the queries resampled to a
//! catadioptric camera:
//!
//! ```toml
//! name = "redkitchen"
//! dataset = "redkitchen.toml"        # relative to this file; its frames under --data
//! downsample = 2                     # pictures at 1/2 of their resolution (320x240)
//! methods = ["localizer", "povs", "rule2/convolved", "rule2/convolved+region"]
//! reference = true                   # each query's photometric optimum, below
//!
//! [fuse]                             # rgbd::FuseOptions
//! voxel_size_m = 0.01
//! min_frames = 2
//!
//! [split]                            # one cloud of map frames, queries held out of it
//! kind = "map"
//! map = "0-999/10"
//! exclude = "450-549"
//! near = "5-995/50"                  # queries between map frames
//! block = "460-510/10"               # queries inside the excluded block
//! # kind = "leave_one_out", frames = "1-5": each frame against a cloud of the others
//!
//! [starts]                           # truth · (t, θw): |t| and |θw| as given, seeded directions
//! offsets = [[0.0, 0.0], [0.05, 3.0], [0.10, 5.0]]
//! seed = 1
//! nearest_map_frame = true           # block queries also from their nearest map frame
//!
//! [global]                           # Method::Global from the nearest map frame, block queries
//! prior = { translation_m = [0.4, 0.4, 0.4], rotation_deg = [20.0, 20.0, 20.0] }
//! grid_spacing_m = [0.2, 0.2, 0.2]
//!
//! [tracking]                         # the block frame after frame, 1 frame in N
//! frames = "450-549"
//! frame_steps = [1, 2, 5, 10]
//! methods = ["povs", "tracker"]
//!
//! [catadioptric]                     # every query resampled to a UCM camera, same pose
//! xi = 0.9
//! methods = ["povs", "localizer"]
//! ```
//!
//! A method is `localizer` (`vvs::Localizer::default()`: Rule2, the Convolved Jacobian,
//! brightness normalised, compared on the common support), `tracker` (Rule2 with
//! `vvs::Tracker::default_config()`) or `method/jacobian` (`povs`,
//! `rule0/convolved`, `rule2/paper`, …) with the localiser's other settings, and
//! `+region` to compare on every pixel of the region as the paper does. The
//! *reference* of a query is its photometric optimum: PoVS from the truth on the common
//! support with the paper's gain, run until it converges (no stall test, 400
//! iterations); its distance to the
//! truth says how far the truth itself is from what the picture and the cloud agree
//! on, and every run reports its distance to it.

mod report;
mod run;
mod spec;

pub use report::write_results;
pub use run::{
    Benchmark, PoseCheckRecord, Query, QueryKind, RealResults, RunRecord, TrackRecord,
    run_benchmark,
};
pub use spec::{BenchMethod, LocalMapSpec, PoseCheckSpec, Preset, RealSpec, Split};
