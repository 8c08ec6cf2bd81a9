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
//! A scene with IPC contact obstacles (`[[contact.obstacles]]`) or run-time colliders
//! (`[[colliders]]`, after the obstacles, on the sequence's paths) adds, for its o obstacles:
//! `obstacle_kinds` (o,) ("box"; "mesh" for an OBJ file, "sphere", "capsule": no peer reads
//! those yet),
//! `obstacle_extents` (o, 3) a box's edge lengths (max - min; NaN for other kinds),
//! `obstacle_rotations` (o, 3) a box's rotation vector about its centre (zeros without one),
//! `obstacle_centres` (frames + 1, o, 3) where each box's centre is at every frame (for a
//! mesh: its scripted translation), placed by the simulator's own keyframe motion
//! ([`mochi_sim::solver::ContactObstacle::offset_at`] at the frame's time) or, for a
//! collider, its pose on the sequence's path at the frame, and `contact_dhat`,
//! `contact_friction`, `contact_epsv`. A scene without them writes none of these keys.

use std::path::Path;

use mochi_sim::bc::BcSequence;
use mochi_sim::contact::ContactSurface;
use mochi_sim::npz::NpzOut;
use mochi_sim::scene::{ContactSpec, ObstacleMesh, ShapeKind};
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
    write_obstacles(&mut npz, problem, bc, frames)?;
    npz.finish()
}

/// One obstacle as a case gives it to a peer.
struct CaseObstacle {
    /// "box", "mesh", "sphere" or "capsule".
    kind: &'static str,
    /// A box's edge lengths (NaN for other kinds).
    extents: [f64; 3],
    /// Rotation vector about its centre.
    rotation: [f64; 3],
    /// Its centre at every frame.
    centres: Vec<[f64; 3]>,
}

/// The contact obstacles' keys (none when the scene has neither obstacle meshes nor
/// run-time colliders): the scripted obstacles first, then the run-time colliders on `bc`'s
/// paths.
fn write_obstacles(npz: &mut NpzOut, problem: &BuiltScene, bc: &BcSequence, frames: u64) -> std::io::Result<()> {
    let Some(spec) = problem.scene.contact.as_ref() else {
        return Ok(());
    };
    let mut obstacles = scripted_obstacles(problem, spec, frames)?;
    obstacles.extend(run_time_colliders(problem, bc, frames)?);
    if obstacles.is_empty() {
        return Ok(());
    }
    let o = obstacles.len() as u64;
    npz.strings("obstacle_kinds", &[o], obstacles.iter().map(|b| b.kind))?;
    npz.array("obstacle_extents", &[o, 3], obstacles.iter().flat_map(|b| b.extents))?;
    npz.array("obstacle_rotations", &[o, 3], obstacles.iter().flat_map(|b| b.rotation))?;
    npz.array(
        "obstacle_centres",
        &[frames, o, 3],
        (0..frames as usize).flat_map(|t| obstacles.iter().flat_map(move |b| b.centres[t])),
    )?;
    npz.array("contact_dhat", &[], [spec.dhat])?;
    npz.array("contact_friction", &[], [spec.friction])?;
    npz.array("contact_epsv", &[], [spec.epsv])?;
    Ok(())
}

/// The scene's `[[contact.obstacles]]`, placed by the simulator's own keyframe motion.
fn scripted_obstacles(problem: &BuiltScene, spec: &ContactSpec, frames: u64) -> std::io::Result<Vec<CaseObstacle>> {
    if spec.obstacles.is_empty() {
        return Ok(Vec::new());
    }
    // The simulator's own obstacles, for their scripted motion.
    let built = spec
        .build(ContactSurface::of_mesh(&problem.mesh), &problem.scene.source)
        .map_err(|e| std::io::Error::other(e.to_string()))?;
    // Frame t is at time t dt, as the simulator places its obstacles at the end of step t.
    let dt = problem.simulator.dt();
    Ok(spec
        .obstacles
        .iter()
        .zip(&built.obstacles)
        .map(|(mesh, scripted)| {
            // A mesh's centre is its scripted translation alone.
            let (kind, extents, centre, rotation) = match mesh {
                ObstacleMesh::Box { min, max, rotation, .. } => (
                    "box",
                    [0, 1, 2].map(|i| max[i] - min[i]),
                    [0, 1, 2].map(|i| 0.5 * (min[i] + max[i])),
                    rotation.unwrap_or([0.0; 3]),
                ),
                ObstacleMesh::File { .. } => ("mesh", [f64::NAN; 3], [0.0; 3], [0.0; 3]),
            };
            let centres = (0..frames)
                .map(|t| {
                    let offset = scripted.offset_at(t as f64 * dt);
                    [0, 1, 2].map(|i| centre[i] + offset[i])
                })
                .collect();
            CaseObstacle {
                kind,
                extents,
                rotation,
                centres,
            }
        })
        .collect())
}

/// The scene's `[[colliders]]` on `bc`'s paths (a box keeps its frame-0 rotation: a path
/// turns only capsules, which no peer takes).
fn run_time_colliders(problem: &BuiltScene, bc: &BcSequence, frames: u64) -> std::io::Result<Vec<CaseObstacle>> {
    let specs = &problem.scene.colliders;
    if bc.colliders.len() != specs.len() {
        return Err(std::io::Error::other(format!(
            "the sequence has {} collider tracks, the scene {} colliders",
            bc.colliders.len(),
            specs.len()
        )));
    }
    specs
        .iter()
        .zip(&bc.colliders)
        .map(|(spec, track)| {
            if track.poses.len() < frames as usize {
                return Err(std::io::Error::other(format!(
                    "a collider track has {} poses, the case {frames} frames",
                    track.poses.len()
                )));
            }
            let (kind, extents) = match spec.shape {
                ShapeKind::Box => ("box", spec.half_extents.map_or([f64::NAN; 3], |h| h.map(|x| 2.0 * x))),
                ShapeKind::Sphere => ("sphere", [f64::NAN; 3]),
                ShapeKind::Capsule => ("capsule", [f64::NAN; 3]),
            };
            Ok(CaseObstacle {
                kind,
                extents,
                rotation: track.poses[0].rotation_vector(),
                centres: track.poses[..frames as usize].iter().map(|p| p.center.into()).collect(),
            })
        })
        .collect()
}
