"""The runtime's step + full decode in JAX and numpy, on the networks `mochi export-weights`
wrote (see trainer/src/eval/network_export.rs for the archive's layout and the math), over the
same boundary-condition signals; checked against the runtime's own positions, then timed.

Run by scripts/bench-jax.sh, which pins it to one core and sets XLA's single-thread flags:

    python bench_jax.py EXPORT.npz [--runtime-table TABLE.md] [--out RESULT.md]

Timings (best of 5 rounds after a warm-up round, microseconds per frame):
  jit per call  one jitted function (integrator step + full decode) called from Python once per
                frame, its positions waited for every frame (as an engine that draws them);
  lax.scan      every frame in one compiled call (`jax.lax.scan`), the positions buffer carried
                from frame to frame (the runtime's caller reuses one buffer too), the latent
                of every frame returned;
  numpy         the same function in eager numpy (float32).
"""

import argparse
import math
import re
import sys
import time

import numpy as np

# Largest vertex distance from the runtime's positions, as a fraction of the rest diagonal.
TOLERANCE = 1e-4
ROUNDS = 5


def load(path):
    """The exported model as a dict of numpy arrays and ints."""
    d = np.load(path)
    if int(d["format_version"]) not in (1, 2):
        sys.exit(f"{path}: export format {int(d['format_version'])}, this script reads 1 and 2")
    m = {key: d[key] for key in d.files}
    for key in ["dim", "num_vertices", "latent", "signal", "hidden", "rotates"]:
        m[key] = int(m[key])
    # Format 1 archives hold position-encoded models only.
    m["bends"] = int(m.get("bends", 0))
    # Archives written before basis decoders existed hold residual MLP decoders.
    m["decoder_basis"] = int(m.get("decoder_basis", 0))
    for net in ["integrator", "decoder"]:
        layers = []
        for i in range(len(m[f"{net}_layers"])):
            w = m[f"{net}_{i}_w"]
            scale = m.get(f"{net}_{i}_scale")
            layers.append((w, m[f"{net}_{i}_b"], scale))
        m[net] = layers
    m["handle_first"] = np.concatenate([[0], np.cumsum(m["handle_counts"])]).astype(np.int64)
    m["diagonal"] = float(m["diagonal"])
    return m


class Ops:
    """The runtime's forward math over an array module (`jax.numpy` or `numpy`)."""

    def __init__(self, xp, m, scan):
        self.xp = xp
        self.m = m
        self.f32 = xp.float32
        # `scan(f, carry, xs)` as `jax.lax.scan`: the strand walk's steps.
        self.scan = scan

    def layer(self, p, x):
        w, b, scale = p
        y = w @ x
        return b + (y if scale is None else scale * y)

    def swish(self, x):
        return x / (1.0 + self.xp.exp(-x))

    def network(self, layers, x):
        """`h = input(x); h += outer(swish(inner(h))); y = output(swish(h))`."""
        h = self.layer(layers[0], x)
        blocks = layers[1:-1]
        for inner, outer in zip(blocks[0::2], blocks[1::2]):
            h = h + self.layer(outer, self.swish(self.layer(inner, h)))
        return self.layer(layers[-1], self.swish(h))

    def decode(self, layers, z):
        """The decoder: a residual MLP, or (`decoder_basis`) a basis applied to
        `[z; 0] + g(z)`, `g` the layers before it (none: the basis applied to `z`)."""
        if not self.m["decoder_basis"]:
            return self.network(layers, z)
        basis, mlp = layers[-1], layers[:-1]
        modes = basis[0].shape[1]
        f = self.xp.concatenate([z, self.xp.zeros(modes - z.shape[0], dtype=self.f32)])
        if mlp:
            f = f + self.network(mlp, z)
        return self.layer(basis, f)

    def rotation(self, v):
        """Rodrigues' formula; the identity below an angle of f32 epsilon."""
        xp = self.xp
        angle = xp.sqrt(xp.sum(v * v))
        small = angle <= np.finfo(np.float32).eps
        safe = xp.where(small, self.f32(1.0), angle)
        k = v / safe
        x, y, z = k[0], k[1], k[2]
        s, c = xp.sin(angle), xp.cos(angle)
        t = 1.0 - c
        r = xp.stack(
            [
                xp.stack([c + x * x * t, x * y * t - z * s, x * z * t + y * s]),
                xp.stack([y * x * t + z * s, c + y * y * t, y * z * t - x * s]),
                xp.stack([z * x * t - y * s, z * y * t + x * s, c + z * z * t]),
            ]
        )
        return xp.where(small, xp.eye(3, dtype=self.f32), r)

    def placement(self, params, signal):
        """Handle targets (slots x 3), encoding frame `R` and origins, as the runtime's
        `Placement` computes them from the frame's signal."""
        xp, m = self.xp, self.m
        handles = len(m["handle_counts"])
        targets, rotations = [], []
        for h in range(handles):
            s = signal[12 * h : 12 * h + 12]
            r = self.rotation(s[9:12])
            rotations.append(r)
            a, b = m["handle_first"][h], m["handle_first"][h + 1]
            pivot = params["pivot"][h]
            ref = params["reference"][a:b]
            targets.append(pivot + s[6:9] + (ref - pivot) @ r.T)
        targets = xp.concatenate(targets)
        if m["dim"] == 2:
            targets = targets * xp.asarray([1.0, 1.0, 0.0], dtype=self.f32)
        centroid = xp.mean(targets, axis=0)
        frame = xp.eye(3, dtype=self.f32)
        if m["rotates"]:
            frame = rotations[0] if handles == 1 else self.best_fit(params, targets, centroid)
            if m["dim"] == 2:
                frame = frame * xp.asarray([[1, 1, 0], [1, 1, 0], [0, 0, 0]], dtype=self.f32)
                frame = frame + xp.asarray(np.diag([0, 0, 1]), dtype=self.f32)
        roots = m["root_slots"]
        # Per encoded vertex, its origin: a strand root's target, or the centroid.
        if len(roots) == 0:
            origins = centroid[None, :]
        else:
            origins = xp.concatenate([targets[roots], centroid[None, :]])[params["origin_index"]]
        return targets, frame, origins

    def best_fit(self, params, targets, centroid):
        """Kabsch: the proper rotation that maps the reference handle points onto their
        targets (the runtime's `best_fit_rotation`)."""
        xp = self.xp
        ref = params["reference"]
        cov = (ref - xp.mean(ref, axis=0)).T @ (targets - centroid)
        if self.m["dim"] == 2:
            angle = xp.arctan2(cov[0, 1] - cov[1, 0], cov[0, 0] + cov[1, 1])
            c, s = xp.cos(angle), xp.sin(angle)
            zero, one = self.f32(0.0), self.f32(1.0)
            return xp.stack([xp.stack([c, -s, zero]), xp.stack([s, c, zero]), xp.stack([zero, zero, one])])
        u, _, vt = xp.linalg.svd(cov)
        r = vt.T @ u.T
        flip = xp.where(xp.linalg.det(r) < 0, self.f32(-1.0), self.f32(1.0))
        return vt.T @ xp.diag(xp.stack([self.f32(1.0), self.f32(1.0), flip])) @ u.T

    def unit(self, v):
        return v / self.xp.sqrt(self.xp.sum(v * v, axis=-1, keepdims=True))

    def cross(self, a, b):
        return self.xp.cross(a, b)

    def walk(self, params, q, targets, frame):
        """Bend-encoded strands (the runtime's `chain_start` and `ChainWalk::step`), all
        strands side by side, one scan step per vertex along them (shorter strands padded and
        masked): the world positions of the free vertices (free x 3). `q`: two bend numbers
        per free vertex."""
        xp = self.xp
        parent = params["chain_parent"]
        anchor = targets[parent[:, 1]]
        d = self.unit(anchor - targets[parent[:, 0]])
        turned = params["chain_rest_normal"] @ frame.T
        projected = turned - d * xp.sum(d * turned, axis=1, keepdims=True)
        norm = xp.sqrt(xp.sum(projected * projected, axis=1, keepdims=True))
        # Where the rest normal turned onto the edge: the unit axis least along it, made
        # normal to it.
        least = xp.argmin(xp.abs(d), axis=1)
        e = (xp.arange(3)[None, :] == least[:, None]).astype(self.f32)
        fallback = self.unit(e - d * xp.sum(d * e, axis=1, keepdims=True))
        u = xp.where(norm > 1e-6, projected / xp.maximum(norm, self.f32(1e-30)), fallback)
        w = self.cross(d, u)

        def step(carry, inputs):
            position, d, u, w = carry
            qi, length, keep = inputs
            g = (u * qi[:, 0:1] + w * qi[:, 1:2]) / length[:, None]
            c = 2.0 / (1.0 + xp.sum(g * g, axis=1, keepdims=True))

            def turn(y):
                h = self.cross(g, y)
                return y + (h + self.cross(g, h)) * c

            d2, u2, w2 = turn(d), turn(u), turn(w)
            moved = (position + d2 * length[:, None], d2, u2, w2)
            keep = keep[:, None]
            new = tuple(xp.where(keep, a, b) for a, b in zip(moved, carry))
            return new, new[0]

        inputs = (q[params["chain_slot"]].transpose(1, 0, 2), params["chain_length"].T, params["chain_mask"].T)
        _, placed = self.scan(step, (anchor, d, u, w), inputs)
        return placed.transpose(1, 0, 2).reshape(-1, 3)[params["walk_index"]]

    def frame(self, params, state, p):
        """One frame: the integrator step (clamped, held when not finite) and the full decode.
        `state` is `(z, z_prev, signal, signal_prev)`; returns the new state and the positions
        (num_vertices x dim)."""
        xp, m = self.xp, self.m
        z, z_prev, s1, s2 = state
        x = xp.concatenate([z, z_prev, p, s1, s2])
        stepped = z + self.network(params["integrator"], x)
        stepped = xp.where(xp.all(xp.isfinite(stepped)), stepped, z)
        stepped = xp.clip(stepped, params["low"], params["high"])
        targets, frame, origins = self.placement(params, p)
        if m["bends"]:
            world = self.walk(params, self.decode(params["decoder"], stepped).reshape(-1, 2), targets, frame)
        else:
            q = self.decode(params["decoder"], stepped).reshape(-1, m["dim"])
            if m["dim"] == 2:
                q = xp.concatenate([q, xp.zeros((q.shape[0], 1), dtype=self.f32)], axis=1)
            world = q @ frame.T + origins
        # Free and handle vertices partition the mesh: one gather puts every vertex in place.
        d = m["dim"]
        placed = xp.concatenate([world[:, :d], targets[:, :d]])
        positions = placed[params["order"]]
        positions = xp.where(xp.all(xp.isfinite(positions)), positions, params["rest"])
        return (stepped, z, p, s1), positions


def params_of(m, xp):
    """The arrays `Ops.frame` reads, as arrays of `xp`."""
    f = lambda a: xp.asarray(np.asarray(a, dtype=np.float32))
    i = lambda a: xp.asarray(np.asarray(a, dtype=np.int32))
    lo, hi = m["latent_min"], m["latent_max"]
    margin = float(m["range_margin"]) * (hi - lo)
    roots = len(m["root_slots"])
    # The runtime's origin index: a strand root, or (past the roots) the centroid.
    origin_index = np.minimum(m["origin_of"].astype(np.int64), roots)
    # Where each vertex is in [free vertices, handle vertices].
    order = np.empty(m["num_vertices"], dtype=np.int64)
    order[m["free_vertices"]] = np.arange(len(m["free_vertices"]))
    order[m["handle_vertices"]] = len(m["free_vertices"]) + np.arange(len(m["handle_vertices"]))
    net = lambda layers: [(f(w), f(b), None if s is None else f(s)) for w, b, s in layers]
    strands = {}
    if m["bends"]:
        # The strands padded to the longest: slot, edge length and mask per (strand, step),
        # and where each free vertex's position lands in the flattened (strand, step) walk.
        counts = m["chain_count"].astype(np.int64)
        chains, longest = len(counts), int(counts.max())
        slot = np.zeros((chains, longest), dtype=np.int64)
        length = np.ones((chains, longest), dtype=np.float32)
        mask = np.zeros((chains, longest), dtype=bool)
        walk_index = np.zeros(len(m["free_vertices"]), dtype=np.int64)
        first = 0
        for c, n in enumerate(counts):
            slot[c, :n] = m["chain_slots"][first : first + n]
            length[c, :n] = m["chain_lengths"][first : first + n]
            mask[c, :n] = True
            walk_index[slot[c, :n]] = c * longest + np.arange(n)
            first += n
        strands = {
            "chain_parent": i(m["chain_parent"]),
            "chain_rest_normal": f(m["chain_rest_normal"]),
            "chain_slot": i(slot),
            "chain_length": f(length),
            "chain_mask": xp.asarray(mask),
            "walk_index": i(walk_index),
        }
    return strands | {
        "integrator": net(m["integrator"]),
        "decoder": net(m["decoder"]),
        "low": f(lo - margin),
        "high": f(hi + margin),
        "pivot": f(m["handle_pivot"]),
        "reference": f(m["handle_reference"]),
        "rest": f(m["rest"]),
        "origin_index": i(origin_index),
        "order": i(order),
    }


def initial_state(m, xp):
    z = xp.asarray(m["initial_latent"].astype(np.float32))
    zero = xp.zeros(m["signal"], dtype=xp.float32)
    return (z, z, zero, zero)


def disagreement(m, positions_of_frame, frames=None):
    """Largest vertex distance / diagonal from the runtime's positions over its kept frames
    (those of them in `frames`, if given)."""
    worst = 0.0
    for frame, want in zip(m["runtime_frames"], m["runtime_positions"]):
        if frames is not None and int(frame) not in frames:
            continue
        got = np.asarray(positions_of_frame(int(frame)), dtype=np.float64)
        worst = max(worst, float(np.max(np.linalg.norm(got - want, axis=1))) / m["diagonal"])
    return worst


def best_of(rounds, run):
    """Best seconds of `run()` over `rounds` rounds after a warm-up round."""
    run()
    best = math.inf
    for _ in range(rounds):
        clock = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - clock)
    return best


def numpy_scan(f, carry, xs):
    """`jax.lax.scan` as a Python loop over the leading axis."""
    outs = []
    for x in zip(*xs):
        carry, y = f(carry, x)
        outs.append(y)
    return carry, np.stack(outs)


def bench_numpy(m):
    ops, params = Ops(np, m, numpy_scan), params_of(m, np)
    signals = [row.astype(np.float32) for row in m["script_signal"]]
    kept = {int(f) for f in m["runtime_frames"]}
    seen = {}

    def run():
        state = initial_state(m, np)
        for t, p in enumerate(signals, start=1):
            state, x = ops.frame(params, state, p)
            if t in kept:
                seen[t] = x

    seconds = best_of(ROUNDS, run)
    return seconds / len(signals), disagreement(m, seen.__getitem__)


def bench_jax(m):
    import jax
    import jax.numpy as jnp

    ops = Ops(jnp, m, jax.lax.scan)
    params = jax.device_put(params_of(m, np))
    signals = jnp.asarray(m["script_signal"], dtype=jnp.float32)
    rows = [jax.device_put(row) for row in np.asarray(m["script_signal"], dtype=np.float32)]
    kept = {int(f) for f in m["runtime_frames"]}

    step = jax.jit(ops.frame)
    seen = {}

    def per_call():
        state = initial_state(m, jnp)
        for t, p in enumerate(rows, start=1):
            state, x = step(params, state, p)
            x.block_until_ready()
            if t in kept:
                seen[t] = x

    @jax.jit
    def rollout(params, state, signals):
        # The positions buffer is carried from frame to frame, as the runtime's caller reuses
        # one buffer; the latents of every frame come out.
        def frame(carry, p):
            state, positions = ops.frame(params, carry[0], p)
            return (state, positions), state[0]

        return jax.lax.scan(frame, (state, params["rest"]), signals)

    state0 = initial_state(m, jnp)
    scanned = {}

    def scan():
        scanned["out"] = jax.block_until_ready(rollout(params, state0, signals))

    per_call_seconds = best_of(ROUNDS, per_call) / len(rows)
    scan_seconds = best_of(ROUNDS, scan) / len(rows)
    (_, last), latents = scanned["out"]
    last_frame = len(rows)
    scan_err = disagreement(m, lambda t: np.asarray(last), frames=[last_frame])
    latent_err = float(np.max(np.abs(np.asarray(latents) - m["runtime_latent"])))
    return (
        (per_call_seconds, disagreement(m, seen.__getitem__)),
        (scan_seconds, scan_err, latent_err),
        jax.__version__,
    )


def runtime_row(path, artifact):
    """Step + full decode (seconds) and disagreement from `mochi bench runtime`'s table."""
    with open(path) as f:
        for line in f:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if cells and cells[0] == artifact and len(cells) > 10 and cells[1] == "f32":
                micro = float(re.match(r"[0-9.]+", cells[3]).group())
                return micro * 1e-6, cells[10]
    sys.exit(f"{path}: no f32 row for {artifact}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("export", help="archive written by `mochi export-weights`")
    parser.add_argument("--runtime-table", help="table written by `mochi bench runtime --out`")
    parser.add_argument("--out", help="also write the table to this markdown file")
    args = parser.parse_args()
    m = load(args.export)
    artifact = str(m["artifact"])
    frames = len(m["script_signal"])
    if str(m["weights"]) != "f32" and args.runtime_table:
        sys.exit("the runtime's table is timed with f32 weights; export with --weights f32")

    (call, call_err), (scan, scan_err, latent_err), version = bench_jax(m)
    numpy_seconds, numpy_err = bench_numpy(m)
    worst = max(call_err, scan_err, numpy_err)
    rows = []
    if args.runtime_table:
        runtime, runtime_err = runtime_row(args.runtime_table, artifact)
        rows.append(("mochi runtime (step + full decode)", runtime, f"{runtime_err} vs trainer"))
    rows += [
        (f"JAX {version} jit, one call per frame", call, f"{call_err:.1e}"),
        (f"JAX {version} jit, lax.scan over {frames} frames", scan, f"{scan_err:.1e} (frame {frames})"),
        (f"numpy {np.__version__} eager", numpy_seconds, f"{numpy_err:.1e}"),
    ]
    lines = [
        f"{artifact}: {m['latent']} latent, hidden {m['hidden']}, {m['num_vertices']} vertices; "
        f"{frames} frames of the reference script, one core, batch 1, f32; best of {ROUNDS} rounds",
        "",
        "| implementation | µs per frame | runtime ÷ this | max distance from the runtime / diagonal |",
        "|---|---|---|---|",
    ]
    for name, seconds, err in rows:
        ratio = f"{rows[0][1] / seconds:.2f}" if args.runtime_table else "-"
        lines.append(f"| {name} | {1e6 * seconds:.1f} | {ratio} | {err} |")
    lines += ["", f"JAX lax.scan latents: at most {latent_err:.1e} from the runtime's over {frames} frames"]
    if args.runtime_table:
        lines.append(f"runtime / JAX lax.scan: {runtime / scan:.2f} (below 1: the runtime takes less time)")
    table = "\n".join(lines) + "\n"
    print(table)
    if args.out:
        with open(args.out, "w") as f:
            f.write(table)
    if worst > TOLERANCE:
        sys.exit(f"positions differ from the runtime's by {worst:.2e} of the diagonal (limit {TOLERANCE:.0e})")


if __name__ == "__main__":
    main()
