//! The `f32` kernel at the machine's limit: fused multiply-add on the widest vectors the CPU
//! has, sums in whatever order suits them (see [`super`] for what targets then agree on).
//!
//! x86-64: AVX-512F where present, else AVX2 + FMA; chosen once at run time under `std`
//! (`is_x86_feature_detected!` caches its answer), and by the compiled target features
//! without it (`-C target-cpu=native`, or `-C target-feature=+avx512f`). AArch64: NEON (every
//! such CPU has it). Elsewhere, and on x86-64 CPUs with neither, no rows are computed here and
//! the caller runs the canonical sum.

use super::Width;
use crate::model::Layer;

/// The kernel [`rows`] uses on this CPU ([`Width::Canonical`] while
/// [`super::use_vector_kernels`] turned them off).
pub fn width() -> Width {
    let width = super::isa_width();
    if width != Width::Canonical && !super::vector_kernels() {
        return Width::Canonical;
    }
    width
}

/// Rows `first..` of the `f32` layer `layer` (weights and biases in `params`, stored by rows
/// or by columns) for the input `x` (`cols` values), written into the leading part of `out`;
/// returns how many rows were written (0 where this CPU has no wide kernel: the caller
/// computes the rest).
pub fn rows(params: &[f32], layer: &Layer, x: &[f32], first: usize, out: &mut [f32]) -> usize {
    if super::isa_width() == Width::Canonical || x.len() != layer.cols as usize || x.is_empty() {
        return 0;
    }
    if !super::vector_kernels() {
        return 0;
    }
    // The whole matrix in its layout, or empty when it does not fit the pool.
    let w = super::matrix(params, layer);
    if w.is_empty() {
        return 0;
    }
    let rows = out.len().min((layer.rows as usize).saturating_sub(first));
    super::isa_rows_f32(params, layer, w, x, first, &mut out[..rows])
}

#[cfg(all(test, feature = "std"))]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::model::WeightFormat;
    use crate::network::dense_rows;
    use crate::network::test_support::{noise, Case};

    /// Every row count and column count (masked tails, partial row blocks, a row offset) is
    /// within rounding of the exact sum: `|y - exact| <= 4 eps * (|b| + sum |w x|)`, and
    /// rows computed alone equal rows computed with the whole layer.
    #[test]
    fn wide_kernel_is_within_rounding_of_the_exact_sum() {
        std::println!("wide kernel: {:?}", width());
        for (rows_n, cols) in [(1, 8), (3, 16), (13, 24), (21, 40), (9, 7), (17, 44), (40, 128), (5, 3)] {
            let case = Case::new(rows_n, cols);
            let x: Vec<f32> = noise(cols as u32, cols).collect();
            let layer = case.layer(WeightFormat::F32);
            let mut out = std::vec![0.0; rows_n];
            dense_rows(&case.weights(), &layer, &[&x], 0, &mut out);
            for (r, y) in out.iter().enumerate() {
                let w = case.row(WeightFormat::F32, r);
                let exact: f64 =
                    case.params[r] as f64 + w.iter().zip(&x).map(|(w, x)| *w as f64 * *x as f64).sum::<f64>();
                let size: f64 =
                    case.params[r].abs() as f64 + w.iter().zip(&x).map(|(w, x)| (w * x).abs() as f64).sum::<f64>();
                let bound = 4.0 * f32::EPSILON as f64 * size;
                assert!(
                    (*y as f64 - exact).abs() <= bound,
                    "{rows_n}x{cols} row {r}: {y} vs {exact}"
                );
            }
            let mut tail = std::vec![0.0; rows_n - 1];
            dense_rows(&case.weights(), &layer, &[&x], 1, &mut tail);
            assert_eq!(tail[..], out[1..], "{rows_n}x{cols} from row 1");
            let mut one = [0.0];
            dense_rows(&case.weights(), &layer, &[&x], rows_n - 1, &mut one);
            assert_eq!(one[0], out[rows_n - 1], "{rows_n}x{cols} last row alone");
        }
    }

    /// An input given in parts (an integrator's latents and signals) gives the rows of the
    /// same input given whole, on the wide kernel where the CPU has one; one longer than the
    /// gathering buffer falls back to the canonical sum, within rounding of it.
    #[test]
    fn an_input_in_parts_gives_the_rows_of_the_whole_input() {
        for cols in [48, 300] {
            let case = Case::new(19, cols);
            let x: Vec<f32> = noise(cols as u32 + 5, cols).collect();
            let layer = case.layer(WeightFormat::F32);
            let mut whole = std::vec![0.0; 19];
            dense_rows(&case.weights(), &layer, &[&x], 0, &mut whole);
            let cut = [6, 12, 24, 36];
            let parts: Vec<&[f32]> = [0, cut[0], cut[1], cut[2], cut[3], cols]
                .windows(2)
                .map(|w| &x[w[0]..w[1]])
                .collect();
            let mut split = std::vec![0.0; 19];
            dense_rows(&case.weights(), &layer, &parts, 0, &mut split);
            if cols <= 256 {
                assert_eq!(split, whole, "{cols} columns");
            } else {
                for (a, b) in split.iter().zip(&whole) {
                    assert!((a - b).abs() <= 1e-4 * (1.0 + b.abs()), "{cols} columns: {a} vs {b}");
                }
            }
        }
    }

    /// A layer that does not fit its pool computes nothing here (no panic, no read past it).
    #[test]
    fn a_layer_outside_its_pool_is_left_to_the_caller() {
        let case = Case::new(4, 16);
        let mut layer = case.layer(WeightFormat::F32);
        layer.weights = u32::MAX - 8;
        let x = [1.0f32; 16];
        let mut out = [0.0f32; 4];
        assert_eq!(rows(&case.params, &layer, &x, 0, &mut out), 0);
        layer = case.layer(WeightFormat::F32);
        assert_eq!(rows(&case.params, &layer, &x[..8], 0, &mut out), 0);
        let done = rows(&case.params, &layer, &x, 3, &mut out);
        assert!(done <= 1, "{done} rows past the layer's last");
    }
}
