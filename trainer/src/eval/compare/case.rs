//! Cases for peers run from their own packages (`scripts/xpbd.sh`): one `.npz` per sequence
//! or condition with the mesh, the material, the handles' path at every frame and the
//! reference positions, so that a peer steps exactly the motion every other method steps.
//!
//! Layout (numpy names and shapes): `kind` ("solid", "cloth", "rod" or "planar"), `rest` and
//! `initial` (n, 3), `cells` (m, 4 | 3 | 2; int64), `mass` (n,) lumped vertex masses,
//! `handles` (k,) int64 and `targets` (frames + 1, k, 3), `dt`, `gravity` (3,), `youngs`,
//! `poisson`, `density`, `thickness` and `radius` (NaN where the scene has none),
//! `material_model`, `reference` (frames + 1, n, 3) and `diagonal`. Coordinates of 2-D
//! meshes get z = 0.

use std::path::Path;

use mochi_sim::bc::BcSequence;
use mochi_sim::npz::NpzOut;
use mochi_sim::{BuiltScene, Elements};

use crate::error::{TrainerError, TrainerResult};

/// Writes the case of `problem` moved by `bc`, with `reference` positions (frames `0..`).
pub fn write_case(path: &Path, problem: &BuiltScene, bc: &BcSequence, reference: &[Vec<f64>]) -> TrainerResult<()> {
    write(path, problem, bc, reference).map_err(|e| TrainerError::io(path, e))
}

fn write(path: &Path, problem: &BuiltScene, bc: &BcSequence, reference: &[Vec<f64>]) -> std::io::Result<()> {
    let mesh = &problem.mesh;
    let dim = mesh.dim;
    let n = mesh.num_vertices() as u64;
    let pad = |x: &[f64]| -> Vec<f64> {
        x.chunks_exact(dim)
            .flat_map(|p| [p[0], p[1], if dim == 3 { p[2] } else { 0.0 }])
            .collect()
    };
    let (kind, width, cells): (&str, u64, Vec<i64>) = match &mesh.elements {
        Elements::Tets(t) => ("solid", 4, t.iter().flatten().map(|&v| v as i64).collect()),
        Elements::Triangles(t) => ("planar", 3, t.iter().flatten().map(|&v| v as i64).collect()),
        Elements::Shell(t) => ("cloth", 3, t.iter().flatten().map(|&v| v as i64).collect()),
        Elements::Rods(r) => (
            "rod",
            2,
            r.iter()
                .flat_map(|rod| rod.windows(2).flat_map(|w| [w[0] as i64, w[1] as i64]))
                .collect(),
        ),
    };
    let frames = reference.len().min(bc.frames() + 1) as u64;
    let handles: Vec<i64> = problem
        .handles
        .iter()
        .flat_map(|h| h.vertices.iter().map(|&v| v as i64))
        .collect();
    let material = &problem.scene.material;
    let mut npz = NpzOut::create(path)?;
    npz.strings("kind", &[], [kind])?;
    npz.array("rest", &[n, 3], pad(&mesh.rest))?;
    npz.array("initial", &[n, 3], pad(&reference[0]))?;
    npz.array("cells", &[cells.len() as u64 / width, width], cells.iter().copied())?;
    npz.array("mass", &[n], problem.simulator.masses().iter().copied())?;
    npz.array("handles", &[handles.len() as u64], handles.iter().copied())?;
    npz.array(
        "targets",
        &[frames, handles.len() as u64, 3],
        (0..frames as usize).flat_map(|t| pad(&bc.targets(&problem.handles, t, dim))),
    )?;
    npz.array("dt", &[], [problem.scene.dt])?;
    npz.array("gravity", &[3], problem.scene.gravity)?;
    npz.array("youngs", &[], [material.youngs])?;
    npz.array("poisson", &[], [material.poisson])?;
    npz.array("density", &[], [material.density])?;
    npz.array("thickness", &[], [material.thickness.unwrap_or(f64::NAN)])?;
    npz.array("radius", &[], [material.radius.unwrap_or(f64::NAN)])?;
    let law = format!("{:?}", material.model);
    npz.strings("material_model", &[], [law.as_str()])?;
    npz.array(
        "reference",
        &[frames, n, 3],
        reference[..frames as usize].iter().flat_map(|x| pad(x)),
    )?;
    npz.array("diagonal", &[], [mesh.rest_diagonal()])?;
    npz.finish()
}
