//! mochi's full-space simulator: meshes and their readers, materials, one definition of
//! every energy (elastic, inertia, external, collision), the Newton solver with implicit
//! Euler or BDF2, boundary conditions, scenes (`Scene`, read from TOML), dataset sequences
//! and trajectories (`.npz`).
//!
//! Depends on no learning, charting or command-line crate: someone who wants the FEM
//! solver gets only that. The layers above (the trainer's learning, evaluation and CLI)
//! build on it; nothing here reaches up to them.

pub mod adaptive;
pub mod bc;
pub mod contact;
pub mod cubature;
pub mod dataset;
pub(crate) mod dofs;
pub mod energy;
pub mod error;
pub(crate) mod hessian;
pub mod material;
pub mod measure;
pub mod mesh;
pub mod npz;
pub mod progress;
pub mod scene;
pub mod solver;
pub mod trajectory;
pub mod vbd;

pub use adaptive::AdaptiveSettings;
pub use bc::Handle;
pub use dataset::{SpeedPlan, Split};
pub use energy::StencilEnergy;
pub use error::{InputError, Location, SimError};
pub use material::{ElementMaterial, MaterialLaw};
pub use mesh::io::MeshKind;
pub use mesh::{Elements, Mesh};
pub use progress::{Progress, Silent};
pub use scene::{BuiltScene, Scene, SceneDocument, SolverSpec};
pub use solver::{Simulator, SimulatorConfig, TimeScheme};
pub use trajectory::Trajectory;
pub use vbd::VbdSettings;
