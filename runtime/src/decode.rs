//! From a decoder's output to world positions: the output layer's rows, the world transform
//! of encoded vertices, and the walk along bend-encoded strands. Shared by
//! [`crate::instance::Instance`]'s full and surface decodes.

use nalgebra::Vector3;

use crate::frame::Placement;
use crate::model::{Chain, Layer, Model, Weights};
use crate::network::world::{WorldTransform, BLOCK_FLOATS, BLOCK_VERTICES};
use crate::network::{self, LayerInput, WorldBlocks, STRAND_LANES};
use crate::strand_lanes::ChainWalks;

/// Writes the first `d` coordinates of `p` as vertex `v` of `out` (element by element: a
/// slice copy of 2 or 3 floats would be a call to `memmove`).
#[inline]
pub(crate) fn put(out: &mut [f32], v: usize, d: usize, p: &Vector3<f32>) {
    for c in 0..d {
        if let Some(o) = out.get_mut(v * d + c) {
            *o = p[c];
        }
    }
}

/// What the decoder's last layer reads for the latent `z` ([`network::decoder_features`]),
/// with scratch on the stack.
pub(crate) fn decoder_features<const H: usize>(m: &Model, z: &[f32]) -> [f32; H] {
    let (mut f, mut h, mut a, mut b) = ([0.0f32; H], [0.0f32; H], [0.0f32; H], [0.0f32; H]);
    network::decoder_features(
        &m.weights(),
        m.decoder,
        m.decoder_basis,
        z,
        &mut f,
        [&mut h, &mut a, &mut b],
    );
    f
}

/// The output layer of a network applied to its last hidden activation, row range by row
/// range: the input is prepared once ([`LayerInput`]).
pub(crate) struct OutputRows<'w, 'l, 'h> {
    weights: Weights<'w>,
    output: Option<&'l Layer>,
    input: LayerInput<'h>,
}

impl<'w, 'l, 'h> OutputRows<'w, 'l, 'h> {
    /// The output layer of `layers` on `h` (of which it reads its first `cols` values).
    pub(crate) fn new(weights: Weights<'w>, layers: &'l [Layer], h: &'h [f32]) -> Self {
        let output = layers.last();
        let x = output.and_then(|l| h.get(..l.cols as usize)).unwrap_or(h);
        let input = LayerInput::new(output.unwrap_or(&Layer::default()), x);
        OutputRows { weights, output, input }
    }

    /// Rows `first..first + out.len()`.
    pub(crate) fn rows(&self, first: usize, out: &mut [f32]) {
        if let Some(output) = self.output {
            self.input.rows(&self.weights, output, first, out);
        }
    }

    /// [`WorldTransform::placed_vertices`] of the layer: the free vertices, sixteen at a time,
    /// decoded and placed straight into `out`; returns how many.
    fn placed_vertices(
        &self,
        (blocks, origin): (&mut WorldBlocks, &mut u32),
        free: &[u32],
        origin_of: &[u32],
        origin_at: &mut dyn FnMut(u32) -> Vector3<f32>,
        out: &mut [f32],
    ) -> usize {
        self.output.map_or(0, |l| {
            blocks.placed_vertices(
                self.weights.params,
                l,
                self.input.values(),
                free,
                origin_of,
                origin,
                origin_at,
                out,
            )
        })
    }

    /// Rows from `first` transformed by `blocks` in the same pass, as many whole blocks of
    /// sixteen 3D vertices as `out` holds; returns the rows written (0 unless the layer is
    /// stored by columns, see [`WorldTransform::placed_rows`]).
    fn placed_rows(&self, blocks: &WorldBlocks, first: usize, out: &mut [f32]) -> usize {
        self.output.map_or(0, |l| {
            blocks.placed_rows(self.weights.params, l, self.input.values(), first, out)
        })
    }
}

/// Encoded vertices whose decoder rows a [`BendRows`] computes at once.
const BEND_BLOCK: usize = 16;

/// One strand's cache of the decoder's output rows for bend-encoded vertices, a block of
/// consecutive free vertices at a time (a strand usually lists consecutive ones): each row
/// has the same bits whichever block computes it (see [`crate::network`]).
#[derive(Clone, Copy)]
struct BendRows {
    /// First free vertex in `rows`, and how many.
    first: usize,
    count: usize,
    rows: [f32; 2 * BEND_BLOCK],
}

impl BendRows {
    const EMPTY: BendRows = BendRows {
        first: 0,
        count: 0,
        rows: [0.0; 2 * BEND_BLOCK],
    };

    /// The two encoded numbers of free vertex `j` of the `total` free vertices (zeros past
    /// them).
    fn get(&mut self, output: &OutputRows, total: usize, j: usize) -> [f32; 2] {
        if j < self.first || j >= self.first + self.count {
            let count = BEND_BLOCK.min(total.saturating_sub(j));
            output.rows(2 * j, &mut self.rows[..2 * count]);
            self.first = j;
            self.count = count;
        }
        if self.count == 0 {
            return [0.0; 2];
        }
        let at = |i: usize| self.rows.get(i).copied().unwrap_or(0.0);
        let i = 2 * j.saturating_sub(self.first);
        [at(i), at(i + 1)]
    }
}

/// Walks every bend-encoded strand of `m` from its start in `place`, with the decoder's last
/// hidden activation `h`, calling `visit(lane, j, position)` for each free vertex `j`: in
/// strand order along each strand, [`STRAND_LANES`] strands side by side (`lane` says which
/// of them, so that a caller can follow each strand's own order).
pub(crate) fn walk_chains(m: &Model, h: &[f32], place: &Placement, mut visit: impl FnMut(usize, usize, &[f32; 3])) {
    let output = OutputRows::new(m.weights(), m.decoder, h);
    let total = m.free_vertices().len();
    let mut chains = m.chains();
    loop {
        let group: [Option<Chain>; STRAND_LANES] = core::array::from_fn(|_| chains.next());
        if group[0].is_none() {
            return;
        }
        let mut walks = ChainWalks::<STRAND_LANES>::idle();
        for (l, chain) in group.iter().enumerate() {
            if let Some(chain) = chain {
                walks.set(l, &place.chain_start(chain));
            }
        }
        let vertex = |chain: &Option<Chain>, t: usize| -> Option<(usize, f32)> {
            let chain = chain.as_ref()?;
            Some((*chain.slots.get(t)? as usize, *chain.lengths.get(t)?))
        };
        let mut rows = [BendRows::EMPTY; STRAND_LANES];
        let longest = group
            .iter()
            .flatten()
            .map(|c| c.slots.len().min(c.lengths.len()))
            .max()
            .unwrap_or(0);
        for t in 0..longest {
            // Lanes whose strand has ended step along an edge of zero bend and unit length.
            let (mut q0, mut q1, mut length) = ([0.0; STRAND_LANES], [0.0; STRAND_LANES], [1.0; STRAND_LANES]);
            for (l, chain) in group.iter().enumerate() {
                if let Some((j, edge)) = vertex(chain, t) {
                    [q0[l], q1[l]] = rows[l].get(&output, total, j);
                    length[l] = edge;
                }
            }
            walks.step(&q0, &q1, &length);
            for (l, chain) in group.iter().enumerate() {
                if let Some((j, _)) = vertex(chain, t) {
                    visit(l, j, &walks.position(l));
                }
            }
        }
    }
}

/// Where each strand lane of [`walk_chains`] last found its vertex in an ascending list of
/// vertices: a strand lists consecutive vertices mostly, so the next one is usually the next
/// entry, and a binary search (whose branches the CPU cannot predict) is the exception.
pub(crate) struct ListCursors {
    at: [usize; STRAND_LANES],
}

impl ListCursors {
    pub(crate) const START: ListCursors = ListCursors { at: [0; STRAND_LANES] };

    /// The index of `v` in the ascending `list`, for strand lane `lane`.
    pub(crate) fn find(&mut self, list: &[u32], lane: usize, v: u32) -> Option<usize> {
        let at = self.at.get_mut(lane)?;
        let i = match list.get(*at + 1) {
            Some(&next) if next == v => *at + 1,
            _ => list.binary_search(&v).ok()?,
        };
        *at = i;
        Some(i)
    }
}

/// How many leading values of `values` count up by one from the first (a run of consecutive
/// vertices, whose output rows are contiguous).
pub(crate) fn consecutive(values: &[u32]) -> usize {
    let Some(&first) = values.first() else {
        return 0;
    };
    values.iter().zip(first..).take_while(|(v, want)| **v == *want).count()
}

/// How many leading values of the strictly ascending `values` count up by one from the first,
/// found by bisection: `values[i] - i` never decreases, so the run is where it stays equal
/// to the first value.
pub(crate) fn consecutive_ascending(values: &[u32]) -> usize {
    let Some(&first) = values.first() else {
        return 0;
    };
    let in_run = |i: usize| values.get(i).is_some_and(|&v| v as usize == first as usize + i);
    // `in_run(lo)` holds and `in_run(hi)` does not (past the end it never does).
    let (mut lo, mut hi) = (0, values.len());
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if in_run(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// Decodes the run of consecutive encoded vertices whose output rows start at `first_row`
/// straight into `run` (`d` floats each, `origin_of` their origin indices) and turns them
/// into world positions: blocks of sixteen 3D vertices that share an origin in one pass
/// where the CPU has the vector transform and the layer is stored by columns, the rest row
/// by row and then [`place_run`].
pub(crate) fn decode_run(
    output: &OutputRows,
    d: usize,
    first_row: usize,
    run: &mut [f32],
    origin_of: &[u32],
    origins: &mut Origins,
) {
    // The target's constant first: where it is `false` the branch is gone before inlining.
    let done = match WorldBlocks::PRESENT && d == 3 && origins.vector {
        true => placed_blocks(output, first_row, run, origin_of, origins),
        false => 0,
    };
    let rest = run.get_mut(done * d..).unwrap_or_default();
    output.rows(first_row + done * d, rest);
    place_run(d, rest, origin_of.get(done..).unwrap_or(&[]), origins);
}

/// The leading free vertices of a full decode into `out` (all the model's vertices, `d`
/// floats each) decoded and placed in one pass over the output layer where the CPU has the
/// vector transform and the layer is stored by columns: every whole block of sixteen free
/// vertices ([`OutputRows::placed_vertices`]). Returns how many; the caller decodes the rest
/// run by run.
pub(crate) fn placed_free(
    output: &OutputRows,
    d: usize,
    free: &[u32],
    origin_of: &[u32],
    out: &mut [f32],
    origins: &mut Origins,
) -> usize {
    if !WorldBlocks::PRESENT || d != 3 || !origins.vector {
        return 0;
    }
    let Some(&origin) = origin_of.first() else {
        return 0;
    };
    if origins.blocks_for(origin).is_none() {
        return 0;
    }
    let place = origins.place;
    match origins.blocks.as_mut() {
        Some((at, blocks)) => output.placed_vertices((blocks, at), free, origin_of, &mut |o| place.origin(o), out),
        None => 0,
    }
}

/// The leading blocks of sixteen 3D vertices of `run` whose vertices share an origin block by
/// block, decoded and placed in one pass ([`OutputRows::placed_rows`]); returns the vertices
/// done.
fn placed_blocks(
    output: &OutputRows,
    first_row: usize,
    run: &mut [f32],
    origin_of: &[u32],
    origins: &mut Origins,
) -> usize {
    let mut done = 0;
    while let Some(&origin) = origin_of.get(done) {
        // Mostly every vertex left shares the origin: a pass without an early exit vectorises.
        let left = origin_of.get(done..).unwrap_or(&[]);
        let shared = match left.iter().fold(true, |all, &o| all & (o == origin)) {
            true => left.len(),
            false => left.iter().take_while(|&&o| o == origin).count(),
        };
        let vertices = shared / BLOCK_VERTICES * BLOCK_VERTICES;
        let (Some(span), Some(blocks)) = (run.get_mut(3 * done..3 * (done + vertices)), origins.blocks_for(origin))
        else {
            break;
        };
        let written = if vertices > 0 {
            output.placed_rows(blocks, first_row + 3 * done, span) / 3
        } else {
            0
        };
        done += written;
        if written == 0 || written < shared {
            break;
        }
    }
    done
}

/// Turns the local coordinates of a run of encoded vertices decoded into `run` (`d` floats
/// each) into world positions in place, `origin_of` their origin indices: sixteen at a time
/// where the CPU has the block transform ([`WorldBlocks`]) and the sixteen share an origin,
/// several per vector where it has a per-vertex one ([`network::isa_place`]), else one by one.
pub(crate) fn place_run(d: usize, run: &mut [f32], origin_of: &[u32], origins: &mut Origins) {
    // The targets' constants first: where they are `false` the branches are gone before
    // inlining, and the loop below is all there is.
    let mut done = 0;
    if WorldBlocks::PRESENT && d == 3 && origins.vector {
        done = place_blocks(run, origin_of, origins);
    }
    if network::ISA_PLACE && d == 3 {
        let frame = origins.place.frame;
        let (rest, of) = (
            run.get_mut(3 * done..).unwrap_or_default(),
            origin_of.get(done..).unwrap_or(&[]),
        );
        done += network::isa_place(&frame, origins.vector, rest, of, |o| origins.get(o));
    }
    let frame = origins.place.frame;
    for (q, &o) in run.chunks_exact_mut(d).zip(origin_of).skip(done) {
        let world = frame * Vector3::new(q[0], q[1], q.get(2).copied().unwrap_or(0.0)) + origins.get(o);
        q.iter_mut().zip(world.iter()).for_each(|(q, w)| *q = *w);
    }
}

/// The leading blocks of sixteen 3D vertices of `run` that share an origin, placed with the
/// vector transform; returns the vertices placed (0 where the CPU has no vector transform).
fn place_blocks(run: &mut [f32], origin_of: &[u32], origins: &mut Origins) -> usize {
    let mut done = 0;
    for (block, of) in run
        .chunks_exact_mut(BLOCK_FLOATS)
        .zip(origin_of.chunks_exact(BLOCK_VERTICES))
    {
        let Some(block) = <&mut [f32; BLOCK_FLOATS]>::try_from(block).ok() else {
            break;
        };
        if !of.iter().all(|&o| o == of[0]) || !origins.place_block(of[0], block) {
            break;
        }
        done += BLOCK_VERTICES;
    }
    done
}

/// The origins of encoded vertices ([`Placement::origin`]), the last one kept: consecutive
/// vertices mostly share an origin, and placing a handle vertex costs a rotation. Also the
/// vector transform for that origin, where the target has one ([`WorldBlocks`]).
pub(crate) struct Origins<'p, 'm, 'a> {
    place: &'p Placement<'m, 'a>,
    last: Option<(u32, Vector3<f32>)>,
    /// Whether the vector transform may be used: only behind an `f32` decoder, whose targets
    /// agree within rounding; `f16` and int8 decoders promise the same bits everywhere, and
    /// the vector transform rounds differently from the scalar one.
    vector: bool,
    blocks: Option<(u32, WorldBlocks)>,
}

impl<'p, 'm, 'a> Origins<'p, 'm, 'a> {
    /// The origins of `place`; `vector` where the decoded coordinates come from an `f32`
    /// layer.
    pub(crate) fn new(place: &'p Placement<'m, 'a>, vector: bool) -> Self {
        Origins {
            place,
            last: None,
            vector,
            blocks: None,
        }
    }

    /// The vector transform for origin `origin`; `None` where the CPU has none.
    fn blocks_for(&mut self, origin: u32) -> Option<&WorldBlocks> {
        let o = match self.blocks {
            Some((at, _)) if at == origin => None,
            _ => Some(self.get(origin)),
        };
        match (&mut self.blocks, o) {
            (_, None) => {}
            // The rotation stays: only the origin moves.
            (Some((at, blocks)), Some(o)) => {
                blocks.set_origin(&o);
                *at = origin;
            }
            (None, Some(o)) => self.blocks = Some((origin, WorldBlocks::new(&self.place.frame, &o)?)),
        }
        self.blocks.as_ref().map(|(_, blocks)| blocks)
    }

    /// Sixteen vertices of origin `origin` placed with the vector transform; `false`, and
    /// nothing done, where the CPU has none.
    fn place_block(&mut self, origin: u32, block: &mut [f32; BLOCK_FLOATS]) -> bool {
        self.blocks_for(origin).map(|blocks| blocks.apply(block)).is_some()
    }

    #[inline]
    pub(crate) fn get(&mut self, origin: u32) -> Vector3<f32> {
        match self.last {
            Some((at, o)) if at == origin => o,
            _ => {
                let o = self.place.origin(origin);
                self.last = Some((origin, o));
                o
            }
        }
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;

    /// Bisection finds the run the linear scan finds, at every start of ascending lists with
    /// runs of every length and gaps.
    #[test]
    fn bisection_finds_the_scanned_run() {
        let mut values = std::vec::Vec::new();
        let mut v = 3u32;
        for (i, run) in [1usize, 2, 7, 16, 33, 1, 100, 5].into_iter().enumerate() {
            values.extend((0..run as u32).map(|k| v + k));
            v += run as u32 + 1 + i as u32 % 3;
        }
        for start in 0..=values.len() {
            assert_eq!(
                consecutive_ascending(&values[start..]),
                consecutive(&values[start..]),
                "from {start}"
            );
        }
    }
}
