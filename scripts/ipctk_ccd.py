"""Continuous collision detection cases for check_ipctk.py: random linear motions of each
primitive pair (general ones, collisions at a random time, near misses, high-speed
tunnelling, starts at a distance near zero), ipctk's additive CCD time of impact on them, and
the comparison with ours.

A case collides at time t* by construction when it is made from a contact configuration
x_c (a point on the triangle, crossing edges, ...) and per-vertex velocities v as
x0 = x_c - t* v, x1 = x_c + (1 - t*) v; a near miss moves x_c off contact by a small gap
first. Some cases ask for a minimum separation (ipctk's `min_distance`) of 0 .. 1e-2.

Ours must never report no collision where ipctk reports one, never report a time of impact
after ipctk's, and report at least 0.8 of ipctk's time of impact on every case both find.
Our times are lowered by a margin for the rounding of our distances (`ROUNDING_ULPS` in
`contact/ccd/additive.rs`); starts closer than about 1e-10 to contact can still end a
relative 1e-3 after ipctk's, where ipctk's own distance is the less accurate one (its 2D
point-edge squared distance 1e-12 .. 1e-9 off an edge is off by up to 1.5e-3 relative
against exact rational arithmetic, ours by 1.3e-4), so the starts here stay above 1e-9.
"""

import numpy as np
import ipctk

# Pair key -> (dim, vertices).
PAIRS = {"pp2": (2, 2), "pp3": (3, 2), "pe2": (2, 3), "pe3": (3, 3), "pt": (3, 4), "ee": (3, 4)}
KINDS = ["general", "collide", "near miss", "tunnel", "start near zero"]
MIN_RATIO = 0.8


def unit(rng, n, dim):
    v = rng.normal(size=(n, dim))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def log_uniform(rng, lo, hi, n):
    return 10.0 ** rng.uniform(lo, hi, n)


def contact(rng, key, n):
    """Configurations in contact, and a unit direction that moves them apart (the contact
    normal, or any direction for point-point)."""
    dim, verts = PAIRS[key]
    x = rng.uniform(-1, 1, (n, verts, dim))
    if key.startswith("pp"):
        x[:, 1] = x[:, 0]
        return x, unit(rng, n, dim), [1]
    if key.startswith("pe"):
        s = rng.uniform(0, 1, (n, 1))
        x[:, 0] = x[:, 1] + s * (x[:, 2] - x[:, 1])
        e = x[:, 2] - x[:, 1]
        off = unit(rng, n, dim)
        off -= np.sum(off * e, axis=1, keepdims=True) / np.sum(e * e, axis=1, keepdims=True) * e
        return x, off / np.linalg.norm(off, axis=1, keepdims=True), [0]
    if key == "pt":
        a, b = rng.uniform(0, 1, (2, n, 1))
        flip = (a + b > 1)[:, 0]
        a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
        u, w = x[:, 2] - x[:, 1], x[:, 3] - x[:, 1]
        x[:, 0] = x[:, 1] + a * u + b * w
        nrm = np.cross(u, w)
        return x, nrm / np.linalg.norm(nrm, axis=1, keepdims=True), [0]
    s, t = rng.uniform(0, 1, (2, n, 1))
    ua, ub = x[:, 1] - x[:, 0], x[:, 3] - x[:, 2]
    shift = x[:, 0] + s * ua - (x[:, 2] + t * ub)
    x[:, 2] += shift
    x[:, 3] += shift
    nrm = np.cross(ua, ub)
    return x, nrm / np.linalg.norm(nrm, axis=1, keepdims=True), [0, 1]


def generate(rng, key, n):
    """`n` cases of `key`: x0, x1 (cases x dofs), min_distance (cases) and kind (cases)."""
    dim, verts = PAIRS[key]
    kind = rng.integers(0, len(KINDS), n)
    xc, normal, moving = contact(rng, key, n)
    v = rng.normal(size=(n, verts, dim)) * log_uniform(rng, -2, 0.5, n)[:, None, None]
    tstar = rng.uniform(0, 1.2, n)
    gap = np.zeros(n)
    m = kind == KINDS.index("near miss")
    gap[m] = log_uniform(rng, -6, -2, m.sum())
    # Tunnelling: fast (speeds 10 .. 1000), crossing inside the step.
    m = kind == KINDS.index("tunnel")
    v[m] *= log_uniform(rng, 1, 3, m.sum())[:, None, None] / np.linalg.norm(v[m], axis=(1, 2))[:, None, None]
    tstar[m] = rng.uniform(0.05, 0.95, m.sum())
    # Starting at a distance 1e-9 .. 1e-3 from contact (closer, the two libraries' rounding
    # of the distance differs by more than our margin: see the module docs).
    m = kind == KINDS.index("start near zero")
    tstar[m] = 0.0
    gap[m] = log_uniform(rng, -9, -3, m.sum())
    for i in moving:
        xc[:, i] += gap[:, None] * normal
    x0 = xc - tstar[:, None, None] * v
    x1 = xc + (1 - tstar)[:, None, None] * v
    m = kind == KINDS.index("general")
    x0[m] = rng.uniform(-1, 1, (m.sum(), verts, dim))
    x1[m] = x0[m] + rng.normal(size=(m.sum(), verts, dim)) * log_uniform(rng, -2, 0.5, m.sum())[:, None, None]
    xi = np.where(rng.random(n) < 0.25, log_uniform(rng, -6, -2, n), 0.0)
    # Starts near zero keep their minimum separation below the starting distance.
    m = kind == KINDS.index("start near zero")
    xi[m] = np.minimum(xi[m], 0.5 * gap[m])
    return x0.reshape(n, -1), x1.reshape(n, -1), xi, kind


def reference(key, x0, x1, xi):
    """ipctk's additive CCD (default parameters): hit (0/1) and time of impact per case."""
    dim, _ = PAIRS[key]
    ipctk.set_logger_level(ipctk.LoggerLevel.error)  # not a warning per start within min_distance
    ccd = ipctk.AdditiveCCD()
    fn = {"pp": ccd.point_point_ccd, "pe": ccd.point_edge_ccd, "pt": ccd.point_triangle_ccd,
          "ee": ccd.edge_edge_ccd}[key[:2]]
    hit, toi = np.zeros(len(x0)), np.zeros(len(x0))
    for c in range(len(x0)):
        a = [np.ascontiguousarray(p) for p in x0[c].reshape(-1, dim)]
        b = [np.ascontiguousarray(p) for p in x1[c].reshape(-1, dim)]
        h, t = fn(*a, *b, min_distance=float(xi[c]), tmax=1.0)
        hit[c], toi[c] = float(h), t
    return hit, toi


def inputs(rng, n):
    """The CCD arrays for the cases file, and ipctk's answers."""
    arrays, refs = {}, {}
    for key in PAIRS:
        x0, x1, xi, kind = generate(rng, key, n)
        arrays.update({f"ccd_{key}_x0": x0, f"ccd_{key}_x1": x1, f"ccd_{key}_xi": xi})
        refs[key] = (reference(key, x0, x1, xi), kind)
    return arrays, refs


def table(refs, ours):
    """Markdown rows comparing our CCD with ipctk's; returns (lines, all pass)."""
    lines = ["| pair | cases | no impact (both) | impact (both) | ipctk only | ours only | ours after ipctk's | "
             "min ours / ipctk | median ours / ipctk | pass |", "|---|---|---|---|---|---|---|---|---|---|"]
    ok_all = True
    per_kind = {k: [0, 0, 0, 0] for k in KINDS}
    for key, ((rhit, rtoi), kind) in refs.items():
        ohit, otoi = ours[f"ccd_{key}_hit"] > 0.5, ours[f"ccd_{key}_toi"]
        rhit = rhit > 0.5
        both, none = ohit & rhit, ~ohit & ~rhit
        ref_only, ours_only = rhit & ~ohit, ohit & ~rhit
        after = both & (otoi > rtoi)
        pos = both & (rtoi > 0)
        ratio = otoi[pos] / rtoi[pos]
        zero_ok = np.all(otoi[both & (rtoi == 0)] == 0)
        rmin = float(ratio.min()) if ratio.size else float("nan")
        rmed = float(np.median(ratio)) if ratio.size else float("nan")
        ok = ref_only.sum() == 0 and after.sum() == 0 and zero_ok and (not ratio.size or rmin >= MIN_RATIO)
        ok_all &= bool(ok)
        lines.append(f"| {key} | {len(rhit)} | {none.sum()} | {both.sum()} | {ref_only.sum()} | {ours_only.sum()} | "
                     f"{after.sum()} | {rmin:.6f} | {rmed:.6f} | {'yes' if ok else 'NO'} |")
        for i, k in enumerate(KINDS):
            m = kind == i
            per_kind[k][0] += m.sum()
            per_kind[k][1] += (m & both).sum()
            per_kind[k][2] += (m & none).sum()
            per_kind[k][3] += (m & ours_only).sum()
    lines.append("")
    lines.append("| kind of case | cases | impact (both) | no impact (both) | ours only |")
    lines.append("|---|---|---|---|---|")
    for k, (c, b, nn, oo) in per_kind.items():
        lines.append(f"| {k} | {c} | {b} | {nn} | {oo} |")
    return lines, ok_all
