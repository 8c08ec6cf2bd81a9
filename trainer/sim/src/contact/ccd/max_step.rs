//! The largest fraction of a step that keeps a contact surface free of intersections: what
//! filters every line-search step (`x0 + t (x1 - x0)` for `t` up to the returned value keeps
//! every candidate pair apart).

use super::additive::AdditiveCcd;
use crate::contact::broad_phase::Candidates;
use crate::contact::ContactSurface;

/// The largest `t` in `[0, 1]` such that moving the surface linearly from `x0` towards `x1`
/// by the fraction `t` keeps every pair of its primitives at least `min_distance` apart
/// (`1` if no pair comes that close). `x0` and `x1` hold `surface.dim` coordinates per
/// vertex. A position that is not a number allows no step (`0`).
pub fn max_step(surface: &ContactSurface, x0: &[f64], x1: &[f64], min_distance: f64, ccd: &AdditiveCcd) -> f64 {
    if x0.iter().chain(x1).any(|v| !v.is_finite()) {
        return 0.0;
    }
    let candidates = Candidates::swept(surface, x0, x1, min_distance);
    max_step_over(&candidates, surface, x0, x1, min_distance, ccd)
}

/// As [`max_step`] over the given candidate pairs (from [`Candidates::swept`] with an
/// inflation of at least `min_distance`).
pub fn max_step_over(
    candidates: &Candidates,
    surface: &ContactSurface,
    x0: &[f64],
    x1: &[f64],
    min_distance: f64,
    ccd: &AdditiveCcd,
) -> f64 {
    let dim = surface.dim;
    let mut s0 = [0.0; 12];
    let mut s1 = [0.0; 12];
    let mut gather = |verts: &[usize]| {
        for (a, &v) in verts.iter().enumerate() {
            s0[a * dim..(a + 1) * dim].copy_from_slice(&x0[v * dim..(v + 1) * dim]);
            s1[a * dim..(a + 1) * dim].copy_from_slice(&x1[v * dim..(v + 1) * dim]);
        }
        let n = verts.len() * dim;
        (s0, s1, n)
    };
    // Each pair only needs to be searched up to the earliest impact found so far.
    let mut t = 1.0;
    for &[v, f] in &candidates.point_triangle {
        let face = surface.faces[f];
        let (a, b, n) = gather(&[v, face[0], face[1], face[2]]);
        if let Some(toi) = ccd.point_triangle(&a[..n], &b[..n], min_distance, t) {
            t = f64::min(t, toi);
        }
    }
    for &[i, j] in &candidates.edge_edge {
        let (ea, eb) = (surface.edges[i], surface.edges[j]);
        let (a, b, n) = gather(&[ea[0], ea[1], eb[0], eb[1]]);
        if let Some(toi) = ccd.edge_edge(&a[..n], &b[..n], min_distance, t) {
            t = f64::min(t, toi);
        }
    }
    for &[v, e] in &candidates.point_edge {
        let edge = surface.edges[e];
        let (a, b, n) = gather(&[v, edge[0], edge[1]]);
        if let Some(toi) = ccd.point_edge(&a[..n], &b[..n], dim, min_distance, t) {
            t = f64::min(t, toi);
        }
    }
    t
}
