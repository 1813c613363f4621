//! Integration tests of `bench-conv`: protocol files, shards and merge, reports.

mod protocol;
