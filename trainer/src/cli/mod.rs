//! Jobs of the `mochi` command that run the whole path: `mochi demo`.

pub mod demo;
