//! Integration tests of `bench-conv`: protocol files, shards and merge, reports.

mod csv_io;
mod fuzz;
mod protocol;
mod real;
mod real_image;
mod tracking;
