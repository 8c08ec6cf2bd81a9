//! Cortex-M4F firmware: runs the generated model on the reference boundary-condition script
//! (`mochi-target-common`) and prints, over semihosting, the checksum of its decoded positions
//! (which must equal the host runtime's), the final positions, the instructions per frame
//! (QEMU's instruction counting: run with `-icount shift=0`, read through SysTick) and the peak
//! stack; for a model with a render mesh, the same script again through the render decode (its
//! checksums, final render positions and normals, and the decode's instructions per frame);
//! then exits with the semihosting status.
#![no_std]
#![no_main]

use core::fmt::Write;
use core::ptr::{addr_of, addr_of_mut};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hio};
use mochi_runtime::{HandleMotion, ValidModel};
use mochi_target_common::{run, run_render, sampled, Script, CHECKPOINTS, FRAMES};

#[allow(dead_code, missing_docs)]
mod model {
    include!(concat!(env!("OUT_DIR"), "/model.rs"));
}

/// Name of the artifact and weight storage (from build.rs).
const NAME: &str = include!(concat!(env!("OUT_DIR"), "/name.rs"));
const WEIGHTS: &str = include!(concat!(env!("OUT_DIR"), "/weights.rs"));

/// Frames of the timing pass.
const TIMED_FRAMES: u32 = 100;

/// Decoded positions (in `.bss`, not on the stack).
static mut POSITIONS: [f32; model::STATE_LEN] = [0.0; model::STATE_LEN];

/// Render positions and normals of a model with a render mesh (empty without one).
static mut RENDER_POSITIONS: [f32; model::RENDER_LEN] = [0.0; model::RENDER_LEN];
static mut RENDER_NORMALS: [f32; model::RENDER_LEN] = [0.0; model::RENDER_LEN];

/// Stack painting: every word between the end of the statics and the stack pointer gets this
/// value before the run; the first word found changed afterwards is the stack's high-water mark.
const PAINT: u32 = 0xa5a5_a5a5;

extern "C" {
    /// End of `.bss` / start of the (unused) heap, from cortex-m-rt's linker script.
    static __sheap: u32;
    /// Initial stack pointer (end of RAM).
    static _stack_start: u32;
}

#[entry]
fn main() -> ! {
    let mut out = match hio::hstdout() {
        Ok(out) => out,
        Err(()) => exit(false),
    };
    // SAFETY: words between the end of the statics and 256 bytes below the current stack
    // pointer are unused RAM (no heap); writing them changes nothing the program reads.
    let stack_floor = unsafe { paint() };
    let ok = match body(&mut out, stack_floor) {
        Ok(()) => true,
        Err(message) => {
            let _ = writeln!(out, "status error {message}");
            false
        }
    };
    exit(ok)
}

fn body(out: &mut hio::HostStream, stack_floor: usize) -> Result<(), &'static str> {
    let model = ValidModel::new(model::MODEL).map_err(|_| "the generated model is not valid")?;
    let _ = writeln!(out, "model {NAME} weights {WEIGHTS} frames {FRAMES}");
    // SAFETY: the only reference to POSITIONS, taken once.
    let positions: &mut [f32] = unsafe { &mut *addr_of_mut!(POSITIONS) };
    let mut failed = false;
    run::<{ model::LATENT }, { model::SIGNAL }, { model::HIDDEN }>(&model, FRAMES, positions, |frame, sum, now| {
        if CHECKPOINTS.contains(&frame) {
            failed |= writeln!(out, "checksum {frame} {:016x}", sum.0).is_err();
        }
        if sampled(WEIGHTS, frame) {
            let _ = write!(out, "frame {frame}");
            for v in now {
                let _ = write!(out, " {:08x}", v.to_bits());
            }
            failed |= writeln!(out).is_err();
        }
    })
    .map_err(|_| "the reference run was refused")?;
    let _ = write!(out, "positions");
    for v in positions.iter() {
        let _ = write!(out, " {:08x}", v.to_bits());
    }
    let _ = writeln!(out);
    // SAFETY: the only references to the render buffers, taken once.
    let (render_positions, render_normals): (&mut [f32], &mut [f32]) =
        unsafe { (&mut *addr_of_mut!(RENDER_POSITIONS), &mut *addr_of_mut!(RENDER_NORMALS)) };
    if model.model().has_render() {
        failed |= render_pass(out, &model, positions, render_positions, render_normals)?;
    }
    let (per_frame, per_tick, render_per_frame) = timing(&model, positions, render_positions, render_normals)?;
    let _ = writeln!(out, "instructions_per_frame {per_frame}");
    let _ = writeln!(out, "instructions_per_systick {per_tick}");
    if model.model().has_render() {
        let _ = writeln!(out, "render_instructions_per_frame {render_per_frame}");
    }
    // SAFETY: reads the painted words below the stack (see `paint`).
    let stack = unsafe { stack_used(stack_floor) };
    let _ = writeln!(out, "stack_bytes {stack}");
    if failed {
        return Err("semihosting write failed");
    }
    let _ = writeln!(out, "status ok");
    Ok(())
}

/// The reference script again with the render decode: its checksums at the checkpoints and
/// the final frame's render positions and normals. Returns whether a write failed.
fn render_pass(
    out: &mut hio::HostStream,
    model: &ValidModel,
    sim: &mut [f32],
    positions: &mut [f32],
    normals: &mut [f32],
) -> Result<bool, &'static str> {
    let mut failed = false;
    run_render::<{ model::LATENT }, { model::SIGNAL }, { model::HIDDEN }>(
        model,
        FRAMES,
        sim,
        positions,
        normals,
        |frame, sum, _, _| {
            if CHECKPOINTS.contains(&frame) {
                failed |= writeln!(out, "render_checksum {frame} {:016x}", sum.0).is_err();
            }
        },
    )
    .map_err(|_| "the reference render run was refused")?;
    for (label, values) in [("render_positions", &*positions), ("render_normals", &*normals)] {
        let _ = write!(out, "{label}");
        for v in values {
            let _ = write!(out, " {:08x}", v.to_bits());
        }
        failed |= writeln!(out).is_err();
    }
    Ok(failed)
}

/// Mean instructions per frame (step + full decode) over [`TIMED_FRAMES`] frames of the script,
/// and the instructions per SysTick tick it was converted with (calibrated on a loop of known
/// length: with `-icount shift=0` QEMU advances its virtual clock one nanosecond per
/// instruction, and SysTick counts that clock).
fn timing(
    model: &ValidModel,
    positions: &mut [f32],
    render_positions: &mut [f32],
    render_normals: &mut [f32],
) -> Result<(u64, u64, u64), &'static str> {
    let Some(peripherals) = cortex_m::Peripherals::take() else {
        return Err("peripherals taken twice");
    };
    let mut syst = peripherals.SYST;
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0x00ff_ffff);
    syst.clear_current();
    syst.enable_counter();
    // Calibration: 2 instructions per iteration (`subs`, `bne`).
    const LOOPS: u32 = 1_000_000;
    let start = SYST::get_current();
    spin(LOOPS);
    let ticks = u64::from(start.wrapping_sub(SYST::get_current()) & 0x00ff_ffff);
    if ticks == 0 {
        return Err("SysTick does not advance (run QEMU with -icount shift=0)");
    }
    let per_tick = (2 * u64::from(LOOPS) + ticks / 2) / ticks;

    let script = Script::for_model(model);
    let mut body = model::Instance::new(model).map_err(|_| "instance")?;
    let mut bc = [HandleMotion::REST; model::HANDLES];
    let (mut total, mut render) = (0u64, 0u64);
    for frame in 1..=TIMED_FRAMES {
        bc.fill(script.motion(frame));
        let start = SYST::get_current();
        body.step(model, &bc).map_err(|_| "step refused")?;
        body.decode_into(model, positions).map_err(|_| "decode refused")?;
        total += u64::from(start.wrapping_sub(SYST::get_current()) & 0x00ff_ffff);
        if model.model().has_render() {
            let start = SYST::get_current();
            body.decode_render_into(model, positions, render_positions, render_normals)
                .map_err(|_| "render decode refused")?;
            render += u64::from(start.wrapping_sub(SYST::get_current()) & 0x00ff_ffff);
        }
    }
    let frames = u64::from(TIMED_FRAMES);
    Ok((total * per_tick / frames, per_tick, render * per_tick / frames))
}

/// `n` iterations of a two-instruction loop.
#[inline(never)]
fn spin(n: u32) {
    // SAFETY: only counts a register down to zero.
    unsafe {
        core::arch::asm!("1:", "subs {0}, #1", "bne 1b", inout(reg) n => _, options(nomem, nostack));
    }
}

/// Paints the free RAM below the stack; returns the lowest painted address.
///
/// # Safety
/// Call once, first thing, with no heap in use.
unsafe fn paint() -> usize {
    let floor = addr_of!(__sheap) as usize;
    let top = cortex_m::register::msp::read() as usize - 256;
    let mut p = floor;
    while p + 4 <= top {
        // SAFETY: unused RAM between the statics and the stack (see the caller).
        unsafe { (p as *mut u32).write_volatile(PAINT) };
        p += 4;
    }
    floor
}

/// Bytes of stack used so far: from the first changed painted word up to the stack's top.
///
/// # Safety
/// After `paint` returned `floor`.
unsafe fn stack_used(floor: usize) -> usize {
    let top = addr_of!(_stack_start) as usize;
    let mut p = floor;
    // SAFETY: painted RAM (see `paint`).
    while p < top && unsafe { (p as *const u32).read_volatile() } == PAINT {
        p += 4;
    }
    top - p
}

fn exit(ok: bool) -> ! {
    debug::exit(if ok { debug::EXIT_SUCCESS } else { debug::EXIT_FAILURE });
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    if let Ok(mut out) = hio::hstdout() {
        let _ = writeln!(out, "status error panic: {info}");
    }
    exit(false)
}
