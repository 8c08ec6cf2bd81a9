"""Case families for check_ipctk.py that target known weak spots of contact primitives, each
checked against an exact reference (rational arithmetic on the float inputs, or mpmath at
60 digits where a root is irrational) with ipctk's outcome beside ours:

- `ee-short-parallel`: edges of length 1e-4 .. 1e-1 at an angle of 1e-8 .. 1e-2 rad; edge b
  translates through edge a along their common normal (and along a by up to 0.1 of its
  length) from a start gap of 1e-9 .. 1e-2 of the length, crossing at a time in
  (0.05, 0.95); the whole configuration turned and moved to coordinates of size ~1. CCD
  against the exact time of impact (the first root in [0, 1] of the coplanarity polynomial
  at which the segments meet), and the distances at the start.
- `degenerate`: zero-length edges (point-edge 2D and 3D, either or both edges of an
  edge-edge pair) and zero-area triangles (collinear, two or three coincident vertices)
  with exactly degenerate coordinates. Reference: the distance to the nearest sub-primitive,
  and its gradient (any of the sub-primitives at that distance; gradients summed over
  coincident vertices, which may share it in any way).
- `distance-0`: coincident points, points on edges and triangles (interior, edge, vertex),
  edges crossing or touching, with dyadic coordinates so that the squared distance is
  exactly 0: everything must be finite, and the barrier gradient, normal force, tangent
  basis and friction must be zero where ipctk's are.
- `near-endpoint`: points 1e-12 .. 1e-3 from either endpoint of an edge (length 1e-3 .. 1),
  off its line (2D and 3D): point-edge distances against the exact ones.
- `ccd-degenerate`: a point passing exactly through a zero-length edge (2D, 3D) or a
  collinear / coincident-vertex triangle, a zero-length edge through an edge and an edge
  through a zero-length one, at t = 1/2 exactly (dyadic coordinates).

Distance errors are relative, |ours - exact| / exact (absolute where exact is 0); gradient
errors are max |ours - exact| / max |exact| per case. CCD cases whose exact start distance
is below the floor (`CCD_FLOOR_ULPS` eps of the largest coordinate) are left out of the
miss counts and counted apart; distances pass within `TOL` relative or within
`DISTANCE_FLOOR_ULPS` eps of the stencil's diameter.
"""

from fractions import Fraction

import mpmath
import numpy as np
import ipctk

# CCD cases whose exact start distance is below CCD_FLOOR_ULPS eps times the motion's largest
# coordinate magnitude (the library's `contact::ccd::additive::FLOOR_ULPS`) are counted apart
# from the misses: below it the gap is not represented by the rounded positions themselves.
CCD_FLOOR_ULPS = 16.0
# Distances pass within TOL relative of the exact one, or within DISTANCE_FLOOR_ULPS eps of
# the stencil's diameter (the largest distance between two of its vertices): every formula
# starts from coordinate differences, each rounded to half an ulp of itself, which alone
# moves a distance by that much (ipctk's errors are listed beside ours).
DISTANCE_FLOOR_ULPS = 8.0
EPS = np.finfo(float).eps
TOL = 1e-10
FAMILIES = ["ee-short-parallel", "degenerate", "distance-0", "near-endpoint", "ccd-degenerate"]
PREFIX = {"ee-short-parallel": "fam_eesp_", "degenerate": "fam_deg_", "distance-0": "fam_d0_",
          "near-endpoint": "fam_ne_", "ccd-degenerate": "fam_ccdd_"}
PAIRS = {"pp2": (2, 2), "pp3": (3, 2), "pe2": (2, 3), "pe3": (3, 3), "pt": (3, 4), "ee": (3, 4)}
IPCTK_DEGENERATE_TRIANGLE_CCD = 200  # ipctk's CCD of a degenerate triangle: 0.4 s a case
EPSX_REST = 1e-3  # degenerate edge pairs: the mollifier threshold of unit-length rest edges
mpmath.mp.dps = 60


def log_uniform(rng, lo, hi, n):
    return 10.0 ** rng.uniform(lo, hi, n)


def unit(rng, n, dim):
    v = rng.normal(size=(n, dim))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def rotations(rng, n):
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    return q * np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]


def dyadic(rng, shape, bits=10, scale=1.0):
    """Numbers k / 2^bits * scale (scale a power of two): sums and small multiples stay exact."""
    return rng.integers(-(2 ** bits), 2 ** bits + 1, shape) / 2.0 ** bits * scale


# ---- Exact geometry on the float inputs (Fractions; 2D points get z = 0) ----------------

def fr(v):
    return [Fraction(float(c)) for c in v] + [Fraction(0)] * (3 - len(v))


def sub(a, b):
    return [x - y for x, y in zip(a, b)]


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def comb(pts, w):
    """sum_k w[k] pts[k] for a dict of weights."""
    out = [Fraction(0)] * 3
    for k, wk in w.items():
        out = [o + wk * c for o, c in zip(out, pts[k])]
    return out


def clamp01(t):
    return min(max(t, Fraction(0)), Fraction(1))


def point_segment(pts, p, a, b):
    """Closest point of segment [a, b] (indices into pts) to pts[p]: (d2, weights of a side)."""
    e = sub(pts[b], pts[a])
    c = dot(e, e)
    t = Fraction(0) if c == 0 else clamp01(dot(sub(pts[p], pts[a]), e) / c)
    w = {a: 1 - t, b: t} if a != b else {a: Fraction(1)}
    diff = sub(pts[p], comb(pts, w))
    return dot(diff, diff), w


def candidates(key, pts):
    """Every (d2, weights of A, weights of B) that a sub-primitive or the whole pair attains;
    the exact distance is their minimum (closest features of convex hulls)."""
    out = []
    if key.startswith("pp"):
        diff = sub(pts[0], pts[1])
        return [(dot(diff, diff), {0: Fraction(1)}, {1: Fraction(1)})]
    if key.startswith("pe"):
        d2, w = point_segment(pts, 0, 1, 2)
        return [(d2, {0: Fraction(1)}, w)] + [(point_segment(pts, 0, a, a)[0], {0: Fraction(1)}, {a: Fraction(1)}) for a in (1, 2)]
    if key == "pt":
        p, t0 = pts[0], pts[1]
        u, v, r = sub(pts[2], t0), sub(pts[3], t0), sub(p, t0)
        n = cross(u, v)
        m = dot(n, n)
        if m != 0:
            # Barycentric coordinates of the projection (ratios of cross products).
            b = dot(cross(r, v), n) / m
            g = dot(cross(u, r), n) / m
            if b >= 0 and g >= 0 and b + g <= 1:
                w = {1: 1 - b - g, 2: b, 3: g}
                diff = sub(p, comb(pts, w))
                out.append((dot(diff, diff), {0: Fraction(1)}, w))
        for a, b_ in ((1, 2), (2, 3), (3, 1)):
            d2, w = point_segment(pts, 0, a, b_)
            out.append((d2, {0: Fraction(1)}, w))
        return out
    # Edge-edge: the lines' closest points if inside both segments, and the four
    # endpoint-to-segment pairs (the boundary of the parameter square).
    a0, b0 = pts[0], pts[2]
    u, w_, r = sub(pts[1], a0), sub(pts[3], b0), sub(b0, a0)
    n = cross(u, w_)
    m = dot(n, n)
    if m != 0:
        s = dot(cross(r, w_), n) / m
        t = dot(cross(r, u), n) / m
        if 0 <= s <= 1 and 0 <= t <= 1:
            wa, wb = {0: 1 - s, 1: s}, {2: 1 - t, 3: t}
            diff = sub(comb(pts, wa), comb(pts, wb))
            out.append((dot(diff, diff), wa, wb))
    for p in (0, 1):
        d2, w = point_segment(pts, p, 2, 3)
        out.append((d2, {p: Fraction(1)}, w))
    for p in (2, 3):
        d2, w = point_segment(pts, p, 0, 1)
        out.append((d2, w, {p: Fraction(1)}))
    return out


def gradient(pts, wa, wb, dim, nverts):
    """Gradient of |c_A - c_B|^2 at fixed weights (the envelope theorem: the distance's
    gradient wherever the closest points are unique)."""
    diff = sub(comb(pts, wa), comb(pts, wb))
    g = np.zeros((nverts, dim))
    for k, wk in wa.items():
        g[k] += [float(2 * wk * c) for c in diff[:dim]]
    for k, wk in wb.items():
        g[k] -= [float(2 * wk * c) for c in diff[:dim]]
    return g


def exact_distance(key, x):
    """Exact squared distance (Fraction) and the gradients of every sub-primitive attaining
    it (float arrays, vertices x dim)."""
    dim, nverts = PAIRS[key]
    pts = [fr(p) for p in x.reshape(nverts, dim)]
    cands = candidates(key, pts)
    best = min(c[0] for c in cands)
    grads = [gradient(pts, wa, wb, dim, nverts) for d2, wa, wb in cands if d2 == best]
    return best, grads, pts


def merge_coincident(g, pts):
    """Gradient rows summed over vertices at the same place within each primitive (a
    degenerate primitive may share the gradient among them in any way)."""
    out = g.copy()
    for i in range(len(pts)):
        for j in range(i):
            if pts[i] == pts[j]:
                out[j] += out[i]
                out[i] = 0.0
                break
    return out


def rel_err(ours, exact):
    exact = float(exact)
    if not np.isfinite(ours):
        return np.inf
    return abs(ours - exact) / exact if exact != 0 else abs(ours)


def grad_err(ours, grads, pts, merge):
    """Smallest error of the gradient `ours` (vertices x dim) over the accepted ones."""
    best = np.inf
    for g in grads:
        a, b = (merge_coincident(ours, pts), merge_coincident(g, pts)) if merge else (ours, g)
        if not np.all(np.isfinite(a)):
            return np.inf
        scale = np.max(np.abs(b))
        best = min(best, np.max(np.abs(a - b)) / (scale if scale > 0 else 1.0))
    return best


# ---- Exact time of impact of a static edge a and a linearly moving edge b --------------

def exact_ee_toi(x0, x1):
    """First t in [0, 1] at which the segments meet (mpmath, 60 digits): the roots of the
    coplanarity polynomial det[ua, b0(t) - a0, b1(t) - a0] (degree <= 2: a does not move)
    checked for the segments meeting there. None if they never meet."""
    p0 = [fr(p) for p in x0.reshape(4, 3)]
    p1 = [fr(p) for p in x1.reshape(4, 3)]
    assert p0[0] == p1[0] and p0[1] == p1[1]
    ua, a0 = sub(p0[1], p0[0]), p0[0]
    r0, r1 = sub(p0[2], a0), sub(p0[3], a0)
    d0, d1 = sub(p1[2], p0[2]), sub(p1[3], p0[3])
    det = lambda a, b, c: dot(a, cross(b, c))
    coef = [det(ua, d0, d1), det(ua, d0, r1) + det(ua, r0, d1), det(ua, r0, r1)]  # t^2, t, 1
    mp = mpmath.mpf
    c = [mp(k.numerator) / k.denominator for k in coef]
    if coef[0] != 0:
        disc = c[1] ** 2 - 4 * c[0] * c[2]
        if disc < 0:
            return None
        sq = mpmath.sqrt(disc)
        q = -(c[1] + (sq if c[1] >= 0 else -sq)) / 2
        roots = [q / c[0]] + ([c[2] / q] if q != 0 else [])
    elif coef[1] != 0:
        roots = [-c[2] / c[1]]
    else:
        return None  # always coplanar (parallel motion in the plane): not generated here
    m = lambda v: [mp(k.numerator) / k.denominator for k in v]
    ua_m, a0_m = m(ua), m(a0)
    for t in sorted(r for r in roots if 0 <= r <= 1):
        b0 = [p + t * d for p, d in zip(m(p0[2]), m(d0))]
        b1 = [p + t * d for p, d in zip(m(p0[3]), m(d1))]
        ub = [q - p for p, q in zip(b0, b1)]
        rr = [q - p for p, q in zip(a0_m, b0)]
        n = [ua_m[1] * ub[2] - ua_m[2] * ub[1], ua_m[2] * ub[0] - ua_m[0] * ub[2], ua_m[0] * ub[1] - ua_m[1] * ub[0]]
        nn = sum(k * k for k in n)
        cr = lambda a, b: [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
        s = sum(i * j for i, j in zip(cr(rr, ub), n)) / nn
        u = sum(i * j for i, j in zip(cr(rr, ua_m), n)) / nn
        if 0 <= s <= 1 and 0 <= u <= 1:
            return float(t)
    return None


# ---- Generators: positions (cases x dofs) per pair ------------------------------------

def gen_short_parallel(rng, n):
    """x0, x1 of edge pairs (a static, b translating through a); cases above and below the
    CCD floor are drawn until there are n above and n // 10 below."""
    m = 4 * n
    L = log_uniform(rng, -4, -1, m)
    lb = L * rng.uniform(0.5, 1.5, m)
    theta = log_uniform(rng, -8, -2, m)
    gap = L * log_uniform(rng, -9, -2, m)
    tstar = rng.uniform(0.05, 0.95, m)
    s, u = rng.uniform(0.15, 0.85, (2, m))
    loc = np.zeros((m, 4, 3))
    loc[:, 0, 0], loc[:, 1, 0] = -s * L, (1 - s) * L
    db = np.stack([np.cos(theta), np.sin(theta), np.zeros(m)], axis=1)
    loc[:, 2], loc[:, 3] = -(u * lb)[:, None] * db, ((1 - u) * lb)[:, None] * db
    # Velocity of b: through a along z, reaching it at t*, half of them sliding along a too.
    vel = np.zeros((m, 3))
    vel[:, 2] = -gap / tstar
    vel[:, 0] = np.where(rng.random(m) < 0.5, rng.uniform(-0.1, 0.1, m) * L, 0.0)
    rot, shift = rotations(rng, m), rng.uniform(-1, 1, (m, 1, 3))
    x0l, x1l = loc.copy(), loc.copy()
    x0l[:, 2:] -= tstar[:, None, None] * vel[:, None, :]
    x1l[:, 2:] += (1 - tstar)[:, None, None] * vel[:, None, :]
    x0 = np.einsum("cij,cvj->cvi", rot, x0l) + shift
    x1 = np.einsum("cij,cvj->cvi", rot, x1l) + shift
    x1[:, :2] = x0[:, :2]
    floor = ccd_floor(x0.reshape(m, -1), x1.reshape(m, -1))
    above = np.flatnonzero(gap >= 2 * floor)[:n]
    below = np.flatnonzero(gap < 0.5 * floor)[: n // 10]
    keep = np.concatenate([above, below])
    return x0[keep].reshape(len(keep), -1), x1[keep].reshape(len(keep), -1), L[keep], theta[keep]


def ccd_floor(x0, x1):
    """Per case (rows), the start distance below which CCD may miss."""
    return CCD_FLOOR_ULPS * EPS * np.maximum(np.abs(x0).max(axis=1), np.abs(x1).max(axis=1))


def diameters(xs, dim):
    """Per case (rows), the largest distance between two vertices of the stencil."""
    v = xs.reshape(len(xs), -1, dim)
    return np.sqrt(((v[:, :, None, :] - v[:, None, :, :]) ** 2).sum(-1)).max(axis=(1, 2))


def distance_ok(ours_d2, exact_d2, diameter):
    """Whether a squared distance is within the bound (see DISTANCE_FLOOR_ULPS)."""
    if not np.isfinite(ours_d2) or ours_d2 < 0:
        return False
    d, e = np.sqrt(ours_d2), np.sqrt(float(exact_d2))
    return abs(d - e) <= TOL * e + DISTANCE_FLOOR_ULPS * EPS * diameter


def gen_degenerate(rng, key, n):
    """Exactly degenerate primitives (dyadic coordinates on a line, or repeated vertices)
    and a point or edge 1e-6 .. 1 away."""
    dim, nverts = PAIRS[key]
    x = rng.uniform(-1, 1, (n, nverts, dim))
    kind = rng.integers(0, 3, n)
    if key.startswith("pe"):
        x[:, 2] = x[:, 1]
    elif key == "pt":
        c = dyadic(rng, (n, 3), 20)
        w = dyadic(rng, (n, 3), 8)
        k = rng.integers(-3, 4, (n, 3)).astype(float)
        k[:, 0] = 0
        k[kind == 1, 2] = k[kind == 1, 1]  # two coincident
        k[kind == 2] = 0  # all three coincident
        lines = c[:, None, :] + k[:, :, None] * w[:, None, :]
        x[:, 1:] = lines[:, rng.permutation(3)]
        # Points near the line or the point: 1e-6 .. 1 away.
        near = rng.random(n) < 0.5
        x[near, 0] = c[near] + rng.uniform(-3, 3, (near.sum(), 1)) * w[near] + unit(rng, near.sum(), 3) * log_uniform(rng, -6, 0, near.sum())[:, None]
    else:
        x[kind == 0, 1] = x[kind == 0, 0]
        x[kind == 1, 3] = x[kind == 1, 2]
        x[kind == 2, 1] = x[kind == 2, 0]
        x[kind == 2, 3] = x[kind == 2, 2]
    if key.startswith("pe"):
        near = rng.random(n) < 0.5
        x[near, 0] = x[near, 1] + unit(rng, near.sum(), dim) * log_uniform(rng, -6, 0, near.sum())[:, None]
    return x.reshape(n, -1)


def gen_distance0(rng, key, n):
    """Dyadic configurations with squared distance exactly 0."""
    dim, nverts = PAIRS[key]
    x = dyadic(rng, (n, nverts, dim), 8)
    t = dyadic(rng, (n, 4), 3) / 2 + 0.5  # k / 16 in [0, 1]
    kind = rng.integers(0, 3, n)
    if key.startswith("pp"):
        x[:, 1] = x[:, 0]
    elif key.startswith("pe"):
        # On the interior (kind 0), or on an endpoint.
        tt = np.where(kind == 0, t[:, 0], np.where(kind == 1, 0.0, 1.0))[:, None]
        x[:, 0] = x[:, 1] + tt * (x[:, 2] - x[:, 1])
    elif key == "pt":
        b, g = t[:, 0] / 2, t[:, 1] / 2  # b + g <= 1
        b = np.where(kind == 1, 0.0, b)  # on the edge t0-t2 (or a vertex if g is 0 or 1)
        g = np.where(kind == 2, 0.0, g)
        x[:, 0] = x[:, 1] + b[:, None] * (x[:, 2] - x[:, 1]) + g[:, None] * (x[:, 3] - x[:, 1])
    else:
        # Crossing interiors (kind 0), an endpoint of b on a (kind 1), touching endpoints.
        sa = t[:, 0][:, None]
        ta = np.where(kind == 0, t[:, 1], 0.0)[:, None]
        sa = np.where((kind == 2)[:, None], 1.0, sa)
        c = x[:, 0] + sa * (x[:, 1] - x[:, 0])
        ub = x[:, 3] - x[:, 2]
        x[:, 2] = c - ta * ub
        x[:, 3] = x[:, 2] + ub
    return x.reshape(n, -1)


def gen_near_endpoint(rng, key, n):
    """Points 1e-12 .. 1e-3 from e0 or e1 (edge length 1e-3 .. 1), off the line, mostly on
    the inner side (projection inside the edge)."""
    dim, _ = PAIRS[key]
    e0 = rng.uniform(-1, 1, (n, dim))
    d = unit(rng, n, dim)
    e1 = e0 + d * log_uniform(rng, -3, 0, n)[:, None]
    perp = unit(rng, n, dim)
    perp -= np.sum(perp * d, axis=1, keepdims=True) * d
    perp /= np.linalg.norm(perp, axis=1, keepdims=True)
    at_e1 = rng.random(n) < 0.5
    inward = np.where(at_e1, -1.0, 1.0)[:, None] * d
    phi = rng.uniform(-0.3, 1.0, n)[:, None] * np.pi / 2  # most with a component inward
    off = (np.cos(phi) * perp + np.sin(phi) * inward) * log_uniform(rng, -12, -3, n)[:, None]
    p = np.where(at_e1[:, None], e1, e0) + off
    return np.stack([p, e0, e1], axis=1).reshape(n, -1)


def gen_ccd_degenerate(rng, key, n):
    """x0, x1 with the moving primitive passing exactly through the degenerate one at t = 1/2
    (dyadic: x0 = xc + w, x1 = xc - w)."""
    dim, nverts = PAIRS[key]
    xc = dyadic(rng, (n, nverts, dim), 8)
    t = dyadic(rng, (n, 2), 3) / 2 + 0.5
    kind = rng.integers(0, 3, n)
    moving = [0]
    if key.startswith("pe"):
        xc[:, 2] = xc[:, 1]
        xc[:, 0] = xc[:, 1]
    elif key == "pt":
        k = rng.integers(-3, 4, (n, 3)).astype(float)
        k[:, 0] = 0
        k[kind == 1, 2] = k[kind == 1, 1]
        k[kind == 2] = 0
        w = dyadic(rng, (n, 3), 6)
        xc[:, 1:] = xc[:, 1:2] + k[:, :, None] * w[:, None, :]
        lo, hi = k.min(axis=1), k.max(axis=1)  # the point on the segment the vertices span
        xc[:, 0] = xc[:, 1] + (lo + t[:, 0] * (hi - lo))[:, None] * w
    else:
        # kind 0, 1: zero-length b through the interior of a; kind 2: a zero-length, b through it.
        c = xc[:, 0] + t[:, 0][:, None] * (xc[:, 1] - xc[:, 0])
        z = kind < 2
        xc[z, 2] = xc[z, 3] = c[z]
        z = kind == 2
        xc[z, 1] = xc[z, 0]
        ub = xc[z, 3] - xc[z, 2]
        xc[z, 2] = xc[z, 0] - t[z, 1][:, None] * ub
        xc[z, 3] = xc[z, 2] + ub
        moving = [2, 3]
    w = np.zeros_like(xc)
    step = dyadic(rng, (n, dim), 6) * 2.0 ** rng.integers(-6, 1, n)[:, None]
    for i in moving:
        w[:, i] = step
    x0, x1 = xc + w, xc - w
    return x0.reshape(n, -1), x1.reshape(n, -1)


# ---- Cases, references and the table --------------------------------------------------

CORE = ["d", "g", "h", "b", "bg", "bh", "N", "m", "mg", "mh"]
FRICTION = ["T", "f", "fg", "fh", "fhp"]
ZERO_AT_CONTACT = ["bg", "N", "T", "f", "fg", "fh"]  # distance-0: zero where ipctk's are


def primitive_family(rng, family, key, xs, reference_one, arrays, refs):
    """Adds one family's pair to the cases file (under the family's prefix) and its exact and
    ipctk references to `refs`."""
    dim, nverts = PAIRS[key]
    n = len(xs)
    exact = [exact_distance(key, x) for x in xs]
    d = np.array([float(e[0]) for e in exact])
    dhats = np.where(d > 0, np.sqrt(d) * rng.uniform(1.01, 4.0, n), log_uniform(rng, -3, -1, n))
    vs = rng.normal(size=xs.shape) * log_uniform(rng, -4, 0, n)[:, None]
    if key == "ee":
        epsx = np.full(n, EPSX_REST) if family != "ee-short-parallel" else \
            np.array([ipctk.edge_edge_mollifier_threshold(*[np.ascontiguousarray(p) for p in x.reshape(4, 3)]) for x in xs])
    else:
        epsx = None
    ipc, raised = [], 0
    for c in range(n):
        try:
            ipc.append(reference_one(key, xs[c], dhats[c], vs[c], None if epsx is None else epsx[c]))
        except RuntimeError:  # ipctk throws on some degenerate input: counted as NaN
            ipc.append(None)
            raised += 1
    proto = next(r for r in ipc if r is not None)
    ipc = {q: np.array([np.full(np.shape(proto[q]), np.nan) if r is None else r[q] for r in ipc]) for q in proto}
    pre = PREFIX[family] + key
    arrays.update({f"{pre}_x": xs, f"{pre}_dhat": dhats, f"{pre}_v": vs, f"{pre}_Nfr": np.nan_to_num(ipc["Nfr"])})
    if epsx is not None:
        arrays[f"{PREFIX[family]}ee_epsx"] = epsx
    refs[(family, key)] = {"kind": "primitive", "exact": exact, "ipc": ipc, "raised": raised,
                           "diameter": diameters(xs, dim)}


def ccd_family(family, key, x0, x1, toi, start, ccd_reference, arrays, refs, ipctk_cases=None):
    """Adds one family's CCD motions; ipctk runs on the first `ipctk_cases` of them (all if
    None: its CCD of a degenerate triangle takes 0.4 s a case)."""
    pre = PREFIX[family] + "ccd_" + key
    xi = np.zeros(len(x0))
    arrays.update({f"{pre}_x0": x0, f"{pre}_x1": x1, f"{pre}_xi": xi})
    k = len(x0) if ipctk_cases is None else min(ipctk_cases, len(x0))
    hit, itoi = np.full(len(x0), np.nan), np.full(len(x0), np.nan)
    hit[:k], itoi[:k] = ccd_reference(key, x0[:k], x1[:k], xi[:k])
    ipctk.set_logger_level(ipctk.LoggerLevel.off)  # (ccd_reference sets it to error)
    refs[(family, "ccd " + key)] = {"kind": "ccd", "pre": pre, "toi": toi, "start": start, "ipc": (hit, itoi),
                                    "floor": ccd_floor(x0, x1)}


def inputs(rng, n, families, reference_one, ccd_reference):
    """Arrays for the cases file and the references of the selected families (n cases per
    pair and family)."""
    arrays = {"eps_v": np.array([1e-2]), "mu": np.array([0.5]), "kappa": np.array([1.0])}
    refs = {}
    ipctk.set_logger_level(ipctk.LoggerLevel.off)  # no line per degenerate edge or failed PSD projection
    if "ee-short-parallel" in families:
        x0, x1, _, _ = gen_short_parallel(rng, n)
        toi = [exact_ee_toi(a, b) for a, b in zip(x0, x1)]
        primitive_family(rng, "ee-short-parallel", "ee", x0, reference_one, arrays, refs)
        start = np.sqrt([float(e[0]) for e in refs[("ee-short-parallel", "ee")]["exact"]])
        ccd_family("ee-short-parallel", "ee", x0, x1, toi, start, ccd_reference, arrays, refs)
    if "degenerate" in families:
        for key in ["pe2", "pe3", "pt", "ee"]:
            primitive_family(rng, "degenerate", key, gen_degenerate(rng, key, n), reference_one, arrays, refs)
    if "distance-0" in families:
        for key in PAIRS:
            xs = gen_distance0(rng, key, n)
            primitive_family(rng, "distance-0", key, xs, reference_one, arrays, refs)
            assert all(e[0] == 0 for e in refs[("distance-0", key)]["exact"]), key
    if "near-endpoint" in families:
        for key in ["pe2", "pe3"]:
            primitive_family(rng, "near-endpoint", key, gen_near_endpoint(rng, key, n), reference_one, arrays, refs)
    if "ccd-degenerate" in families:
        for key in ["pe2", "pe3", "pt", "ee"]:
            x0, x1 = gen_ccd_degenerate(rng, key, n)
            start = np.sqrt([float(exact_distance(key, x)[0]) for x in x0])
            # Contact exactly at t = 1/2 by construction (checked), first unless the motion
            # runs along the degenerate primitive's line (then left out as below the floor).
            mid = 0.5 * (x0 + x1)
            assert all(exact_distance(key, x)[0] == 0 for x in mid), key
            along = np.array([parallel_motion(key, a, b) for a, b in zip(x0, x1)])
            start[along] = 0.0
            ccd_family("ccd-degenerate", key, x0, x1, [0.5] * len(x0), start, ccd_reference, arrays, refs,
                       IPCTK_DEGENERATE_TRIANGLE_CCD if key == "pt" else None)
    return arrays, refs


def parallel_motion(key, x0, x1):
    """Whether the moving vertices' direction is parallel to the line of the degenerate
    primitive (or of edge b, moving through a zero-length a)."""
    dim, nverts = PAIRS[key]
    a, b = x0.reshape(nverts, dim), x1.reshape(nverts, dim)
    pad = lambda v: fr(v)
    mv = [i for i in range(nverts) if not np.array_equal(a[i], b[i])]
    w = sub(pad(b[mv[0]]), pad(a[mv[0]]))
    static = [pad(a[i]) for i in range(nverts) if i not in mv]
    if key == "ee" and mv == [2, 3]:
        static = [pad(a[2]), pad(a[3])]
    dirs = [sub(p, static[0]) for p in static[1:] if p != static[0]]
    return any(cross(w, e) == [0, 0, 0] for e in dirs)


def nan_cases(arrs, quantities, n):
    bad = np.zeros(n, dtype=bool)
    for q in quantities:
        if q in arrs:
            bad |= np.isnan(np.asarray(arrs[q]).reshape(n, -1)).any(axis=1)
    return int(bad.sum())


def table(refs, ours):
    """Markdown table of the families; returns (lines, all pass)."""
    lines = ["| family | pair | cases | NaN ours / ipctk | friction NaN ours / ipctk | d² rel. error ours / ipctk | "
             "gradient error ours / ipctk | not 0 where ipctk's is 0 | CCD misses ours / ipctk (below floor) | "
             "TOI after exact ours / ipctk | pass |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    ok_all, notes = True, []
    for (family, key), ref in refs.items():
        if ref["kind"] == "ccd":
            pre = ref["pre"]
            ohit, otoi = ours[f"{pre}_hit"] > 0.5, ours[f"{pre}_toi"]
            ihit_raw, itoi = ref["ipc"]
            ran = ~np.isnan(ihit_raw)
            ihit = ihit_raw > 0.5
            exact = np.array([np.nan if t is None else t for t in ref["toi"]])
            has = ~np.isnan(exact)
            above = ref["start"] >= ref["floor"]
            n, k = len(exact), int(ran.sum())
            sel = has & above
            miss_o, miss_i = (sel & ~ohit).sum(), (sel & ran & ~ihit).sum()
            below_o = (has & ~above & ~ohit).sum()
            late_o, late_i = (sel & ohit & (otoi > exact)).sum(), (sel & ran & ihit & (itoi > exact)).sum()
            zero_o, zero_i = (sel & ohit & (otoi == 0)).sum(), (sel & ran & ihit & (itoi == 0)).sum()
            nan_o, nan_i = int(np.isnan(otoi).sum()), int((ran & np.isnan(itoi)).sum())
            ok = miss_o == 0 and late_o == 0 and nan_o == 0 and zero_o == 0
            pos, ipos = sel & ohit & (otoi > 0), sel & ran & ihit & (itoi > 0)
            rmin = float(np.min(otoi[pos] / exact[pos])) if pos.any() else float("nan")
            imin = float(np.min(itoi[ipos] / exact[ipos])) if ipos.any() else float("nan")
            on = "" if k == n else f" (ipctk on the first {k})"
            lines.append(f"| {family} | {key} | {n}{on} | {nan_o} / {nan_i} (TOI) | - | - | - | - | {miss_o} / {miss_i} "
                         f"({(~above).sum()} below, {below_o} missed) | {late_o} / {late_i}; TOI 0: {zero_o} / {zero_i} | {'yes' if ok else 'NO'} |")
            notes.append(f"{family} {key}: {has.sum()} of {n} cases meet exactly, {sel.sum()} of them start above the floor; "
                         f"min TOI / exact over those found with TOI > 0: ours {rmin:.6f}, ipctk {imin:.6f}")
            ok_all &= bool(ok)
            continue
        pre = PREFIX[family] + key
        n = len(ref["exact"])
        dim, nverts = PAIRS[key]
        o = {q: ours[f"{pre}_{q}"] for q in CORE + FRICTION if f"{pre}_{q}" in ours}
        ipc = ref["ipc"]
        nan_o, nan_i = nan_cases(o, CORE, n), nan_cases(ipc, CORE, n)
        fnan_o, fnan_i = nan_cases(o, FRICTION, n), nan_cases(ipc, FRICTION, n)
        merge = family == "degenerate"
        derr_o = np.array([rel_err(o["d"][c], e[0]) for c, e in enumerate(ref["exact"])])
        derr_i = np.array([rel_err(ipc["d"][c], e[0]) for c, e in enumerate(ref["exact"])])
        gerr_o = np.array([grad_err(o["g"][c].reshape(nverts, dim), e[1], e[2], merge) for c, e in enumerate(ref["exact"])])
        gerr_i = np.array([grad_err(np.asarray(ipc["g"][c]).reshape(nverts, dim), e[1], e[2], merge) for c, e in enumerate(ref["exact"])])
        grad_checked = family in ("degenerate", "near-endpoint", "distance-0")
        within_o = np.array([distance_ok(o["d"][c], e[0], ref["diameter"][c]) for c, e in enumerate(ref["exact"])])
        within_i = np.array([distance_ok(ipc["d"][c], e[0], ref["diameter"][c]) for c, e in enumerate(ref["exact"])])
        relative = np.array([float(e[0]) > 0 and derr_o[c] <= 2 * TOL for c, e in enumerate(ref["exact"])])
        ok = nan_o == 0 and within_o.all() and (fnan_o == 0 or family == "degenerate")
        if grad_checked:
            ok &= gerr_o.max() <= TOL
        zero = "-"
        if family == "distance-0":
            differ = np.zeros(n, dtype=bool)
            for q in ZERO_AT_CONTACT:
                r, w = np.asarray(ipc[q]).reshape(n, -1), np.asarray(o[q]).reshape(n, -1)
                differ |= np.all(r == 0, axis=1) & ~np.all(w == 0, axis=1)
            zero = str(int(differ.sum()))
            ok &= differ.sum() == 0
        raised = f" ({ref['raised']} raised)" if ref["raised"] else ""
        which = lambda arrs: ", ".join(q for q in CORE + FRICTION if q in arrs and nan_cases(arrs, [q], n)) or "none"
        if nan_o + nan_i + fnan_o + fnan_i:
            notes.append(f"{family} {key}: NaN in ours: {which(o)}; in ipctk's: {which(ipc)}")
        if family == "distance-0":
            for q in ZERO_AT_CONTACT:
                r, w = np.asarray(ipc[q]).reshape(n, -1), np.asarray(o[q]).reshape(n, -1)
                c = int((np.all(r == 0, axis=1) & ~np.all(w == 0, axis=1)).sum())
                if c:
                    notes.append(f"{family} {key}: {q} not 0 where ipctk's is 0 in {c} cases")
        notes.append(f"{family} {key}: distance within the bound: ours {within_o.sum()} of {n}, ipctk {within_i.sum()}; "
                     f"within 1e-10 relative: ours {relative.sum()}")
        gcol = f"{gerr_o.max():.2e} / {gerr_i.max():.2e}" + ("" if grad_checked else " (not checked)")
        lines.append(f"| {family} | {key} | {n} | {nan_o} / {nan_i}{raised} | {fnan_o} / {fnan_i} | "
                     f"{derr_o.max():.2e} / {derr_i.max():.2e} | {gcol} | {zero} | - | - | {'yes' if ok else 'NO'} |")
        ok_all &= bool(ok)
    return lines + [""] + [f"- {x}" for x in notes], ok_all
