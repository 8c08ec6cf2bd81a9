//! `mochi distill`: a trained model with its decoder replaced by a distilled one
//! ([`crate::learn::distill`]): the latents come from the model's own rollouts over its
//! scene's training motions (the states its integrator visits), the integrator is kept.

use crate::artifact::Artifact;
use crate::artifact::EncodingData;
use crate::error::{TrainerError, TrainerResult};
use crate::eval::rollout::{rebuild_problem, roll, LoadedModel};
use crate::learn::distill::{distill_decoder, distill_encoder, distill_outputs, DistillShape, Distilled};
use crate::learn::distill_integrator::{distill_integrator, DistilledIntegrator, IntegratorDistillShape, Step};
use crate::learn::encoding::{collider_inputs, pack_signals};
use crate::learn::train::{AdamWConfig, TrainConfig, TrainError};
use mochi_sim::dataset::{self, Split};

/// Settings of a distillation; every field has the default named in its documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct DistillOptions {
    /// The distilled decoder's shape (default: 8 modes after an MLP of width 32, 1 block).
    pub shape: DistillShape,
    /// Training epochs over the latents (default 300).
    pub epochs: usize,
    /// Learning rate at the first epoch (default 3e-3), decayed by a cosine to ...
    pub learning_rate: f64,
    /// ... this at the last (default 1e-5).
    pub final_learning_rate: f64,
    /// Latents per minibatch (default 256).
    pub batch: usize,
    /// Frames of each rollout (default: the scene's dataset frames).
    pub frames: Option<usize>,
    /// Every this many rollout latents, one is held out of the fit to check it (default 10).
    pub hold_out_every: usize,
    /// Seed of the initialisation and the shuffling (default 1).
    pub seed: u64,
    /// Fit the decoder to rod strands as positions (root-relative, in the handles' frame)
    /// when the model encodes them by their bends: the runtime's decode then skips the
    /// strand walk (default false: the model's own encoding).
    pub strand_positions: bool,
    /// Show progress bars.
    pub progress: bool,
}

impl Default for DistillOptions {
    fn default() -> Self {
        DistillOptions {
            shape: DistillShape {
                modes: 8,
                hidden: 32,
                blocks: 1,
            },
            epochs: 300,
            learning_rate: 3e-3,
            final_learning_rate: 1e-5,
            batch: 256,
            frames: None,
            hold_out_every: 10,
            seed: 1,
            strand_positions: false,
            progress: false,
        }
    }
}

/// A distilled model and how it was made.
#[derive(Debug, Clone)]
pub struct DistillOutcome {
    /// The model with the distilled decoder.
    pub artifact: Artifact,
    /// The fit.
    pub distilled: Distilled,
    /// Latents fitted on and held out.
    pub latents: (usize, usize),
    /// RMS vertex distance between the distilled and the teacher's decoding on the held-out
    /// latents, over the rest diagonal.
    pub fit_error: f64,
    /// The same for the teacher's decoding projected onto the basis (the basis' share).
    pub basis_error: f64,
    /// Where the encoding changed ([`DistillOptions::strand_positions`]): the RMS latent
    /// error of the encoder fitted to it on the held-out latents.
    pub encoder_error: Option<f64>,
}

/// Width of the encoder fitted when a distillation changes the encoding.
const ENCODER_WIDTH: usize = 32;

/// Distils the decoder of `artifact` (see the module documentation).
pub fn distill_artifact(artifact: &Artifact, options: &DistillOptions) -> TrainerResult<DistillOutcome> {
    if options.hold_out_every < 2 {
        return Err(TrainerError::invalid("hold_out_every must be at least 2"));
    }
    let (problem, encoding) = rebuild_problem(artifact)?;
    let model = LoadedModel::new(artifact.clone())?;
    let spec = &problem.scene.dataset;
    let frames = options.frames.unwrap_or(spec.frames);
    // The encoding the distilled decoder outputs, and each visited state in it (`None`: the
    // teacher's own outputs).
    let student = match options.strand_positions && encoding.strand_bends() {
        true => Some(encoding.without_strand_bends()),
        false => None,
    };
    let (mut train, mut held_out) = ((Vec::new(), Vec::new()), (Vec::new(), Vec::new()));
    for plan in dataset::plan(spec).iter().filter(|p| p.split == Split::Train) {
        let bc = problem.sequence(&plan.speeds, frames, plan.seed);
        let mut failed = None;
        roll(&model, &problem, &encoding, &bc, frames, |t, z, _, x| {
            let output = match &student {
                Some(student) => {
                    let targets = bc.targets(&problem.handles, t, problem.mesh.dim);
                    match student.frame(&targets).and_then(|frame| student.encode(x, &frame)) {
                        Ok(q) => q,
                        Err(e) => {
                            failed = Some(e);
                            return false;
                        }
                    }
                }
                None => Vec::new(),
            };
            let (latents, outputs) = match t % options.hold_out_every == 0 {
                true => (&mut held_out.0, &mut held_out.1),
                false => (&mut train.0, &mut train.1),
            };
            latents.push(z.to_vec());
            outputs.push(output);
            true
        })?;
        if let Some(e) = failed {
            return Err(e.into());
        }
    }
    let config = train_config(format!("distill-{}", artifact.scene), options);
    let mut out = artifact.clone();
    let mut encoder_error = None;
    let distilled = match &student {
        Some(student) => {
            let (fit, check) = ((&train.0[..], &train.1[..]), (&held_out.0[..], &held_out.1[..]));
            let distilled = distill_outputs(fit, check, options.shape, &config)?;
            // The fields in the training encoding follow it into the new one: the PCA of the
            // outputs (its leading `latent` components) and an encoder fitted to the pairs.
            let k = artifact.latent as usize;
            let (encoder, encoder_rms) = distill_encoder(fit, check, &distilled.pca, ENCODER_WIDTH, &config)?;
            out.encoding = EncodingData::new(student);
            out.pca_mean = distilled.pca.mean.iter().map(|&v| v as f32).collect();
            let leading = distilled.pca.basis.get(..k).ok_or_else(|| {
                TrainerError::invalid(format!(
                    "a basis of {} modes for a latent of {k}",
                    distilled.pca.basis.len()
                ))
            })?;
            out.pca_basis = leading.iter().flatten().map(|&v| v as f32).collect();
            out.encoder = encoder.layers().into_iter().cloned().collect();
            // The envelope's radius in the new encoding, over the teacher's rollouts.
            out.summary.max_radius = train
                .1
                .iter()
                .chain(&held_out.1)
                .flat_map(|q| q.chunks_exact(student.values_per_vertex()))
                .map(|c| c.iter().map(|v| v * v).sum::<f64>().sqrt())
                .fold(0.0, f64::max);
            encoder_error = Some(encoder_rms);
            distilled
        }
        None => distill_decoder(&model.decoder, &train.0, &held_out.0, options.shape, &config)?,
    };
    out.decoder = distilled.decoder.layers().into_iter().cloned().collect();
    out.decoder_basis = true;
    let per_vertex = (out.encoded_len() / out.encoding.free_vertices.len().max(1)) as f64;
    let to_vertex = per_vertex.sqrt() / artifact.diagonal;
    Ok(DistillOutcome {
        fit_error: distilled.fit_rms * to_vertex,
        basis_error: distilled.basis_rms * to_vertex,
        artifact: out,
        latents: (train.0.len(), held_out.0.len()),
        encoder_error,
        distilled,
    })
}

/// `artifact` with the decoder of `distilled` (a [`distill_artifact`] of a model with the same
/// integrator and latent space) and every field that goes with it: the encoding it decodes
/// into, the PCA, the encoder and the envelope's radius.
pub(crate) fn adopt_decoder(artifact: &mut Artifact, distilled: &Artifact) {
    artifact.decoder = distilled.decoder.clone();
    artifact.decoder_basis = distilled.decoder_basis;
    artifact.encoding = distilled.encoding.clone();
    artifact.pca_mean = distilled.pca_mean.clone();
    artifact.pca_basis = distilled.pca_basis.clone();
    artifact.encoder = distilled.encoder.clone();
    artifact.summary.max_radius = distilled.summary.max_radius;
}

/// Replaces the integrator of `artifact` by one of `shape` distilled from it
/// ([`crate::learn::distill_integrator`]) on the packed inputs of rollouts over the scene's
/// training motions; `options` sets the fits (epochs, rates, batch, seed), its decoder shape
/// is not used.
pub fn distill_artifact_integrator(
    artifact: &Artifact,
    shape: IntegratorDistillShape,
    options: &DistillOptions,
) -> TrainerResult<(Artifact, DistilledIntegrator)> {
    let (problem, encoding) = rebuild_problem(artifact)?;
    let model = LoadedModel::new(artifact.clone())?;
    let spec = &problem.scene.dataset;
    let frames = options.frames.unwrap_or(spec.frames);
    // The training motions at their own frame times (a model that takes the frame time is
    // distilled over its trained range).
    let sequences: Vec<_> = dataset::plan(spec)
        .iter()
        .filter(|p| p.split == Split::Train)
        .map(|p| {
            let dt = artifact.timed().then(|| p.dt.unwrap_or(problem.scene.dt));
            (problem.plan_sequence(p, frames), dt)
        })
        .collect();
    let (lo, hi) = (&artifact.latent_min, &artifact.latent_max);
    // A rollout stops where its latent leaves the training range widened by its width on
    // each side (the runtime clamps there) or is not finite.
    let inside = |z: &[f32]| {
        z.iter()
            .zip(lo.iter().zip(hi))
            .all(|(v, (l, h))| v.is_finite() && *v >= l - (h - l) && *v <= h + (h - l))
    };
    let dim = problem.mesh.dim;
    let rollout = |step: &Step| {
        let mut inputs = Vec::new();
        for (bc, dt) in &sequences {
            let mut z_prev = artifact.initial_latent.clone();
            let mut z_prev2 = artifact.initial_latent.clone();
            let mut signals = [bc.signal(0), bc.signal(0), bc.signal(0)];
            for t in 1..=frames {
                signals.rotate_right(1);
                signals[0] = bc.signal(t);
                let targets = bc.targets(&problem.handles, t, dim);
                let frame = encoding
                    .frame(&targets)
                    .map_err(|e| TrainError::Invalid(e.to_string()))?;
                let states = bc.collider_states(t);
                let colliders =
                    collider_inputs(artifact.colliders(), &frame, &targets, dim, artifact.diagonal, &states);
                let q = pack_signals(
                    &z_prev,
                    &z_prev2,
                    [&signals[0], &signals[1], &signals[2]],
                    &colliders,
                    *dt,
                );
                let z = step(&q)?;
                inputs.push(q);
                if !inside(&z) {
                    break;
                }
                z_prev2 = std::mem::replace(&mut z_prev, z);
            }
        }
        Ok(inputs)
    };
    let config = train_config(format!("distill-integrator-{}", artifact.scene), options);
    let distilled = distill_integrator(
        &model.integrator,
        (artifact.bc_len as usize, artifact.colliders()),
        shape,
        &config,
        rollout,
    )?;
    let mut out = artifact.clone();
    out.integrator = distilled.integrator.mlp().layers().into_iter().cloned().collect();
    Ok((out, distilled))
}

/// The fit's settings from `options` (no checkpoints: a fit takes seconds to minutes).
fn train_config(name: String, options: &DistillOptions) -> TrainConfig {
    TrainConfig {
        name,
        epochs: options.epochs,
        batch_size: options.batch,
        seed: options.seed,
        optimizer: AdamWConfig {
            lr: options.learning_rate,
            ..AdamWConfig::default()
        },
        final_lr: Some(options.final_learning_rate),
        warmup_step: None,
        checkpoint: None,
        progress: options.progress,
    }
}
