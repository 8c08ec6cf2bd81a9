//! What people look at: line and scatter charts, the selection's candidates table and Pareto
//! charts, mesh previews and OBJ files (with a contact scene's obstacles).

pub mod candidates;
pub(crate) mod chart;
pub mod render;
pub mod scene_view;

pub use candidates::candidates_table;
