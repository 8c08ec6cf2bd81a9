//! `mochi export-weights`: the networks of an artifact exactly as the runtime runs them, and
//! the runtime's own rollout of the targets' reference script, as a numpy `.npz` archive, so
//! that another framework can run the same computation on the same inputs and be checked
//! against the runtime (`scripts/bench-jax.sh`). A bend-encoded model (`bends`) also carries
//! its strands: each starts at its second prescribed vertex with the axes of
//! [`mochi_runtime::frame::Placement::chain_start`] and places one vertex per decoded pair
//! of bend numbers ([`mochi_runtime::ChainWalk::step`]).
//!
//! A network is the layer list `[input, inner_0, outer_0, ..., output]` of
//! [`mochi_runtime::model`]: `h = input(x); h += outer_j(swish(inner_j(h))); y =
//! output(swish(h))` with `layer(x) = b + s * (W x)` (`s = 1` unless the layer is stored as
//! int8). The integrator maps `[z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]` to `z_t - z_{t-1}`
//! (then clamped into the widened training range, see [`mochi_runtime::RANGE_MARGIN`]); the
//! decoder maps `z_t` to the free vertices in the encoding frame, placed in the world as
//! `R q + o` where `R` is the handle's rotation (`rotates`; Kabsch over all handle vertices
//! for several handles) and `o` the centroid of the handle vertices' targets (or a strand
//! root's target, `root_slots`); handle vertices are put on their targets `pivot + t +
//! R_h (reference - pivot)`.
//!
//! | array | dtype | shape |
//! |---|---|---|
//! | `format_version` | uint32 | `()` |
//! | `artifact`, `weights` | unicode | `()`: file name, storage (`f32`, `f16`, `int8`) |
//! | `dim`, `num_vertices`, `latent`, `signal`, `hidden`, `rotates` | uint32 | `()` |
//! | `decoder_basis` | uint32 | `()`: 1 when the decoder's last layer is a basis applied to `[z; 0] + g(z)` (`mochi_runtime::Model::decoder_basis`) |
//! | `dt`, `diagonal`, `range_margin` | float32 | `()` |
//! | `integrator_layers`, `decoder_layers` | uint32 | `(layers, 2)`: rows, cols |
//! | `integrator_I_w`, `decoder_I_w` | float32 | `(rows, cols)`: layer `I`'s stored weights, converted exactly (int8: the integers) |
//! | `integrator_I_b`, `decoder_I_b` | float32 | `(rows,)` |
//! | `integrator_I_scale`, `decoder_I_scale` | float32 | `(rows,)`, int8 layers only |
//! | `initial_latent`, `latent_min`, `latent_max` | float32 | `(latent,)` |
//! | `rest` | float32 | `(num_vertices, dim)` |
//! | `handle_counts` | uint32 | `(handles,)`: vertices per handle |
//! | `handle_vertices` | uint32 | `(slots,)`: prescribed vertices in handle order |
//! | `handle_reference` | float32 | `(slots, 3)` |
//! | `handle_pivot` | float32 | `(handles, 3)` |
//! | `free_vertices`, `origin_of` | uint32 | `(free,)` |
//! | `root_slots` | uint32 | `(roots,)` |
//! | `bends` | uint32 | `()`: 1 when the decoder's output is two bend numbers per free vertex, walked along strands (`mochi_runtime::Chain`, `ChainWalk`) |
//! | `chain_parent` | uint32 | `(chains, 2)`: handle slots of each strand's two prescribed vertices (bends only) |
//! | `chain_rest_normal` | float32 | `(chains, 3)` (bends only) |
//! | `chain_count` | uint32 | `(chains,)`: free vertices per strand (bends only) |
//! | `chain_slots`, `chain_lengths` | uint32, float32 | `(sum of chain_count,)`: free-vertex index and rest length of the edge ending at it, root to tip, strand after strand (bends only) |
//! | `script_signal` | float32 | `(frames, signal)`: `p_t` of frames `1..=frames` |
//! | `runtime_latent` | float32 | `(frames, latent)`: the runtime's `z_t` |
//! | `runtime_stepped` | uint8 | `(frames,)`: 0 stepped, 1 clamped, 2 held |
//! | `runtime_frames` | uint32 | `(c,)`: frames whose positions follow |
//! | `runtime_positions` | float32 | `(c, num_vertices, dim)`: the runtime's full decode |

use std::path::Path;

use mochi_codegen::quantize::weights_f32;
use mochi_codegen::{format_name, Options, Quantized};
use mochi_runtime::{AnyInstance, HandleMotion, Layer, Model, OwnedModel, Stepped, ValidModel, WeightFormat};
use mochi_sim::npz::NpzOut;
use mochi_target_common::{Script, CHECKPOINTS};

use crate::error::{bail, Context, TrainerError, TrainerResult as Result};

/// Version number stored in `format_version`; bumped when the layout changes.
pub const FORMAT_VERSION: u32 = 2;

/// What an export wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct Exported {
    /// Latent size.
    pub latent: usize,
    /// Boundary-condition numbers per frame.
    pub signal: usize,
    /// Widest hidden layer.
    pub hidden: usize,
    /// Layers of the integrator and of the decoder.
    pub layers: [usize; 2],
    /// Frames of the script.
    pub frames: usize,
    /// Frames on which the runtime clamped or held its latent.
    pub departures: usize,
}

/// Writes the networks of the artifact at `artifact`, stored as `weights` (as `mochi codegen
/// --weights` would), and the runtime's rollout of `frames` frames of the reference
/// [`Script`] to `out` (see the module docs).
pub fn export(artifact: &Path, out: &Path, frames: usize, weights: WeightFormat) -> Result<Exported> {
    if frames == 0 {
        bail!("--frames must be at least 1");
    }
    let bytes = crate::error::fs::read(artifact)?;
    let mut storage = OwnedModel::default();
    let loaded = storage
        .load(&bytes)
        .with_context(|| format!("{}: runtime refused the artifact", artifact.display()))?;
    let options = Options::weights(weights);
    let stored = Quantized::split(loaded.model(), options.decoder, options.integrator);
    let model = ValidModel::new(stored.model(loaded.model()))
        .with_context(|| format!("{}: with {} weights", artifact.display(), format_name(weights)))?;
    let m = model.model();
    let rollout = Rollout::run(&model, frames)?;
    let name = artifact
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned());
    write(m, &name, weights, &rollout, out).map_err(|e| TrainerError::io(out, e))?;
    Ok(Exported {
        latent: m.latent as usize,
        signal: m.bc_len as usize,
        hidden: m.hidden(),
        layers: [m.integrator.len(), m.decoder.len()],
        frames,
        departures: rollout.stepped.iter().filter(|&&s| s != 0).count(),
    })
}

/// The runtime's rollout of the reference script.
struct Rollout {
    /// Signal per frame.
    signal: Vec<f32>,
    /// Latent after each step.
    latent: Vec<f32>,
    /// What each step did (0 stepped, 1 clamped, 2 held).
    stepped: Vec<u8>,
    /// Frames whose positions are kept, and their positions.
    kept: Vec<u32>,
    positions: Vec<f32>,
}

impl Rollout {
    /// Runs `model` from rest over `frames` frames of the [`Script`], every handle moving
    /// alike (as the targets run it), keeping the positions of the [`CHECKPOINTS`] and of
    /// the last frame.
    fn run(model: &ValidModel, frames: usize) -> Result<Self> {
        let m = model.model();
        let script = Script::for_model(model);
        let mut body = AnyInstance::new(model)?;
        let mut x = vec![0.0f32; m.state_len()];
        let mut r = Rollout {
            signal: Vec::with_capacity(frames * m.bc_len as usize),
            latent: Vec::with_capacity(frames * m.latent as usize),
            stepped: Vec::with_capacity(frames),
            kept: Vec::new(),
            positions: Vec::new(),
        };
        for frame in 1..=frames as u32 {
            let bc: Vec<HandleMotion> = vec![script.motion(frame); m.handles.len()];
            r.signal.extend(bc.iter().flat_map(HandleMotion::signal));
            r.stepped.push(match body.step(model, &bc)? {
                Stepped::Ok => 0,
                Stepped::Clamped => 1,
                Stepped::Held => 2,
            });
            r.latent.extend_from_slice(body.latent());
            body.decode_into(model, &mut x)?;
            if CHECKPOINTS.contains(&frame) || frame as usize == frames {
                r.kept.push(frame);
                r.positions.extend_from_slice(&x);
            }
        }
        Ok(r)
    }
}

/// The arrays of the module docs.
fn write(m: &Model, name: &str, weights: WeightFormat, r: &Rollout, out: &Path) -> std::io::Result<()> {
    let mut npz = NpzOut::create(out)?;
    let (n, d, k, s) = (m.num_vertices as u64, m.dim as u64, m.latent as u64, m.bc_len as u64);
    npz.array("format_version", &[], [FORMAT_VERSION])?;
    npz.strings("artifact", &[], [name])?;
    npz.strings("weights", &[], [format_name(weights)])?;
    for (key, value) in [
        ("dim", m.dim),
        ("num_vertices", m.num_vertices),
        ("latent", m.latent),
        ("signal", m.bc_len),
        ("hidden", m.hidden() as u32),
        ("rotates", u32::from(m.rotates)),
        ("decoder_basis", u32::from(m.decoder_basis)),
    ] {
        npz.array(key, &[], [value])?;
    }
    npz.array("dt", &[], [m.dt])?;
    npz.array("diagonal", &[], [m.diagonal])?;
    npz.array("range_margin", &[], [mochi_runtime::RANGE_MARGIN])?;
    for (net, layers) in [("integrator", m.integrator), ("decoder", m.decoder)] {
        npz.array(
            &format!("{net}_layers"),
            &[layers.len() as u64, 2],
            layers.iter().flat_map(|l| [l.rows, l.cols]),
        )?;
        for (i, layer) in layers.iter().enumerate() {
            let (rows, cols) = (layer.rows as u64, layer.cols as u64);
            npz.array(&format!("{net}_{i}_w"), &[rows, cols], stored_weights(m, layer))?;
            npz.array(
                &format!("{net}_{i}_b"),
                &[rows],
                params(m, layer.bias, rows).iter().copied(),
            )?;
            if layer.format == WeightFormat::Int8 {
                let scales = params(m, layer.scales, rows);
                npz.array(&format!("{net}_{i}_scale"), &[rows], scales.iter().copied())?;
            }
        }
    }
    for (key, values) in [
        ("initial_latent", m.initial_latent()),
        ("latent_min", m.latent_min()),
        ("latent_max", m.latent_max()),
    ] {
        npz.array(key, &[k], values.iter().copied())?;
    }
    npz.array("rest", &[n, d], m.rest().iter().copied())?;
    let counts: Vec<u32> = m.handles.iter().map(|h| h.vertices.len).collect();
    npz.array("handle_counts", &[counts.len() as u64], counts)?;
    let slots = m.handle_vertices();
    npz.array("handle_vertices", &[slots.len() as u64], slots.iter().copied())?;
    let reference: Vec<f32> = m
        .handles
        .iter()
        .flat_map(|h| m.handle_reference_of(h).iter().copied())
        .collect();
    npz.array("handle_reference", &[slots.len() as u64, 3], reference)?;
    npz.array(
        "handle_pivot",
        &[m.handles.len() as u64, 3],
        m.handles.iter().flat_map(|h| h.pivot),
    )?;
    for (key, values) in [
        ("free_vertices", m.free_vertices()),
        ("origin_of", m.origin_of()),
        ("root_slots", m.root_slots()),
    ] {
        npz.array(key, &[values.len() as u64], values.iter().copied())?;
    }
    npz.array("bends", &[], [u32::from(m.bends())])?;
    if m.bends() {
        let chains: Vec<_> = m.chains().collect();
        let c = chains.len() as u64;
        npz.array("chain_parent", &[c, 2], chains.iter().flat_map(|ch| ch.parent))?;
        npz.array(
            "chain_rest_normal",
            &[c, 3],
            chains.iter().flat_map(|ch| ch.rest_normal),
        )?;
        npz.array("chain_count", &[c], chains.iter().map(|ch| ch.slots.len() as u32))?;
        let total = chains.iter().map(|ch| ch.slots.len() as u64).sum::<u64>();
        npz.array(
            "chain_slots",
            &[total],
            chains.iter().flat_map(|ch| ch.slots.iter().copied()),
        )?;
        npz.array(
            "chain_lengths",
            &[total],
            chains.iter().flat_map(|ch| ch.lengths.iter().copied()),
        )?;
    }
    let frames = r.stepped.len() as u64;
    npz.array("script_signal", &[frames, s], r.signal.iter().copied())?;
    npz.array("runtime_latent", &[frames, k], r.latent.iter().copied())?;
    npz.array("runtime_stepped", &[frames], r.stepped.iter().copied())?;
    npz.array("runtime_frames", &[r.kept.len() as u64], r.kept.iter().copied())?;
    npz.array(
        "runtime_positions",
        &[r.kept.len() as u64, n, d],
        r.positions.iter().copied(),
    )?;
    npz.finish()
}

/// `rows` numbers of the model's `f32` pool from `start`.
fn params<'a>(m: &Model<'a>, start: u32, rows: u64) -> &'a [f32] {
    m.params
        .get(start as usize..start as usize + rows as usize)
        .unwrap_or(&[])
}

/// The weights of `layer` as stored, converted exactly to `f32` (int8: the integers, without
/// their scales).
fn stored_weights(m: &Model, layer: &Layer) -> Vec<f32> {
    match layer.format {
        WeightFormat::F32 | WeightFormat::F16 | WeightFormat::F32Columns => weights_f32(m, layer),
        WeightFormat::Int8 => {
            let start = layer.weights as usize;
            let range = start..start + layer.rows as usize * layer.cols as usize;
            m.bytes
                .get(range)
                .unwrap_or(&[])
                .iter()
                .map(|&b| f32::from(b))
                .collect()
        }
    }
}
