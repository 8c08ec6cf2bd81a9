//! The one list of a [`Model`]'s fields, by name and kind, in declaration order: code
//! generation writes the `Model` literal from it, and the loader starts from
//! [`Model::EMPTY`] (docs/design.md, decision 4).
//!
//! Both are written with every field named (no `..`), so a field added to [`Model`] does not
//! compile until it is added here.

use crate::model::{Handle, Layer, Model, Span};

/// The value of one [`Model`] field, by kind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FieldValue<'a> {
    /// A count or size.
    U32(u32),
    /// A real.
    F32(f32),
    /// A flag.
    Bool(bool),
    /// A range of [`Model::floats`] or [`Model::indices`].
    Span(Span),
    /// A pool of `f32`.
    F32s(&'a [f32]),
    /// A pool of half-precision bit patterns.
    U16s(&'a [u16]),
    /// A pool of signed bytes.
    I8s(&'a [i8]),
    /// A pool of indices.
    U32s(&'a [u32]),
    /// A network's layers.
    Layers(&'a [Layer]),
    /// The handles.
    Handles(&'a [Handle]),
}

const EMPTY_SPAN: Span = Span { start: 0, len: 0 };

impl Model<'static> {
    /// A model with every size zero, every pool empty and every span empty (not valid; the
    /// start from which the loader fills in what it reads).
    pub const EMPTY: Model<'static> = Model {
        dim: 0,
        num_vertices: 0,
        latent: 0,
        bc_len: 0,
        dt: 0.0,
        dt_min: 0.0,
        dt_max: 0.0,
        rate_input: false,
        diagonal: 0.0,
        rotates: false,
        params: &[],
        halves: &[],
        bytes: &[],
        floats: &[],
        indices: &[],
        decoder: &[],
        decoder_basis: false,
        integrator: &[],
        handles: &[],
        rest: EMPTY_SPAN,
        handle_vertices: EMPTY_SPAN,
        free_vertices: EMPTY_SPAN,
        origin_of: EMPTY_SPAN,
        root_slots: EMPTY_SPAN,
        chains: EMPTY_SPAN,
        chain_floats: EMPTY_SPAN,
        chain_order: EMPTY_SPAN,
        surface_vertices: EMPTY_SPAN,
        surface_source: EMPTY_SPAN,
        surface_triangles: EMPTY_SPAN,
        initial_latent: EMPTY_SPAN,
        latent_min: EMPTY_SPAN,
        latent_max: EMPTY_SPAN,
        collider_shapes: EMPTY_SPAN,
        render_anchors: EMPTY_SPAN,
        render_weights: EMPTY_SPAN,
        render_triangles: EMPTY_SPAN,
        render_uvs: EMPTY_SPAN,
    };
}

impl<'a> Model<'a> {
    /// Number of fields of a [`Model`].
    pub const FIELDS: usize = 38;

    /// Every field with its name, in declaration order.
    pub fn fields(&self) -> [(&'static str, FieldValue<'a>); Model::FIELDS] {
        use FieldValue as V;
        let Model {
            dim,
            num_vertices,
            latent,
            bc_len,
            dt,
            dt_min,
            dt_max,
            rate_input,
            diagonal,
            rotates,
            params,
            halves,
            bytes,
            floats,
            indices,
            decoder,
            decoder_basis,
            integrator,
            handles,
            rest,
            handle_vertices,
            free_vertices,
            origin_of,
            root_slots,
            chains,
            chain_floats,
            chain_order,
            surface_vertices,
            surface_source,
            surface_triangles,
            initial_latent,
            latent_min,
            latent_max,
            collider_shapes,
            render_anchors,
            render_weights,
            render_triangles,
            render_uvs,
        } = *self;
        [
            ("dim", V::U32(dim)),
            ("num_vertices", V::U32(num_vertices)),
            ("latent", V::U32(latent)),
            ("bc_len", V::U32(bc_len)),
            ("dt", V::F32(dt)),
            ("dt_min", V::F32(dt_min)),
            ("dt_max", V::F32(dt_max)),
            ("rate_input", V::Bool(rate_input)),
            ("diagonal", V::F32(diagonal)),
            ("rotates", V::Bool(rotates)),
            ("params", V::F32s(params)),
            ("halves", V::U16s(halves)),
            ("bytes", V::I8s(bytes)),
            ("floats", V::F32s(floats)),
            ("indices", V::U32s(indices)),
            ("decoder", V::Layers(decoder)),
            ("decoder_basis", V::Bool(decoder_basis)),
            ("integrator", V::Layers(integrator)),
            ("handles", V::Handles(handles)),
            ("rest", V::Span(rest)),
            ("handle_vertices", V::Span(handle_vertices)),
            ("free_vertices", V::Span(free_vertices)),
            ("origin_of", V::Span(origin_of)),
            ("root_slots", V::Span(root_slots)),
            ("chains", V::Span(chains)),
            ("chain_floats", V::Span(chain_floats)),
            ("chain_order", V::Span(chain_order)),
            ("surface_vertices", V::Span(surface_vertices)),
            ("surface_source", V::Span(surface_source)),
            ("surface_triangles", V::Span(surface_triangles)),
            ("initial_latent", V::Span(initial_latent)),
            ("latent_min", V::Span(latent_min)),
            ("latent_max", V::Span(latent_max)),
            ("collider_shapes", V::Span(collider_shapes)),
            ("render_anchors", V::Span(render_anchors)),
            ("render_weights", V::Span(render_weights)),
            ("render_triangles", V::Span(render_triangles)),
            ("render_uvs", V::Span(render_uvs)),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_distinct_and_the_empty_model_is_empty() {
        let fields = Model::EMPTY.fields();
        for (i, (a, _)) in fields.iter().enumerate() {
            assert!(fields[i + 1..].iter().all(|(b, _)| a != b), "{a} twice");
        }
        assert!(fields.iter().all(|(_, v)| match *v {
            FieldValue::U32(n) => n == 0,
            FieldValue::F32(x) => x == 0.0,
            FieldValue::Bool(b) => !b,
            FieldValue::Span(s) => s.len == 0,
            FieldValue::F32s(p) => p.is_empty(),
            FieldValue::U16s(p) => p.is_empty(),
            FieldValue::I8s(p) => p.is_empty(),
            FieldValue::U32s(p) => p.is_empty(),
            FieldValue::Layers(p) => p.is_empty(),
            FieldValue::Handles(p) => p.is_empty(),
        }));
    }
}
