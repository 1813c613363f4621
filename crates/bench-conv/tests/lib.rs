//! Integration tests of `bench-conv`: protocol files, shards and merge, reports.

mod fuzz;
mod protocol;
mod real;
mod real_image;
mod tracking;
