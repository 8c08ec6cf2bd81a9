//! Procedural meshes (filled in).
