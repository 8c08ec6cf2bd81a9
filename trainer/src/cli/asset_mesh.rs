//! `mochi mesh ASSET`: an artist's surface (glTF, OBJ, STL) in, a tet mesh, its render
//! embedding and a ready-to-edit scene out, so that `mochi train` can take the scene.
//!
//! Read and repair ([`mochi_sim::mesh::asset`]), then fTetWild through `scripts/tetwild.sh`
//! (PyPI `pytetwild` in its own virtual environment) at a target edge length or vertex count,
//! the tet mesh read back through the scene loader's own reader (so what it accepts, `mochi
//! train` accepts), the render vertices embedded in it, and the scene written beside it. Every
//! file is written whole or not at all.
//!
//! Files, for `-o DIR/NAME.mesh` (default `out/assets/NAME/NAME.mesh`, NAME the asset's stem):
//! `NAME.mesh` (MEDIT tets, in the asset's units and frame), `NAME.render.npz` (the render
//! mesh and its embedding, layout in [`mochi_sim::mesh::asset::render`]), `NAME.surface.npz`
//! (the repaired surface the mesher got: `vertices`, `faces`) and `NAME.toml` (the scene).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use mochi_sim::mesh::asset::render::RenderEmbedding;
use mochi_sim::mesh::asset::repair::{repair, RepairPolicy, Repaired};
use mochi_sim::mesh::asset::{read_surface, temporary_beside, write_atomically, Surface};
use mochi_sim::mesh::io::{load, MeshKind};
use mochi_sim::npz::NpzOut;
use mochi_sim::Mesh;

use super::asset_scene::{scene_toml, HandleChoice, MesherRun};

/// fTetWild's envelope (relative to the diagonal) for an edge length: its own default.
pub const DEFAULT_EPSILON: f64 = 1e-3;

/// The widest envelope a vertex-count target may ask for.
pub const MAX_EPSILON: f64 = 1.6e-2;

/// Most mesher runs a vertex-count target makes.
const MAX_RUNS: usize = 6;

/// The resolution of the tet mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Resolution {
    /// Target tet edge length, in the asset's units.
    EdgeLength(f64),
    /// Target number of tet-mesh vertices: up to six mesher runs stop within 20% of it, the
    /// surface envelope widened where the surface's detail holds the count up; the run closest
    /// to it is kept (the count is a target, not a promise).
    Vertices(usize),
}

/// What `mochi mesh` is asked to do.
#[derive(Clone, Debug)]
pub struct MeshOptions {
    /// The asset file.
    pub asset: PathBuf,
    /// Resolution; default: an edge of 1/20 of the bounding-box diagonal (fTetWild's default).
    pub resolution: Option<Resolution>,
    /// The tet mesh to write; the other files go beside it.
    pub out: Option<PathBuf>,
    /// Accept holes, non-manifold edges and self-intersections (fTetWild meshes the inside
    /// by winding number) instead of refusing them.
    pub accept_defects: bool,
    /// fTetWild's threads (0: all cores).
    pub threads: usize,
    /// Draw a spinner while the mesher runs.
    pub bar: bool,
}

/// What `mochi mesh` did.
#[derive(Clone, Debug)]
pub struct MeshOutcome {
    /// Repair's findings and the defects accepted.
    pub repaired: Repaired,
    /// Render vertices and triangles of the asset.
    pub render_size: (usize, usize),
    /// Named parts of the asset.
    pub parts: Vec<String>,
    /// Every mesher run (the one kept last).
    pub runs: Vec<MesherRun>,
    /// The kept tet mesh's vertices and tets.
    pub tet_size: (usize, usize),
    /// Largest distance of a render vertex from its tet, relative to the diagonal.
    pub max_render_distance: f64,
    /// The handle chosen, in words.
    pub handle: String,
    /// Files written.
    pub mesh_path: PathBuf,
    /// The scene.
    pub scene_path: PathBuf,
    /// The render embedding.
    pub render_path: PathBuf,
    /// The repaired surface.
    pub surface_path: PathBuf,
    /// Wall time of the whole command (s).
    pub seconds: f64,
}

/// Reads, repairs, tetrahedralises and embeds the asset, and writes the scene.
pub fn mesh_asset(options: &MeshOptions) -> Result<MeshOutcome> {
    let start = Instant::now();
    let asset = &options.asset;
    let surface = read_surface(asset)?;
    let policy = if options.accept_defects {
        RepairPolicy::accepting_defects()
    } else {
        RepairPolicy::default()
    };
    let repaired = repair(&surface, asset, &policy)
        .map_err(|e| anyhow!("{e}\n(`--accept-defects` lets fTetWild mesh the inside of an open, non-manifold or self-intersecting surface)"))?;
    let name = asset_name(asset);
    let mesh_path = options
        .out
        .clone()
        .unwrap_or_else(|| Path::new("out").join("assets").join(&name).join(format!("{name}.mesh")));
    if mesh_path.extension().and_then(|e| e.to_str()) != Some("mesh") {
        bail!(
            "{}: the tet mesh is written as MEDIT, so its name must end in .mesh",
            mesh_path.display()
        );
    }
    if let Some(dir) = mesh_path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let beside = |suffix: &str| {
        let stem = mesh_path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        mesh_path.with_file_name(format!("{stem}{suffix}"))
    };
    let (surface_path, render_path, scene_path) = (beside(".surface.npz"), beside(".render.npz"), beside(".toml"));
    write_surface_npz(&repaired, &surface_path)?;

    let runs = tetrahedralise(&repaired, &surface_path, &mesh_path, options)?;
    let mesh = load(&mesh_path, MeshKind::Solid).with_context(|| "reading the mesher's output back")?;
    let render = RenderEmbedding::new(&surface, &mesh)
        .map_err(|e| anyhow!("{}: embedding the render mesh: {e}", mesh_path.display()))?;
    render.write_npz(&render_path)?;
    let diagonal = surface.diagonal();
    let handle = choose_handle(&surface, &mesh);
    let toml = scene_toml(&name, asset, &mesh_path, &mesh, &handle, &repaired, &runs);
    write_atomically(&scene_path, toml.as_bytes()).with_context(|| format!("writing {}", scene_path.display()))?;
    // What `mochi train` will do with the scene: parse it and build the problem.
    let recipe = crate::Recipe::load(&scene_path.to_string_lossy())?;
    recipe.scene.build()?;
    Ok(MeshOutcome {
        render_size: (surface.positions.len(), surface.triangles.len()),
        parts: surface.parts.iter().filter_map(|p| p.name.clone()).collect(),
        repaired,
        tet_size: (mesh.num_vertices(), mesh.num_elements()),
        max_render_distance: render.max_distance() / diagonal,
        handle: handle.describe(),
        runs,
        mesh_path,
        scene_path,
        render_path,
        surface_path,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The asset's file stem as a scene name: letters, digits, `-` and `_`.
fn asset_name(asset: &Path) -> String {
    let stem = asset
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c.to_ascii_lowercase()
            } else {
                '-'
            }
        })
        .collect();
    if name.is_empty() {
        "asset".into()
    } else {
        name
    }
}

/// The repaired surface as the mesher script reads it.
fn write_surface_npz(repaired: &Repaired, path: &Path) -> Result<()> {
    let temporary = temporary_beside(path);
    let written = (|| -> std::io::Result<()> {
        let mut npz = NpzOut::create(&temporary)?;
        let (n, m) = (repaired.positions.len() as u64, repaired.triangles.len() as u64);
        npz.array("vertices", &[n, 3], repaired.positions.iter().flatten().copied())?;
        npz.array("faces", &[m, 3], repaired.triangles.iter().flatten().map(|&v| v as i64))?;
        npz.finish()?;
        std::fs::rename(&temporary, path)
    })();
    if let Err(e) = written {
        let _ = std::fs::remove_file(&temporary);
        bail!("{}: cannot write: {e}", path.display());
    }
    Ok(())
}

/// The mesher script: `MOCHI_TETWILD` if set, else `scripts/tetwild.sh` of this source tree.
fn mesher_script() -> PathBuf {
    std::env::var_os("MOCHI_TETWILD")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/tetwild.sh"))
}

/// Runs the mesher until the resolution is met (one run for an edge length; up to six for a
/// vertex count, each edge length corrected from the last counts), keeping the run closest to
/// the target at `mesh_path`; it comes last in the returned runs.
fn tetrahedralise(
    repaired: &Repaired,
    surface: &Path,
    mesh_path: &Path,
    options: &MeshOptions,
) -> Result<Vec<MesherRun>> {
    let diagonal = {
        let s = Surface {
            positions: repaired.positions.clone(),
            ..Surface::default()
        };
        s.diagonal()
    };
    let volume = repaired.report.volume.abs().max(1e-12 * diagonal.powi(3));
    let mut runs: Vec<MesherRun> = Vec::new();
    let (mut edge, target) = match options.resolution {
        None => (diagonal / 20.0, None),
        Some(Resolution::EdgeLength(l)) if l.is_finite() && l > 0.0 => (l, None),
        Some(Resolution::EdgeLength(l)) => bail!("--edge-length must be a positive length, got {l}"),
        Some(Resolution::Vertices(n)) if n >= 4 => {
            // About 0.45 e^3 of volume per vertex in a tet mesh of edge e (regular tets of
            // volume e^3 / (6 sqrt 2), about five per vertex); corrected from each run's count.
            ((volume / (0.45 * n as f64)).cbrt(), Some(n))
        }
        Some(Resolution::Vertices(n)) => bail!("--vertices must be at least 4, got {n}"),
    };
    let mut epsilon = DEFAULT_EPSILON;
    // Each run's mesh in a file of its own beside the output; the one closest to the target
    // is renamed to `mesh_path` and the others removed.
    let run_path = |k: usize| temporary_beside(&mesh_path.with_extension(format!("run{k}.mesh")));
    let outcome = (|| -> Result<()> {
        loop {
            let run = run_mesher(surface, &run_path(runs.len()), edge, epsilon, options)?;
            let made = run.vertices as f64;
            runs.push(run);
            let Some(n) = target else { return Ok(()) };
            let ratio = made / n as f64;
            if (ratio - 1.0).abs() <= 0.2 || runs.len() == MAX_RUNS {
                return Ok(());
            }
            // Vertices go as about edge^-3 in the volume, edge^-2 on the surface: the exponent
            // from the last two runs at this envelope where there are two, else 1/2.5.
            let exponent = match runs.as_slice() {
                [.., a, b] if a.epsilon == b.epsilon && a.vertices != b.vertices && a.edge_length != b.edge_length => {
                    let slope = ((b.vertices as f64).ln() - (a.vertices as f64).ln())
                        / (b.edge_length.ln() - a.edge_length.ln());
                    if slope < -0.5 {
                        -1.0 / slope
                    } else {
                        // The count hardly follows the edge: the surface's detail inside the
                        // envelope holds it; a wider envelope lets fTetWild simplify it, by
                        // about as much as the count is to fall.
                        if ratio > 1.0 {
                            epsilon = (ratio.clamp(2.0, 8.0) * epsilon).min(MAX_EPSILON);
                        }
                        0.4
                    }
                }
                _ => 0.4,
            };
            edge *= ratio.powf(exponent);
        }
    })();
    let best = target.map_or(runs.len().saturating_sub(1), |n| {
        let miss = |r: &MesherRun| (r.vertices as f64 / n as f64).ln().abs();
        (0..runs.len())
            .min_by(|&a, &b| miss(&runs[a]).total_cmp(&miss(&runs[b])))
            .unwrap_or(0)
    });
    let kept = match outcome {
        Ok(()) => {
            std::fs::rename(run_path(best), mesh_path).with_context(|| format!("writing {}", mesh_path.display()))
        }
        Err(e) => Err(e),
    };
    for k in 0..=runs.len() {
        let _ = std::fs::remove_file(run_path(k));
    }
    kept?;
    if best + 1 != runs.len() {
        let kept_run = runs.remove(best);
        runs.push(kept_run);
    }
    Ok(runs)
}

/// One run of the mesher script, with a spinner while it works.
fn run_mesher(surface: &Path, mesh_path: &Path, edge: f64, epsilon: f64, options: &MeshOptions) -> Result<MesherRun> {
    let script = mesher_script();
    let spinner = if options.bar {
        ProgressBar::new_spinner()
    } else {
        ProgressBar::hidden()
    };
    spinner.set_style(
        ProgressStyle::with_template("{spinner} {msg} {elapsed}").unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    spinner.set_message(format!("fTetWild, edge {edge:.4}, envelope {epsilon:.0e}"));
    spinner.enable_steady_tick(Duration::from_millis(120));
    let output = Command::new(&script)
        .arg("run")
        .arg(surface)
        .arg(mesh_path)
        .arg("--edge-length")
        .arg(format!("{edge:e}"))
        .arg("--epsilon")
        .arg(format!("{epsilon:e}"))
        .arg("--threads")
        .arg(options.threads.to_string())
        .output()
        .with_context(|| format!("running {}", script.display()))?;
    spinner.finish_and_clear();
    let stdout = String::from_utf8_lossy(&output.stdout);
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        let tail: Vec<&str> = stderr
            .lines()
            .rev()
            .take(6)
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect();
        bail!(
            "{}: the mesher failed ({}):\n{}",
            options.asset.display(),
            output.status,
            tail.join("\n")
        );
    }
    let line = stdout
        .lines()
        .rev()
        .find(|l| l.trim_start().starts_with('{'))
        .unwrap_or("");
    let number = |key: &str| -> Result<f64> {
        json_number(line, key).ok_or_else(|| anyhow!("the mesher's summary has no `{key}`: `{line}`"))
    };
    Ok(MesherRun {
        edge_length: edge,
        epsilon,
        vertices: number("vertices")? as usize,
        tets: number("tets")? as usize,
        seconds: number("seconds")?,
        islands_dropped: json_number(line, "islands_dropped").unwrap_or(0.0) as usize,
        island_vertices: json_number(line, "island_vertices").unwrap_or(0.0) as usize,
    })
}

/// The number after `"key":` in a one-line JSON object of numbers and strings.
fn json_number(line: &str, key: &str) -> Option<f64> {
    let after = line.split(&format!("\"{key}\":")).nth(1)?;
    let token: String = after
        .trim_start()
        .chars()
        .take_while(|c| c.is_ascii_digit() || matches!(c, '.' | '-' | '+' | 'e' | 'E'))
        .collect();
    token.parse().ok()
}

/// The handle: of an asset with several named parts (glTF nodes, OBJ objects), the part whose
/// bounding box holds the fewest tet vertices; else the bottom of the body along y (glTF's up).
fn choose_handle(surface: &Surface, mesh: &Mesh) -> HandleChoice {
    let pad = 0.01 * surface.diagonal();
    let in_box = |lo: [f64; 3], hi: [f64; 3]| {
        mesh.rest
            .chunks_exact(3)
            .filter(|p| (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]))
            .count()
    };
    let named = surface.parts.iter().filter_map(|p| {
        let (lo, hi) = surface.part_bounds(p);
        let (lo, hi) = (lo.map(|c| c - pad), hi.map(|c| c + pad));
        Some((p.name.clone()?, lo, hi, in_box(lo, hi)))
    });
    let parts: Vec<(String, [f64; 3], [f64; 3], usize)> = named.collect();
    if parts.len() >= 2 {
        // The part whose box holds the fewest tet vertices (at least 3): the rest stays free.
        if let Some((name, min, max, vertices)) = parts.into_iter().filter(|p| p.3 >= 3).min_by_key(|p| p.3) {
            return HandleChoice::Part {
                name,
                min,
                max,
                vertices,
            };
        }
    }
    let (lo, hi) = mesh.bounding_box(&mesh.rest);
    let extent = (hi[1] - lo[1]).max(f64::MIN_POSITIVE);
    let mut tolerance = 0.05;
    loop {
        let count = mesh
            .rest
            .chunks_exact(3)
            .filter(|p| p[1] - lo[1] <= tolerance * extent)
            .count();
        if count >= 3 || tolerance >= 0.5 {
            return HandleChoice::Bottom {
                tolerance,
                vertices: count,
            };
        }
        tolerance *= 2.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mesher_summary_line_is_read() {
        let line = r#"{"mesher": "ftetwild", "vertices": 770, "tets": 2354, "seconds": 2.929, "min_volume": 1.9e-01}"#;
        assert_eq!(json_number(line, "vertices"), Some(770.0));
        assert_eq!(json_number(line, "seconds"), Some(2.929));
        assert_eq!(json_number(line, "min_volume"), Some(0.19));
        assert_eq!(json_number(line, "flipped"), None);
    }

    #[test]
    fn scene_names_come_from_the_asset_stem() {
        assert_eq!(asset_name(Path::new("dir/My Jelly.v2.glb")), "my-jelly-v2");
        assert_eq!(asset_name(Path::new(".glb")), "-glb");
    }
}
