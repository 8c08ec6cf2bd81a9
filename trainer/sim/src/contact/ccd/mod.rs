//! Continuous collision detection: the time of impact of each primitive pair moving
//! linearly over a step ([`AdditiveCcd`]), and the largest fraction of a step that keeps a
//! whole contact surface free of intersections ([`max_step`]).

pub mod additive;
pub mod max_step;

pub use additive::AdditiveCcd;
pub use max_step::{max_step, max_step_over};
