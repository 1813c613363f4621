//! Integration tests of `world`, one binary.

mod city;
mod sequence;
