//! Jobs of the `mochi` command: `mochi demo` (the whole path), `mochi distill` and `mochi mesh`
//! (a surface asset in, a tet mesh, its render embedding and a scene out).

pub mod asset_mesh;
pub mod asset_scene;
pub mod demo;
pub mod distill;
