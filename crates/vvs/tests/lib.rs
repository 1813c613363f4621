//! Integration tests of `vvs`, one binary (modules below) for fast linking. Every
//! optimiser claim is tested on renderings of the synthetic city with known ground
//! truth.

mod common;
mod config;
mod convergence;
mod degenerate;
mod global;
mod localize;
mod pipeline;
mod pipeline_support;
mod support;
mod track;
mod vignetting;
