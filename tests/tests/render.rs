//! The render decode agrees between the trainer, the generated code and the artifact loaded
//! from bytes: on `tiny-render` (`tiny` with its box's surface as a render mesh), over the
//! first frames of every test sequence (up to a latent the runtime clamps), the runtime's render positions are within 1e-5 of the
//! diagonal of the trainer's (its own rollout, each render vertex its anchors' weighted sum in
//! `f64`), its normals within 1e-4 (a unit vector's angle, in radians), and every render vertex
//! stays in its tet's convex hull within the weights' tolerance.

use std::path::Path;

use mochi_runtime::render::RENDER_WEIGHT_TOLERANCE;
use mochi_runtime::{Instance, OwnedModel, Stepped, ValidModel};
use mochi_sim::dataset::{self, Split};
use mochi_tests::{motions, tiny_render};
use mochi_trainer::artifact::{render, Artifact};
use mochi_trainer::eval::{self, LoadedModel as TrainerModel};

/// Frames compared per test sequence.
const FRAMES: usize = 120;
const POSITIONS: f64 = 1e-5;
const NORMALS: f64 = 1e-4;

type Body = Instance<{ tiny_render::LATENT }, { tiny_render::SIGNAL }, { tiny_render::HIDDEN }>;

/// Barycentric coordinates of `p` in the tet `x` (four corners), in `f64`.
fn barycentric(x: [[f64; 3]; 4], p: [f64; 3]) -> [f64; 4] {
    use nalgebra::{Matrix3, Vector3};
    let e = |i: usize| Vector3::from(x[i]) - Vector3::from(x[0]);
    let m = Matrix3::from_columns(&[e(1), e(2), e(3)]);
    let l = m.try_inverse().unwrap() * (Vector3::from(p) - Vector3::from(x[0]));
    [1.0 - l.sum(), l[0], l[1], l[2]]
}

/// Worst position and normal disagreement with the trainer over every test sequence, and the
/// farthest any render vertex got outside its tet (barycentric units).
fn compare(model: &ValidModel) -> (f64, f64, f64) {
    let artifact = Artifact::read(Path::new("artifacts/tiny-render.mochi")).unwrap();
    let (problem, encoding) = eval::rebuild_problem(&artifact).unwrap();
    let trainer = TrainerModel::new(artifact.clone()).unwrap();
    let m = model.model();
    assert_eq!(m.render_len(), tiny_render::RENDER_LEN);
    let (mut worst, mut worst_normal, mut outside) = (0.0f64, 0.0f64, 0.0f64);
    let mut longest = 0;
    let plans = dataset::plan(&problem.scene.dataset);
    for plan in plans.iter().filter(|p| p.split == Split::Test) {
        let bc = problem.sequence(&plan.speeds, FRAMES, plan.seed);
        let reference = eval::stable_rollout(&trainer, &problem, &encoding, &bc, FRAMES).unwrap();
        assert_eq!(reference.len(), FRAMES, "the trainer's rollout is stable");
        let mut body = Body::new(model).unwrap();
        let mut compared = 0;
        let mut sim = vec![0.0f32; m.state_len()];
        let (mut positions, mut normals) = (vec![0.0f32; m.render_len()], vec![0.0f32; m.render_len()]);
        for (t, x) in reference.iter().enumerate() {
            // A latent the runtime clamps departs from the trainer on purpose (as in
            // agreement.rs): the sequence is compared up to there.
            if body.step(model, &motions(&bc, t + 1)).unwrap() != Stepped::Ok {
                break;
            }
            compared += 1;
            body.decode_render_into(model, &mut sim, &mut positions, &mut normals)
                .unwrap();
            let want = render::positions(&artifact.render, x);
            let want_normals = render::normals(&artifact.render, &want);
            for (a, b) in positions.chunks_exact(3).zip(want.chunks_exact(3)) {
                let d = (0..3).map(|c| (a[c] as f64 - b[c]).powi(2)).sum::<f64>().sqrt();
                worst = worst.max(d / artifact.diagonal);
            }
            for (a, b) in normals.chunks_exact(3).zip(want_normals.chunks_exact(3)) {
                let d = (0..3).map(|c| (a[c] as f64 - b[c]).powi(2)).sum::<f64>().sqrt();
                worst_normal = worst_normal.max(d);
            }
            let anchors = m.render_anchors().chunks_exact(4);
            for (a, p) in anchors.zip(positions.chunks_exact(3)) {
                let corner = |i: usize| std::array::from_fn(|c| sim[3 * a[i] as usize + c] as f64);
                let l = barycentric(std::array::from_fn(corner), std::array::from_fn(|c| p[c] as f64));
                outside = l.iter().fold(outside, |o, &l| o.max(-l));
            }
        }
        longest = longest.max(compared);
    }
    assert_eq!(longest, FRAMES, "no test sequence runs {FRAMES} frames unclamped");
    (worst, worst_normal, outside)
}

fn check(what: &str, model: &ValidModel) {
    let (positions, normals, outside) = compare(model);
    println!("{what}: positions {positions:.2e} of the diagonal, normals {normals:.2e}, outside {outside:.2e}");
    assert!(
        positions <= POSITIONS,
        "{what}: render positions {positions:.2e} diagonals from the trainer"
    );
    assert!(normals <= NORMALS, "{what}: normals {normals:.2e} from the trainer's");
    // The weights' own tolerance plus the f32 rounding of the decoded positions, relative to a
    // tet's size (tiny's tets are about 1/10 of the diagonal across).
    assert!(
        outside <= RENDER_WEIGHT_TOLERANCE as f64 + 1e-5,
        "{what}: a render vertex {outside:.2e} outside its tet"
    );
}

#[test]
fn generated_render_decode_agrees_with_the_trainer() {
    check("generated", &ValidModel::new(tiny_render::MODEL).unwrap());
}

#[test]
fn loaded_render_decode_agrees_with_the_trainer_and_the_generated_tables() {
    let bytes = std::fs::read("artifacts/tiny-render.mochi").unwrap();
    let mut storage = Box::new(tiny_render::Loaded::new());
    let model = storage.load(&bytes).unwrap();
    check("loaded", &model);
    let (loaded, generated) = (model.model(), tiny_render::MODEL);
    assert_eq!(loaded.render_anchors(), generated.render_anchors());
    assert_eq!(loaded.render_weights(), generated.render_weights());
    assert_eq!(loaded.render_triangles(), generated.render_triangles());
    assert_eq!(loaded.render_uvs(), generated.render_uvs());
    // The owned storage reads the same.
    let mut owned = OwnedModel::default();
    assert_eq!(
        owned.load(&bytes).unwrap().model().render_len(),
        tiny_render::RENDER_LEN
    );
}
