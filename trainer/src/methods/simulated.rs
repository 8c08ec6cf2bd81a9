//! The simulator's own solvers as [`Method`]s: full-space Newton, the adaptive subspace
//! solver and Vertex Block Descent (whichever the scene's `[solver]` says), optionally with
//! several substeps per frame (the time-converged reference, a halved time step), and the
//! same scene on a coarser mesh whose positions reach the scene's mesh through a barycentric
//! [`Embedding`].

use mochi_sim::bc::BcSequence;
use mochi_sim::mesh::embedding::Embedding;
use mochi_sim::{BuiltScene, Scene, SolverSpec};

use super::method::{Method, StepCost};
use crate::error::{TrainerError, TrainerResult};

/// A scene stepped by the simulator.
pub struct Simulated {
    family: String,
    setting: String,
    problem: BuiltScene,
    substeps: usize,
    fine: BcSequence,
    /// The scene mesh's vertices in a coarse mesh, and their positions.
    embedded: Option<(Embedding, Vec<f64>)>,
    /// The adaptive solver's enriched share of the free vertices, summed over the steps since
    /// the last reset, and the steps.
    enriched: (f64, usize),
}

impl Simulated {
    /// `scene` as it is, with `substeps` steps of `dt / substeps` per frame (at least one).
    pub fn new(scene: &Scene, substeps: usize, setting: impl Into<String>) -> TrainerResult<Self> {
        let substeps = substeps.max(1);
        let mut scene = scene.clone();
        scene.dt /= substeps as f64;
        let problem = scene.build()?;
        Ok(Simulated {
            family: family_of(&scene.solver).into(),
            setting: setting.into(),
            problem,
            substeps,
            fine: BcSequence::default(),
            embedded: None,
            enriched: (0.0, 0),
        })
    }

    /// `scene` on a mesh with about half the cells along each axis (its solver, its time
    /// step); its positions are given at the vertices of `fine`, the scene's own built mesh,
    /// through a barycentric embedding, and its handles pivot where `fine`'s do.
    pub fn coarse(scene: &Scene, fine: &BuiltScene) -> TrainerResult<Self> {
        let mut coarse = scene.clone();
        coarse.mesh = scene.mesh.coarsened().ok_or_else(|| {
            TrainerError::invalid(format!(
                "scene `{}`: a mesh read from a file has no coarser version",
                scene.name
            ))
        })?;
        let mut problem = coarse.build()?;
        if problem.handles.len() != fine.handles.len() {
            return Err(TrainerError::invalid(format!(
                "scene `{}`: the coarse mesh has {} handles, the scene {}",
                scene.name,
                problem.handles.len(),
                fine.handles.len()
            )));
        }
        for (c, f) in problem.handles.iter_mut().zip(&fine.handles) {
            c.pivot = f.pivot;
        }
        let embedding = Embedding::new(&problem.mesh, &fine.mesh.rest).map_err(TrainerError::invalid)?;
        let setting = format!(
            "{} of {} vertices",
            problem.mesh.num_vertices(),
            fine.mesh.num_vertices()
        );
        let out = vec![0.0; fine.mesh.rest.len()];
        Ok(Simulated {
            family: "coarse mesh".into(),
            setting,
            problem,
            substeps: 1,
            fine: BcSequence::default(),
            embedded: Some((embedding, out)),
            enriched: (0.0, 0),
        })
    }

    /// The built scene it steps.
    pub fn problem(&self) -> &BuiltScene {
        &self.problem
    }

    /// Mean over the steps since the last reset of the adaptive solver's enriched share of the
    /// free vertices (0 for the other solvers).
    pub fn enriched_share(&self) -> f64 {
        self.enriched.0 / self.enriched.1.max(1) as f64
    }

    fn embed(&mut self) {
        if let Some((embedding, out)) = &mut self.embedded {
            embedding.apply(self.problem.simulator.positions(), out);
        }
    }
}

/// How reports call a solver.
fn family_of(solver: &SolverSpec) -> &'static str {
    match solver {
        SolverSpec::FullSpace => "full space",
        SolverSpec::Adaptive(_) => "adaptive",
        SolverSpec::Vbd(_) => "VBD",
    }
}

impl Method for Simulated {
    fn family(&self) -> String {
        self.family.clone()
    }

    fn setting(&self) -> String {
        self.setting.clone()
    }

    fn reset(&mut self, bc: &BcSequence) -> TrainerResult<()> {
        self.fine = bc.refined(self.substeps, self.problem.scene.dt * self.substeps as f64);
        self.problem.start(&self.fine)?;
        self.enriched = (0.0, 0);
        self.embed();
        Ok(())
    }

    fn step(&mut self, _bc: &BcSequence, frame: usize) -> TrainerResult<StepCost> {
        let mut iterations = 0;
        for sub in 1..=self.substeps {
            let report = self.problem.step_to(&self.fine, (frame - 1) * self.substeps + sub)?;
            iterations += report.iterations;
            if let Some(a) = &report.adaptive {
                self.enriched.0 += a.enriched_vertices as f64 / a.free_vertices.max(1) as f64;
            }
            self.enriched.1 += 1;
        }
        self.embed();
        Ok(StepCost::iterated(f64::NAN, iterations as f64))
    }

    fn positions(&self) -> &[f64] {
        match &self.embedded {
            Some((_, out)) => out,
            None => self.problem.simulator.positions(),
        }
    }
}
