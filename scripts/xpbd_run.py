"""XPBD peer: Bender's PositionBasedDynamics (PyPI `pypbd`) driven on a case `.npz` written by
`mochi compare SCENE --cases DIR` (rest shape, cells, lumped masses, handles and their targets,
material, the scene's implicit-Euler reference, and a contact scene's obstacle boxes (scripted
obstacles and run-time box colliders) with their centres at every frame, dhat and friction;
layout in trainer/src/eval/compare/case.rs). Run by scripts/xpbd.sh, which makes its virtual
environment and pins it to one core:

    python xpbd_run.py CASE.npz --substeps S --iterations I --out RESULT.npz
    python xpbd_run.py CASE.npz --sweep OUTDIR [--substeps-list 1,2,4 --iterations-list 1,5]
    python xpbd_run.py --self-check

Result `.npz` (one per setting):
  positions     (frames+1, n, 3) float64  frame 0 is the case's `initial`
  step_seconds  (frames,) float64         wall time of each frame: the library's step calls and
                                          the kinematic handle updates (perf_counter, one core)
  solver_seconds (frames,) float64        the library's step calls alone
  cpu_seconds   (frames,) float64         the frame's CPU time of the thread (thread_time): less
                                          sensitive than wall time to other work on the machine
  substeps, iterations                    0-d int64: substeps per frame, solver iterations per substep
  mass_scale, bending                     0-d float64: the unit scaling and bending stiffness used
  error_percent (frames+1,) float64       mean vertex distance to `reference`, % of `diagonal`
  constraint                              0-d str: the constraints, their parameters and the scaling
  pypbd_version                           0-d str
  contact, tolerance                      (cases with obstacles) 0-d str: the contact setup;
                                          0-d float64: the collision tolerance (m)
`--sweep` writes `s{S}-i{I}.npz` per setting into OUTDIR and `sweep.md` (one table row per
setting: mean error % over all frames, final-frame error %, ms per frame: wall mean and median,
the library's calls, thread CPU; then the Pareto front by CPU time, the cost `mochi compare`
uses), and `sweep.json` with the same rows.

How the library is driven (its Python API, version in PYPBD_VERSION):
- one library `step` per substep: `NUM_SUB_STEPS` = 1 and the time step size dt / S, so the
  handles can be moved between substeps; the library's own substep loop is the same loop
  (prediction with gravity, `MAX_ITERATIONS` Gauss-Seidel sweeps over the constraint groups,
  first-order velocity update);
- handles are kinematic: mass 0 (inverse mass 0, so neither prediction nor constraints move
  them) and their positions written before each substep's step, linearly interpolated between
  the frame's targets. `ParticleData.getVertices()` returns a read-only memoryview onto the
  library's position array; the script writes the handle rows through a writable numpy view of
  the same memory (one numpy assignment per substep instead of one `setPosition` call per
  vertex), and checks once that `getPosition` reads back what it wrote;
- gravity is the library's default (0, -9.81, 0): its Python API cannot set the gravity vector
  (`Simulation::GRAVITATION` is a vector parameter without a binding), so a case with another
  gravity is refused;
- velocities start at zero (a case starts at rest), masses are the case's lumped masses;
- velocity iterations (`MAX_ITERATIONS_V`) are 0 without obstacles: they only act on contacts.

Obstacles (a case with `obstacle_kinds`; solid cases, axis-aligned boxes): the library's own
collision handling, `DistanceFieldCollisionDetection` (the `CubicSDFCollisionDetection` that
`Simulation.initDefault` installs):
- each box is a rigid body of mass 0 (static: the library neither integrates it nor applies
  impulses to it) with a box mesh, and `addCollisionBox` gives it the library's analytic box
  distance field; the tet model is added with `testMesh`, so its vertices are tested against
  the boxes (`collisionDetectionRBSolid`; only vertices: a box edge pressing into a face between
  vertices is not seen, unlike IPC's edge-edge and point-face pairs);
- a moving box (the case's centres change over the frames) is placed before every substep where
  it is at the substep's end (linear between the frame's centres), with the velocity of that
  motion: `RigidBody.setPosition` / `setVelocity`, then `updateInverseTransformation` (the
  world-to-box transform the distance query uses; the library updates it only for bodies with
  mass). The body's mesh serves only the broad phase (its bounding box); the library never
  moves the mesh of a body of mass 0, and `RigidBody.getGeometry` returns a copy in the binding
  (pybind11's default policy for a returned reference), so `updateMeshTransformation` on it
  moves nothing: a moving box's mesh therefore spans the box's whole path from the start;
- contact is the library's particle-rigid body contact: found after each step's position
  solve, within the collision tolerance (where the distance to the box less the tolerance is
  below 0),
  and solved by `MAX_ITERATIONS_V` velocity iterations (default 5, the library's): the relative
  normal velocity goes to 0 (restitution 0 here: the reference's contacts are inelastic),
  Coulomb friction with the case's coefficient (the library sums the two bodies'
  coefficients: the tet model gets the case's, the boxes 0), and a penetration below the
  tolerance surface gets a velocity of stiffness x depth (`setContactStiffnessParticleRigidBody`);
  positions are never projected, so a penetration is undone only by that velocity over the
  next substeps, while the tets' own constraints push against it;
- collision tolerance: the case's dhat (1 mm on stomp) unless `--tolerance`; contact stiffness:
  the library's default 100 (1/s) or `--contact-stiffness`, or `--contact-stiffness-h C` for
  C / h (h the substep; C = 1 undoes a penetration in one substep).

Constraints per body kind (all XPBD, i.e. with compliance alpha = 1 / (k h^2), h the substep):
- solid: the library's XPBD FEM tet constraint (`addSolidConstraints` method 3), Young's modulus
  and Poisson ratio of the case. Its material is St. Venant-Kirchhoff (Green strain); the
  constraint is C = sqrt(2 U / E), so the XPBD potential is exactly U. The library skips a tet
  whose sum_i w_i |grad U/E|^2 + C^2 alpha is below 1e-6 (`eps` in XPBD.cpp). That sum is
  dimensional (m^4 / kg with time unchanged) and quadratic in the strain: on beam's tets (about
  3e-6 m^3, 14 g per vertex) it is below 1e-6 for every strain the beam reaches, so every
  constraint is skipped and the beam falls until its tets are grossly strained (measured:
  `--threshold-report`, `--self-check` and the note docs/notes/2026-11-28-xpbd-peer.md). Masses and moduli are therefore multiplied by one factor
  `mass_scale` (default 1e-12): with lengths and time unchanged, the equations of motion depend
  only on E / rho and g, so the motion is the same, and the threshold then bites only below a
  strain about 1e6 times smaller (the sum grows as 1 / mass_scale). Gravity cannot be scaled
  through the API, which is why lengths are not. The tet constraint is also skipped for a
  Poisson ratio above 0.49 (refused here).
  Iterations: the constraint's first iteration in a substep is exact XPBD (its multiplier
  starts at 0). From the second on, the multiplier it carries is the sum of the steps
  Delta lambda / C rather than Delta lambda (XPBD.cpp, `multiplier += lambda` with
  lambda = -C (C + alpha multiplier) / (...), since 2.2.1), which with C = sqrt(2 U / E) of order
  1e-6 overweights alpha * multiplier by about 1 / C: on beam 5 or more iterations per
  substep diverge within a few frames at 2 or more substeps and 2 iterations stay above 56 %
  error (measured, docs/results/methods.md).
  The library's own default is one iteration (`maxIterations` = 1) with substeps, the regime
  of Macklin et al. 2019 ("Small steps in physics simulation"); the sweep adds 64, 128 and 256
  substeps at one iteration.
- cloth: XPBD distance constraints on every edge, spring constant
  k_e = 2 E t / (1 - nu) * (A_e / |e|^2), A_e a third of the rest area of the edge's triangles.
  This gives a uniformly stretched sheet the energy of the StVK membrane under the same strain,
  E t eps^2 / (1 - nu) per area (a spring network cannot match every strain state; the library
  has no XPBD triangle FEM constraint, its FEM and strain triangle constraints are PBD with
  iteration-dependent stiffness). Bending: the library's XPBD isometric bending constraint
  (Bergou et al. 2006) on every interior edge; its constraint is the quadratic bending energy
  itself, so its XPBD potential is quartic in the bend angle and has no stiffness that equals
  the plate's D = E t^3 / (12 (1 - nu^2)); its stiffness is a tuned value (`--bending`), by
  default 0 (no bending constraint): on cloth-line (test-01) no stiffness from 0.1 to 1000
  lowered the error by more than 0.8 points, some raised it by up to 3 points, and the
  constraint took 2.7-3.9x the CPU time (the sheet's bending length (D / (rho t g))^(1/3) is
  4 cm, under one grid spacing).
- rod: XPBD distance constraints on every edge with k = E pi r^2 / |e_rest| (exactly the
  stretching energy of our rods), and bending by XPBD distance constraints between the two
  neighbours of every interior vertex (the library's rod models need orientations: Cosserat
  stretch-shear and bend-twist constraints are PBD with iteration-dependent stiffness, and the
  stiff-rods solver works on rigid bodies). Such a spring has no linear stiffness about a
  straight rod (its length changes with the square of the bend angle), so its stiffness is a
  tuned value (`--bending`), by default 10 N/m (on test-01 at three settings the best or within
  0.8 points of it; without bending the error was 8-28 points higher).
All stiffnesses are multiplied by `mass_scale` with the masses.
"""

import argparse
import json
import os
import subprocess
import sys

import numpy as np

from xpbd_peer import DIVERGED, MASS_SCALE, PYPBD_VERSION, Peer, errors, fem_threshold_fraction, load_case

SWEEP_SUBSTEPS = [1, 2, 4, 8, 16, 32]
SWEEP_ITERATIONS = [1, 2, 5, 10, 20]
# Added to the default grid: more substeps at one iteration, the library's default iteration
# count and the regime where its XPBD FEM constraint is exact (see the note on iterations).
SWEEP_EXTRA = [(64, 1), (128, 1), (256, 1)]

def run_one(case, args, out):
    peer = Peer(case, args.substeps, args.iterations, args.mass_scale, args.bending, args.velocity_order,
                contact_options(args))
    limit = DIVERGED * case["diagonal"]
    ref = case["reference"]
    positions, step_s, solver_s = peer.run(
        args.frames, lambda f, x: not (np.isfinite(x).all() and np.abs(x - ref[f]).max() < limit))
    err = errors(case, positions)
    done = int(np.sum(np.isfinite(step_s)))
    np.savez(
        out,
        positions=positions,
        step_seconds=step_s,
        solver_seconds=solver_s,
        cpu_seconds=peer.cpu_seconds,
        substeps=np.int64(args.substeps),
        iterations=np.int64(args.iterations),
        mass_scale=np.float64(args.mass_scale),
        bending=np.float64(peer.bending),
        error_percent=err,
        frames_completed=np.int64(done),
        constraint=np.array(peer.constraint),
        pypbd_version=np.array(PYPBD_VERSION),
        **({"contact": np.array(peer.contact_text), "tolerance": np.float64(peer.tolerance)} if peer.boxes else {}),
    )
    row = {
        "substeps": args.substeps,
        "iterations": args.iterations,
        "frames": len(step_s),
        "frames_completed": done,
        "diverged": done < len(step_s),
        "mean_error_percent": float(err[1:].mean()),
        "final_error_percent": float(err[-1]),
        "ms_per_frame": 1e3 * float(np.nanmean(step_s)),
        "ms_per_frame_median": 1e3 * float(np.nanmedian(step_s)),
        "solver_ms_per_frame": 1e3 * float(np.nanmean(solver_s)),
        "cpu_ms_per_frame": 1e3 * float(np.nanmean(peer.cpu_seconds)),
    }
    print(json.dumps(row))
    return row, peer.constraint


def contact_options(args):
    """The contact settings given on the command line (the rest: CONTACT_DEFAULTS)."""
    given = {"tolerance": args.tolerance, "stiffness": args.contact_stiffness, "stiffness_h": args.contact_stiffness_h,
             "velocity_iterations": args.velocity_iterations, "restitution": args.restitution}
    return {k: v for k, v in given.items() if v is not None}


CONTACT_FLAGS = {"tolerance": "--tolerance", "stiffness": "--contact-stiffness", "stiffness_h": "--contact-stiffness-h",
                 "velocity_iterations": "--velocity-iterations", "restitution": "--restitution"}


def parse_list(text):
    return [int(v) for v in text.split(",")]


def sweep(case_path, args):
    os.makedirs(args.sweep, exist_ok=True)
    substeps = parse_list(args.substeps_list) if args.substeps_list else SWEEP_SUBSTEPS
    iterations = parse_list(args.iterations_list) if args.iterations_list else SWEEP_ITERATIONS
    grid = [(S, I) for S in substeps for I in iterations]
    if not (args.substeps_list or args.iterations_list):
        grid += SWEEP_EXTRA
    rows, constraint = [], ""
    for S, I in grid:
        out = os.path.join(args.sweep, f"s{S}-i{I}.npz")
        # One process per setting: the library keeps one global simulation.
        cmd = [sys.executable, __file__, case_path, "--substeps", str(S), "--iterations", str(I),
               "--out", out, "--mass-scale", repr(args.mass_scale)]
        if args.bending is not None:
            cmd += ["--bending", repr(args.bending)]
        if args.frames is not None:
            cmd += ["--frames", str(args.frames)]
        cmd += ["--velocity-order", str(args.velocity_order)]
        for key, value in contact_options(args).items():
            cmd += [CONTACT_FLAGS[key], repr(value)]
        line = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1]
        row = json.loads(line)
        rows.append(row)
        constraint = str(np.load(out)["constraint"])
        print(f"S {S:3d} I {I:2d}: mean error {row['mean_error_percent']:.3f} % over "
              f"{row['frames_completed']}/{row['frames']} frames, "
              f"{row['cpu_ms_per_frame']:.2f} ms/frame CPU, {row['ms_per_frame']:.2f} wall", flush=True)
    with open(os.path.join(args.sweep, "sweep.json"), "w") as f:
        json.dump({"case": case_path, "constraint": constraint, "pypbd_version": PYPBD_VERSION, "rows": rows}, f, indent=1)
    write_table(args.sweep, rows, constraint)


def write_table(outdir, rows, constraint):
    """OUTDIR/sweep.md from the sweep's rows (also printed)."""
    lines = [
        f"pypbd {PYPBD_VERSION}; {constraint}",
        "",
        "| substeps | iterations | mean error % | final error % | ms/frame (mean) | ms/frame (median) | library ms/frame | CPU ms/frame |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        err = f"diverged at frame {r['frames_completed']}" if r["diverged"] else f"{r['mean_error_percent']:.3f}"
        final = "-" if r["diverged"] else f"{r['final_error_percent']:.3f}"
        lines.append(f"| {r['substeps']} | {r['iterations']} | {err} | {final} | "
                     f"{r['ms_per_frame']:.2f} | {r['ms_per_frame_median']:.2f} | {r['solver_ms_per_frame']:.2f} | "
                     f"{r['cpu_ms_per_frame']:.2f} |")
    # Best setting per budget: the lowest error at or under each cost.
    # Cost by the thread's CPU time, as `mochi compare` costs every method.
    finite = sorted((r for r in rows if not r["diverged"]), key=lambda r: r["cpu_ms_per_frame"])
    lines += ["", "Pareto front by CPU time (cheapest first; each row lowers the error of every cheaper one):", ""]
    best = float("inf")
    for r in finite:
        if r["mean_error_percent"] < best:
            best = r["mean_error_percent"]
            lines.append(f"- S {r['substeps']} x I {r['iterations']}: {best:.3f} % at {r['cpu_ms_per_frame']:.2f} ms/frame CPU"
                         f" ({r['ms_per_frame']:.2f} wall)")
    with open(os.path.join(outdir, "sweep.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


def box_case(cells=(1, 4, 1), size=(0.025, 0.125, 0.025), frames=60):
    """A tiny solid case with the beam scene's tet size and material (cells of 0.03125 x 0.025 x
    0.025 m in the trainer's box tetrahedralisation, E 5 MPa, nu 0.3, 1000 kg/m^3): a bar along
    y whose top face is held, no reference (zeros)."""
    nx, ny, nz = cells
    idx = lambda i, j, k: i + (nx + 1) * (j + (ny + 1) * k)
    rest = np.array([[size[0] * i / nx, size[1] * j / ny, size[2] * k / nz]
                     for k in range(nz + 1) for j in range(ny + 1) for i in range(nx + 1)])
    paths = [([0, 1, 2], False), ([1, 2, 0], False), ([2, 0, 1], False), ([0, 2, 1], True), ([1, 0, 2], True), ([2, 1, 0], True)]
    tets = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                for axes, odd in paths:
                    c, t = [i, j, k], [idx(i, j, k)] * 4
                    for s, a in enumerate(axes):
                        c[a] += 1
                        t[s + 1] = idx(*c)
                    if odd:
                        t[2], t[3] = t[3], t[2]
                    tets.append(t)
    tets = np.array(tets, dtype=np.int64)
    rho = 1000.0
    x = rest[tets]
    vol = np.abs(np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])) / 6
    mass = np.zeros(len(rest))
    np.add.at(mass, tets.ravel(), np.repeat(rho * vol / 4, 4))
    handles = np.nonzero(rest[:, 1] == rest[:, 1].max())[0].astype(np.int64)
    return {
        "kind": "solid", "rest": rest, "initial": rest.copy(), "cells": tets, "mass": mass,
        "handles": handles, "targets": np.repeat(rest[handles][None], frames + 1, axis=0),
        "dt": 1 / 30, "gravity": np.array([0, -9.81, 0.0]), "youngs": 5e6, "poisson": 0.3,
        "density": rho, "thickness": float("nan"), "radius": float("nan"), "material_model": "stvk",
        "reference": np.zeros((frames + 1, len(rest), 3)), "diagonal": float(np.linalg.norm(size)),
    }


def obstacle_case(frames=30, descent=0.006):
    """A block of 32 tets (0.1 x 0.03 x 0.05 m, E 1e5 Pa, nu 0.4, as stomp) 0.5 mm over a ground
    box, pressed by a box over its middle that descends `descent` in 0.5 s from just above its top
    and holds: the case layout of a scene with obstacles (box kinds, extents, centres per frame,
    dhat 1e-3, friction 0.5), no reference (zeros)."""
    case = box_case(cells=(4, 2, 2), size=(0.1, 0.03, 0.05), frames=frames)
    case["rest"] = case["rest"] + np.array([-0.05, 0.0005, -0.025])
    case["initial"] = case["rest"].copy()
    case["handles"] = np.zeros(0, np.int64)
    case["targets"] = np.zeros((frames + 1, 0, 3))
    case["youngs"], case["poisson"] = 1e5, 0.4
    t = np.arange(frames + 1) * case["dt"]
    bottom = case["rest"][:, 1].max() + 0.001 - np.minimum(t / 0.5, 1) * descent
    press = np.stack([np.zeros_like(t), bottom + 0.02, np.zeros_like(t)], axis=1)
    case["obstacle_kinds"] = ["box", "box"]
    case["obstacle_extents"] = np.array([[1.0, 0.1, 1.0], [0.06, 0.04, 0.1]])
    case["obstacle_rotations"] = np.zeros((2, 3))
    case["obstacle_centres"] = np.stack([np.tile([0.0, -0.05, 0.0], (frames + 1, 1)), press], axis=1)
    case["contact_dhat"], case["contact_friction"], case["contact_epsv"] = 1e-3, 0.5, 1e-3
    return case


def _press(case, substeps, contact):
    """Runs the obstacle case; returns the lowest vertex over the last 10 frames and the range
    of (top vertex under the press box - the box's bottom) over them."""
    peer = Peer(case, substeps, 1, contact=contact)
    positions, _, _ = peer.run()
    last = positions[-10:]
    top = case["rest"][:, 1] == case["rest"][:, 1].max()
    under = top & (np.abs(case["rest"][:, 0]) < 0.03)
    bottom = case["obstacle_centres"][-10:, 1, 1] - 0.5 * case["obstacle_extents"][1, 1]
    gap = last[:, under, 1] - bottom[:, None]
    return float(last[:, :, 1].min()), float(gap.min()), float(gap.max())


def self_check():
    """A bar of 24 tets (the beam scene's tet size and material) hanging from its top face under
    gravity for 2 s from rest, and a block pressed onto a ground box (`obstacle_case`). Checks: (1) on its hanging shape, the library's skip test switches
    off every tet in the case's own units and none at the default mass_scale; (2) at the default
    mass_scale and 256 substeps x 1 iteration the bar hangs (centre drop under 1 mm) with the
    static stretch of a bar under its own weight, rho g L^2 / (2 E), within 10%; (3) at
    mass_scale 1 the constraints are off where they matter: the bar's stretch is off the static
    value by more than 10x; (4) the block's vertices stay above the ground and its top under the press
    follows the press down to within the collision tolerance."""
    case = box_case()
    g = 9.81
    L = float(np.ptp(case["rest"][:, 1]))
    analytic = case["density"] * g * L * L / (2 * case["youngs"])
    drop, stretch, hanging = _in_fresh_process(_hang, case, MASS_SCALE, 256)
    _, stretch_unscaled, _ = _in_fresh_process(_hang, case, 1.0, 256)
    h = case["dt"] / 256
    off_unscaled = fem_threshold_fraction(case, hanging[None], h, 1.0)
    off_scaled = fem_threshold_fraction(case, hanging[None], h, MASS_SCALE)
    print(f"tets the library skips on the hanging bar: {100 * off_unscaled:.0f} % at mass_scale 1, "
          f"{100 * off_scaled:.0f} % at mass_scale {MASS_SCALE:g}")
    print(f"stretch (mean of the last second): {stretch:.4e} m at mass_scale {MASS_SCALE:g}, "
          f"{stretch_unscaled:.4e} m at mass_scale 1; static rho g L^2 / (2E) {analytic:.4e} m; "
          f"centre drop {drop:.2e} m")
    # Obstacles: the block on the ground, squashed by 6 mm by the press (64 substeps x 1, contact
    # stiffness 1 / h; collision tolerance = dhat 1 mm).
    obstacles = obstacle_case()
    lowest, gap_min, gap_max = _in_fresh_process(_press, obstacles, 64, {"stiffness_h": 1.0})
    print(f"obstacles: lowest vertex {lowest:.2e} m over the ground's top (y = 0); top vertices under the press"
          f" {gap_min:.2e} to {gap_max:.2e} m from its bottom (collision tolerance 1e-3 m)")
    checks = [
        (lowest > -5e-4, "obstacles: the ground holds the pressed block (at most 0.5 mm into it)"),
        (-1.5e-3 < gap_min and gap_max < 5e-4, "obstacles: the press pushes the block's top down with it"),
        (off_unscaled == 1.0 and off_scaled == 0.0, "skip test: all tets off unscaled, none scaled"),
        (abs(drop) < 1e-3 and abs(stretch - analytic) < 0.1 * analytic, "scaled: hangs with the static stretch"),
        (abs(stretch_unscaled - analytic) > 10 * analytic, "unscaled: constraints off, stretch far from static"),
    ]
    failed = [name for ok, name in checks if not ok]
    for name in failed:
        print("FAILED:", name)
    print(f"xpbd self-check: {len(checks) - len(failed)} passed, {len(failed)} failed")
    return 1 if failed else 0


def _in_fresh_process(fn, *args):
    """Runs fn in a new process: the library keeps one global simulation."""
    import multiprocessing as mp

    with mp.get_context("spawn").Pool(1) as pool:
        return pool.apply(fn, args)


def _hang(case, mass_scale, substeps):
    """Hangs the self-check bar at `substeps` x 1 iteration; returns the drop of its centre at
    the end, its stretch along y averaged over the last 30 frames, and its last positions."""
    peer = Peer(case, substeps, 1, mass_scale)
    positions, _, _ = peer.run()
    drop = float(case["rest"][:, 1].mean() - positions[-1, :, 1].mean())
    top = case["rest"][:, 1] == case["rest"][:, 1].max()
    bottom = case["rest"][:, 1] == case["rest"][:, 1].min()
    length = positions[-30:, top, 1].mean(axis=1) - positions[-30:, bottom, 1].mean(axis=1)
    return drop, float(length.mean() - np.ptp(case["rest"][:, 1])), positions[-1]


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("case", nargs="?")
    p.add_argument("--substeps", type=int, default=32)
    p.add_argument("--iterations", type=int, default=1)
    p.add_argument("--out")
    p.add_argument("--sweep", metavar="OUTDIR")
    p.add_argument("--substeps-list", help="sweep: comma-separated substeps (default 1,2,4,8,16,32)")
    p.add_argument("--iterations-list", help="sweep: comma-separated iterations (default 1,2,5,10,20)")
    p.add_argument("--frames", type=int, help="simulate only the first FRAMES frames")
    p.add_argument("--mass-scale", type=float, default=MASS_SCALE)
    p.add_argument("--bending", type=float, help="cloth/rod bending stiffness (before mass scale)")
    p.add_argument("--velocity-order", type=int, choices=[1, 2], default=1,
                   help="the library's velocity update: first order (its default) or second order")
    p.add_argument("--tolerance", type=float,
                   help="obstacles: the library's collision tolerance in m (default: the case's dhat)")
    p.add_argument("--contact-stiffness", type=float,
                   help="obstacles: the library's particle-rigid body contact stiffness (default 100, its own)")
    p.add_argument("--contact-stiffness-h", type=float, metavar="C",
                   help="obstacles: contact stiffness C / h, h the substep (instead of --contact-stiffness)")
    p.add_argument("--velocity-iterations", type=int,
                   help="obstacles: the library's velocity iterations per step (default 5, its own)")
    p.add_argument("--restitution", type=float, help="obstacles: restitution coefficient (default 0)")
    p.add_argument("--threshold-report", action="store_true",
                   help="solid: fraction of (tet, frame) of the reference where the library would skip the tet")
    p.add_argument("--table", metavar="OUTDIR", help="rewrite OUTDIR/sweep.md from OUTDIR/sweep.json")
    p.add_argument("--self-check", action="store_true")
    args = p.parse_args()
    if args.self_check:
        sys.exit(self_check())
    if args.table:
        args.case = args.case or ""
    elif not args.case:
        p.error("CASE is required")
    case = load_case(args.case) if args.case else None
    if args.threshold_report:
        ref = case["reference"][1:][:: max(1, len(case["reference"]) // 30)]  # frame 0 is at rest
        for S in [1, 8, 32]:
            for ms in [1.0, 1e-6, 1e-9, MASS_SCALE]:
                frac = fem_threshold_fraction(case, ref, case["dt"] / S, ms)
                print(f"substeps {S:2d} mass_scale {ms:g}: {100 * frac:.2f} % of (tet, frame) below the 1e-6 threshold")
        return
    if args.sweep:
        sweep(args.case, args)
        return
    if args.table:
        with open(os.path.join(args.table, "sweep.json")) as f:
            saved = json.load(f)
        write_table(args.table, saved["rows"], saved["constraint"])
        return
    if not args.out:
        p.error("--out is required")
    run_one(case, args, args.out)


if __name__ == "__main__":
    main()
