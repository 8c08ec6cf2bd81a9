//! Bend-encoded strands walked side by side: [`ChainWalks`] advances `N` strand walks at
//! once, lane `l` doing exactly the arithmetic of [`ChainWalk::step`] for its own strand.
//!
//! One strand's walk is a chain of dependent rotations (each vertex turns the axes the next
//! one starts from), so a single walk waits on its own divisions and products. Strands are
//! independent of each other: stepping several in lanes lets the CPU overlap them, and the
//! lane loops below (plain arrays, one operation per lane, no fused multiply-add) compile to
//! vector instructions where the target has them. Tiny values are flushed to zero as in the
//! scalar walk ([`crate::frame::flush_tiny`]). Every lane performs the same `f32`
//! operations in the same order as the scalar walk, so the positions are the same bits on
//! every target and in any lane (`lanes_give_the_scalar_walk_bit_for_bit`).

use crate::frame::{flush_tiny, ChainWalk};

/// `N` strand walks in structure-of-arrays form: coordinate `i` of lane `l` is `[i][l]`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ChainWalks<const N: usize> {
    position: [[f32; N]; 3],
    /// `d`, `u`, `w` as in [`ChainWalk::axes`].
    axes: [[[f32; N]; 3]; 3],
}

impl<const N: usize> ChainWalks<N> {
    /// Lanes at rest: position zero, the coordinate axes (a lane with no strand steps
    /// harmlessly and is never read).
    pub(crate) fn idle() -> Self {
        let mut axes = [[[0.0; N]; 3]; 3];
        for (a, axis) in axes.iter_mut().enumerate() {
            axis[a] = [1.0; N];
        }
        ChainWalks {
            position: [[0.0; N]; 3],
            axes,
        }
    }

    /// Puts the walk `walk` into lane `l` (ignored past `N`).
    pub(crate) fn set(&mut self, l: usize, walk: &ChainWalk) {
        if l >= N {
            return;
        }
        for i in 0..3 {
            self.position[i][l] = walk.position[i];
            for a in 0..3 {
                self.axes[a][i][l] = walk.axes[a][i];
            }
        }
    }

    /// The position of lane `l` (zero past `N`).
    pub(crate) fn position(&self, l: usize) -> [f32; 3] {
        if l >= N {
            return [0.0; 3];
        }
        core::array::from_fn(|i| self.position[i][l])
    }

    /// [`ChainWalk::step`] in every lane: `q0`, `q1` the encoded numbers and `length` the
    /// rest length of each lane's next edge. On a CPU with AVX-512F every sixteen lanes run
    /// `network/strand_avx512.rs`'s `step16`, the same operations in the same order, written
    /// with its intrinsics (several sixteens one after another, independent, so the CPU
    /// overlaps them).
    pub(crate) fn step(&mut self, q0: &[f32; N], q1: &[f32; N], length: &[f32; N]) {
        if crate::network::isa_strand_step(&mut self.position, &mut self.axes, q0, q1, length) {
            return;
        }
        self.step_lanes(q0, q1, length);
    }

    /// [`ChainWalks::step`] as plain lane loops.
    fn step_lanes(&mut self, q0: &[f32; N], q1: &[f32; N], length: &[f32; N]) {
        let (q0, q1) = (q0.map(flush_tiny), q1.map(flush_tiny));
        let [_, u, w] = self.axes;
        let g: [[f32; N]; 3] =
            core::array::from_fn(|i| lanes(|l| flush_tiny((u[i][l] * q0[l] + w[i][l] * q1[l]) / length[l])));
        let gg = dot(&g, &g);
        let c: [f32; N] = lanes(|l| 2.0 / (1.0 + gg[l]));
        for y in &mut self.axes {
            let h = cross(&g, y).map(|h| h.map(flush_tiny));
            let k = cross(&g, &h);
            for i in 0..3 {
                let turned = lanes(|l| flush_tiny(y[i][l] + (h[i][l] + k[i][l]) * c[l]));
                y[i] = turned;
            }
        }
        let d = self.axes[0];
        for (p, d) in self.position.iter_mut().zip(&d) {
            *p = lanes(|l| p[l] + d[l] * length[l]);
        }
    }
}

/// `[f(0), .., f(N - 1)]`.
#[inline(always)]
fn lanes<const N: usize>(f: impl FnMut(usize) -> f32) -> [f32; N] {
    core::array::from_fn(f)
}

/// The lane-wise `a . b`, in the order of the scalar walk's `dot`.
#[inline(always)]
fn dot<const N: usize>(a: &[[f32; N]; 3], b: &[[f32; N]; 3]) -> [f32; N] {
    lanes(|l| a[0][l] * b[0][l] + a[1][l] * b[1][l] + a[2][l] * b[2][l])
}

/// The lane-wise `a x b`, in the order of the scalar walk's `cross`.
#[inline(always)]
fn cross<const N: usize>(a: &[[f32; N]; 3], b: &[[f32; N]; 3]) -> [[f32; N]; 3] {
    [
        lanes(|l| a[1][l] * b[2][l] - a[2][l] * b[1][l]),
        lanes(|l| a[2][l] * b[0][l] - a[0][l] * b[2][l]),
        lanes(|l| a[0][l] * b[1][l] - a[1][l] * b[0][l]),
    ]
}

#[cfg(all(test, feature = "std"))]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::network::test_support::noise;

    /// A unit direction and two unit normals from three noise values.
    fn start(seed: u32) -> ChainWalk {
        let v: Vec<f32> = noise(seed, 6).collect();
        let norm = |a: [f32; 3]| {
            let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            a.map(|c| c / n)
        };
        let d = norm([v[0], v[1], v[2] + 2.0]);
        let t = [v[3] + 2.0, v[4], v[5]];
        let along = d[0] * t[0] + d[1] * t[1] + d[2] * t[2];
        let u = norm(core::array::from_fn(|i| t[i] - d[i] * along));
        let w = [
            d[1] * u[2] - d[2] * u[1],
            d[2] * u[0] - d[0] * u[2],
            d[0] * u[1] - d[1] * u[0],
        ];
        ChainWalk {
            position: [v[0], v[2], v[4]],
            axes: [d, u, w],
        }
    }

    #[test]
    fn lanes_give_the_scalar_walk_bit_for_bit() {
        lanes_match_the_scalar_walk::<8>();
        // Sixteen and thirty-two lanes: the AVX-512F step where the CPU has it.
        lanes_match_the_scalar_walk::<16>();
        lanes_match_the_scalar_walk::<32>();
    }

    fn lanes_match_the_scalar_walk<const N: usize>() {
        // One strand fewer than lanes: the last lane idles.
        let mut scalar: Vec<ChainWalk> = (0..N as u32 - 1).map(start).collect();
        let mut walks = ChainWalks::<N>::idle();
        for (l, s) in scalar.iter().enumerate() {
            walks.set(l, s);
        }
        for step in 0..200u32 {
            let q: Vec<f32> = noise(1000 + step, 2 * N).map(|v| 0.3 * v).collect();
            let len: Vec<f32> = noise(5000 + step, N).map(|v| 0.05 + 0.04 * v).collect();
            let q0: [f32; N] = core::array::from_fn(|l| q[2 * l]);
            let q1: [f32; N] = core::array::from_fn(|l| q[2 * l + 1]);
            let length: [f32; N] = core::array::from_fn(|l| len[l]);
            walks.step(&q0, &q1, &length);
            for (l, s) in scalar.iter_mut().enumerate() {
                let p = s.step([q0[l], q1[l]], length[l]);
                let got = walks.position(l);
                assert_eq!(p.map(f32::to_bits), got.map(f32::to_bits), "lane {l}, step {step}");
            }
        }
        assert_eq!(walks.position(N), [0.0; 3]);
    }

    /// A strand bending in its plane, with out-of-plane bends of subnormal and tiny size (as a
    /// decoder gives for a strand that swings in a plane): no axis component ever leaves
    /// `f32`'s normal range, and the positions are those of exactly planar bends.
    #[test]
    fn tiny_out_of_plane_bends_are_zero_and_nothing_turns_subnormal() {
        const N: usize = 4;
        let planar = ChainWalk {
            position: [0.0, 0.0, 0.0],
            axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        };
        let (mut tiny, mut exact) = (ChainWalks::<N>::idle(), ChainWalks::<N>::idle());
        for l in 0..N {
            tiny.set(l, &planar);
            exact.set(l, &planar);
        }
        let length = [0.02; N];
        for step in 0..500 {
            let bend: [f32; N] = core::array::from_fn(|l| 0.01 * (step as f32 * 0.1 + l as f32).sin());
            // Out-of-plane bends: subnormal, just above it, and up to just below 2^-50.
            let stray = [3.0e-39, -7.0e-40, 1.0e-30, -8.0e-16];
            tiny.step(&stray, &bend, &length);
            exact.step(&[0.0; N], &bend, &length);
            for axis in tiny.axes.iter().flatten().flatten() {
                assert!(*axis == 0.0 || axis.is_normal(), "step {step}: axis component {axis:e}");
            }
            for l in 0..N {
                assert_eq!(tiny.position(l), exact.position(l), "lane {l}, step {step}");
            }
        }
    }
}
