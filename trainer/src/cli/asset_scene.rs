//! The ready-to-edit scene `mochi mesh` writes beside an asset's tet mesh: the mesh file
//! (normalised to a 1 m body, centred), gravity along -y, a soft default material, one handle
//! shaken at varying speeds, and the dataset plan of the shipped scenes.

use std::path::Path;

use mochi_sim::mesh::asset::repair::Repaired;
use mochi_sim::Mesh;

/// One mesher run.
#[derive(Clone, Debug, PartialEq)]
pub struct MesherRun {
    /// Target edge length given.
    pub edge_length: f64,
    /// fTetWild's envelope: how far the tet mesh's surface may be from the asset's, relative
    /// to the bounding-box diagonal.
    pub epsilon: f64,
    /// Vertices and tets made.
    pub vertices: usize,
    /// Tets made.
    pub tets: usize,
    /// The mesher's own time (s).
    pub seconds: f64,
    /// Separate pieces the mesher dropped (all but the largest by volume: nothing would hold
    /// them to the body; their render vertices ride on the nearest kept tet).
    pub islands_dropped: usize,
    /// Vertices of the dropped pieces.
    pub island_vertices: usize,
}

/// Which vertices the scene's handle takes, in the asset's frame.
#[derive(Clone, Debug, PartialEq)]
pub enum HandleChoice {
    /// The tet vertices in a named part's bounding box (grown by 1% of the diagonal).
    Part {
        /// The part's name.
        name: String,
        /// Box corners.
        min: [f64; 3],
        /// Box corners.
        max: [f64; 3],
        /// Tet vertices inside.
        vertices: usize,
    },
    /// The tet vertices within `tolerance` of the y extent above the lowest.
    Bottom {
        /// Relative to the y extent.
        tolerance: f64,
        /// Tet vertices taken.
        vertices: usize,
    },
}

impl HandleChoice {
    /// In words, for the summary.
    pub fn describe(&self) -> String {
        match self {
            HandleChoice::Part { name, vertices, .. } => format!("part `{name}` ({vertices} tet vertices in its box)"),
            HandleChoice::Bottom { tolerance, vertices } => {
                format!("bottom {:.0}% along y ({vertices} tet vertices)", 100.0 * tolerance)
            }
        }
    }
}

/// The scene's TOML text. The mesh path is written relative to the scene file (both in one
/// directory).
pub fn scene_toml(
    name: &str,
    asset: &Path,
    mesh_path: &Path,
    mesh: &Mesh,
    handle: &HandleChoice,
    repaired: &Repaired,
    runs: &[MesherRun],
) -> String {
    let (lo, hi) = mesh.bounding_box(&mesh.rest);
    let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    let centre: Vec<f64> = (0..3).map(|k| 0.5 * (lo[k] + hi[k])).collect();
    // The loader's normalisation (centre on the box, divide by the largest extent), applied to
    // a point of the asset's frame.
    let normalised = |p: [f64; 3]| -> [f64; 3] { [0, 1, 2].map(|k| (p[k] - centre[k]) / extent) };
    let select = match handle {
        HandleChoice::Part { min, max, .. } => {
            let (a, b) = (normalised(*min), normalised(*max));
            format!("{{ box = {{ min = {}, max = {} }} }}", array(a), array(b))
        }
        HandleChoice::Bottom { tolerance, .. } => {
            format!("{{ side = {{ axis = 1, end = \"min\", tolerance = {tolerance} }} }}")
        }
    };
    let handle_name = match handle {
        HandleChoice::Part { name, .. } => toml_string(name),
        HandleChoice::Bottom { .. } => "\"base\"".into(),
    };
    let mesh_file = mesh_path
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default();
    // `mochi mesh` writes the render embedding beside the mesh: `STEM.render.npz`.
    let render_file = mesh_path
        .file_stem()
        .map(|s| format!("{}.render.npz", s.to_string_lossy()))
        .unwrap_or_default();
    let last = runs.last();
    let report = &repaired.report;
    format!(
        r#"# Written by `mochi mesh {asset}`: edit freely. The tet mesh {mesh_file} is in the asset's
# units and frame; the render mesh rides on it through {render_file}.
# Repair: {summary}
# Tet mesh: {vertices} vertices, {tets} tets (fTetWild, target edge {edge:.4e} in asset units,
# envelope {epsilon:.1e} of the diagonal){islands}.
name = {quoted_name}
description = "Surface asset {asset_file} as a soft body: {handle_words}, shaken at varying speeds, under gravity"
dt = 0.0333333333333333
gravity = [0.0, -9.81, 0.0]

[mesh]
type = "file"
path = {quoted_mesh}
# The body is simulated centred and 1 m across its largest extent (the handle box below is
# in that frame); the render embedding's weights do not depend on the scale.
normalize = true
# The render mesh riding on the tets: trained models carry it (`mochi export`, the runtime's
# render decode).
render = {quoted_render}

[material]
# A soft default (a firm jelly, which holds a 1 m body up against gravity): Young's modulus in
# Pa, density in kg/m^3.
model = "stable-neo-hookean"
youngs = 3e5
poisson = 0.45
density = 1000.0

[[handles]]
name = {handle_name}
select = {select}

[handles.motion]
segment_frames = [10, 25]
directions = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
rotation_axes = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]
rotation_share = 0.3
speed = [0.1, 0.6]
angular_speed = [0.3, 1.2]

[dataset]
train = 6
test = 4
frames = 150
seed = 1
beyond = 1.5
"#,
        asset = asset.display(),
        asset_file = asset
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default()
            .replace('"', "'"),
        summary = report.summary(),
        vertices = mesh.num_vertices(),
        tets = mesh.num_elements(),
        edge = last.map_or(0.0, |r| r.edge_length),
        epsilon = last.map_or(0.0, |r| r.epsilon),
        islands = match last {
            Some(r) if r.islands_dropped > 0 => format!(
                ";\n# {} separate piece(s) of {} vertices dropped (nothing held them to the body; their\n\
                 # render vertices ride on the nearest kept tet)",
                r.islands_dropped, r.island_vertices
            ),
            _ => String::new(),
        },
        quoted_name = toml_string(name),
        quoted_mesh = toml_string(&mesh_file),
        quoted_render = toml_string(&render_file),
        handle_words = handle.describe().replace('`', "").replace('"', "'"),
    )
}

fn array(p: [f64; 3]) -> String {
    format!("[{:.6}, {:.6}, {:.6}]", p[0], p[1], p[2])
}

/// A TOML basic string.
fn toml_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => out.push_str(&format!("\\u{:04X}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}
