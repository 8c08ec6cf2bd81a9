//! Errors for bad input: every one names the file and the line, field or element at fault.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in an input file a problem is.
#[derive(Debug, Clone, PartialEq)]
pub enum Location {
    /// The file as a whole.
    File,
    /// A 1-based line number.
    Line(usize),
    /// A dotted field path in a structured file, e.g. `material.youngs`.
    Field(String),
    /// A 0-based element (or vertex, stencil) index.
    Element(usize),
}

/// A problem with an input file (mesh, scene, artifact, dataset).
#[derive(Debug, Clone, PartialEq)]
pub struct InputError {
    /// The file the problem is in (or a description such as `<procedural box>`).
    pub file: PathBuf,
    /// Where in the file.
    pub location: Location,
    /// What is wrong.
    pub message: String,
}

impl InputError {
    /// Builds an error at `location` of `file`.
    pub fn new(file: impl AsRef<Path>, location: Location, message: impl Into<String>) -> Self {
        InputError {
            file: file.as_ref().to_path_buf(),
            location,
            message: message.into(),
        }
    }
    /// Error at a 1-based line.
    pub fn line(file: impl AsRef<Path>, line: usize, message: impl Into<String>) -> Self {
        Self::new(file, Location::Line(line), message)
    }
    /// Error at a named field.
    pub fn field(file: impl AsRef<Path>, field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(file, Location::Field(field.into()), message)
    }
    /// Error at a 0-based element index.
    pub fn element(file: impl AsRef<Path>, element: usize, message: impl Into<String>) -> Self {
        Self::new(file, Location::Element(element), message)
    }
    /// Error about the file as a whole.
    pub fn file(file: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Self::new(file, Location::File, message)
    }
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let file = self.file.display();
        match &self.location {
            Location::File => write!(f, "{file}: {}", self.message),
            Location::Line(l) => write!(f, "{file}:{l}: {}", self.message),
            Location::Field(name) => write!(f, "{file}: field `{name}`: {}", self.message),
            Location::Element(e) => write!(f, "{file}: element {e}: {}", self.message),
        }
    }
}

impl std::error::Error for InputError {}

/// Errors of the simulator's library calls: bad input, a failed step, a file that cannot be
/// written.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A problem with an input file or value.
    #[error(transparent)]
    Input(#[from] InputError),
    /// A full-space step failed while simulating a sequence.
    #[error("simulating {sequence} of `{scene}`: {source}")]
    Step {
        /// The scene's name.
        scene: String,
        /// The sequence's name.
        sequence: String,
        /// Why the step failed.
        source: StepError,
    },
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
}

/// Why a step could not be taken.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum StepError {
    /// A boundary-condition target was NaN or infinite.
    #[error("boundary condition target for vertex {vertex} is not finite ({value})")]
    NonFiniteBoundary {
        /// The prescribed vertex.
        vertex: usize,
        /// The offending coordinate.
        value: f64,
    },
    /// The wrong number of boundary-condition targets was given.
    #[error("expected {expected} boundary-condition coordinates, got {got}")]
    BoundaryLength {
        /// Prescribed vertices times dim.
        expected: usize,
        /// What was passed.
        got: usize,
    },
    /// The state became NaN or infinite (e.g. a singular system).
    #[error("frame {frame}: the solver produced a non-finite state at Newton iteration {iteration}")]
    Diverged {
        /// The frame the step was computing (0: the initial static equilibrium).
        frame: usize,
        /// Iteration at which it happened.
        iteration: usize,
    },
    /// The objective, its gradient or its Hessian held a NaN or an infinity: a material,
    /// load or state too large for `f64`. The step stops there rather than searching on.
    #[error(
        "frame {frame}, Newton iteration {iteration}: the {quantity} is not finite (NaN or \
         infinite); a material parameter, load or velocity is too large for the solver"
    )]
    NonFinite {
        /// The frame the step was computing (0: the initial static equilibrium).
        frame: usize,
        /// Iteration at which it happened.
        iteration: usize,
        /// Which quantity.
        quantity: Quantity,
    },
    /// The Hessian stayed indefinite through every diagonal shift the factorisation tries.
    #[error(
        "frame {frame}, Newton iteration {iteration}: the Hessian could not be factorised, \
         not even with a diagonal shift of {shift:e}"
    )]
    Unfactorisable {
        /// The frame the step was computing (0: the initial static equilibrium).
        frame: usize,
        /// Iteration at which it happened.
        iteration: usize,
        /// The largest shift tried.
        shift: f64,
    },
    /// The wrong number of collider poses was given.
    #[error("expected a pose for each of the {expected} colliders, got {got}")]
    ColliderCount {
        /// Colliders of the scene.
        expected: usize,
        /// Poses passed.
        got: usize,
    },
    /// The adaptive model could not be updated or its system solved.
    #[error("adaptive solver, Newton iteration {iteration}: {message}")]
    Adaptive {
        /// Iteration at which it happened.
        iteration: usize,
        /// What went wrong.
        message: String,
    },
}

/// A quantity of Newton's objective that [`StepError::NonFinite`] names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    /// The objective (incremental potential: inertia, elastic and external energies).
    Energy,
    /// Its gradient.
    Gradient,
    /// Its assembled Hessian.
    Hessian,
}

impl fmt::Display for Quantity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Quantity::Energy => "energy",
            Quantity::Gradient => "energy gradient",
            Quantity::Hessian => "Hessian",
        })
    }
}
