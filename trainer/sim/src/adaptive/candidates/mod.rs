//! Candidate bases of a body for the adaptive subspace (Trusty et al., Sec. 3.5): the
//! vectors the adaptivity may add to the active basis, grouped into the blocks it queries
//! one at a time ("modal block candidates"): the rigid modes as one block, the rest of the
//! affine modes as another, and each linear mode of the rest shape as its own block.
//!
//! - [`body`]: what a body is here (rest shape, lumped masses, prescribed vertices);
//! - [`rigid`]: rigid and affine modes;
//! - [`linear_modes`]: the lowest eigenpairs of `K u = lambda M u` at the rest shape;
//! - [`lanczos`]: the shift-invert block Lanczos eigensolver behind them;
//! - [`data_modes`]: principal components of a dataset's displacements (optional).
//!
//! Every mode is a vector over all of the body's dofs, zero on the prescribed ones, and
//! each block is M-orthonormal (lumped mass). Blocks need not be M-orthogonal to each
//! other, except that a floating body's linear modes are M-orthogonal to its rigid ones.

pub mod body;
pub mod data_modes;
mod error;
pub mod lanczos;
pub mod linear_modes;
pub mod rigid;
#[cfg(test)]
mod tests;

pub use body::Body;
pub use data_modes::data_modes;
pub use error::CandidateError;
pub use lanczos::LanczosSettings;
pub use linear_modes::{linear_modes, LinearModeSettings, LinearModes};
pub use rigid::{affine_modes, rigid_modes};

use crate::energy::StencilEnergy;
use faer::{Mat, MatRef};
use std::ops::Range;

/// What a block of candidate modes is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlockKind {
    /// The rigid modes (translations and linearised rotations).
    Rigid,
    /// The affine modes that are not rigid (stretches and shears), M-orthogonal to the
    /// rigid block.
    Affine,
    /// The linear mode with this index (0 = lowest).
    LinearMode(usize),
    /// The data mode with this index (0 = largest variance, [`data_modes`]).
    DataMode(usize),
}

/// A block of candidate modes: consecutive columns of [`CandidateSet::modes`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Block {
    /// What the block is.
    pub kind: BlockKind,
    /// Its columns.
    pub columns: Range<usize>,
}

/// Which candidates to build.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CandidateSpec {
    /// Include the rigid block.
    pub rigid: bool,
    /// Include the affine block (the non-rigid affine modes).
    pub affine: bool,
    /// Number of linear modes (each its own block).
    pub linear_modes: usize,
    /// How the linear modes are computed.
    pub settings: LinearModeSettings,
}

impl Default for CandidateSpec {
    fn default() -> Self {
        CandidateSpec {
            rigid: true,
            affine: true,
            linear_modes: 20,
            settings: LinearModeSettings::default(),
        }
    }
}

/// The candidate modes of one body, as columns, and their blocks.
#[derive(Clone, Debug)]
pub struct CandidateSet {
    /// Coordinates per vertex.
    pub dim: usize,
    /// Every candidate mode as a column (`dim * n` rows, zero on prescribed dofs), block
    /// after block.
    pub modes: Mat<f64>,
    /// The blocks, in column order: rigid, affine, the linear modes, then any data modes.
    pub blocks: Vec<Block>,
    /// The linear modes' eigenvalues and residuals (their columns are also in `modes`).
    pub linear: Option<LinearModes>,
}

impl CandidateSet {
    /// The candidates of `body` with the elastic terms `elastic` (whose rest-shape Hessian
    /// is the stiffness of the linear modes).
    pub fn new(body: &Body, elastic: &[&dyn StencilEnergy], spec: &CandidateSpec) -> Result<Self, CandidateError> {
        body.validate()?;
        let mut columns: Vec<MatRef<'_, f64>> = Vec::new();
        let mut kinds = Vec::new();
        let affine = if spec.rigid || spec.affine {
            let rigid_count = rigid_modes(body)?.ncols();
            Some((affine_modes(body)?, rigid_count))
        } else {
            None
        };
        if let Some((modes, rigid_count)) = &affine {
            if spec.rigid {
                columns.push(modes.as_ref().subcols(0, *rigid_count));
                kinds.push(BlockKind::Rigid);
            }
            if spec.affine {
                columns.push(modes.as_ref().subcols(*rigid_count, modes.ncols() - rigid_count));
                kinds.push(BlockKind::Affine);
            }
        }
        let linear = if spec.linear_modes > 0 {
            Some(linear_modes(body, elastic, spec.linear_modes, &spec.settings)?)
        } else {
            None
        };
        if let Some(l) = &linear {
            for j in 0..l.modes.ncols() {
                columns.push(l.modes.as_ref().subcols(j, 1));
                kinds.push(BlockKind::LinearMode(j));
            }
        }
        let total: usize = columns.iter().map(|c| c.ncols()).sum();
        let mut modes = Mat::zeros(body.num_dofs(), total);
        let mut blocks = Vec::with_capacity(kinds.len());
        let mut at = 0;
        for (block, kind) in columns.iter().zip(kinds) {
            modes.as_mut().subcols_mut(at, block.ncols()).copy_from(block);
            blocks.push(Block {
                kind,
                columns: at..at + block.ncols(),
            });
            at += block.ncols();
        }
        Ok(CandidateSet {
            dim: body.dim,
            modes,
            blocks,
            linear,
        })
    }

    /// Appends `modes` (columns over the body's dofs, zero on prescribed ones, such as
    /// [`data_modes`] makes) as one block each.
    pub fn with_data_modes(mut self, modes: Mat<f64>) -> Result<Self, CandidateError> {
        if modes.nrows() != self.modes.nrows() {
            return Err(CandidateError::InvalidBody(format!(
                "data modes have {} rows, the candidates {}",
                modes.nrows(),
                self.modes.nrows()
            )));
        }
        let at = self.modes.ncols();
        let mut all = Mat::zeros(self.modes.nrows(), at + modes.ncols());
        all.as_mut().subcols_mut(0, at).copy_from(self.modes.as_ref());
        all.as_mut().subcols_mut(at, modes.ncols()).copy_from(modes.as_ref());
        self.blocks.extend((0..modes.ncols()).map(|j| Block {
            kind: BlockKind::DataMode(j),
            columns: at + j..at + j + 1,
        }));
        self.modes = all;
        Ok(self)
    }

    /// The columns of block `b`.
    pub fn block(&self, b: usize) -> MatRef<'_, f64> {
        let range = self.blocks[b].columns.clone();
        self.modes.as_ref().subcols(range.start, range.len())
    }
}
