//! Simulates a scene's dataset (full space, IPC contact with its analytic colliders) and
//! prints the time per frame, the Newton iterations per frame and the smallest distance of a
//! surface vertex to a collider over every frame: `collider_dataset SCENE.toml OUT_DIR`.
//! (`mochi dataset SCENE` writes the same files and prints the same figures.)

use std::error::Error;
use std::path::Path;

use mochi_sim::scene::read_text;
use mochi_sim::{dataset, SceneDocument, Silent};

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let usage = "usage: collider_dataset SCENE.toml OUT_DIR";
    let path = args.next().ok_or(usage)?;
    let out = args.next().ok_or(usage)?;
    let text = read_text(Path::new(&path))?;
    let mut doc = SceneDocument::parse(&text, Path::new(&path))?;
    for table in ["latent", "reduced"] {
        doc.take_section::<toml::Table>(table)?;
    }
    let scene = doc.into_scene()?;
    let mut problem = scene.build()?;
    let report = dataset::generate(&mut problem, Path::new(&out), None, true, &Silent)?;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let most = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    println!(
        "{}: {} sequences, {} frames in {:.1} s; {:.1} ms/frame (most {:.1}), {:.2} Newton iterations/frame (most {}); smallest vertex-collider distance {}",
        scene.name,
        report.sequences,
        report.step_seconds.len(),
        report.seconds,
        1e3 * mean(&report.step_seconds),
        1e3 * most(&report.step_seconds),
        mean(&report.newton_iterations),
        most(&report.newton_iterations),
        report
            .collider_min_distance
            .map_or("none (no colliders)".into(), |d| format!("{d:.3e} m")),
    );
    Ok(())
}
