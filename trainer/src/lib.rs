//! mochi trainer: learns latent spaces and integrators for the scenes that [`mochi_sim`]
//! simulates, writes them as artifacts for the runtime, and evaluates every method against
//! the full-space reference.
//!
//! Data flows one way, folder by folder: [`learn`] (the `[latent]` recipe, encoding, PCA,
//! networks, losses, the training loop) → [`artifact`] (the `.mochi` file, written through
//! the runtime's contract) → [`pipeline`] (`mochi train`'s named stages, from dataset to
//! artifacts) → [`eval`] (rollouts, `mochi eval`, weight storage, the runtime benchmark) →
//! [`cli`] (`mochi demo`); [`report`] draws charts and previews and [`progress`] reports long
//! work, for any of them.
//!
//! The library prints nothing: long calls report stages, messages and progress to a
//! [`Reporter`] the caller chooses ([`Quiet`] in tests), and fail with a [`TrainerError`].
//!
//! The API most programs need is re-exported here: a scene's [`Recipe`], [`train_scene`]
//! with its [`TrainOptions`] and [`TrainOutcome`], [`evaluate`] with its [`EvalOptions`],
//! the [`Artifact`] a training run writes, and the demo ([`run_demo`]).

pub mod artifact;
pub mod cli;
pub mod error;
pub mod eval;
pub mod export;
pub mod learn;
pub mod methods;
pub mod pipeline;
pub mod progress;
pub mod report;

pub use artifact::{Artifact, Method};
pub use cli::demo::{run as run_demo, DemoOptions, DemoReport};
pub use error::{TrainerError, TrainerResult};
pub use eval::{evaluate, EvalOptions, ModelReport};
pub use learn::recipe::{shipped_scene_names, Recipe};
pub use learn::train::TrainError;
pub use mochi_sim::{InputError, Location};
pub use pipeline::assemble::artifact_paths;
pub use pipeline::{train_scene, TrainOptions, TrainOutcome, FRAME_MEMORY};
pub use progress::{FramesBar, Quiet, Reporter};

/// Environment variable candle (and rayon) read for their thread count.
pub const THREADS_VAR: &str = "RAYON_NUM_THREADS";

/// Sets up the thread pools every trainer program (`mochi` and the examples) runs with; call
/// it first thing in `main`, before any thread starts.
///
/// Assembly runs in parallel (rayon); the sparse factorisation runs sequentially: at these
/// sizes on small machines faer's parallel factorisation spends more time synchronising than
/// it saves (`mochi bench sim`). candle asks for its thread count on every matrix product
/// (`utils::get_num_threads`: `RAYON_NUM_THREADS`, else a count of the CPUs each time);
/// setting it once to rayon's own default (the logical cores) keeps every rayon pool's size
/// and skips the counting. A value the user set wins.
pub fn configure_threads() {
    faer::set_global_parallelism(faer::Par::Seq);
    if std::env::var_os(THREADS_VAR).is_none() {
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        std::env::set_var(THREADS_VAR, threads.to_string());
    }
}
