//! `mochi export`: a trained model's rollout, out to engines and 3D tools.
//!
//! The runtime steps the model (in the weight storage asked for) on one motion of its own
//! scene, as [`crate::methods::learned::LearnedRuntime`] steps it for evaluation; every frame
//! the render mesh riding on the simulation mesh is decoded ([`mochi_runtime::render`]), or,
//! for a model without one, the simulation mesh's drawn surface; vertices inside a collider
//! are pushed out to its surface as an engine showing the model would
//! ([`mochi_runtime::push_out`], design decision 11); normals are recomputed from the
//! triangles. [`glb`] writes the frames as one glTF 2.0 binary.

pub mod glb;

use std::path::Path;

use mochi_codegen::{format_name, Options, Quantized};
use mochi_runtime::render::{render_positions, triangle_normals};
use mochi_runtime::{push_out, OwnedModel, ValidModel, WeightFormat};
use mochi_sim::dataset::SpeedPlan;

use crate::error::{bail, Context, TrainerError, TrainerResult as Result};
use crate::methods::learned::{collider_states, LearnedRuntime};
use crate::methods::method::Method;
use crate::{Artifact, Recipe};

/// What to roll out. Defaults: 120 frames, speed level 0.5, the scene's dataset seed, `f32`.
#[derive(Clone, Debug)]
pub struct ExportOptions {
    /// Frames after the first (at least 1).
    pub frames: usize,
    /// Speed of the sampled handle motion: 0 the bottom, 1 the top of the training range.
    pub level: f64,
    /// Seed of the sampled motion and collider paths (default: the scene's dataset seed).
    pub seed: Option<u64>,
    /// Weight storage the runtime steps with, as `mochi codegen --weights`.
    pub weights: WeightFormat,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            frames: 120,
            level: 0.5,
            seed: None,
            weights: WeightFormat::F32,
        }
    }
}

/// Which mesh the frames show.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExportedMesh {
    /// The asset's render mesh, embedded in the simulation tets.
    Render,
    /// The simulation mesh's drawn surface (a model without a render mesh).
    Surface,
}

/// A triangle mesh moving over frames: what [`glb::write`] writes.
#[derive(Clone, Debug)]
pub struct MeshAnimation {
    /// Name of the mesh and its node (the scene's name).
    pub name: String,
    /// Which mesh this is.
    pub mesh: ExportedMesh,
    /// Seconds between frames.
    pub dt: f64,
    /// Vertices of the mesh.
    pub vertices: usize,
    /// Three vertex indices per triangle.
    pub triangles: Vec<u32>,
    /// Two texture coordinates per vertex, or empty.
    pub uvs: Vec<f32>,
    /// Three numbers per vertex per frame, frame after frame (frame 0: the start).
    pub positions: Vec<f32>,
    /// Unit normals, as `positions`.
    pub normals: Vec<f32>,
    /// Vertex moves the collider push-out made, over all frames.
    pub pushed_out: usize,
}

impl MeshAnimation {
    /// Vertices of the mesh.
    pub fn vertices(&self) -> usize {
        self.vertices
    }

    /// Frames, the start included.
    pub fn frames(&self) -> usize {
        self.positions.len().checked_div(3 * self.vertices).unwrap_or(0)
    }

    /// Positions of frame `f`.
    pub fn frame_positions(&self, f: usize) -> &[f32] {
        let n = 3 * self.vertices();
        &self.positions[f * n..(f + 1) * n]
    }

    /// Normals of frame `f`.
    pub fn frame_normals(&self, f: usize) -> &[f32] {
        let n = 3 * self.vertices();
        &self.normals[f * n..(f + 1) * n]
    }
}

/// Rolls the model at `artifact` out as `options` says and returns its mesh's frames.
pub fn roll_out(artifact: &Path, options: &ExportOptions) -> Result<MeshAnimation> {
    if options.frames == 0 {
        bail!("--frames must be at least 1");
    }
    if !options.level.is_finite() || options.level < 0.0 {
        bail!("--level must be a non-negative number, got {}", options.level);
    }
    let file = Artifact::read(artifact)?;
    let recipe = Recipe::parse(&file.scene_toml, Path::new(&file.scene_path))
        .with_context(|| format!("{}: the scene it was trained on", artifact.display()))?;
    let problem = recipe.build()?;
    let bytes = crate::error::fs::read(artifact)?;
    let mut storage = OwnedModel::default();
    let loaded = storage
        .load(&bytes)
        .with_context(|| format!("{}: runtime refused the artifact", artifact.display()))?;
    let storage_options = Options::weights(options.weights);
    let stored = Quantized::split(loaded.model(), storage_options.decoder, storage_options.integrator);
    let model = ValidModel::new(stored.model(loaded.model()))
        .with_context(|| format!("{}: with {} weights", artifact.display(), format_name(options.weights)))?;
    let m = model.model();
    if m.dim() != 3 {
        bail!(
            "{}: a {}D model has no surface to export (glTF meshes are 3D)",
            artifact.display(),
            m.dim()
        );
    }
    let mesh = if m.has_render() {
        ExportedMesh::Render
    } else {
        ExportedMesh::Surface
    };
    let triangles = match mesh {
        ExportedMesh::Render => m.render_triangles().to_vec(),
        ExportedMesh::Surface => m.surface_triangles().to_vec(),
    };
    if triangles.is_empty() {
        bail!(
            "{}: the model draws no triangles (a strand model's surface is its vertices); nothing to export",
            artifact.display()
        );
    }
    let seed = options.seed.unwrap_or(recipe.scene.dataset.seed);
    let bc = problem.sequence(&SpeedPlan::constant(options.level), options.frames, seed);
    let mut runtime = LearnedRuntime::new(&model, "learned", format_name(options.weights).into())?;
    runtime.reset(&bc)?;
    let mut frame = Frame::new(&model, mesh);
    let mut animation = MeshAnimation {
        name: recipe.scene.name.clone(),
        mesh,
        dt: f64::from(m.dt),
        vertices: frame.positions.len() / 3,
        triangles,
        uvs: match mesh {
            ExportedMesh::Render => m.render_uvs().to_vec(),
            ExportedMesh::Surface => Vec::new(),
        },
        positions: Vec::new(),
        normals: Vec::new(),
        pushed_out: 0,
    };
    for t in 0..=options.frames {
        if t > 0 {
            runtime
                .step(&bc, t)
                .with_context(|| format!("{}: frame {t}", artifact.display()))?;
        }
        animation.pushed_out += frame
            .draw(&model, runtime.positions(), &collider_states(&bc, t, m.colliders()))
            .map_err(|e| TrainerError::invalid(format!("{}: frame {t}: {e}", artifact.display())))?;
        animation.positions.extend_from_slice(&frame.positions);
        animation.normals.extend_from_slice(&frame.normals);
    }
    Ok(animation)
}

/// One frame's mesh, from the decoded simulation positions.
struct Frame {
    mesh: ExportedMesh,
    sim: Vec<f32>,
    positions: Vec<f32>,
    normals: Vec<f32>,
}

impl Frame {
    fn new(model: &ValidModel, mesh: ExportedMesh) -> Self {
        let m = model.model();
        let len = match mesh {
            ExportedMesh::Render => m.render_len(),
            ExportedMesh::Surface => 3 * m.surface_vertices().len(),
        };
        Frame {
            mesh,
            sim: vec![0.0; m.state_len()],
            positions: vec![0.0; len],
            normals: vec![0.0; len],
        }
    }

    /// Places the mesh on the simulation positions `x` (as the runtime decoded them), pushes
    /// it out of the colliders at `states` and recomputes its normals; returns the vertex
    /// moves the push-out made.
    fn draw(
        &mut self,
        model: &ValidModel,
        x: &[f64],
        states: &[mochi_runtime::collider::ColliderState],
    ) -> std::result::Result<usize, String> {
        let m = model.model();
        if x.iter().any(|v| !v.is_finite()) {
            return Err("the model's positions are not finite".into());
        }
        // The runtime decoded `f32`s: the conversion back is exact.
        self.sim.iter_mut().zip(x).for_each(|(s, &v)| *s = v as f32);
        match self.mesh {
            ExportedMesh::Render => {
                render_positions(model, &self.sim, &mut self.positions).map_err(|e| format!("render decode: {e:?}"))?
            }
            ExportedMesh::Surface => {
                for (o, &v) in self.positions.chunks_exact_mut(3).zip(m.surface_vertices()) {
                    let i = 3 * v as usize;
                    o.copy_from_slice(&self.sim[i..i + 3]);
                }
            }
        }
        let colliders: Vec<_> = states
            .iter()
            .enumerate()
            .filter_map(|(slot, s)| mochi_runtime::collider::slot_collider(m, slot, s))
            .collect();
        let moved = push_out(&mut self.positions, 3, &colliders, 0.0).map_err(|e| format!("push-out: {e:?}"))?;
        let triangles = match self.mesh {
            ExportedMesh::Render => m.render_triangles(),
            ExportedMesh::Surface => m.surface_triangles(),
        };
        triangle_normals(triangles, &self.positions, &mut self.normals);
        Ok(moved)
    }
}
