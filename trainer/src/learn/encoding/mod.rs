//! Encoding of full-space states relative to their boundary conditions (Li et al. 2025,
//! Sec. 3.2; docs/design.md, decision 3), so that networks never have to learn the rigid motion
//! of the handles.
//!
//! Handle (prescribed) vertices are left out of the encoded vector `q`; decoding puts them
//! at their boundary-condition targets. Every other vertex `v` is stored, in ascending
//! vertex order, `dim` numbers each, as
//!
//! ```text
//! q_v = R^T (x_v - o_v)          decoded as          x_v = R q_v + o_v
//! ```
//!
//! where the [`Frame`] of a state holds the rotation `R` and the origins `o`:
//!
//! - `o_v` is the root vertex of `v`'s strand for rods whose every root is prescribed
//!   ([`Origins::StrandRoots`]), and otherwise (cloth, solids, 2D, anything else) the
//!   centroid `c` of the current handle-vertex positions ([`Origins::HandleCentroid`]);
//! - `R` is the best-fit proper rotation (Kabsch) carrying the handles' reference
//!   positions (their frame-0 targets) to their current targets, when the scene's handles
//!   can rotate, and the identity otherwise (e.g. the cloth's two pinned corners are
//!   collinear, so their rotation is ill-determined; translation alone is removed there).
//!
//! Both `R` and the origins depend only on the handle targets, so decoding is one affine map
//! per vertex that a runtime without allocation can repeat. For a single rigid handle,
//! `R` equals the handle's pose rotation and `c` is the pose applied to the reference
//! centroid, so such a runtime need not run an SVD. In 2D, `R` is the upper-left 2x2 block
//!
//! # Files
//!
//! `error`: what can go wrong; `frame`: the rotation and origins of a state (the Kabsch fit);
//! `strands`: rod strands encoded by their bends (chains, the Cayley map); `codec`: the
//! [`Encoding`] itself, which encodes and decodes states, and the integrator's input layout;
//! `collider_inputs`: run-time colliders seen from the encoding frame.

mod codec;
mod collider_inputs;
pub mod error;
mod frame;
mod strands;
#[cfg(test)]
mod tests;

pub(crate) use codec::pack_signals;
pub use codec::{decode_world, Encoding};
pub use collider_inputs::{collider_inputs, collider_state};
pub use error::EncodingError;
pub use frame::Frame;
pub(crate) use frame::Origins;
pub use strands::{Chain, ChainStart};
