//! Jobs of the `mochi` command: `mochi demo` (the whole path) and `mochi distill`.

pub mod demo;
pub mod distill;
