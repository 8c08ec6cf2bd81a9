//! [`Model::validate`]: every size, span and index of a model checked once, and every number
//! finite, so that stepping and decoding cannot index out of bounds (the accessors of
//! [`crate::model`] then cannot fail).

use crate::model::{
    ascending, column_stride, Layer, Model, ModelError, Problem, WeightFormat, HANDLE_SOURCE, MAX_HANDLES, MAX_LAYERS,
    SIGNAL_PER_HANDLE,
};

fn fail<T>(field: &'static str, problem: Problem) -> Result<T, ModelError> {
    Err(ModelError { field, problem })
}

impl Model<'_> {
    /// Checks every size, span and index and that all numbers are finite, so that stepping
    /// and decoding cannot index out of bounds.
    pub fn validate(&self) -> Result<(), ModelError> {
        let dim = self.dim();
        let n = self.num_vertices as usize;
        let k = self.latent as usize;
        if !(dim == 2 || dim == 3) {
            return fail("dim", Problem::Unsupported);
        }
        let positive = |v: f32| v.is_finite() && v > 0.0;
        if !positive(self.dt) {
            return fail("dt", Problem::NotFinite);
        }
        if !positive(self.diagonal) {
            return fail("diagonal", Problem::NotFinite);
        }
        let float_spans = [
            ("rest", self.rest, n * dim),
            ("initial_latent", self.initial_latent, k),
            ("latent_min", self.latent_min, k),
            ("latent_max", self.latent_max, k),
            (
                "collider_shapes",
                self.collider_shapes,
                self.collider_shapes.len as usize,
            ),
        ];
        for (field, span, len) in float_spans {
            let values = span.of(self.floats).ok_or(ModelError {
                field,
                problem: Problem::OutOfRange,
            })?;
            if values.len() != len {
                return fail(
                    field,
                    Problem::Length {
                        expected: len,
                        found: values.len(),
                    },
                );
            }
            if !values.iter().all(|v| v.is_finite()) {
                return fail(field, Problem::NotFinite);
            }
        }
        if self.latent_min().iter().zip(self.latent_max()).any(|(lo, hi)| lo > hi) {
            return fail("latent_min", Problem::Inconsistent);
        }
        let index_spans = [
            ("handle_vertices", self.handle_vertices),
            ("free_vertices", self.free_vertices),
            ("origin_of", self.origin_of),
            ("root_slots", self.root_slots),
            ("surface_vertices", self.surface_vertices),
            ("surface_source", self.surface_source),
            ("surface_triangles", self.surface_triangles),
            ("chain_order", self.chain_order),
        ];
        for (field, span) in index_spans {
            if span.of(self.indices).is_none() {
                return fail(field, Problem::OutOfRange);
            }
        }
        self.validate_vertices()?;
        self.validate_triangles()?;
        self.validate_handles()?;
        self.validate_chains()?;
        let bc = SIGNAL_PER_HANDLE * self.handles.len();
        if self.bc_len as usize != bc {
            return fail(
                "bc_len",
                Problem::Length {
                    expected: bc,
                    found: self.bc_len as usize,
                },
            );
        }
        self.validate_decoder(k)?;
        self.validate_frame_times()?;
        self.validate_colliders()?;
        self.validate_render()?;
        self.validate_network("integrator", self.integrator, self.integrator_input(), k)?;
        if !self.params.iter().all(|v| v.is_finite()) {
            return fail("params", Problem::NotFinite);
        }
        // Exponent bits all set: a half-precision infinity or NaN.
        if self.halves.iter().any(|h| h & 0x7c00 == 0x7c00) {
            return fail("halves", Problem::NotFinite);
        }
        Ok(())
    }

    /// The collider slots: whole shape rows, at most [`crate::collider::MAX_COLLIDERS`], each a
    /// known shape with positive sizes.
    fn validate_colliders(&self) -> Result<(), ModelError> {
        use crate::collider::{shape_from_row, MAX_COLLIDERS, SHAPE_ROW};
        let rows = self.collider_shape_rows();
        if !rows.len().is_multiple_of(SHAPE_ROW) || rows.len() / SHAPE_ROW > MAX_COLLIDERS {
            return fail("collider_shapes", Problem::Unsupported);
        }
        if rows.chunks_exact(SHAPE_ROW).any(|r| shape_from_row(r).is_none()) {
            return fail("collider_shapes", Problem::Domain);
        }
        Ok(())
    }

    /// The trained range of frame times: both 0 (one frame time), or finite with
    /// `0 < dt_min <= dt_max`; a rate input only with a range.
    fn validate_frame_times(&self) -> Result<(), ModelError> {
        let (lo, hi) = (self.dt_min, self.dt_max);
        if self.rate_input && hi == 0.0 {
            return fail("rate_input", Problem::Domain);
        }
        for (field, v) in [("dt_min", lo), ("dt_max", hi)] {
            if !v.is_finite() {
                return fail(field, Problem::NotFinite);
            }
        }
        match (lo, hi) {
            (0.0, 0.0) => Ok(()),
            (lo, hi) if lo > 0.0 && lo <= hi => Ok(()),
            (lo, _) if lo <= 0.0 => fail("dt_min", Problem::Domain),
            _ => fail("dt_max", Problem::Domain),
        }
    }

    fn validate_vertices(&self) -> Result<(), ModelError> {
        let n = self.num_vertices as usize;
        let (handle, free) = (self.handle_vertices(), self.free_vertices());
        if handle.len() + free.len() != n {
            return fail(
                "free_vertices",
                Problem::Length {
                    expected: n - handle.len().min(n),
                    found: free.len(),
                },
            );
        }
        if !ascending(free) || free.last().is_some_and(|&v| v as usize >= n) {
            return fail("free_vertices", Problem::Inconsistent);
        }
        // Prescribed vertices are in range, not free, and listed once, each handle's in
        // ascending order (with the count above, handle and free vertices then partition the
        // mesh).
        if handle.iter().any(|v| *v as usize >= n || free.binary_search(v).is_ok()) || !self.handle_vertices_distinct()
        {
            return fail("handle_vertices", Problem::Inconsistent);
        }
        if self.origin_of().len() != free.len() {
            return fail(
                "origin_of",
                Problem::Length {
                    expected: free.len(),
                    found: self.origin_of().len(),
                },
            );
        }
        let roots = self.root_slots();
        let origins = roots.len().max(1);
        if self.origin_of().iter().any(|&o| o as usize >= origins) {
            return fail("origin_of", Problem::OutOfRange);
        }
        if roots.iter().any(|&s| s as usize >= handle.len()) {
            return fail("root_slots", Problem::OutOfRange);
        }
        let surface = self.surface_vertices();
        if !ascending(surface) || surface.last().is_some_and(|&v| v as usize >= n) {
            return fail("surface_vertices", Problem::Inconsistent);
        }
        let source = self.surface_source();
        if source.len() != surface.len() {
            return fail(
                "surface_source",
                Problem::Length {
                    expected: surface.len(),
                    found: source.len(),
                },
            );
        }
        for (&v, &s) in surface.iter().zip(source) {
            let found = if s & HANDLE_SOURCE != 0 {
                handle.get((s & !HANDLE_SOURCE) as usize)
            } else {
                free.get(s as usize)
            };
            if found != Some(&v) {
                return fail("surface_source", Problem::Inconsistent);
            }
        }
        Ok(())
    }

    /// Whole triangles over the drawn vertices (one pass).
    fn validate_triangles(&self) -> Result<(), ModelError> {
        let triangles = self.surface_triangles();
        if !triangles.len().is_multiple_of(3) {
            return fail(
                "surface_triangles",
                Problem::Length {
                    expected: triangles.len() - triangles.len() % 3,
                    found: triangles.len(),
                },
            );
        }
        let drawn = self.surface_vertices.len;
        if triangles.iter().any(|&i| i >= drawn) {
            return fail("surface_triangles", Problem::OutOfRange);
        }
        Ok(())
    }

    /// The chain tables (see [`Model::chains`]): records that fit, parents that are two
    /// distinct handle slots, unit normals, positive lengths, and slots that list every free
    /// vertex exactly once. Runs after the vertex sets are validated.
    fn validate_chains(&self) -> Result<(), ModelError> {
        let table = self.chains.of(self.indices).ok_or(ModelError {
            field: "chains",
            problem: Problem::OutOfRange,
        })?;
        let reals = self.chain_floats.of(self.floats).ok_or(ModelError {
            field: "chains.lengths",
            problem: Problem::OutOfRange,
        })?;
        if table.is_empty() {
            let order = self.chain_order.len as usize;
            if order != 0 {
                return fail(
                    "chain_order",
                    Problem::Length {
                        expected: 0,
                        found: order,
                    },
                );
            }
            if !reals.is_empty() {
                return fail(
                    "chains.lengths",
                    Problem::Length {
                        expected: 0,
                        found: reals.len(),
                    },
                );
            }
            return Ok(());
        }
        if self.dim() != 3 {
            return fail("chains", Problem::Unsupported);
        }
        let (slots, free) = (self.handle_vertices().len(), self.free_vertices().len());
        let (mut i, mut f, mut covered) = (0usize, 0usize, 0usize);
        while i < table.len() {
            let Some(&[p0, p1, n]) = table.get(i..).and_then(|t| t.first_chunk::<3>()) else {
                return fail("chains", Problem::Inconsistent);
            };
            let n = n as usize;
            let end = |start: usize| start.checked_add(3).and_then(|s| s.checked_add(n));
            let Some(strand) = end(i).and_then(|e| table.get(i + 3..e)) else {
                return fail("chains", Problem::Inconsistent);
            };
            let Some(record) = end(f).and_then(|e| reals.get(f..e)) else {
                return fail(
                    "chains.lengths",
                    Problem::Length {
                        expected: f.saturating_add(3).saturating_add(n),
                        found: reals.len(),
                    },
                );
            };
            if p0 as usize >= slots || p1 as usize >= slots {
                return fail("chains.parent", Problem::OutOfRange);
            }
            if p0 == p1 {
                return fail("chains.parent", Problem::Inconsistent);
            }
            let (normal, lengths) = record.split_at(3);
            if !normal.iter().all(|v| v.is_finite()) {
                return fail("chains.rest_normal", Problem::NotFinite);
            }
            let squared = normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2];
            if (squared - 1.0).abs() >= 1e-4 {
                return fail("chains.rest_normal", Problem::Domain);
            }
            if !lengths.iter().all(|l| l.is_finite()) {
                return fail("chains.lengths", Problem::NotFinite);
            }
            if !lengths.iter().all(|&l| l > 0.0) {
                return fail("chains.lengths", Problem::Domain);
            }
            if strand.iter().any(|&j| j as usize >= free) {
                return fail("chains.slots", Problem::OutOfRange);
            }
            covered += n;
            i += 3 + n;
            f += 3 + n;
        }
        if f != reals.len() {
            return fail(
                "chains.lengths",
                Problem::Length {
                    expected: f,
                    found: reals.len(),
                },
            );
        }
        if covered != free {
            return fail(
                "chains.slots",
                Problem::Length {
                    expected: free,
                    found: covered,
                },
            );
        }
        // Every free vertex exactly once, through the positions `chain_order` gives them.
        match self.chain_order_problem(free) {
            Some((field, problem)) => fail(field, problem),
            None => Ok(()),
        }
    }

    fn validate_handles(&self) -> Result<(), ModelError> {
        if self.handles.len() > MAX_HANDLES {
            return fail("handles", Problem::Unsupported);
        }
        let mut slot = 0usize;
        let all = self.handle_vertices();
        for h in self.handles {
            let vertices = h.vertices.of(self.indices).ok_or(ModelError {
                field: "handles",
                problem: Problem::OutOfRange,
            })?;
            let reference = h.reference.of(self.floats).ok_or(ModelError {
                field: "handles",
                problem: Problem::OutOfRange,
            })?;
            if reference.len() != 3 * vertices.len() {
                return fail(
                    "handles",
                    Problem::Length {
                        expected: 3 * vertices.len(),
                        found: reference.len(),
                    },
                );
            }
            if all.get(slot..slot + vertices.len()) != Some(vertices) {
                return fail("handles", Problem::Inconsistent);
            }
            if !reference.iter().chain(&h.pivot).all(|v| v.is_finite()) {
                return fail("handles", Problem::NotFinite);
            }
            slot += vertices.len();
        }
        if slot != all.len() {
            return fail(
                "handle_vertices",
                Problem::Length {
                    expected: slot,
                    found: all.len(),
                },
            );
        }
        Ok(())
    }

    /// The decoder: a residual MLP `k -> encoded`, or a basis `encoded x m` (`m >= k`) after a
    /// residual MLP `k -> m` (none when `m == k`).
    fn validate_decoder(&self, k: usize) -> Result<(), ModelError> {
        let (encoded, field) = (self.encoded_len(), "decoder");
        let Some((basis, mlp)) = self.decoder.split_last().filter(|_| self.decoder_basis) else {
            return self.validate_network(field, self.decoder, k, encoded);
        };
        let m = basis.cols as usize;
        if m < k || (mlp.is_empty() && m != k) || basis.rows as usize != encoded {
            return fail(field, Problem::Shape);
        }
        if !mlp.is_empty() {
            self.validate_network(field, mlp, k, m)?;
        }
        self.validate_layers(field, core::slice::from_ref(basis), |_| (encoded, m))
    }

    fn validate_network(
        &self,
        field: &'static str,
        layers: &[Layer],
        input: usize,
        output: usize,
    ) -> Result<(), ModelError> {
        if layers.len() < 2 || !layers.len().is_multiple_of(2) || layers.len() > MAX_LAYERS {
            return fail(field, Problem::Unsupported);
        }
        let hidden = layers[0].rows as usize;
        let last = layers.len() - 1;
        self.validate_layers(field, layers, |i| match i {
            0 => (hidden, input),
            _ if i == last => (output, hidden),
            _ => (hidden, hidden),
        })
    }

    /// Each layer has the shape `shape(i)` gives (rows, cols) and fits its pools.
    fn validate_layers(
        &self,
        field: &'static str,
        layers: &[Layer],
        shape: impl Fn(usize) -> (usize, usize),
    ) -> Result<(), ModelError> {
        for (i, l) in layers.iter().enumerate() {
            let (rows, cols) = (l.rows as usize, l.cols as usize);
            let (want_rows, want_cols) = shape(i);
            if rows != want_rows || cols != want_cols || rows == 0 {
                return fail(field, Problem::Shape);
            }
            let fits =
                |start: u32, len: usize, pool: usize| (start as usize).checked_add(len).is_some_and(|e| e <= pool);
            let weights_fit = match l.format {
                WeightFormat::F32 => fits(l.weights, rows * cols, self.params.len()),
                WeightFormat::F32Columns => fits(l.weights, column_stride(rows) * cols, self.params.len()),
                WeightFormat::F16 => fits(l.weights, rows * cols, self.halves.len()),
                WeightFormat::Int8 => {
                    fits(l.weights, rows * cols, self.bytes.len()) && fits(l.scales, rows, self.params.len())
                }
            };
            if !weights_fit || !fits(l.bias, rows, self.params.len()) {
                return fail(field, Problem::OutOfRange);
            }
        }
        Ok(())
    }
}
