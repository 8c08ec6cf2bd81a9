//! The Cortex-M4F firmware (`targets/cortex-m4`) built for `thumbv7em-none-eabihf` and run
//! under QEMU (mps2-an386) by `scripts/run-cortex-m4.sh`: its checksums of the decoded
//! positions equal the host runtime's, bit for bit, over the 1,000-frame reference script.

use std::path::Path;
use std::process::Command;

use mochi_runtime::{Model, ValidModel};
use mochi_target_common::host;
use mochi_tests::{
    beam, beam_int8, beam_m8, beam_m8_int8, rods, rods_m8, tiny, tiny_int8, tiny_poke, tiny_poke_int8, tiny_render,
    tiny_render_int8,
};

/// Runs the firmware for the artifact `name` with `weights` and checks it against `model`
/// with an `Instance<K, S, H>`; returns the script's output (sizes and rates).
fn firmware_matches_the_host<const K: usize, const S: usize, const H: usize>(
    name: &str,
    weights: &str,
    model: Model<'static>,
) -> String {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let script = repo.join("scripts/run-cortex-m4.sh");
    let run = Command::new("bash")
        .arg(&script)
        .arg(repo.join(format!("tests/artifacts/{name}.mochi")))
        .arg(weights)
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", script.display()));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        run.status.success(),
        "{} failed (tools missing? run scripts/install-cross.sh):\n{stderr}\n{}",
        script.display(),
        String::from_utf8_lossy(&run.stdout)
    );
    let path = repo.join(format!("target/targets/cortex-m4-{name}-{weights}.txt"));
    let report = host::parse(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert_eq!((report.model.as_str(), report.weights.as_str()), (name, weights));
    let model = ValidModel::new(model).unwrap();
    host::check::<K, S, H>(&model, &report).unwrap();
    let per_frame = report.instructions_per_frame.expect("instructions per frame");
    assert!(
        per_frame > 10_000 && per_frame < 100_000_000,
        "{per_frame} instructions per frame"
    );
    String::from_utf8_lossy(&run.stdout).into_owned()
}

#[test]
fn firmware_under_qemu_matches_the_host_bit_for_bit() {
    use tiny::{HIDDEN, LATENT, SIGNAL};
    firmware_matches_the_host::<LATENT, SIGNAL, HIDDEN>("tiny", "f32", tiny::MODEL);
    // The int8 kernels too (int8 decoder, f16 integrator).
    firmware_matches_the_host::<LATENT, SIGNAL, HIDDEN>("tiny", "int8", tiny_int8::MODEL);
}

/// A model with a render mesh (`tiny-render`: 1,014 render vertices on its box's surface):
/// the render decode on the firmware agrees with the host's (int8 bit for bit, `f32` within
/// the tolerances), and its cost per frame is reported.
#[test]
fn render_decode_on_the_firmware_matches_the_host() {
    use tiny_render::{HIDDEN, LATENT, SIGNAL};
    for (weights, model) in [("f32", tiny_render::MODEL), ("int8", tiny_render_int8::MODEL)] {
        let output = firmware_matches_the_host::<LATENT, SIGNAL, HIDDEN>("tiny-render", weights, model);
        let report = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join(format!("../target/targets/cortex-m4-tiny-render-{weights}.txt")),
        )
        .unwrap();
        let report = host::parse(&report).unwrap();
        assert_eq!(report.render_checksums.len(), 4, "a render checksum per checkpoint");
        let render = report
            .render_instructions_per_frame
            .expect("render decode instructions");
        let (flash, ram) = kibibytes(&output);
        println!(
            "tiny-render {weights}: {flash} KiB of flash, {ram} KiB of RAM; render decode {render} instructions per frame \
             (step + full decode {})",
            report.instructions_per_frame.unwrap()
        );
        assert!(render > 1_014, "{render} instructions for 1,014 render vertices");
    }
}

/// The shipped beam model with int8 weights links into 1 MiB of flash and runs in 64 KiB of
/// RAM (the firmware's linker script has exactly that), bit-identical to the host.
#[test]
fn beam_int8_fits_one_mebibyte_of_flash_and_matches_the_host() {
    let output = firmware_matches_the_host::<{ beam::LATENT }, { beam::SIGNAL }, { beam::HIDDEN }>(
        "beam",
        "int8",
        beam_int8::MODEL,
    );
    let (flash, ram) = kibibytes(&output);
    assert!(flash <= 1024.0 && ram <= 64.0, "{flash} KiB of flash, {ram} KiB of RAM");
}

/// The right-sized beam (`beam-m8`, int8 decoder) within 512 KiB of flash and 64 KiB of RAM at
/// 60 frames per second or more on a 168 MHz Cortex-M4 (at most 2.8 M instructions per
/// frame), bit-identical to the host.
#[test]
fn right_sized_beam_runs_at_60_frames_per_second_within_512_kib() {
    let output = firmware_matches_the_host::<{ beam_m8::LATENT }, { beam_m8::SIGNAL }, { beam_m8::HIDDEN }>(
        "beam-m8",
        "int8",
        beam_m8_int8::MODEL,
    );
    let (flash, ram) = kibibytes(&output);
    assert!(flash <= 512.0 && ram <= 64.0, "{flash} KiB of flash, {ram} KiB of RAM");
    let report = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/targets/cortex-m4-beam-m8-int8.txt"),
    )
    .unwrap();
    let per_frame = host::parse(&report).unwrap().instructions_per_frame.unwrap();
    assert!(per_frame <= 2_800_000, "{per_frame} instructions per frame");
}

/// The `rods` scene's model (bend-encoded strands, `f32` weights) within 1 MiB of flash and
/// 64 KiB of RAM, within the `f32` tolerance of the host.
#[test]
fn rods_fit_one_mebibyte_of_flash_and_match_the_host() {
    let output =
        firmware_matches_the_host::<{ rods::LATENT }, { rods::SIGNAL }, { rods::HIDDEN }>("rods", "f32", rods::MODEL);
    let (flash, ram) = kibibytes(&output);
    assert!(flash <= 1024.0 && ram <= 64.0, "{flash} KiB of flash, {ram} KiB of RAM");
}

/// The right-sized rods (`rods-m8`: strands decoded as root-relative positions, one origin per
/// strand) within 1 MiB of flash and 64 KiB of RAM, within the `f32` tolerance of the host,
/// whose decode places blocks across strands in one pass.
#[test]
fn right_sized_rods_fit_one_mebibyte_of_flash_and_match_the_host() {
    let output = firmware_matches_the_host::<{ rods_m8::LATENT }, { rods_m8::SIGNAL }, { rods_m8::HIDDEN }>(
        "rods-m8",
        "f32",
        rods_m8::MODEL,
    );
    let (flash, ram) = kibibytes(&output);
    assert!(flash <= 1024.0 && ram <= 64.0, "{flash} KiB of flash, {ram} KiB of RAM");
}

/// A model with a run-time collider slot (`tiny-poke`: the ball circling the block's top as
/// the reference script moves it) on the firmware: within the `f32` tolerance of the host, and
/// bit-identical with int8 weights; prints its sizes and frames per second.
#[test]
fn collider_model_runs_on_the_firmware_and_matches_the_host() {
    use tiny_poke::{HIDDEN, LATENT, SIGNAL};
    for (weights, model) in [("f32", tiny_poke::MODEL), ("int8", tiny_poke_int8::MODEL)] {
        let output = firmware_matches_the_host::<LATENT, SIGNAL, HIDDEN>("tiny-poke", weights, model);
        let (flash, ram) = kibibytes(&output);
        assert!(flash <= 1024.0 && ram <= 64.0, "{flash} KiB of flash, {ram} KiB of RAM");
        let rate = output
            .lines()
            .find(|l| l.contains("frames/s"))
            .expect("a frames-per-second line");
        println!("tiny-poke {weights}: {flash} KiB of flash, {ram} KiB of RAM; {rate}");
    }
}

/// Flash and RAM in KiB from the script's size line (`flash N B (X KiB of 1024) ... (Y KiB of
/// 64)`).
fn kibibytes(output: &str) -> (f64, f64) {
    let line = output.lines().find(|l| l.starts_with("flash ")).expect("a size line");
    let kib = |before: &str| -> f64 {
        let text = line.split(before).next().unwrap_or("");
        let open = text.rfind('(').unwrap_or(0);
        text[open + 1..]
            .split_whitespace()
            .next()
            .unwrap_or("")
            .parse()
            .unwrap_or(f64::NAN)
    };
    (kib("KiB of 1024"), kib("KiB of 64"))
}
