//! Tests of the membrane energy.

use super::*;

#[test]
fn membrane_matches_finite_differences_on_random_triangles() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let (m, t) = stiff();
    let mut worst = (0.0f64, 0.0f64);
    for _ in 0..200 {
        let rest: Vec<f64> = (0..9).map(|_| rng.random_range(-1.0..1.0)).collect();
        let Ok(energy) = ShellMembrane::new(&rest, &[[0, 1, 2]], &[m], t, path()) else {
            continue;
        };
        // Stretched, sheared, compressed and occasionally inverted triangles in 3D.
        let (rotation, shift) = random_rigid(&mut rng);
        let x = perturb(&transform(&rest, &rotation, &shift), &mut rng, 0.5);
        let r = check_stencil(&energy, 0, &x, 1e-6);
        worst = (worst.0.max(r.grad_error), worst.1.max(r.hess_error));
    }
    assert!(worst.0 < 1e-7 && worst.1 < 1e-7, "{worst:?}");
}
