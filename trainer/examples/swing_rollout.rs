//! Diagnostic: implicit Euler in a subspace with an exact swing coordinate, for a sheet hung
//! from collinear handle vertices (the two pinned corners of `cloth-line`), rolled out on
//! the scene's test sequences against the full-space reference.
//!
//! ```sh
//! cargo run --release -p mochi-trainer --example swing_rollout -- SCENE K DATASET_DIR [FRAMES] [SEQUENCE,...]
//! ```
//!
//! Handles on one line leave the sheet free to rotate about that line. A linear subspace
//! follows that rotation only by stretching the membrane, and the restricted dynamics drift
//! (`pca_rollout`). Here the rotation is a coordinate of its own: the swing angle `theta` of
//! the encoded state (the angle of its vertex centroid about the handle line, measured from
//! the direction of gravity), and the shape is the first `K` principal components of the
//! training frames turned back by their own angle:
//!
//! ```text
//! q = R(theta) (mean + B w),   z = (L theta, w),   L = |mean|
//! ```
//!
//! so turning the sheet costs no stretch, and angles beyond any training frame are still
//! reached by a rotation. Newton's method and the report are those of `pca_rollout`.

mod common;

use common::{rollout, test_sequences, DiagnosticArgs, Subspace};
use mochi_sim::BuiltScene;
use mochi_trainer::learn::pca::Pca;
use nalgebra::{DMatrix, Rotation3, Unit, Vector3};

/// The line of a scene's handle vertices and the directions that measure a swing about it.
struct HandleLine {
    axis: Unit<Vector3<f64>>,
    down: Vector3<f64>,
    side: Vector3<f64>,
}

impl HandleLine {
    /// The line through `problem`'s handle vertices (they must lie on one line), with
    /// `down` the direction of gravity across it.
    fn of(problem: &BuiltScene) -> anyhow::Result<Self> {
        let points: Vec<Vector3<f64>> = problem
            .handles
            .iter()
            .flat_map(|h| h.reference.iter().map(|&p| Vector3::from(p)))
            .collect();
        let (Some(&first), Some(&last)) = (points.first(), points.last()) else {
            anyhow::bail!("the scene has no handle vertices");
        };
        let axis = Unit::try_new(last - first, 1e-12)
            .ok_or_else(|| anyhow::anyhow!("the handle vertices do not span a line"))?;
        for p in &points {
            let off = (p - first) - axis.into_inner() * axis.dot(&(p - first));
            anyhow::ensure!(off.norm() < 1e-9, "the handle vertices are not collinear");
        }
        let gravity = Vector3::from(problem.scene.gravity);
        let down = (gravity - axis.into_inner() * axis.dot(&gravity))
            .try_normalize(1e-12)
            .ok_or_else(|| anyhow::anyhow!("gravity is along the handle line"))?;
        let side = axis.cross(&down);
        Ok(HandleLine { axis, down, side })
    }

    /// The swing angle of an encoded state: its vertex centroid about the handle line,
    /// zero straight down, positive towards `axis x down`.
    fn angle(&self, q: &[f64]) -> f64 {
        let n = q.len() / 3;
        let centroid = q
            .chunks(3)
            .fold(Vector3::zeros(), |acc, v| acc + Vector3::new(v[0], v[1], v[2]))
            / n as f64;
        centroid.dot(&self.side).atan2(centroid.dot(&self.down))
    }

    /// The smallest and largest swing angle of `states`, in degrees, as `min..max`.
    fn angle_range<'a>(&self, states: impl Iterator<Item = &'a [f64]>) -> String {
        let (lo, hi) = states
            .map(|q| self.angle(q).to_degrees())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), a| (lo.min(a), hi.max(a)));
        format!("{lo:.0}..{hi:.0}")
    }

    /// `q` with every vertex turned by `angle` about the handle line.
    fn rotated(&self, q: &[f64], angle: f64) -> Vec<f64> {
        let r = Rotation3::from_axis_angle(&self.axis, angle);
        q.chunks(3)
            .flat_map(|v| {
                let w = r * Vector3::new(v[0], v[1], v[2]);
                [w.x, w.y, w.z]
            })
            .collect()
    }
}

/// A swing angle about the handle line and the principal components of the unswung shapes.
struct SwingSubspace {
    line: HandleLine,
    pca: Pca,
    /// Length that turns the angle into the first coordinate (`|mean|`), so that all
    /// columns of the Jacobian have comparable norms.
    scale: f64,
}

impl SwingSubspace {
    /// The first `k` principal components of `encoded` turned back by their swing angles.
    fn fit(line: HandleLine, encoded: &[Vec<f64>], k: usize) -> anyhow::Result<Self> {
        let unswung: Vec<Vec<f64>> = encoded.iter().map(|q| line.rotated(q, -line.angle(q))).collect();
        let pca = Pca::fit(&unswung, k)?;
        let scale = pca.mean.iter().map(|v| v * v).sum::<f64>().sqrt();
        Ok(SwingSubspace { line, pca, scale })
    }
}

impl Subspace for SwingSubspace {
    fn describe(&self) -> String {
        format!(
            "swing angle about the handle line + PCA k={} of the unswung training frames",
            self.pca.num_components()
        )
    }
    fn lower(&self, z: &[f64]) -> anyhow::Result<Vec<f64>> {
        Ok(self.line.rotated(&self.pca.reconstruct(&z[1..])?, z[0] / self.scale))
    }
    fn lift(&self, q: &[f64]) -> anyhow::Result<Vec<f64>> {
        let angle = self.line.angle(q);
        let mut z = vec![angle * self.scale];
        z.extend(self.pca.project(&self.line.rotated(q, -angle))?);
        Ok(z)
    }
    fn jacobian(&self, z: &[f64]) -> anyhow::Result<DMatrix<f64>> {
        let angle = z[0] / self.scale;
        let q = self.lower(z)?;
        let mut jacobian = DMatrix::zeros(q.len(), z.len());
        // d/d theta of R(theta) p is axis x (R p).
        for (i, v) in q.chunks(3).enumerate() {
            let d = self.line.axis.cross(&Vector3::new(v[0], v[1], v[2])) / self.scale;
            for c in 0..3 {
                jacobian[(3 * i + c, 0)] = d[c];
            }
        }
        for (j, b) in self.pca.basis.iter().enumerate() {
            for (i, v) in self.line.rotated(b, angle).into_iter().enumerate() {
                jacobian[(i, j + 1)] = v;
            }
        }
        Ok(jacobian)
    }
}

fn main() -> anyhow::Result<()> {
    mochi_trainer::configure_threads();
    let DiagnosticArgs {
        problem,
        encoding,
        encoded,
        k,
        dir,
        frames,
        only,
    } = DiagnosticArgs::parse("swing_rollout")?;
    anyhow::ensure!(problem.mesh.dim == 3, "swing_rollout needs a 3D scene");
    let subspace = SwingSubspace::fit(HandleLine::of(&problem)?, &encoded, k)?;
    println!(
        "swing angles (degrees) of the training frames: {}",
        subspace.line.angle_range(encoded.iter().map(Vec::as_slice))
    );
    for (plan, reference) in test_sequences(&problem, &dir, &only)? {
        let states = encoding.encode_trajectory(&reference)?;
        println!(
            "swing angles (degrees) of the reference, {}: {}",
            plan.name,
            subspace.line.angle_range(states.iter().map(Vec::as_slice))
        );
    }
    rollout(&problem, &encoding, &subspace, &dir, frames, &only)
}
