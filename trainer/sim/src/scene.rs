//! Scenes: TOML files describing a body (mesh, material), its environment (time step,
//! gravity, obstacles, loads, run-time colliders), its boundary conditions (handles and
//! their motions) and how datasets are sampled. `Scene::build` turns one into a ready [`Problem`].

use crate::bc::Handle;
use crate::energy::external::{Collision, ConstantForce, Obstacle};
use crate::energy::rod::{RodBend, RodStretch};
use crate::energy::shell::{ShellBending, ShellMembrane};
use crate::energy::tet::TetElastic;
use crate::energy::tri2d::Tri2dElastic;
use crate::energy::StencilEnergy;
use crate::error::InputError;
use crate::mesh::lumped_masses;
use crate::mesh::{self, Elements, Mesh};
use crate::solver::{NewtonSettings, Simulator, SimulatorConfig, TimeScheme};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

mod checks;
mod colliders;
#[cfg(test)]
mod colliders_tests;
mod contact;
#[cfg(test)]
mod contact_tests;
mod document;
mod regions;
mod solver;
mod spec;
pub use checks::{MAX_LENGTH, MAX_MAGNITUDE, MAX_MATERIAL, MAX_ROTATION, MIN_MATERIAL, MIN_SIZE};
pub use colliders::{parked_pose, ColliderSpec, ShapeKind, MAX_COLLIDERS, PARKED_DIAGONALS};
pub use contact::{box_triangles, ContactSpec, ObstacleMesh};
pub use document::{read_text, SceneDocument};
pub use solver::SolverSpec;
pub use spec::{
    BoxSpec, CollisionSpec, DatasetSpec, End, HandleSpec, LoadSpec, MaterialSpec, MeshSpec, RegionSpec, Selection,
    Split, Start,
};

/// A scene as written in its TOML file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Scene name (used for output files).
    pub name: String,
    /// One-line description.
    #[serde(default)]
    pub description: String,
    /// Time step in seconds (default 1/30).
    #[serde(default = "default_dt")]
    pub dt: f64,
    /// Gravitational acceleration.
    #[serde(default)]
    pub gravity: [f64; 3],
    /// Time integration scheme.
    #[serde(default)]
    pub integrator: TimeScheme,
    /// Newton settings.
    #[serde(default)]
    pub newton: NewtonSettings,
    /// Which solver steps the scene (`[solver]`, `kind = "full-space"` by default,
    /// `"adaptive"` or `"vbd"` with their settings).
    #[serde(default)]
    pub solver: SolverSpec,
    /// Geometry.
    pub mesh: MeshSpec,
    /// Material.
    pub material: MaterialSpec,
    /// Collision energy parameters (used when there are obstacles).
    #[serde(default)]
    pub collision: CollisionSpec,
    /// Analytic obstacles.
    #[serde(default)]
    pub obstacles: Vec<Obstacle>,
    /// IPC contact and its obstacle meshes (see [`ContactSpec`]); none when absent.
    #[serde(default)]
    pub contact: Option<ContactSpec>,
    /// Analytic kinematic colliders and their dataset motions (see [`ColliderSpec`]); they
    /// need `[contact]`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub colliders: Vec<ColliderSpec>,
    /// Prescribed vertex sets and their motions.
    #[serde(default)]
    pub handles: Vec<HandleSpec>,
    /// Constant loads.
    #[serde(default)]
    pub loads: Vec<LoadSpec>,
    /// Initial state: at rest in the rest shape, or in static equilibrium.
    #[serde(default)]
    pub start: Start,
    /// The body's velocity at frame 0 (m/s; default at rest), e.g. to throw a ball.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial_velocity: Option<[f64; 3]>,
    /// Dataset sampling.
    #[serde(default)]
    pub dataset: DatasetSpec,
    /// The file this scene was read from (set on load; relative mesh paths resolve
    /// against its directory).
    #[serde(skip)]
    pub source: PathBuf,
}

fn default_dt() -> f64 {
    1.0 / 30.0
}

impl Scene {
    /// Loads a scene file. A file that also holds tables for other layers (the trainer's
    /// `[latent]`) is read through [`SceneDocument`], which takes them out first.
    pub fn load(path: &Path) -> Result<Scene, InputError> {
        let text = read_text(path)?;
        SceneDocument::parse(&text, path)?.into_scene()
    }

    /// Parses and validates scene text; `path` is used in errors and to resolve mesh files.
    pub fn parse(text: &str, path: &Path) -> Result<Scene, InputError> {
        SceneDocument::parse(text, path)?.into_scene()
    }

    fn field_error(&self, field: impl Into<String>, message: impl Into<String>) -> InputError {
        InputError::field(&self.source, field, message)
    }

    /// Builds the mesh described by the scene.
    pub fn build_mesh(&self) -> Result<Mesh, InputError> {
        build_mesh(&self.mesh, &self.source, "mesh")
    }

    /// The render mesh riding on the scene's tet mesh (`mesh.render`), read and checked against
    /// the built `mesh`; `None` when the scene names none.
    pub fn render_embedding(&self, mesh: &Mesh) -> Result<Option<mesh::asset::render::RenderEmbedding>, InputError> {
        let MeshSpec::File { render: Some(file), .. } = &self.mesh else {
            return Ok(None);
        };
        let path = self.source.parent().unwrap_or(Path::new(".")).join(file);
        mesh::asset::render::RenderEmbedding::read_for(&path, mesh).map(Some)
    }

    /// Builds the mesh, energies, handles and simulator.
    pub fn build(&self) -> Result<BuiltScene, InputError> {
        let mesh = self.build_mesh()?;
        let Energies { masses, potentials } = self.build_energies(&mesh)?;
        let handles = self.build_handles(&mesh)?;
        let fixed: Vec<usize> = handles.iter().flat_map(|h| h.vertices.iter().copied()).collect();
        let contact = match &self.contact {
            Some(c) => {
                let mut config = c.build(crate::contact::ContactSurface::of_mesh(&mesh), &self.source)?;
                config.colliders = self.build_colliders(&mesh)?;
                Some(config)
            }
            None => None,
        };
        let simulator = Simulator::new(SimulatorConfig {
            dim: mesh.dim,
            x0: mesh.rest.clone(),
            masses,
            potentials,
            fixed_vertices: fixed.clone(),
            dt: self.dt,
            scheme: self.integrator,
            settings: self.newton,
            length_scale: mesh.rest_diagonal(),
            contact,
        });
        let simulator = match &self.solver {
            SolverSpec::FullSpace => simulator,
            SolverSpec::Adaptive(settings) => simulator.with_adaptive(self.build_adaptive(settings, &mesh, &fixed)?),
            SolverSpec::Vbd(settings) => self.with_vbd(simulator, settings)?,
        };
        let warnings = self.region_warnings(&mesh);
        Ok(BuiltScene {
            scene: self.clone(),
            mesh,
            handles,
            simulator,
            warnings,
        })
    }

    /// The analytic colliders at their idle poses ([`ColliderSpec::idle_pose`]); a body that is not
    /// 3D cannot have any.
    pub fn build_colliders(&self, mesh: &Mesh) -> Result<Vec<crate::contact::Collider>, InputError> {
        if !self.colliders.is_empty() && mesh.dim != 3 {
            return Err(self.field_error("colliders", "colliders need a 3D body"));
        }
        let (lo, hi) = mesh.bounding_box(&mesh.rest);
        self.colliders
            .iter()
            .enumerate()
            .map(|(k, spec)| {
                let shape = spec
                    .shape()
                    .map_err(|(f, msg)| self.field_error(format!("colliders[{k}].{f}"), msg))?;
                let pose = spec.idle_pose(lo, hi);
                Ok(crate::contact::Collider { shape, pose })
            })
            .collect()
    }

    /// Lumped masses and the conservative energy terms of the scene's body: elastic terms
    /// for its element kind, gravity, loads and obstacle collision. The solver and the
    /// training losses both build their energies here, so there is one definition.
    pub fn build_energies(&self, mesh: &Mesh) -> Result<Energies, InputError> {
        let Energies { masses, mut potentials } = self.build_elastic_energies(mesh)?;
        let dim = mesh.dim;
        if self.gravity.iter().any(|g| *g != 0.0) {
            potentials.push(Box::new(ConstantForce::gravity(dim, &masses, self.gravity)));
        }
        for (k, load) in self.loads.iter().enumerate() {
            let verts = self.select(mesh, &load.select, &format!("loads[{k}].select"))?;
            potentials.push(Box::new(ConstantForce::load(dim, verts, load.force)));
        }
        if !self.obstacles.is_empty() {
            potentials.push(Box::new(Collision::new(
                dim,
                masses.clone(),
                self.obstacles.clone(),
                self.collision.stiffness,
                self.collision.margin,
            )));
        }
        Ok(Energies { masses, potentials })
    }

    /// Lumped vertex masses and the elastic terms alone of the scene's body (what
    /// [`Scene::build_energies`] starts from): the terms whose rest-shape Hessian is the
    /// body's stiffness.
    pub fn build_elastic_energies(&self, mesh: &Mesh) -> Result<Energies, InputError> {
        let materials = self.element_materials(mesh)?;
        let densities: Vec<f64> = materials.iter().map(|m| m.density).collect();
        let thickness = self.material.thickness.unwrap_or(1.0);
        let radius = self.material.radius.unwrap_or(1.0);
        let masses = lumped_masses(mesh, &densities, thickness, radius);
        let src = &self.source;
        let model = self.material.model;
        let rest = &mesh.rest;
        let potentials: Vec<Box<dyn StencilEnergy>> = match &mesh.elements {
            Elements::Tets(t) => vec![Box::new(TetElastic::new(model, rest, t, &materials, src)?)],
            Elements::Triangles(t) => vec![Box::new(Tri2dElastic::new(model, rest, t, &materials, src)?)],
            Elements::Shell(t) => vec![
                Box::new(ShellMembrane::new(rest, t, &materials, thickness, src)?),
                Box::new(ShellBending::new(rest, t, &materials, thickness, src)?),
            ],
            Elements::Rods(s) => vec![
                Box::new(RodStretch::new(rest, s, &materials, radius, src)?),
                Box::new(RodBend::new(rest, s, &materials, radius, src)?),
            ],
        };
        Ok(Energies { masses, potentials })
    }

    /// Resolves a selection to sorted vertex indices; an empty selection is an error.
    pub fn select(&self, mesh: &Mesh, sel: &Selection, field: &str) -> Result<Vec<usize>, InputError> {
        let n = mesh.num_vertices();
        let dim = mesh.dim;
        let coord = |v: usize, i: usize| if i < dim { mesh.rest[v * dim + i] } else { 0.0 };
        let mut verts: Vec<usize> = match sel {
            Selection::Box(b) => (0..n)
                .filter(|&v| b.contains([coord(v, 0), coord(v, 1), coord(v, 2)]))
                .collect(),
            Selection::Indices(ids) => {
                if let Some(&bad) = ids.iter().find(|&&v| v >= n) {
                    return Err(self.field_error(field, format!("vertex index {bad} out of range (mesh has {n})")));
                }
                ids.clone()
            }
            Selection::RodRoots(k) => match &mesh.elements {
                Elements::Rods(strands) => strands.iter().flat_map(|s| s.iter().take(*k).copied()).collect(),
                _ => {
                    return Err(self.field_error(field, "rod-roots selects vertices of rods, but the mesh is not rods"))
                }
            },
            Selection::Nearest(points) => points
                .iter()
                .map(|p| {
                    let dist2 = |v: usize| (0..3).map(|i| (coord(v, i) - p[i]).powi(2)).sum::<f64>();
                    (0..n).min_by(|&a, &b| dist2(a).total_cmp(&dist2(b))).unwrap_or(0)
                })
                .collect(),
            Selection::Side { axis, end, tolerance } => {
                if *axis >= dim {
                    return Err(self.field_error(field, format!("axis {axis} does not exist in {dim}D")));
                }
                let (lo, hi) = mesh.bounding_box(&mesh.rest);
                let extent = (hi[*axis] - lo[*axis]).max(f64::MIN_POSITIVE);
                let target = if *end == End::Min { lo[*axis] } else { hi[*axis] };
                (0..n)
                    .filter(|&v| (coord(v, *axis) - target).abs() <= tolerance * extent)
                    .collect()
            }
        };
        verts.sort_unstable();
        verts.dedup();
        if verts.is_empty() {
            return Err(self.field_error(field, "selects no vertices"));
        }
        Ok(verts)
    }

    /// The scene's prescribed vertex sets on `mesh`, in the simulator's fixed-vertex order
    /// (a vertex in two handles is an error).
    pub fn build_handles(&self, mesh: &Mesh) -> Result<Vec<Handle>, InputError> {
        let mut taken = vec![false; mesh.num_vertices()];
        let mut handles = Vec::new();
        for (k, spec) in self.handles.iter().enumerate() {
            let vertices = self.select(mesh, &spec.select, &format!("handles[{k}].select"))?;
            if let Some(&v) = vertices.iter().find(|&&v| taken[v]) {
                return Err(self.field_error(
                    format!("handles[{k}].select"),
                    format!("vertex {v} already belongs to another handle"),
                ));
            }
            vertices.iter().for_each(|&v| taken[v] = true);
            let rest: Vec<[f64; 3]> = vertices
                .iter()
                .map(|&v| {
                    let mut p = [0.0; 3];
                    p[..mesh.dim].copy_from_slice(&mesh.rest[v * mesh.dim..(v + 1) * mesh.dim]);
                    p
                })
                .collect();
            let centroid = |pts: &[[f64; 3]]| {
                let mut c = [0.0; 3];
                pts.iter()
                    .for_each(|p| (0..3).for_each(|i| c[i] += p[i] / pts.len() as f64));
                c
            };
            let (lo, hi) = mesh.bounding_box(&mesh.rest);
            let center = [0, 1, 2].map(|i| 0.5 * (lo[i] + hi[i]));
            let scale = spec.reference_scale.unwrap_or([1.0; 3]);
            let reference: Vec<[f64; 3]> = rest
                .iter()
                .map(|p| [0, 1, 2].map(|i| center[i] + scale[i] * (p[i] - center[i])))
                .collect();
            let pivot = spec.pivot.unwrap_or_else(|| centroid(&reference));
            handles.push(Handle {
                name: spec.name.clone(),
                vertices,
                reference,
                pivot,
            });
        }
        Ok(handles)
    }
}

/// The mesh `spec` describes; errors name the field under `field` (`mesh`,
/// `mesh.parts[1]`).
fn build_mesh(spec: &MeshSpec, scene_file: &Path, field: &str) -> Result<Mesh, InputError> {
    match spec {
        MeshSpec::Box { min, max, cells } => mesh::procedural::box_tets(*min, *max, *cells),
        MeshSpec::Ball { center, radius, cells } => mesh::procedural::ball_tets(*center, *radius, *cells),
        MeshSpec::ClothGrid {
            size,
            verts,
            origin,
            axes,
        } => mesh::procedural::cloth_grid(*size, *verts, *origin, (axes[0], axes[1])),
        MeshSpec::Rods {
            count,
            verts_per_rod,
            length,
            spacing,
            direction,
            origin,
        } => {
            // Roots on a near-square grid centred on `origin`, across the rods' direction.
            let d = nalgebra::Vector3::from(*direction);
            let helper = if d.x.abs() < 0.9 * d.norm() {
                nalgebra::Vector3::x()
            } else {
                nalgebra::Vector3::y()
            };
            let e1 = helper.cross(&d).try_normalize(1e-12).unwrap_or(nalgebra::Vector3::z());
            let e2 = d.cross(&e1).try_normalize(1e-12).unwrap_or(nalgebra::Vector3::x());
            let columns = (*count as f64).sqrt().ceil().max(1.0) as usize;
            let rows = count.div_ceil(columns);
            let corner = nalgebra::Vector3::from(*origin)
                - e1 * (*spacing * (columns - 1) as f64 / 2.0)
                - e2 * (*spacing * (rows.max(1) - 1) as f64 / 2.0);
            let roots = mesh::procedural::RootGrid {
                origin: corner.into(),
                axes: (e1.into(), e2.into()),
                columns,
                spacing: *spacing,
            };
            mesh::procedural::rod_group(*count, *verts_per_rod, *length, &roots, *direction)
        }
        MeshSpec::File {
            path,
            normalize,
            scale,
            kind,
            ..
        } => {
            let full = scene_file.parent().unwrap_or(Path::new(".")).join(path);
            let kind = match kind.as_deref() {
                None => mesh::io::MeshKind::Auto,
                Some("cloth") => mesh::io::MeshKind::Cloth,
                Some("rods") => mesh::io::MeshKind::Rods,
                Some(other) => {
                    return Err(InputError::field(
                        scene_file,
                        format!("{field}.kind"),
                        format!("unknown kind `{other}` (cloth or rods)"),
                    ));
                }
            };
            let mut mesh = mesh::io::load(&full, kind)?;
            if *normalize {
                mesh = mesh.normalized();
            }
            if let Some(s) = scale {
                if s.len() != mesh.dim || !s.iter().all(|c| c.is_finite() && *c > 0.0) {
                    return Err(InputError::field(
                        scene_file,
                        format!("{field}.scale"),
                        format!("needs {} positive factors", mesh.dim),
                    ));
                }
                mesh = mesh.scaled(s);
            }
            Ok(mesh)
        }
        MeshSpec::Parts { parts } => {
            let meshes = parts
                .iter()
                .enumerate()
                .map(|(k, p)| build_mesh(p, scene_file, &format!("{field}.parts[{k}]")))
                .collect::<Result<Vec<_>, _>>()?;
            mesh::parts::concat(meshes).map_err(|msg| InputError::field(scene_file, format!("{field}.parts"), msg))
        }
    }
}

/// The energy terms of a scene's body (see [`Scene::build_energies`]).
pub struct Energies {
    /// Lumped vertex masses.
    pub masses: Vec<f64>,
    /// Conservative terms: the elastic ones, then (from [`Scene::build_energies`]) gravity,
    /// loads and collision.
    pub potentials: Vec<Box<dyn StencilEnergy>>,
}

/// A scene built and ready to simulate.
pub struct BuiltScene {
    /// The scene it came from.
    pub scene: Scene,
    /// The body.
    pub mesh: Mesh,
    /// Prescribed vertex sets, in the simulator's fixed-vertex order.
    pub handles: Vec<Handle>,
    /// The full-space simulator.
    pub simulator: Simulator,
    /// Problems worth telling the user that do not stop the scene (see
    /// [`Scene::region_warnings`]); the simulator prints nothing itself.
    pub warnings: Vec<String>,
}
