//! mochi trainer: full-space finite-element simulation, datasets, training and evaluation.

pub mod artifact;
pub mod bc;
pub mod chart;
pub mod dataset;
pub mod demo;
pub mod encoding;
pub mod energy;
pub mod error;
pub mod eval;
pub mod framing;
pub mod latent;
pub mod loss;
pub mod material;
pub mod mesh;
pub mod model;
pub mod pca;
pub mod render;
pub mod runtime_bench;
pub mod scene;
pub mod solver;
pub mod storage;
pub mod stretch;
pub mod train;
pub mod trajectory;

pub use error::{InputError, Location};

/// Environment variable candle (and rayon) read for their thread count.
pub const THREADS_VAR: &str = "RAYON_NUM_THREADS";

/// Sets up the thread pools every trainer program (`mochi` and the examples) runs with; call
/// it first thing in `main`, before any thread starts.
///
/// Assembly runs in parallel (rayon); the sparse factorisation runs sequentially: at these
/// sizes on small machines faer's parallel factorisation spends more time synchronising than
/// it saves (beam: 80 -> 61 ms/step on 2 cores, `mochi bench sim beam`). candle asks for its
/// thread count on every matrix product and, unless `RAYON_NUM_THREADS` is set, answers by
/// parsing /proc/cpuinfo each time (candle-core 0.11, `utils::get_num_threads`); setting it
/// once to rayon's own default (the logical cores) keeps every rayon pool's size and skips
/// the reads. candle's element-wise kernels run on a separate pool of spinning threads
/// (`CANDLE_NUM_THREADS`) that competes with the physics loss's rayon workers for the same
/// cores: on one thread they run inline. With the bending kernel's gradient-only path,
/// 6-epoch integrator runs on `cloth` went from 25.7 / 29.5 s to 17.7 / 19.7 s on 2 cores. A
/// value the user set wins.
pub fn configure_threads() {
    faer::set_global_parallelism(faer::Par::Seq);
    for (name, threads) in [
        (THREADS_VAR, std::thread::available_parallelism().map_or(1, |n| n.get())),
        ("CANDLE_NUM_THREADS", 1),
    ] {
        if std::env::var_os(name).is_none() {
            std::env::set_var(name, threads.to_string());
        }
    }
}
