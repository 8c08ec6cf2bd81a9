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
//!
//! A scene with IPC contact obstacles (`[[contact.obstacles]]`) adds, for its o obstacles:
//! `obstacle_kinds` (o,) ("box", or "mesh" for an OBJ file, which no peer reads yet),
//! `obstacle_extents` (o, 3) a box's edge lengths (max - min; NaN for a mesh),
//! `obstacle_rotations` (o, 3) a box's rotation vector about its centre (zeros without one),
//! `obstacle_centres` (frames + 1, o, 3) where each box's centre is at every frame (for a
//! mesh: its scripted translation), placed by the simulator's own keyframe motion
//! ([`ContactObstacle::offset_at`] at the frame's time), and `contact_dhat`,
//! `contact_friction`, `contact_epsv`. A scene without them writes none of these keys.

use std::path::Path;

use mochi_sim::bc::BcSequence;
use mochi_sim::contact::ContactSurface;
use mochi_sim::npz::NpzOut;
use mochi_sim::scene::ObstacleMesh;
use mochi_sim::solver::ContactObstacle;
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
    write_obstacles(&mut npz, problem, frames)?;
    npz.finish()
}

/// The contact obstacles' keys (none when the scene has no obstacle meshes).
fn write_obstacles(npz: &mut NpzOut, problem: &BuiltScene, frames: u64) -> std::io::Result<()> {
    let Some(spec) = problem.scene.contact.as_ref().filter(|c| !c.obstacles.is_empty()) else {
        return Ok(());
    };
    // The simulator's own obstacles, for their scripted motion.
    let built = spec
        .build(ContactSurface::of_mesh(&problem.mesh), &problem.scene.source)
        .map_err(|e| std::io::Error::other(e.to_string()))?;
    let obstacles: Vec<(&ObstacleMesh, &ContactObstacle)> = spec.obstacles.iter().zip(&built.obstacles).collect();
    let o = obstacles.len() as u64;
    let box_of = |mesh: &ObstacleMesh| match mesh {
        ObstacleMesh::Box { min, max, rotation, .. } => Some((*min, *max, rotation.unwrap_or([0.0; 3]))),
        ObstacleMesh::File { .. } => None,
    };
    let kinds: Vec<&str> = obstacles
        .iter()
        .map(|(m, _)| if box_of(m).is_some() { "box" } else { "mesh" })
        .collect();
    npz.strings("obstacle_kinds", &[o], kinds.iter().copied())?;
    npz.array(
        "obstacle_extents",
        &[o, 3],
        obstacles.iter().flat_map(|(m, _)| match box_of(m) {
            Some((min, max, _)) => [0, 1, 2].map(|i| max[i] - min[i]),
            None => [f64::NAN; 3],
        }),
    )?;
    npz.array(
        "obstacle_rotations",
        &[o, 3],
        obstacles.iter().flat_map(|(m, _)| box_of(m).map_or([0.0; 3], |b| b.2)),
    )?;
    // Frame t is at time t dt, as the simulator places its obstacles at the end of step t.
    let dt = problem.simulator.dt();
    npz.array(
        "obstacle_centres",
        &[frames, o, 3],
        (0..frames).flat_map(|t| {
            obstacles.iter().flat_map(move |(m, c)| {
                let offset = c.offset_at(t as f64 * dt);
                let centre = box_of(m).map_or([0.0; 3], |(min, max, _)| [0, 1, 2].map(|i| 0.5 * (min[i] + max[i])));
                [0, 1, 2].map(|i| centre[i] + offset[i])
            })
        }),
    )?;
    npz.array("contact_dhat", &[], [spec.dhat])?;
    npz.array("contact_friction", &[], [spec.friction])?;
    npz.array("contact_epsv", &[], [spec.epsv])?;
    Ok(())
}
