//! Checks of [`Mlp64`]'s derivatives against the plain forward pass, finite differences and
//! each other.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::learn::network::exported::{forward_exported, DenseLayer};
use crate::learn::network::layout::{MlpSpec, MlpStyle};
use crate::learn::network::test_support::{randomise, styled_network, STYLES};

const R: usize = 4;
const OUT: usize = 30;

/// A random network of `style` (2 blocks, 4 inputs, 30 outputs, 16 hidden units) and a random
/// point.
fn setup(seed: u64, style: MlpStyle) -> (ExportedMlp, Mlp64, Vec<f64>, ChaCha8Rng) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let spec = MlpSpec {
        input: R,
        output: OUT,
        hidden: 16,
        blocks: 2,
    };
    let mlp = styled_network(spec, style, &mut rng);
    randomise(&mlp.parameters("m"), 0.5, &mut rng);
    let exported = mlp.export().unwrap();
    let x = random_vec(R, &mut rng);
    let net = Mlp64::new(&exported);
    (exported, net, x, rng)
}

fn random_vec(n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    (0..n).map(|_| rng.random_range(-1.5..1.5)).collect()
}

/// Largest `|a - b|` relative to the largest `|b|`.
fn relative_error(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 1e-3, "comparison against near zeros");
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs())) / scale
}

fn value(net: &Mlp64, x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; net.output_len()];
    net.value(x, &mut y, &mut Mlp64Workspace::default()).unwrap();
    y
}

fn jacobian(net: &Mlp64, x: &[f64], ws: &mut Mlp64Workspace) -> (Vec<f64>, Vec<f64>) {
    let (mut y, mut jac) = (vec![0.0; net.output_len()], vec![0.0; net.output_len() * R]);
    net.jacobian(x, &mut y, &mut jac, ws).unwrap();
    (y, jac)
}

/// Central differences of `g` (`m` values) at `x`: `m × x.len()`, row-major.
fn central_differences(x: &[f64], m: usize, step: f64, g: impl Fn(&[f64]) -> Vec<f64>) -> Vec<f64> {
    let mut out = vec![0.0; m * x.len()];
    for k in 0..x.len() {
        let (mut plus, mut minus) = (x.to_vec(), x.to_vec());
        plus[k] += step;
        minus[k] -= step;
        let (gp, gm) = (g(&plus), g(&minus));
        (0..m).for_each(|i| out[i * x.len() + k] = (gp[i] - gm[i]) / (2.0 * step));
    }
    out
}

#[test]
fn value_matches_forward_exported() {
    for style in STYLES {
        value_matches_forward_exported_for(style);
    }
}

fn value_matches_forward_exported_for(style: MlpStyle) {
    let (exported, net, _, mut rng) = setup(1, style);
    for _ in 0..5 {
        let x = random_vec(R, &mut rng);
        let err = relative_error(&value(&net, &x), &forward_exported::<f64>(&exported, &x).unwrap());
        assert!(err < 1e-14, "value differs from forward_exported by {err}");
    }
}

#[test]
fn jacobian_matches_central_differences() {
    for style in STYLES {
        jacobian_matches_central_differences_for(style);
    }
}

fn jacobian_matches_central_differences_for(style: MlpStyle) {
    let (_, net, x, _) = setup(2, style);
    let mut ws = Mlp64Workspace::new(&net);
    let (y, jac) = jacobian(&net, &x, &mut ws);
    assert_eq!(y, value(&net, &x));
    let err = relative_error(&jac, &central_differences(&x, OUT, 1e-5, |x| value(&net, x)));
    assert!(err < 1e-8, "Jacobian differs from finite differences by {err}");
    // A reused workspace gives the same numbers.
    assert_eq!(jacobian(&net, &x, &mut ws), (y, jac));
}

#[test]
fn pulled_back_gradient_matches_the_jacobian_and_differences() {
    for style in STYLES {
        pulled_back_gradient_matches_the_jacobian_and_differences_for(style);
    }
}

fn pulled_back_gradient_matches_the_jacobian_and_differences_for(style: MlpStyle) {
    let (_, net, x, mut rng) = setup(7, style);
    let w = random_vec(OUT, &mut rng);
    let mut ws = Mlp64Workspace::default();
    let mut gradient = vec![0.0; R];
    net.pulled_back(&x, &w, &mut gradient, &mut ws).unwrap();
    let (_, jac) = jacobian(&net, &x, &mut ws);
    let through_jacobian: Vec<f64> = (0..R).map(|k| (0..OUT).map(|o| w[o] * jac[o * R + k]).sum()).collect();
    let err = relative_error(&gradient, &through_jacobian);
    assert!(err < 1e-13, "reverse mode differs from wᵀJ by {err}");
    let phi = |x: &[f64]| vec![value(&net, x).iter().zip(&w).map(|(y, w)| y * w).sum::<f64>()];
    let err = relative_error(&gradient, &central_differences(&x, 1, 1e-5, phi));
    assert!(err < 1e-8, "reverse mode differs from finite differences by {err}");
    // After `value` at x, reusing its hidden pass gives the same bits.
    let mut y = vec![0.0; OUT];
    net.value(&x, &mut y, &mut ws).unwrap();
    let mut after_value = vec![0.0; R];
    net.pulled_back_after_value(&w, &mut after_value, &mut ws).unwrap();
    assert_eq!(after_value, gradient);
    assert!(net.pulled_back_after_value(&w[1..], &mut after_value, &mut ws).is_err());
    let short = &x[..R - 1];
    assert!(net.pulled_back(short, &w, &mut gradient, &mut ws).is_err());
    assert!(net.pulled_back(&x, &w[1..], &mut gradient, &mut ws).is_err());
    assert!(net.pulled_back(&x, &w, &mut gradient[1..], &mut ws).is_err());
}

#[test]
fn contracted_hessian_matches_differences_of_the_gradient() {
    for style in STYLES {
        contracted_hessian_matches_differences_of_the_gradient_for(style);
    }
}

fn contracted_hessian_matches_differences_of_the_gradient_for(style: MlpStyle) {
    let (_, net, x, mut rng) = setup(3, style);
    let w = random_vec(OUT, &mut rng);
    let mut hess = vec![0.0; R * R];
    net.contracted_hessian(&x, &w, &mut hess, &mut Mlp64Workspace::default())
        .unwrap();
    let gradient = |x: &[f64]| {
        let (_, jac) = jacobian(&net, x, &mut Mlp64Workspace::default());
        (0..R).map(|k| (0..OUT).map(|o| w[o] * jac[o * R + k]).sum()).collect()
    };
    let err = relative_error(&hess, &central_differences(&x, R, 1e-5, gradient));
    assert!(
        err < 1e-8,
        "contracted Hessian differs from finite differences by {err}"
    );
    for k in 0..R {
        for l in 0..R {
            assert_eq!(hess[k * R + l], hess[l * R + k]);
        }
    }
}

#[test]
fn second_directional_matches_hessian_and_differences() {
    for style in STYLES {
        second_directional_matches_hessian_and_differences_for(style);
    }
}

fn second_directional_matches_hessian_and_differences_for(style: MlpStyle) {
    let (_, net, x, mut rng) = setup(4, style);
    let v = random_vec(R, &mut rng);
    let mut ws = Mlp64Workspace::default();
    let mut second = vec![0.0; OUT];
    net.second_directional(&x, &v, &mut second, &mut ws).unwrap();
    // vᵀ ∇²y_i v from the contracted Hessian with w = e_i.
    let mut quadratic = vec![0.0; OUT];
    let (mut e, mut hess) = (vec![0.0; OUT], vec![0.0; R * R]);
    for (i, q) in quadratic.iter_mut().enumerate() {
        e.iter_mut()
            .enumerate()
            .for_each(|(o, e)| *e = if o == i { 1.0 } else { 0.0 });
        net.contracted_hessian(&x, &e, &mut hess, &mut ws).unwrap();
        *q = (0..R * R).map(|kl| v[kl / R] * hess[kl] * v[kl % R]).sum();
    }
    let err = relative_error(&second, &quadratic);
    assert!(err < 1e-12, "second directional derivative differs from vᵀHv by {err}");
    let t = 1e-3;
    let at = |s: f64| value(&net, &x.iter().zip(&v).map(|(x, v)| x + s * v).collect::<Vec<_>>());
    let (plus, mid, minus) = (at(t), at(0.0), at(-t));
    let differences: Vec<f64> = (0..OUT)
        .map(|o| (plus[o] - 2.0 * mid[o] + minus[o]) / (t * t))
        .collect();
    let err = relative_error(&second, &differences);
    assert!(
        err < 1e-5,
        "second directional derivative differs from finite differences by {err}"
    );
}

#[test]
fn selected_rows_give_the_same_rows() {
    for style in STYLES {
        selected_rows_give_the_same_rows_for(style);
    }
}

fn selected_rows_give_the_same_rows_for(style: MlpStyle) {
    let (_, net, x, _) = setup(5, style);
    let rows = [3, 0, 29, 3];
    let sub = net.rows(&rows).unwrap();
    let mut ws = Mlp64Workspace::new(&net);
    let (y, jac) = jacobian(&net, &x, &mut ws);
    let (sub_y, sub_jac) = jacobian(&sub, &x, &mut ws);
    for (s, &r) in rows.iter().enumerate() {
        assert_eq!(sub_y[s], y[r]);
        assert_eq!(sub_jac[s * R..(s + 1) * R], jac[r * R..(r + 1) * R]);
    }
    assert!(net.rows(&[1, OUT]).is_err());
}

#[test]
fn wrong_sizes_are_errors() {
    for style in STYLES {
        wrong_sizes_are_errors_for(style);
    }
}

fn wrong_sizes_are_errors_for(style: MlpStyle) {
    let (_, net, x, _) = setup(6, style);
    let mut ws = Mlp64Workspace::default();
    let (mut y, mut jac, mut hess) = (vec![0.0; OUT], vec![0.0; OUT * R], vec![0.0; R * R]);
    let short = &x[..R - 1];
    assert!(net.value(short, &mut y, &mut ws).is_err());
    assert!(net.value(&x, &mut y[1..], &mut ws).is_err());
    assert!(net.jacobian(short, &mut y, &mut jac, &mut ws).is_err());
    assert!(net.jacobian(&x, &mut y, &mut jac[1..], &mut ws).is_err());
    assert!(net.contracted_hessian(&x, &y[1..], &mut hess, &mut ws).is_err());
    assert!(net.contracted_hessian(&x, &y, &mut hess[1..], &mut ws).is_err());
    assert!(net.second_directional(&x, short, &mut y, &mut ws).is_err());
    assert!(net.second_directional(&x, &x, &mut y[1..], &mut ws).is_err());
}

#[test]
fn the_wide_products_give_the_portable_bits() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    // Columns off the multiple of four (the dot product's tail) and 1, 3, 4 and 11 directions
    // (every register block of the tangent products).
    for (rows, cols) in [(37, 13), (5, 64), (130, 7)] {
        let layer = Dense64::new(&DenseLayer {
            rows,
            cols,
            weights: (0..rows * cols).map(|_| rng.random_range(-1.0f32..1.0)).collect(),
            bias: (0..rows).map(|_| rng.random_range(-1.0f32..1.0)).collect(),
        });
        let x = random_vec(cols, &mut rng);
        let (mut wide, mut portable) = (vec![0.0; rows], vec![0.0; rows]);
        layer.matvec(&x, |i, v| wide[i] = v);
        layer.matvec_portable(&x, |i, v| portable[i] = v);
        assert_eq!(wide, portable, "{rows} x {cols}");
        for count in [1, 3, 4, 11] {
            let t = random_vec(cols * count, &mut rng);
            let start = random_vec(rows * count, &mut rng);
            for add in [false, true] {
                let (mut value_w, mut out_w) = (start[..rows].to_vec(), start.clone());
                let (mut value_p, mut out_p) = (value_w.clone(), out_w.clone());
                layer.with_tangents(&x, &t, &mut value_w, &mut out_w, add);
                layer.with_tangents_portable(&x, &t, &mut value_p, &mut out_p, add);
                assert_eq!((value_w, out_w), (value_p, out_p), "{rows} x {cols}, {count}");
            }
            let v = random_vec(rows * count, &mut rng);
            let (mut out_w, mut out_p) = (random_vec(cols * count, &mut rng), vec![]);
            out_p.clone_from(&out_w);
            layer.add_transposed(&v, &mut out_w);
            layer.add_transposed_portable(&v, &mut out_p);
            assert_eq!(out_w, out_p, "{rows} x {cols}, {count}");
        }
    }
}
