//! Runs an artifact on the reference boundary-condition script (`mochi-target-common`) in a
//! chosen weight storage and prints the report every target prints (checksums, sampled and
//! final positions; for a model with a render mesh, the render pass too), so that a build for another CPU, run under emulation, can be checked
//! against the host (`scripts/run-aarch64.sh`, `tests/tests/target_aarch64.rs`).
//!
//! ```text
//! mochi-aarch64 ARTIFACT f32|f16|int8 [canonical] [--timed N]
//! ```
//!
//! The model is the one code generation would emit for that storage (`mochi_codegen::Quantized`:
//! int8 keeps the integrator in `f16`), built from the artifact at run time, so that one
//! program serves every model. `canonical` turns the hand-written vector kernels off (the
//! canonical code the compiler makes of the portable loops). After the reference run, `N`
//! more frames (default 100) of a fresh instance run between two calls of
//! [`mochi_count_mark`], where an instruction-counting QEMU plugin (`targets/aarch64/insn-count.c`)
//! reads its count: the difference over `N` is the instructions per frame (step + full decode).

use std::io::Write;
use std::process::ExitCode;

use mochi_codegen::{parse_format, Options, Quantized};
use mochi_runtime::{AnyInstance, HandleMotion, OwnedModel, ValidModel};
use mochi_target_common::{run, run_render, sampled, Script, CHECKPOINTS, FRAMES};

/// Marks a point of the run for the instruction-counting plugin (which finds it by the name in
/// its symbol and prints its count when it starts); does nothing else.
#[inline(never)]
fn mochi_count_mark() {
    // An empty function whose calls the optimiser may not remove: `black_box` of a value it
    // cannot see through.
    std::hint::black_box(0u8);
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match body(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            println!("status error {message}");
            ExitCode::FAILURE
        }
    }
}

fn body(args: &[String]) -> Result<(), String> {
    let usage = "usage: mochi-aarch64 ARTIFACT f32|f16|int8 [canonical] [--timed N]";
    let (Some(path), Some(weights)) = (args.first(), args.get(1)) else {
        return Err(usage.into());
    };
    let mut timed = 100u32;
    let mut rest = args[2..].iter();
    while let Some(arg) = rest.next() {
        match arg.as_str() {
            "canonical" => mochi_runtime::network::use_vector_kernels(false),
            "--timed" => {
                timed = rest
                    .next()
                    .and_then(|n| n.parse().ok())
                    .ok_or_else(|| usage.to_string())?
            }
            _ => return Err(usage.into()),
        }
    }
    let format = parse_format(weights).ok_or_else(|| format!("no weight storage `{weights}`"))?;
    let bytes = std::fs::read(path).map_err(|e| format!("{path}: {e}"))?;
    let mut storage = OwnedModel::default();
    let loaded = storage.load(&bytes).map_err(|e| format!("{path}: {e}"))?;
    let options = Options::weights(format);
    let quantized = Quantized::split(loaded.model(), options.decoder, options.integrator);
    let model = ValidModel::new(quantized.model(loaded.model())).map_err(|e| format!("{weights} weights: {e}"))?;
    let name = std::path::Path::new(path)
        .file_stem()
        .map_or("model".into(), |s| s.to_string_lossy().into_owned());

    let out = std::io::stdout();
    let mut out = std::io::BufWriter::new(out.lock());
    let mut write = |line: std::fmt::Arguments| writeln!(out, "{line}").map_err(|e| format!("stdout: {e}"));
    write(format_args!("model {name} weights {weights} frames {FRAMES}"))?;
    let mut positions = vec![0.0f32; model.model().state_len()];
    let mut lines = Vec::new();
    run::<{ mochi_runtime::MAX_LATENT }, { mochi_runtime::MAX_SIGNAL }, { mochi_runtime::MAX_HIDDEN }>(
        &model,
        FRAMES,
        &mut positions,
        |frame, sum, now| {
            if CHECKPOINTS.contains(&frame) {
                lines.push(format!("checksum {frame} {:016x}", sum.0));
            }
            if sampled(weights, frame) {
                lines.push(format!("frame {frame}{}", hex(now)));
            }
        },
    )
    .map_err(|e| format!("the reference run was refused: {e}"))?;
    for line in &lines {
        write(format_args!("{line}"))?;
    }
    write(format_args!("positions{}", hex(&positions)))?;
    if model.model().has_render() {
        // The script again through the render decode (render positions and normals).
        let len = model.model().render_len();
        let (mut render, mut normals) = (vec![0.0f32; len], vec![0.0f32; len]);
        let mut sums = Vec::new();
        run_render::<{ mochi_runtime::MAX_LATENT }, { mochi_runtime::MAX_SIGNAL }, { mochi_runtime::MAX_HIDDEN }>(
            &model,
            FRAMES,
            &mut positions,
            &mut render,
            &mut normals,
            |frame, sum, _, _| {
                if CHECKPOINTS.contains(&frame) {
                    sums.push(format!("render_checksum {frame} {:016x}", sum.0));
                }
            },
        )
        .map_err(|e| format!("the reference render run was refused: {e}"))?;
        for line in &sums {
            write(format_args!("{line}"))?;
        }
        write(format_args!("render_positions{}", hex(&render)))?;
        write(format_args!("render_normals{}", hex(&normals)))?;
    }
    timing(&model, &mut positions, timed)?;
    write(format_args!("timed_frames {timed}"))?;
    write(format_args!("status ok"))?;
    Ok(())
}

/// ` xxxxxxxx` per value (its bit pattern).
fn hex(values: &[f32]) -> String {
    values.iter().map(|v| format!(" {:08x}", v.to_bits())).collect()
}

/// Frames `1..=frames` of the script on a fresh instance (step + full decode), between two
/// [`mochi_count_mark`] calls.
fn timing(model: &ValidModel, positions: &mut [f32], frames: u32) -> Result<(), String> {
    let script = Script::for_model(model);
    let mut body = Box::new(AnyInstance::new(model).map_err(|e| format!("instance: {e}"))?);
    let mut bc = vec![HandleMotion::REST; model.model().handles.len()];
    mochi_count_mark();
    for frame in 1..=frames {
        bc.fill(script.motion(frame));
        body.step(model, &bc).map_err(|e| format!("step: {e}"))?;
        body.decode_into(model, positions).map_err(|e| format!("decode: {e}"))?;
    }
    mochi_count_mark();
    Ok(())
}
