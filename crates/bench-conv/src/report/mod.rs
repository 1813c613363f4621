//! Results of the convergence protocols, one module per concept:
//!
//! - [`runs`]: the runs CSV (`runs.csv`), a row per run, and the merge of shards;
//! - [`manifest`]: the manifest beside it (`run.toml`) and whether a merge is complete;
//! - [`results_dir`]: the results folder itself (lock, incomplete marker, atomic writes);
//! - [`summary`]: per-method statistics, the Markdown summary with the paper's rates and
//!   the cumulative-distribution plot of Fig. 3;
//! - [`domain`](mod@domain): the convergence domain (success against the scale of the
//!   offsets);
//! - [`axes`]: the basin along each axis alone.
//!
//! Every item is also here, at `report::`, where the rest of the harness names it.

pub mod axes;
pub mod domain;
pub mod manifest;
pub mod results_dir;
pub mod runs;
pub mod summary;

pub use axes::{axis_basins, axis_basins_markdown};
pub use domain::{
    DomainPoint, domain, domain_markdown, plot_domain, read_domain_csv, write_domain,
    write_domain_csv,
};
pub use manifest::{
    Completeness, MANIFEST, RunManifest, check_run_ids, completeness, fingerprint, read_manifest,
    write_manifest,
};
pub use results_dir::{
    INCOMPLETE_MARKER, LOCK_FILE, RESULT_FILES, ResultsLock, begin_results, finish_results,
    write_atomically,
};
pub use runs::{RunRecord, apply_threshold, is_success, merge, read_csv, write_csv};
pub(crate) use summary::plot_error_cdf;
pub use summary::{
    MethodSummary, paper_success_rate, parse_config_name, plot_cdf, summarize, summary_markdown,
};
