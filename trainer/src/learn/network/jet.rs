//! Forward-mode jets of a [`ResMlp`] in candle: the value of the network and its first and
//! second derivatives along given input directions, built from ordinary differentiable candle
//! operations (matrix products, broadcast arithmetic, `tanh`, `silu`, `elu`, `exp`), so that any loss of them
//! backpropagates to the weights. candle differentiates in reverse mode to first order only; a
//! loss on the decoder's derivatives (a Lipschitz regulariser) needs them inside the graph.
//!
//! # Maths
//!
//! Along the line `x + t v`, every hidden vector `a(t)` is carried as its value `a`, tangent
//! `ȧ = da/dt` and curvature `ä = d²a/dt²` at `t = 0`. A dense layer `a ↦ W a + b` maps the
//! value by `W a + b` and the tangent and curvature by `W` alone (the bias is constant); a
//! residual addition adds all three. Swish `s(u) = u σ(u)` maps `(u, u̇, ü)` to
//!
//! ```text
//! (s(u), s'(u) u̇, s''(u) u̇² + s'(u) ü)
//! s'(u)  = σ + u σ (1 - σ)
//! s''(u) = σ (1 - σ) (2 + u (1 - 2σ))
//! ```
//!
//! with `σ(u) = (1 + tanh(u / 2)) / 2`, a form whose gradient stays finite for any `u`. ELU
//! (`α = 1`) has `s'(u) = e^min(u, 0)` and `s''(u) = s'(u) - [u > 0]`, written as
//! `exp(-relu(-u))` so that the gradient of `s'` is `s''`. A plain hidden layer `h = W a(h)`
//! applies the activation to `h` itself and replaces the residual addition. The
//! input starts as `(x, v, 0)`; the curvature stays zero (and is not computed) until the first
//! Swish. For a batch, values are `(B, n)` and the `K` tangents and curvatures of each row are
//! `(B, K, n)`; a layer maps them with one matrix product of the `(B·K, n)` reshaping.

use candle_core::{bail, Tensor};

use super::layout::Activation;
use super::mlp::{activate, Dense, ResMlp};

/// The value and derivatives of a network along directions: for inputs `x: (B, in)` and
/// directions `v: (B, K, in)`, the value `f(x)`, the tangents `J v` and the curvatures
/// `d²/dt² f(x + t v)` at `t = 0`.
#[derive(Debug, Clone)]
pub(crate) struct Jet {
    /// `f(x)`: `(B, out)`.
    pub value: Tensor,
    /// `J(x) v`: `(B, K, out)`.
    pub tangent: Tensor,
    /// `d²/dt² f(x + t v)` at `t = 0`: `(B, K, out)`.
    pub curvature: Tensor,
}

/// A hidden quantity with its derivatives along the directions; `curvature` is `None` while
/// it is zero.
struct Stream {
    value: Tensor,
    tangent: Tensor,
    curvature: Option<Tensor>,
}

/// The jet of `mlp` at the rows of `x: (B, in)` along the directions `v: (B, K, in)` (f32, like
/// the weights). Every output depends differentiably on the weights of `mlp`.
pub(crate) fn jet(mlp: &ResMlp, x: &Tensor, v: &Tensor) -> candle_core::Result<Jet> {
    let (batch, input) = x.dims2()?;
    let (v_batch, _, v_input) = v.dims3()?;
    if (v_batch, v_input) != (batch, input) {
        bail!(
            "jet: inputs {:?} and directions {:?} do not match (expected (B, in) and (B, K, in))",
            x.shape(),
            v.shape()
        );
    }
    let start = Stream {
        value: x.clone(),
        tangent: v.clone(),
        curvature: None,
    };
    let style = mlp.style();
    let (input_projection, output_projection) = mlp.projections();
    let start = match input_projection {
        Some(p) => dense(p, &start)?,
        None => start,
    };
    let mut h = dense(mlp.input_layer(), &start)?;
    for (inner, outer) in mlp.block_layers() {
        let u = match inner {
            Some(inner) => activation(style.activation, &dense(inner, &h)?)?,
            None => activation(style.activation, &h)?,
        };
        let r = dense(outer, &u)?;
        h = if style.residual { add(&h, &r)? } else { r };
    }
    let mut y = dense(mlp.output_layer(), &activation(style.activation, &h)?)?;
    if let Some(p) = output_projection {
        y = dense(p, &y)?;
    }
    let curvature = match y.curvature {
        Some(c) => c,
        None => y.tangent.zeros_like()?,
    };
    Ok(Jet {
        value: y.value,
        tangent: y.tangent,
        curvature,
    })
}

/// `a ↦ W a + b` on the value, `W` on the tangent and curvature.
fn dense(layer: &Dense, s: &Stream) -> candle_core::Result<Stream> {
    let w = layer.weight();
    Ok(Stream {
        value: s.value.matmul(&w.t()?)?.broadcast_add(layer.bias())?,
        tangent: along(&s.tangent, w)?,
        curvature: s.curvature.as_ref().map(|c| along(c, w)).transpose()?,
    })
}

/// `W` applied to every vector of `t: (B, K, n)`, giving `(B, K, rows)`.
fn along(t: &Tensor, w: &Tensor) -> candle_core::Result<Tensor> {
    let (batch, dirs, n) = t.dims3()?;
    t.reshape((batch * dirs, n))?
        .matmul(&w.t()?)?
        .reshape((batch, dirs, w.dim(0)?))
}

/// The activation on the value, with the chain rule to second order on the derivatives.
fn activation(activation: Activation, s: &Stream) -> candle_core::Result<Stream> {
    let u = &s.value;
    let (first, second) = match activation {
        Activation::Swish => {
            let sig = u.affine(0.5, 0.0)?.tanh()?.affine(0.5, 0.5)?;
            let one_minus = sig.affine(-1.0, 1.0)?;
            let first = sig.mul(&u.mul(&one_minus)?.affine(1.0, 1.0)?)?;
            let second = sig
                .mul(&one_minus)?
                .mul(&u.mul(&sig.affine(-2.0, 1.0)?)?.affine(1.0, 2.0)?)?;
            (first, second)
        }
        Activation::Elu => {
            let first = u.neg()?.relu()?.neg()?.exp()?;
            let positive = u.gt(0.0)?.to_dtype(u.dtype())?;
            let second = first.sub(&positive)?;
            (first, second)
        }
    };
    let (first, second) = (first.unsqueeze(1)?, second.unsqueeze(1)?);
    let mut curvature = s.tangent.sqr()?.broadcast_mul(&second)?;
    if let Some(c) = &s.curvature {
        curvature = curvature.add(&c.broadcast_mul(&first)?)?;
    }
    Ok(Stream {
        value: activate(activation, u)?,
        tangent: s.tangent.broadcast_mul(&first)?,
        curvature: Some(curvature),
    })
}

/// The residual addition `a + b`.
fn add(a: &Stream, b: &Stream) -> candle_core::Result<Stream> {
    let curvature = match (&a.curvature, &b.curvature) {
        (Some(x), Some(y)) => Some(x.add(y)?),
        (Some(x), None) | (None, Some(x)) => Some(x.clone()),
        (None, None) => None,
    };
    Ok(Stream {
        value: a.value.add(&b.value)?,
        tangent: a.tangent.add(&b.tangent)?,
        curvature,
    })
}

#[cfg(test)]
mod tests {
    use candle_core::Device;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::learn::network::derivatives::{Mlp64, Mlp64Workspace};
    use crate::learn::network::exported::ExportedMlp;
    use crate::learn::network::layout::{MlpSpec, MlpStyle};

    use crate::learn::network::tensor::tensor_to_rows;
    use crate::learn::network::test_support::{
        as_tensor, max_relative_difference, random_rows, randomise, styled_network, STYLES,
    };

    const B: usize = 3;
    const K: usize = 2;
    const IN: usize = 4;
    const OUT: usize = 30;

    /// A random network (2 blocks, 16 hidden units), `B` inputs, `K` directions for each and
    /// weights `c` for the curvatures in the test loss.
    struct Case {
        mlp: ResMlp,
        x: Vec<Vec<f32>>,
        v: Vec<Vec<f32>>,
        c: Vec<f32>,
    }

    impl Case {
        fn new(seed: u64, style: MlpStyle) -> Self {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let spec = MlpSpec {
                input: IN,
                output: OUT,
                hidden: 16,
                blocks: 2,
            };
            let mlp = styled_network(spec, style, &mut rng);
            randomise(&mlp.parameters("m"), 0.5, &mut rng);
            let x = random_rows(B, IN, 1.5, &mut rng);
            let v = random_rows(B * K, IN, 1.0, &mut rng);
            let c = (0..B * K * OUT).map(|_| rng.random_range(-1.0..1.0)).collect();
            Case { mlp, x, v, c }
        }

        fn jet(&self) -> Jet {
            let v = as_tensor(&self.v).reshape((B, K, IN)).unwrap();
            jet(&self.mlp, &as_tensor(&self.x), &v).unwrap()
        }

        /// `Σ c ⊙ curvature + Σ tangent²`, the test loss, in candle.
        fn loss(&self, jet: &Jet) -> Tensor {
            let c = Tensor::from_vec(self.c.clone(), (B, K, OUT), &Device::Cpu).unwrap();
            let curvature = jet.curvature.mul(&c).unwrap().sum_all().unwrap();
            curvature.add(&jet.tangent.sqr().unwrap().sum_all().unwrap()).unwrap()
        }

        /// Tangents and curvatures (one row per input and direction) in f64 by [`Mlp64`].
        fn derivatives64(&self, net: &Mlp64) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
            let mut ws = Mlp64Workspace::new(net);
            let (mut y, mut jac) = (vec![0.0; OUT], vec![0.0; OUT * IN]);
            let (mut tangents, mut curvatures) = (Vec::new(), Vec::new());
            for (row, v) in self.v.iter().enumerate() {
                let x: Vec<f64> = self.x[row / K].iter().map(|&a| a as f64).collect();
                let v: Vec<f64> = v.iter().map(|&a| a as f64).collect();
                net.jacobian(&x, &mut y, &mut jac, &mut ws).unwrap();
                tangents.push(
                    jac.chunks_exact(IN)
                        .map(|j| j.iter().zip(&v).map(|(a, b)| a * b).sum())
                        .collect(),
                );
                let mut second = vec![0.0; OUT];
                net.second_directional(&x, &v, &mut second, &mut ws).unwrap();
                curvatures.push(second);
            }
            (tangents, curvatures)
        }

        /// The test loss in f64 by [`Mlp64`].
        fn loss64(&self, mlp: &ExportedMlp) -> f64 {
            let (tangents, curvatures) = self.derivatives64(&Mlp64::new(mlp));
            let curvature: f64 = curvatures
                .iter()
                .flatten()
                .zip(&self.c)
                .map(|(a, &c)| a * c as f64)
                .sum();
            curvature + tangents.iter().flatten().map(|a| a * a).sum::<f64>()
        }
    }

    fn narrow(rows: &[Vec<f64>]) -> Vec<Vec<f32>> {
        rows.iter().map(|r| r.iter().map(|&a| a as f32).collect()).collect()
    }

    fn flat_rows(t: &Tensor) -> Vec<Vec<f32>> {
        tensor_to_rows(&t.reshape((B * K, OUT)).unwrap()).unwrap()
    }

    #[test]
    fn jet_value_matches_forward() {
        for style in STYLES {
            jet_value_matches_forward_for(style);
        }
    }

    fn jet_value_matches_forward_for(style: MlpStyle) {
        let case = Case::new(1, style);
        let forward = tensor_to_rows(&case.mlp.forward(&as_tensor(&case.x)).unwrap()).unwrap();
        let diff = max_relative_difference(&tensor_to_rows(&case.jet().value).unwrap(), &forward);
        assert!(diff < 1e-6, "jet value differs from forward by {diff}");
    }

    #[test]
    fn jet_derivatives_match_the_f64_network() {
        for style in STYLES {
            jet_derivatives_match_for(style);
        }
    }

    fn jet_derivatives_match_for(style: MlpStyle) {
        let case = Case::new(2, style);
        let jet = case.jet();
        let (tangents, curvatures) = case.derivatives64(&Mlp64::new(&case.mlp.export().unwrap()));
        let diff = max_relative_difference(&flat_rows(&jet.tangent), &narrow(&tangents));
        assert!(diff < 1e-5, "jet tangents differ from J v by {diff}");
        let diff = max_relative_difference(&flat_rows(&jet.curvature), &narrow(&curvatures));
        assert!(
            diff < 1e-5,
            "jet curvatures differ from second directional derivatives by {diff}"
        );
    }

    /// For two entries (the one of largest gradient and a fixed one) of every weight and bias,
    /// the candle gradient of the loss matches central differences of the f64 loss.
    #[test]
    fn jet_gradient_matches_differences_in_each_weight() {
        for style in STYLES {
            jet_gradient_matches_differences_for(style);
        }
    }

    fn jet_gradient_matches_differences_for(style: MlpStyle) {
        let case = Case::new(3, style);
        let grads = case.loss(&case.jet()).backward().unwrap();
        let exported = case.mlp.export().unwrap();
        let layers: Vec<_> = exported.layers().into_iter().cloned().collect();
        let (mut worst, mut largest) = (0.0f64, 0.0f64);
        for (p, (name, var)) in case.mlp.parameters("m").iter().enumerate() {
            let gradient: Vec<f32> = match grads.get(var.as_tensor()) {
                Some(g) => g.flatten_all().unwrap().to_vec1().unwrap(),
                None => vec![0.0; var.as_tensor().elem_count()],
            };
            let top = (0..gradient.len())
                .max_by(|&a, &b| gradient[a].abs().total_cmp(&gradient[b].abs()))
                .unwrap_or(0);
            // Errors relative to the entry's gradient, or to 1% of the tensor's largest one.
            let scale = (1e-2 * gradient[top].abs() as f64).max(1e-3);
            for entry in [top, gradient.len() / 3] {
                let perturbed = |delta: f32| {
                    let mut layers = layers.clone();
                    // The projections are fixed: no variable of theirs.
                    let layer = &mut layers[p / 2 + usize::from(style.input_projection)];
                    let values = if p % 2 == 0 {
                        &mut layer.weights
                    } else {
                        &mut layer.bias
                    };
                    values[entry] += delta;
                    let weight = values[entry] as f64;
                    (
                        weight,
                        case.loss64(&ExportedMlp::from_styled_layers(layers, style).unwrap()),
                    )
                };
                let ((w_plus, l_plus), (w_minus, l_minus)) = (perturbed(1e-3), perturbed(-1e-3));
                let (fd, g) = ((l_plus - l_minus) / (w_plus - w_minus), gradient[entry] as f64);
                let err = (g - fd).abs() / fd.abs().max(scale);
                assert!(err < 1e-5, "{name}[{entry}]: backward {g}, differences {fd}");
                worst = worst.max(err);
                largest = largest.max(fd.abs());
            }
        }
        assert!(largest > 1.0, "the loss hardly depends on the weights: {largest}");
        assert!(worst < 1e-5);
    }

    #[test]
    fn mismatched_shapes_are_errors() {
        let case = Case::new(4, MlpStyle::default());
        let x = as_tensor(&case.x);
        let v = as_tensor(&case.v);
        assert!(jet(&case.mlp, &x, &v).is_err());
        assert!(jet(&case.mlp, &x, &v.reshape((K, B, IN)).unwrap()).is_err());
        assert!(jet(
            &case.mlp,
            &x.narrow(1, 0, IN - 1).unwrap(),
            &v.reshape((B, K, IN)).unwrap()
        )
        .is_err());
    }
}
