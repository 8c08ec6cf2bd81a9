//! Prints the lowest linear modes of a scene's body (its handles' vertices clamped), with
//! the time each stage took: `linear_modes SCENE.toml [COUNT]` (default 10 modes).
//!
//! Tables the simulator does not read (the trainer's `[latent]`, `[reduced]`) are skipped.

use std::error::Error;
use std::path::Path;
use std::time::Instant;

use mochi_sim::adaptive::candidates::CandidateSpec;
use mochi_sim::scene::read_text;
use mochi_sim::SceneDocument;

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: linear_modes SCENE.toml [COUNT]")?;
    let count: usize = match args.next() {
        Some(c) => c.parse().map_err(|e| format!("COUNT `{c}`: {e}"))?,
        None => 10,
    };
    let path = Path::new(&path);
    let text = read_text(path)?;
    let mut document = SceneDocument::parse(&text, path)?;
    for table in ["latent", "reduced"] {
        document.take_section::<toml::Table>(table)?;
    }
    let scene = document.into_scene()?;
    let start = Instant::now();
    let set = scene.candidate_set(&CandidateSpec {
        linear_modes: count,
        ..CandidateSpec::default()
    })?;
    let total = start.elapsed().as_secs_f64();
    let dofs = set.modes.nrows();
    println!(
        "scene `{}`: {dofs} dofs, {} candidate modes in {} blocks",
        scene.name,
        set.modes.ncols(),
        set.blocks.len()
    );
    if let Some(linear) = &set.linear {
        let t = linear.timings;
        println!(
            "linear modes: shift {:.3e}, {} restarts; assembly {:.3} s, factorisation {:.3} s, eigensolve {:.3} s; candidates in all {total:.3} s",
            linear.shift, linear.restarts, t.assembly, t.factorisation, t.eigensolve
        );
        println!(
            "{:>4} {:>14} {:>12} {:>12}",
            "mode", "lambda (1/s^2)", "freq (Hz)", "residual"
        );
        for (j, (l, f)) in linear.eigenvalues.iter().zip(linear.frequencies_hz()).enumerate() {
            println!("{j:>4} {l:>14.6e} {f:>12.5} {:>12.2e}", linear.residuals[j]);
        }
    }
    Ok(())
}
