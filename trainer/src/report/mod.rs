//! What people look at: line and scatter charts, mesh previews and OBJ files.

pub(crate) mod chart;
pub mod render;
