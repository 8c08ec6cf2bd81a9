//! Dense-layer kernels: the residual MLP forward pass of [`crate::model`], with scratch on the
//! stack (`H` floats per buffer, fixed at compile time).
//!
//! A row `r` of a layer is `y[r] = b[r] + W[r] . x`. How the dot product is computed depends on
//! how the layer's weights are stored, and that choice fixes what targets agree on:
//!
//! - **`f32`** ([`fast`] where the CPU has it): any order, fused multiply-add allowed, the
//!   widest vectors the CPU has (AVX-512F, else AVX2 + FMA, chosen at run time under `std` and
//!   by target features without it). Targets agree within rounding: the cross-target check
//!   asks for the decoded positions to stay within 1e-5 of the rest diagonal over 1,000
//!   frames. Targets without a fast kernel (Cortex-M4, wasm) run the canonical sum below.
//!   A layer stored column by column ([`WeightFormat::F32Columns`], a decoder's narrow
//!   output layer as the x86-64 loader stores it) is computed the same way: one chain of
//!   fused multiply-adds over the columns per row in the wide kernel, the canonical sum
//!   without it.
//! - **`f16`** ([`canonical`]): the canonical sum, every product and sum rounded to `f32` in a
//!   fixed order (no FMA), so every target computes the same bits:
//!
//!   ```text
//!   lane[l] = sum over columns c = l, l + 8, l + 16, ... (ascending) of  w[r][c] * x[c]
//!   y[r]    = b[r] + (((lane0 + lane4) + (lane1 + lane5)) + ((lane2 + lane6) + (lane3 + lane7)))
//!   ```
//!
//! - **int8** ([`integer`]): the input vector is quantised to integers with one scale per
//!   vector, multiplied by the int8 weights and summed in `i32`, which is exact, so every
//!   target computes the same bits in whatever order its vector units add; then
//!   `y[r] = b[r] + s[r] * (sum * scale_x)` in `f32`.
//!
//! Every row is computed the same way whichever call computes it, so a caller may compute any
//! subset of a layer's rows ([`dense_rows`]) and get the same bits as a whole-layer call.

#[cfg(target_arch = "aarch64")]
#[allow(unsafe_code)]
pub(crate) mod aarch64;
pub mod activation;
#[cfg(all(target_arch = "arm", feature = "armv7em"))]
#[allow(unsafe_code)]
mod armv7em;
pub mod canonical;
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod columns;
pub mod fast;
pub mod integer;
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod narrow;
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod strand_avx512;
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod swish_avx512;
#[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
#[allow(unsafe_code)]
mod wasm;
pub(crate) mod world;
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86;
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86_lanes;
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86_world;

use crate::model::{Layer, WeightFormat, Weights};

// The instruction set: which ISA module each kernel comes from is chosen here, at compile
// time where the target fixes it (and by run-time detection inside the x86-64 and AArch64
// modules); the generic kernels (`fast`, `canonical`, `integer`) call these and name no
// instruction set.

/// The wide `f32` kernel this CPU has, whether or not [`use_vector_kernels`] turned it off.
#[inline(always)]
fn isa_width() -> Width {
    #[cfg(target_arch = "x86_64")]
    return x86::width();
    #[cfg(target_arch = "aarch64")]
    return Width::Neon;
    #[allow(unreachable_code)]
    Width::Canonical
}

/// The wide `f32` kernel's rows (see [`fast::rows`]); 0 where there is none.
#[inline(always)]
fn isa_rows_f32(params: &[f32], layer: &Layer, w: &[f32], x: &[f32], first: usize, out: &mut [f32]) -> usize {
    #[cfg(target_arch = "x86_64")]
    return x86::rows_f32(params, layer, w, x, first, out);
    #[cfg(target_arch = "aarch64")]
    return aarch64::rows_f32(params, layer, w, x, first, out);
    #[allow(unreachable_code)]
    {
        let _ = (params, layer, w, x, first, out);
        0
    }
}

/// The canonical `f16` sum's leading rows with this CPU's vectors (AVX2 + F16C, NEON) or
/// FPU (Armv7E-M: two weights per load); 0 where the portable code does them.
#[inline(always)]
fn isa_rows_f16(weights: &Weights, layer: &Layer, parts: &[&[f32]], first: usize, out: &mut [f32]) -> usize {
    #[cfg(target_arch = "x86_64")]
    return match parts {
        [x] => x86::rows_f16(weights, layer, x, first, out),
        _ => 0,
    };
    #[cfg(target_arch = "aarch64")]
    return match vector_kernels() {
        true => joined(parts, |x| match x.len() == layer.cols as usize {
            true => aarch64::rows_f16(weights.params, layer, matrix(weights.halves, layer), x, first, out),
            false => 0,
        }),
        false => 0,
    };
    #[cfg(all(target_arch = "arm", feature = "armv7em", target_abi = "eabihf"))]
    return match vector_kernels() {
        true => armv7em::rows_f16(weights.params, layer, matrix(weights.halves, layer), parts, first, out),
        false => 0,
    };
    #[allow(unreachable_code)]
    {
        let _ = (weights, layer, parts, first, out);
        0
    }
}

/// Puts int8 activations in the order this target's [`isa_dot_i8`] reads them.
#[inline(always)]
fn isa_arrange_i8(q: &mut [i16]) {
    #[cfg(all(target_arch = "arm", feature = "armv7em"))]
    armv7em::arrange(q);
    #[cfg(target_arch = "aarch64")]
    aarch64::arrange(q);
    let _ = q;
}

/// The int8 dot product's sum over the leading columns this target's kernel takes, and the
/// columns it leaves (which the caller adds).
#[inline(always)]
fn isa_dot_i8<'a, 'b>(w: &'a [i8], q: &'b [i16]) -> (i32, &'a [i8], &'b [i16]) {
    #[cfg(target_arch = "x86_64")]
    return x86::dot_i8(w, q).map_or((0, w, q), |sum| (sum, &[], &[]));
    #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
    return wasm::dot_i8(w, q);
    #[cfg(all(target_arch = "arm", feature = "armv7em"))]
    return armv7em::dot_i8(w, q);
    #[cfg(target_arch = "aarch64")]
    return aarch64::dot_i8(w, q);
    #[allow(unreachable_code)]
    (0, w, q)
}

/// Leading rows of an int8 layer computed several at a time (see `aarch64::rows_i8`); 0 where
/// the caller's row-by-row loop does them.
#[inline(always)]
fn isa_rows_i8(w: &[i8], q: &[i16], scale_x: f32, bias: &[f32], scale: &[f32], out: &mut [f32]) -> usize {
    #[cfg(target_arch = "aarch64")]
    return aarch64::rows_i8(w, q, scale_x, bias, scale, out);
    #[allow(unreachable_code)]
    {
        let _ = (w, q, scale_x, bias, scale, out);
        0
    }
}

/// The `f16` with bits `h` as `f32` (exact): the FPU's `VCVTB` on Armv7E-M with an FPU, the
/// `half` crate elsewhere.
#[inline(always)]
fn isa_f16_to_f32(h: u16) -> f32 {
    #[cfg(all(target_arch = "arm", feature = "armv7em", target_abi = "eabihf"))]
    return armv7em::f16_to_f32(h);
    #[allow(unreachable_code)]
    half::f16::from_bits(h).to_f32()
}

/// The activation of an `f32` layer's values with this CPU's vectors (AVX-512F); `false`, and
/// nothing computed, where the portable code does it.
#[inline(always)]
fn isa_swish_all(v: &mut [f32]) -> bool {
    #[cfg(target_arch = "x86_64")]
    return swish_avx512::swish_all(v);
    #[allow(unreachable_code)]
    {
        let _ = v;
        false
    }
}

/// Whether every value is finite, with this CPU's widest vectors (AVX-512F); `None` where the
/// portable pass does it.
#[inline(always)]
pub(crate) fn isa_all_finite(values: &[f32]) -> Option<bool> {
    #[cfg(target_arch = "x86_64")]
    return x86::all_finite(values);
    #[allow(unreachable_code)]
    {
        let _ = values;
        None
    }
}

/// One step of `N` strand lanes (`crate::strand_lanes::ChainWalks::step`) sixteen lanes per
/// AVX-512F vector where the CPU has it and `N` is a multiple of sixteen; `false`, and nothing
/// done, where the plain lane loops do it.
#[inline(always)]
pub(crate) fn isa_strand_step<const N: usize>(
    position: &mut [[f32; N]; 3],
    axes: &mut [[[f32; N]; 3]; 3],
    q0: &[f32; N],
    q1: &[f32; N],
    length: &[f32; N],
) -> bool {
    #[cfg(target_arch = "x86_64")]
    return strand_avx512::step(position, axes, q0, q1, length);
    #[allow(unreachable_code)]
    {
        let _ = (position, axes, q0, q1, length);
        false
    }
}

/// The vector world transform and one-pass decode of this target ([`world::WorldTransform`]):
/// AVX-512F on x86-64 (chosen at run time: `new` gives `None` without it), none elsewhere.
#[cfg(target_arch = "x86_64")]
pub(crate) type WorldBlocks = x86_world::WorldBlocks;
/// The vector world transform and one-pass decode of this target: none.
#[cfg(not(target_arch = "x86_64"))]
pub(crate) type WorldBlocks = world::NoWorldBlocks;

/// Whether [`isa_place`] places any vertices on this target.
pub(crate) const ISA_PLACE: bool = cfg!(target_arch = "aarch64");

/// Places 3D vertices of `run` in the world (`frame * v + origin(o)`, `origin_of` giving
/// each vertex's `o`) several per vector where this target's transform takes any origin per
/// vertex (NEON: four at a time; `fused` behind an `f32` decoder, else the scalar transform's
/// own operations and bits). Returns the leading vertices placed (0 where the caller places
/// them).
#[inline(always)]
pub(crate) fn isa_place(
    frame: &nalgebra::Matrix3<f32>,
    fused: bool,
    run: &mut [f32],
    origin_of: &[u32],
    origin: impl FnMut(u32) -> nalgebra::Vector3<f32>,
) -> usize {
    #[cfg(target_arch = "aarch64")]
    return match (vector_kernels(), fused) {
        (true, true) => aarch64::place::<true>(frame, run, origin_of, origin),
        (true, false) => aarch64::place::<false>(frame, run, origin_of, origin),
        (false, _) => 0,
    };
    #[allow(unreachable_code)]
    {
        let _ = (frame, fused, run, origin_of, origin);
        0
    }
}

/// Strands a decode walks side by side (`crate::strand_lanes::ChainWalks`): sixteen on x86-64
/// (one AVX-512 vector, [`isa_strand_step`]), eight where the lanes become other vector
/// instructions, one on targets without vectors (the Cortex-M4), where more lanes only add
/// bookkeeping. Any number gives the same bits.
pub(crate) const STRAND_LANES: usize = if cfg!(target_arch = "x86_64") {
    16
} else if cfg!(any(
    target_arch = "aarch64",
    all(target_arch = "wasm32", target_feature = "simd128")
)) {
    8
} else {
    1
};

/// Rows the canonical sum computes together: four where vector registers hold their lanes;
/// two on the Cortex-M4, whose 32 single-precision registers hold two rows' eight lanes with
/// room for the input and the weights (four rows' lanes would be spilled to the stack).
const ISA_ROW_BLOCK: usize = if cfg!(target_arch = "arm") { 2 } else { 4 };

/// Which wide `f32` kernel this CPU runs ([`fast::width`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Width {
    /// 16 lanes, AVX-512F.
    Avx512,
    /// 8 lanes, AVX2 with FMA.
    Avx2,
    /// 4 lanes, AArch64 NEON.
    Neon,
    /// No wide kernel: the canonical sum.
    Canonical,
}

pub use activation::swish;
use activation::swish_all;

/// Whether the hand-written vector kernels run ([`use_vector_kernels`]).
static VECTOR_KERNELS: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(true);

/// Turns the hand-written vector kernels of the dense layers on (the default) or off for the
/// whole process; off, every layer runs the canonical code (the portable loops as the compiler
/// makes them), which is what a frame costs without them. int8 and `f16` layers give the same
/// bits either way, `f32` layers agree within the `f32` tolerance.
pub fn use_vector_kernels(on: bool) {
    VECTOR_KERNELS.store(on, core::sync::atomic::Ordering::Relaxed);
}

/// Whether the hand-written vector kernels run ([`use_vector_kernels`]).
#[inline(always)]
pub fn vector_kernels() -> bool {
    VECTOR_KERNELS.load(core::sync::atomic::Ordering::Relaxed)
}

/// `b[r] + s[r] * sum` for row `r` of `layer` (`s[r] = 1` unless the layer is int8).
#[inline(always)]
pub(crate) fn finish(params: &[f32], layer: &Layer, r: usize, sum: f32) -> f32 {
    let b = params.get(layer.bias as usize + r).copied().unwrap_or(0.0);
    match layer.format {
        WeightFormat::Int8 => b + params.get(layer.scales as usize + r).copied().unwrap_or(0.0) * sum,
        WeightFormat::F32 | WeightFormat::F16 | WeightFormat::F32Columns => b + sum,
    }
}

/// The weights of `layer` in its pool (empty when the layer does not fit the pool: every row
/// then reads as zeros and gives its bias, never a panic; loading rejects such models).
#[inline(always)]
pub(crate) fn matrix<'p, T>(pool: &'p [T], layer: &Layer) -> &'p [T] {
    let start = layer.weights as usize;
    let rows = match layer.format {
        WeightFormat::F32Columns => crate::model::column_stride(layer.rows as usize),
        _ => layer.rows as usize,
    };
    pool.get(start..start + rows * layer.cols as usize).unwrap_or(&[])
}

/// Rows `first..first + out.len()` of `layer` applied to the concatenation of `parts`.
pub fn dense_rows(weights: &Weights, layer: &Layer, parts: &[&[f32]], first: usize, out: &mut [f32]) {
    let p = weights.params;
    match layer.format {
        WeightFormat::F32 | WeightFormat::F32Columns => {
            let done = match parts {
                [x] => fast::rows(p, layer, x, first, out),
                _ => joined_rows(p, layer, parts, first, out),
            };
            let (first, out) = (first + done, &mut out[done..]);
            match layer.format {
                _ if out.is_empty() => {}
                WeightFormat::F32Columns => canonical::column_rows(p, layer, matrix(p, layer), parts, first, out),
                _ => canonical::rows(p, layer, matrix(p, layer), parts, first, out),
            }
        }
        WeightFormat::F16 => {
            let done = isa_rows_f16(weights, layer, parts, first, out);
            let (first, out) = (first + done, &mut out[done..]);
            canonical::rows(p, layer, matrix(weights.halves, layer), parts, first, out);
        }
        WeightFormat::Int8 => integer::rows(p, layer, matrix(weights.bytes, layer), parts, first, out),
    }
}

/// The input of one layer prepared once for many [`LayerInput::rows`] calls (a decode computes
/// the output layer's rows run by run): an int8 layer's quantisation is done once.
pub struct LayerInput<'x> {
    x: &'x [f32],
    /// `Some` for an int8 layer whose input is finite.
    quantized: Option<integer::Quantized>,
}

impl<'x> LayerInput<'x> {
    /// `x` prepared for `layer`.
    pub fn new(layer: &Layer, x: &'x [f32]) -> Self {
        let quantized = match layer.format {
            WeightFormat::Int8 => integer::Quantized::new(&[x], layer.cols as usize),
            WeightFormat::F32 | WeightFormat::F16 | WeightFormat::F32Columns => None,
        };
        LayerInput { x, quantized }
    }

    /// The input's values.
    pub fn values(&self) -> &'x [f32] {
        self.x
    }

    /// [`dense_rows`] of `layer` (the layer this input was prepared for) on this input: the
    /// same bits.
    pub fn rows(&self, weights: &Weights, layer: &Layer, first: usize, out: &mut [f32]) {
        match (layer.format, &self.quantized) {
            (WeightFormat::Int8, Some(x)) => {
                integer::quantized_rows(weights.params, layer, matrix(weights.bytes, layer), x, first, out)
            }
            (WeightFormat::Int8, None) => out.fill(f32::NAN),
            (WeightFormat::F32 | WeightFormat::F16 | WeightFormat::F32Columns, _) => {
                dense_rows(weights, layer, &[self.x], first, out)
            }
        }
    }
}

/// Longest input that [`joined_rows`] gathers on the stack.
const JOINED_MAX: usize = 256;

/// The wide `f32` kernel ([`fast::rows`]) for an input given in `parts` (an integrator's
/// latents and signals), gathered into one stack buffer first; returns the rows written (0
/// when the input is longer than [`JOINED_MAX`] or the CPU has no wide kernel).
fn joined_rows(p: &[f32], layer: &Layer, parts: &[&[f32]], first: usize, out: &mut [f32]) -> usize {
    if fast::width() == Width::Canonical {
        return 0;
    }
    joined(parts, |x| fast::rows(p, layer, x, first, out))
}

/// `kernel` applied to the concatenation of `parts`: the one part itself, or the parts
/// gathered into a stack buffer; 0 without calling it when they are longer than
/// [`JOINED_MAX`].
#[inline(always)]
fn joined(parts: &[&[f32]], kernel: impl FnOnce(&[f32]) -> usize) -> usize {
    if let [x] = parts {
        return kernel(x);
    }
    let total: usize = parts.iter().map(|x| x.len()).sum();
    if total > JOINED_MAX {
        return 0;
    }
    let mut buffer = [0.0f32; JOINED_MAX];
    let mut at = 0;
    for x in parts {
        buffer[at..at + x.len()].copy_from_slice(x);
        at += x.len();
    }
    kernel(&buffer[..total])
}

/// The last hidden activation `swish(h)` of a network for the input `parts`, written into
/// `h`; `scratch` holds two more buffers. All three must hold the hidden width. The output
/// layer is then applied with [`dense_rows`], so a caller can compute only the rows it needs.
pub fn hidden(weights: &Weights, layers: &[Layer], parts: &[&[f32]], h: &mut [f32], scratch: [&mut [f32]; 2]) {
    let Some((input, rest)) = layers.split_first() else {
        return;
    };
    let blocks = rest.split_last().map_or(&[][..], |(_, b)| b);
    let [a, r] = scratch;
    let width = (input.rows as usize).min(h.len()).min(a.len()).min(r.len());
    let (h, a, r) = (&mut h[..width], &mut a[..width], &mut r[..width]);
    dense_rows(weights, input, parts, 0, h);
    for pair in blocks.chunks_exact(2) {
        dense_rows(weights, &pair[0], &[h], 0, a);
        swish_all(&pair[0], a);
        dense_rows(weights, &pair[1], &[a], 0, r);
        h.iter_mut().zip(r.iter()).for_each(|(h, r)| *h += r);
    }
    // `h` sums the outputs of the input layer and of every block's second layer: the vector
    // activation only where all of them are `f32`.
    let mut sources = core::iter::once(input).chain(blocks.chunks_exact(2).map(|pair| &pair[1]));
    let exact = sources.find(|l| !l.format.is_f32());
    swish_all(exact.unwrap_or(input), h);
}

/// What a decoder's last layer reads for the latent `z`, written into `f`: the last hidden
/// activation of a residual MLP decoder ([`hidden`]), or for a basis decoder
/// (`basis = true`, see [`crate::model`]) the features `[z; 0] + g(z)`, `g` the layers before
/// the basis (`f = z` when there are none). `f` and `scratch` must hold the hidden width.
pub fn decoder_features(
    weights: &Weights,
    layers: &[Layer],
    basis: bool,
    z: &[f32],
    f: &mut [f32],
    scratch: [&mut [f32]; 3],
) {
    let Some(mlp) = layers.split_last().map(|(_, mlp)| mlp).filter(|_| basis) else {
        let [a, r, _] = scratch;
        return hidden(weights, layers, &[z], f, [a, r]);
    };
    f.iter_mut().for_each(|v| *v = 0.0);
    if let Some(output) = mlp.last() {
        let [h, a, r] = scratch;
        hidden(weights, mlp, &[z], h, [a, r]);
        let m = (output.rows as usize).min(f.len());
        let x = h.get(..output.cols as usize).unwrap_or(h);
        dense_rows(weights, output, &[x], 0, &mut f[..m]);
    }
    f.iter_mut().zip(z).for_each(|(f, z)| *f += z);
}

/// Multiply-adds of one forward pass of `layers` (for GFLOP/s reports).
pub fn multiply_adds(layers: &[Layer]) -> usize {
    layers.iter().map(|l| l.rows as usize * l.cols as usize).sum()
}

/// Inputs and weights shared by the kernels' tests.
#[cfg(all(test, feature = "std"))]
pub(crate) mod test_support {
    extern crate std;
    use std::vec::Vec;

    use crate::model::{Layer, WeightFormat};

    /// A pseudo-random sequence in `[-1, 1]` (no dependency for a test).
    pub fn noise(seed: u32, n: usize) -> impl Iterator<Item = f32> {
        let mut state = seed.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
        (0..n).map(move |_| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state as f32 / u32::MAX as f32) * 2.0 - 1.0
        })
    }

    /// A layer of `rows x cols` in every storage: `params` holds `rows` biases, `rows` scales,
    /// then the `f32` weights; `halves` and `bytes` the other two storages of the same weights.
    pub struct Case {
        pub rows: usize,
        pub cols: usize,
        pub params: Vec<f32>,
        pub halves: Vec<u16>,
        pub bytes: Vec<i8>,
    }

    impl Case {
        pub fn new(rows: usize, cols: usize) -> Case {
            let w32: Vec<f32> = noise(rows as u32 * 7 + cols as u32, rows * cols).collect();
            let mut params: Vec<f32> = noise(99, rows).collect();
            params.extend(noise(98, rows).map(|s| 0.01 * (1.5 + s)));
            params.extend(&w32);
            Case {
                rows,
                cols,
                halves: w32.iter().map(|&v| half::f16::from_f32(v).to_bits()).collect(),
                bytes: w32.iter().map(|&v| (v * 127.0) as i8).collect(),
                params,
            }
        }

        pub fn weights(&self) -> crate::model::Weights<'_> {
            crate::model::Weights {
                params: &self.params,
                halves: &self.halves,
                bytes: &self.bytes,
            }
        }

        pub fn layer(&self, format: WeightFormat) -> Layer {
            Layer {
                rows: self.rows as u32,
                cols: self.cols as u32,
                format,
                weights: if format.is_f32() { 2 * self.rows as u32 } else { 0 },
                bias: 0,
                scales: self.rows as u32,
            }
        }

        /// `params` with the weights stored column by column instead
        /// ([`WeightFormat::F32Columns`], same offsets).
        pub fn columns(&self) -> Vec<f32> {
            let stride = crate::model::column_stride(self.rows);
            let mut params = self.params[..2 * self.rows].to_vec();
            params.resize(2 * self.rows + stride * self.cols, 0.0);
            let w = &self.params[2 * self.rows..];
            for r in 0..self.rows {
                for c in 0..self.cols {
                    params[2 * self.rows + c * stride + r] = w[r * self.cols + c];
                }
            }
            params
        }

        /// Row `r`'s weights as `f32` in `format`, unscaled.
        pub fn row(&self, format: WeightFormat, r: usize) -> Vec<f32> {
            let span = r * self.cols..(r + 1) * self.cols;
            match format {
                WeightFormat::F32 | WeightFormat::F32Columns => self.params[2 * self.rows..][span].to_vec(),
                WeightFormat::F16 => self.halves[span]
                    .iter()
                    .map(|&h| half::f16::from_bits(h).to_f32())
                    .collect(),
                WeightFormat::Int8 => self.bytes[span].iter().map(|&b| f32::from(b)).collect(),
            }
        }
    }
}
