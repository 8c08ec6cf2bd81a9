//! Weight storage at code generation: re-stores a model's network weights as `f32`, `f16` or
//! int8 with one scale per output channel (row), biases staying `f32`.

use mochi_runtime::{Layer, Model, WeightFormat};

/// Parses `f32`, `f16` or `int8` (the CLI's and build scripts' spelling).
pub fn parse_format(name: &str) -> Option<WeightFormat> {
    match name {
        "f32" => Some(WeightFormat::F32),
        "f16" => Some(WeightFormat::F16),
        "int8" | "i8" => Some(WeightFormat::Int8),
        _ => None,
    }
}

/// The spelling [`parse_format`] reads.
pub fn format_name(format: WeightFormat) -> &'static str {
    match format {
        WeightFormat::F32 | WeightFormat::F32Columns => "f32",
        WeightFormat::F16 => "f16",
        WeightFormat::Int8 => "int8",
    }
}

/// Both networks of a model with their weights re-stored (owned pools; biases and int8 scales
/// in `params`).
#[derive(Clone, Debug, Default)]
pub struct Quantized {
    /// Format of the layers being added.
    format: WeightFormat,
    /// Biases, scales and (for `f32`) weights.
    pub params: Vec<f32>,
    /// Half-precision weights.
    pub halves: Vec<u16>,
    /// Int8 weights.
    pub bytes: Vec<i8>,
    /// Decoder layers, pointing into the pools above.
    pub decoder: Vec<Layer>,
    /// Integrator layers.
    pub integrator: Vec<Layer>,
}

impl Quantized {
    /// Re-stores the networks of `model` (any formats) in `format`.
    pub fn new(model: &Model, format: WeightFormat) -> Self {
        Self::split(model, format, format)
    }

    /// Re-stores the decoder in `decoder` and the integrator in `integrator`.
    pub fn split(model: &Model, decoder: WeightFormat, integrator: WeightFormat) -> Self {
        let mut q = Quantized {
            format: decoder,
            ..Quantized::default()
        };
        let last = model.decoder.len().saturating_sub(1);
        q.decoder = model
            .decoder
            .iter()
            .enumerate()
            .map(|(i, l)| q.push(model, l, i == last && mochi_runtime::stores_columns(l.cols as usize)))
            .collect();
        q.format = integrator;
        q.integrator = model.integrator.iter().map(|l| q.push(model, l, false)).collect();
        q
    }

    /// `base` with its networks replaced by these.
    pub fn model<'a>(&'a self, base: &Model<'a>) -> Model<'a> {
        Model {
            params: &self.params,
            halves: &self.halves,
            bytes: &self.bytes,
            decoder: &self.decoder,
            integrator: &self.integrator,
            ..*base
        }
    }

    /// Appends one layer of `model` and returns it pointing into these pools; `f32` weights
    /// stay column by column only where every loader stores them so (`columns`: a decoder's
    /// narrow output layer, [`mochi_runtime::stores_columns`]), other layers a wide kernel's
    /// loader stored by columns go back to rows, so that the module does not depend on the
    /// machine that generated it.
    fn push(&mut self, model: &Model, layer: &Layer, columns: bool) -> Layer {
        let rows = layer.rows as usize;
        let cols = layer.cols as usize;
        let w = weights_f32(model, layer);
        let mut out = Layer {
            format: self.format,
            ..*layer
        };
        // Weights, then biases, then scales: for `f32` a decoder's narrow output layer column
        // by column, padded, as every loader stores it; everything else row by row.
        if self.format.is_f32() {
            // Every layer's `f32` weights start on a cache line, as the loader places them.
            while !self.params.len().is_multiple_of(mochi_runtime::aligned::LINE) {
                self.params.push(0.0);
            }
        }
        match self.format {
            WeightFormat::F32 | WeightFormat::F32Columns if columns && layer.format == WeightFormat::F32Columns => {
                out.format = WeightFormat::F32Columns;
                out.weights = self.params.len() as u32;
                let start = layer.weights as usize;
                let padded = mochi_runtime::column_stride(rows) * cols;
                self.params
                    .extend(model.params.get(start..start + padded).unwrap_or(&[]));
            }
            WeightFormat::F32 | WeightFormat::F32Columns => {
                out.format = WeightFormat::F32;
                out.weights = self.params.len() as u32;
                self.params.extend(&w);
            }
            WeightFormat::F16 => {
                out.weights = self.halves.len() as u32;
                self.halves.extend(w.iter().map(|&v| half::f16::from_f32(v).to_bits()));
            }
            WeightFormat::Int8 => out.weights = self.bytes.len() as u32,
        }
        out.bias = self.params.len() as u32;
        let b = layer.bias as usize;
        self.params.extend(model.params.get(b..b + rows).unwrap_or(&[]));
        if self.format == WeightFormat::Int8 {
            out.scales = self.params.len() as u32;
            for row in w.chunks(cols.max(1)) {
                let (scale, q) = int8_row(row);
                self.params.push(scale);
                self.bytes.extend(q);
            }
        }
        out
    }
}

/// Symmetric int8 for one output channel: `scale = max |w| / 127`, `q = round(w / scale)`.
pub fn int8_row(row: &[f32]) -> (f32, Vec<i8>) {
    let largest = row.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    if largest == 0.0 || !largest.is_finite() {
        return (0.0, vec![0; row.len()]);
    }
    let scale = largest / 127.0;
    let q = row
        .iter()
        .map(|v| (v / scale).round().clamp(-127.0, 127.0) as i8)
        .collect();
    (scale, q)
}

/// The weights of `layer` of `model` as `f32`, row by row (exact conversions from its
/// storage, whichever layout).
pub fn weights_f32(model: &Model, layer: &Layer) -> Vec<f32> {
    let (rows, cols) = (layer.rows as usize, layer.cols as usize);
    let range = layer.weights as usize..layer.weights as usize + rows * cols;
    match layer.format {
        WeightFormat::F32 => model.params.get(range).unwrap_or(&[]).to_vec(),
        WeightFormat::F32Columns => {
            let stride = mochi_runtime::column_stride(rows);
            let start = layer.weights as usize;
            let w = model.params.get(start..start + stride * cols).unwrap_or(&[]);
            let at = |i: usize| w.get((i % cols) * stride + i / cols).copied().unwrap_or(0.0);
            if w.is_empty() {
                Vec::new()
            } else {
                (0..rows * cols).map(at).collect()
            }
        }
        WeightFormat::F16 => model
            .halves
            .get(range)
            .unwrap_or(&[])
            .iter()
            .map(|&h| half::f16::from_bits(h).to_f32())
            .collect(),
        WeightFormat::Int8 => {
            let bytes = model.bytes.get(range).unwrap_or(&[]);
            let scales = model
                .params
                .get(layer.scales as usize..layer.scales as usize + rows)
                .unwrap_or(&[]);
            bytes
                .chunks(cols.max(1))
                .zip(scales)
                .flat_map(|(q, &s)| q.iter().map(move |&q| s * f32::from(q)))
                .collect()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn int8_rows_round_to_the_nearest_step_of_their_own_scale() {
        let (scale, q) = int8_row(&[0.5, -1.27, 0.0, 1.0]);
        assert!((scale - 0.01).abs() < 1e-7);
        assert_eq!(q, vec![50, -127, 0, 100]);
        // Every weight within half a step.
        let row = [0.3, -0.71, 0.05, 0.9, -0.9];
        let (scale, q) = int8_row(&row);
        for (w, q) in row.iter().zip(&q) {
            assert!((w - scale * f32::from(*q)).abs() <= 0.5 * scale + 1e-7);
        }
        assert_eq!(int8_row(&[0.0, 0.0]), (0.0, vec![0, 0]));
    }

    #[test]
    fn formats_parse_and_print_back() {
        for f in [WeightFormat::F32, WeightFormat::F16, WeightFormat::Int8] {
            assert_eq!(parse_format(format_name(f)), Some(f));
        }
        assert_eq!(parse_format("f64"), None);
    }
}
