//! What people look at: line and scatter charts, the selection's candidates table and Pareto
//! charts, mesh previews and OBJ files.

pub mod candidates;
pub(crate) mod chart;
pub mod render;

pub use candidates::candidates_table;
