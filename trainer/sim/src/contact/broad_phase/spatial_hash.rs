//! Overlapping pairs of boxes through a uniform grid: every box is entered in each cell it
//! touches, the entries are sorted by cell, and boxes sharing a cell are tested against each
//! other. A pair is reported only from the cell holding the lower corner of the two boxes'
//! intersection, so each pair comes out once without a set of seen pairs.
//!
//! A grid fits contact primitives: on a mesh they have similar sizes, so with cells about
//! the size of a typical box each box touches a few cells and each cell holds a few boxes.
//! The cell is the mean box size. A box more than 16 cells long on some axis (an obstacle's
//! face, a box swept far by a fast vertex) stays out of the grid and is tested against every
//! box instead: sizing the cells for it would put a whole fine mesh into a few cells and test
//! all of its boxes against each other. At most one box in 16 can be that long (their sizes
//! alone would exceed the mean otherwise), and in a scene they are the few obstacle
//! primitives. Written here rather than taken
//! from a crate: the BVH crates (`bvh`, `parry`) bring f32 or their own geometry types
//! and a tree rebuilt every step, while this is a sort over `(cell, box)` entries in f64.

use super::aabb::Aabb;

/// Cells per axis a box of the grid spans at most, less one; longer boxes are tested against
/// every box (see the module docs).
const MAX_CELLS_PER_AXIS: f64 = 16.0;

/// The grid's cell size and origin.
struct Grid {
    origin: [f64; 3],
    cell: f64,
}

impl Grid {
    fn fit(boxes: &[&[Aabb]]) -> Grid {
        let mut bound = Aabb::EMPTY;
        let (mut sum, mut count) = (0.0, 0usize);
        for b in boxes.iter().flat_map(|s| s.iter()).filter(|b| finite(b)) {
            bound.include(&b.min);
            bound.include(&b.max);
            sum += b.largest_extent();
            count += 1;
        }
        let mut cell = if count > 0 { sum / count as f64 } else { 1.0 };
        if !cell.is_finite() || cell <= 0.0 {
            // Points only: about one per cell along the bound's longest side.
            let side = bound.largest_extent();
            cell = if side > 0.0 { side / (count as f64).cbrt() } else { 1.0 };
        }
        let origin = if count > 0 { bound.min } else { [0.0; 3] };
        Grid { origin, cell }
    }

    fn cell_of(&self, p: [f64; 3]) -> [i64; 3] {
        [0, 1, 2].map(|k| ((p[k] - self.origin[k]) / self.cell).floor() as i64)
    }

    /// Whether the (finite) box `b` is too long for the grid.
    fn is_long(&self, b: &Aabb) -> bool {
        b.largest_extent() > MAX_CELLS_PER_AXIS * self.cell
    }
}

fn finite(b: &Aabb) -> bool {
    b.min.iter().chain(&b.max).all(|v| v.is_finite())
}

/// One box entered in one cell: which set (0 or 1) and its index there.
type Entry = ([i64; 3], u8, u32);

/// Enters the finite boxes that are not too long for the grid; returns the long ones.
fn enter(grid: &Grid, boxes: &[Aabb], set: u8, entries: &mut Vec<Entry>) -> Vec<usize> {
    let mut long = Vec::new();
    for (i, b) in boxes.iter().enumerate().filter(|(_, b)| finite(b)) {
        if grid.is_long(b) {
            long.push(i);
            continue;
        }
        let (lo, hi) = (grid.cell_of(b.min), grid.cell_of(b.max));
        for cx in lo[0]..=hi[0] {
            for cy in lo[1]..=hi[1] {
                for cz in lo[2]..=hi[2] {
                    entries.push(([cx, cy, cz], set, i as u32));
                }
            }
        }
    }
    long
}

/// Pairs `[i, j]` of a box `a[i]` and a box `b[j]` that overlap and pass `keep(i, j)`, each
/// once, sorted. Boxes with a non-finite coordinate overlap nothing.
pub fn overlapping_pairs(a: &[Aabb], b: &[Aabb], keep: impl FnMut(usize, usize) -> bool) -> Vec<[usize; 2]> {
    pairs(a, Some(b), keep)
}

/// Pairs `[i, j]`, `i < j`, of boxes of `a` that overlap and pass `keep(i, j)`, each once,
/// sorted.
pub fn overlapping_self_pairs(a: &[Aabb], keep: impl FnMut(usize, usize) -> bool) -> Vec<[usize; 2]> {
    pairs(a, None, keep)
}

fn pairs(a: &[Aabb], b: Option<&[Aabb]>, mut keep: impl FnMut(usize, usize) -> bool) -> Vec<[usize; 2]> {
    let other = b.unwrap_or(a);
    let grid = match b {
        Some(b) => Grid::fit(&[a, b]),
        None => Grid::fit(&[a]),
    };
    let mut entries = Vec::new();
    let long_a = enter(&grid, a, 0, &mut entries);
    let long_b = b.map(|b| enter(&grid, b, 1, &mut entries));
    entries.sort_unstable();
    let mut out = long_pairs(a, b, &long_a, long_b.as_deref(), &mut keep);
    let mut start = 0;
    while start < entries.len() {
        let cell = entries[start].0;
        let end = start + entries[start..].iter().take_while(|e| e.0 == cell).count();
        let run = &entries[start..end];
        // Entries of set 0 come first in a run (sorted by set after cell).
        let first_b = run.iter().position(|e| e.1 == 1).unwrap_or(run.len());
        let (in_a, in_b) = if b.is_some() { run.split_at(first_b) } else { (run, run) };
        for (k, ea) in in_a.iter().enumerate() {
            // Self pairs: each unordered pair once, from its first entry in the run.
            let partners = if b.is_some() { in_b } else { &in_b[k + 1..] };
            for eb in partners {
                let (i, j) = (ea.2 as usize, eb.2 as usize);
                let (ba, bb) = (&a[i], &other[j]);
                if !ba.overlaps(bb) {
                    continue;
                }
                let corner = [0, 1, 2].map(|d| ba.min[d].max(bb.min[d]));
                if grid.cell_of(corner) != cell {
                    continue;
                }
                let pair = if b.is_none() && j < i { [j, i] } else { [i, j] };
                if keep(pair[0], pair[1]) {
                    out.push(pair);
                }
            }
        }
        start = end;
    }
    out.sort_unstable();
    out
}

/// The pairs with a box too long for the grid (`long_a` of `a`, `long_b` of `b`), each once,
/// by testing it against every finite box of the other set (of `a` for self pairs).
fn long_pairs(
    a: &[Aabb],
    b: Option<&[Aabb]>,
    long_a: &[usize],
    long_b: Option<&[usize]>,
    keep: &mut impl FnMut(usize, usize) -> bool,
) -> Vec<[usize; 2]> {
    let mut out = Vec::new();
    let mut is_long_a = vec![false; if long_a.is_empty() { 0 } else { a.len() }];
    for &i in long_a {
        is_long_a[i] = true;
    }
    let other = b.unwrap_or(a);
    for &i in long_a {
        for (j, bj) in other.iter().enumerate().filter(|(_, x)| finite(x)) {
            // Self pairs: a pair of two long boxes from the lower one only.
            if b.is_none() && (j == i || (is_long_a[j] && j < i)) {
                continue;
            }
            if !a[i].overlaps(bj) {
                continue;
            }
            let pair = if b.is_none() && j < i { [j, i] } else { [i, j] };
            if keep(pair[0], pair[1]) {
                out.push(pair);
            }
        }
    }
    if let (Some(b), Some(long_b)) = (b, long_b) {
        for &j in long_b {
            // Pairs with a long box of `a` came from the loop above.
            for (i, ai) in a
                .iter()
                .enumerate()
                .filter(|(i, x)| finite(x) && is_long_a.get(*i) != Some(&true))
            {
                if ai.overlaps(&b[j]) && keep(i, j) {
                    out.push([i, j]);
                }
            }
        }
    }
    out
}

/// The same pairs as [`overlapping_pairs`] by testing every pair (for tests).
pub fn overlapping_pairs_brute_force(
    a: &[Aabb],
    b: &[Aabb],
    mut keep: impl FnMut(usize, usize) -> bool,
) -> Vec<[usize; 2]> {
    let mut out = Vec::new();
    for (i, ba) in a.iter().enumerate().filter(|(_, x)| finite(x)) {
        for (j, bb) in b.iter().enumerate().filter(|(_, x)| finite(x)) {
            if ba.overlaps(bb) && keep(i, j) {
                out.push([i, j]);
            }
        }
    }
    out
}

/// The same pairs as [`overlapping_self_pairs`] by testing every pair (for tests).
pub fn overlapping_self_pairs_brute_force(a: &[Aabb], mut keep: impl FnMut(usize, usize) -> bool) -> Vec<[usize; 2]> {
    let mut out = Vec::new();
    for (i, ba) in a.iter().enumerate().filter(|(_, x)| finite(x)) {
        for (j, bb) in a.iter().enumerate().skip(i + 1).filter(|(_, x)| finite(x)) {
            if ba.overlaps(bb) && keep(i, j) {
                out.push([i, j]);
            }
        }
    }
    out
}
