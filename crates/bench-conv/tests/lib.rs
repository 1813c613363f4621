//! Integration tests of `bench-conv`: protocol files, shards and merge, reports.

mod protocol;
mod real_image;
mod tracking;
