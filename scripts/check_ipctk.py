"""Compares mochi's contact primitives with IPC's toolkit (ipctk) on random cases.

Generates random cases per primitive pair (general positions and near-degenerate ones:
nearly parallel edges, points near planes, edges and vertices, nearly coincident points;
10,000 per pair by default, 1.6 times that for point-edge and edge-edge so that their
well-conditioned subsets alone reach 10,000), evaluates them with ipctk, runs the
`contact_cases` example of mochi-sim on the same cases, and prints a table.

Error per case and quantity: max_i |ours_i - ref_i| / max(1, max_i |ref_i|) over the
entries i of that case's array (scalar, vector or matrix); for friction Hessians the
denominator also includes mu N f1(|tau|)/|tau| max |P^T P|, the size of the two terms that
cancel along a sliding direction. A row passes when its worst error over the
well-conditioned cases (see `conditioned`) is at most 1e-10; the worst error over all cases
is printed beside it. A second table compares the times of impact of additive CCD on
random motions of every pair (`ipctk_ccd.py` beside this script). A third checks families
of hard cases against exact references (`ipctk_families.py`: short nearly parallel edges
with their CCD, degenerate primitives, distance 0, points near an edge's endpoints, CCD of
degenerate primitives), n cases per family and pair.

Usage: check_ipctk.py CONTACT_CASES_BINARY WORK_DIR [--cases N] [--seed S]
       [--only primitives|ccd|families] [--families NAME,...]
"""

import argparse
import os
import subprocess
import sys

import numpy as np
import ipctk

import ipctk_ccd
import ipctk_families

TOL = 1e-10
EPS_V = 1e-2
MU = 0.5
KAPPA = 1.0

# Pair key -> (dim, vertices).
PAIRS = {"pp2": (2, 2), "pp3": (3, 2), "pe2": (2, 3), "pe3": (3, 3), "pt": (3, 4), "ee": (3, 4)}


def log_uniform(rng, lo, hi, n):
    return 10.0 ** rng.uniform(lo, hi, n)


def unit(rng, n, dim):
    v = rng.normal(size=(n, dim))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def gen_pp(rng, n, dim):
    x = rng.uniform(-1, 1, (n, 2, dim))
    near = rng.random(n) < 0.5  # nearly coincident points
    x[near, 1] = x[near, 0] + unit(rng, near.sum(), dim) * log_uniform(rng, -8, -2, near.sum())[:, None]
    return x.reshape(n, -1)


def gen_pe(rng, n, dim):
    x = rng.uniform(-1, 1, (n, 3, dim))
    kind = rng.integers(0, 3, n)
    e0, e1 = x[:, 1], x[:, 2]
    # Points near the edge's line, inside and past its ends.
    m = kind == 1
    t = rng.uniform(-0.5, 1.5, m.sum())[:, None]
    x[m, 0] = e0[m] + t * (e1[m] - e0[m]) + unit(rng, m.sum(), dim) * log_uniform(rng, -8, -2, m.sum())[:, None]
    # Points near an endpoint.
    m = kind == 2
    end = np.where(rng.random(m.sum()) < 0.5, 1, 2)
    x[m, 0] = x[m, end] + unit(rng, m.sum(), dim) * log_uniform(rng, -8, -2, m.sum())[:, None]
    return x.reshape(n, -1)


def gen_pt(rng, n):
    x = rng.uniform(-1, 1, (n, 4, 3))
    kind = rng.integers(0, 4, n)
    t0, t1, t2 = x[:, 1], x[:, 2], x[:, 3]
    normal = np.cross(t1 - t0, t2 - t0)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    # Points just above or below the plane, over the triangle or beside it.
    m = kind == 1
    a, b = rng.uniform(-0.5, 1.5, (2, m.sum(), 1))
    h = log_uniform(rng, -8, -2, m.sum())[:, None] * np.where(rng.random((m.sum(), 1)) < 0.5, -1, 1)
    x[m, 0] = t0[m] + a * (t1[m] - t0[m]) + b * (t2[m] - t0[m]) + h * normal[m]
    # Points near an edge.
    m = kind == 2
    i = rng.integers(0, 3, m.sum())
    j = (i + 1) % 3
    s = rng.uniform(-0.2, 1.2, m.sum())[:, None]
    rows = np.arange(n)[m]
    p = x[rows, 1 + i] + s * (x[rows, 1 + j] - x[rows, 1 + i])
    x[m, 0] = p + unit(rng, m.sum(), 3) * log_uniform(rng, -8, -2, m.sum())[:, None]
    # Points near a vertex.
    m = kind == 3
    i = rng.integers(1, 4, m.sum())
    x[m, 0] = x[np.arange(n)[m], i] + unit(rng, m.sum(), 3) * log_uniform(rng, -8, -2, m.sum())[:, None]
    return x.reshape(n, -1)


def gen_ee(rng, n):
    x = rng.uniform(-1, 1, (n, 4, 3))
    kind = rng.integers(0, 4, n)
    # Nearly parallel edges (angle 1e-8 .. 1e-2 rad), offset and shifted along each other.
    m = kind == 1
    k = m.sum()
    ua = x[m, 1] - x[m, 0]
    d = ua / np.linalg.norm(ua, axis=1, keepdims=True)
    perp = np.cross(d, unit(rng, k, 3))
    perp /= np.linalg.norm(perp, axis=1, keepdims=True)
    angle = log_uniform(rng, -8, -2, k)[:, None]
    db = np.cos(angle) * d + np.sin(angle) * perp
    gap = unit(rng, k, 3) * log_uniform(rng, -6, 0, k)[:, None]
    x[m, 2] = x[m, 0] + rng.uniform(-0.5, 0.5, (k, 1)) * ua + gap
    x[m, 3] = x[m, 2] + rng.uniform(0.3, 2.0, (k, 1)) * db
    # Crossing edges at a small gap.
    m = kind == 2
    k = m.sum()
    ua = x[m, 1] - x[m, 0]
    ub = x[m, 3] - x[m, 2]
    nrm = np.cross(ua, ub)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    s, t = rng.uniform(0.05, 0.95, (2, k, 1))
    pa = x[m, 0] + s * ua
    shift = pa + nrm * log_uniform(rng, -8, -2, k)[:, None] - (x[m, 2] + t * ub)
    x[m, 2] += shift
    x[m, 3] += shift
    # An endpoint of b near the interior or an end of a.
    m = kind == 3
    k = m.sum()
    s = rng.uniform(-0.2, 1.2, (k, 1))
    x[m, 2] = x[m, 0] + s * (x[m, 1] - x[m, 0]) + unit(rng, k, 3) * log_uniform(rng, -8, -2, k)[:, None]
    return x.reshape(n, -1)


def split(x, dim):
    return [np.ascontiguousarray(v) for v in x.reshape(-1, dim)]


# Closest-feature type -> (ipctk collision class, stencil vertices it acts on), as ipctk's
# collision builder turns a pair into its lower-dimensional collision.
def typed_collision(key, ty):
    vv = lambda *i: (ipctk.VertexVertexNormalCollision(0, 1), list(i))
    ev = lambda *i: (ipctk.EdgeVertexNormalCollision(0, 0), list(i))
    if key.startswith("pp"):
        return vv(0, 1)
    if key.startswith("pe"):
        return [vv(0, 1), vv(0, 2), ev(0, 1, 2)][ty]
    if key == "pt":
        return [vv(0, 1), vv(0, 2), vv(0, 3), ev(0, 1, 2), ev(0, 2, 3), ev(0, 3, 1),
                (ipctk.FaceVertexNormalCollision(0, 0), [0, 1, 2, 3])][ty]
    raise ValueError(key)


def scatter(values, verts, dim, n, hessian):
    idx = np.array([v * dim + i for v in verts for i in range(dim)])
    if hessian:
        full = np.zeros((n, n))
        full[np.ix_(idx, idx)] = values
    else:
        full = np.zeros(n)
        full[idx] = values
    return full


def reference(key, xs, dhats, vs, epsx):
    """ipctk's values of every quantity on the cases of one pair (arrays over the cases)."""
    rows = [reference_one(key, x, dhats[c], vs[c], None if epsx is None else epsx[c]) for c, x in enumerate(xs)]
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}


def reference_one(key, x, dhat, vel, epsx):
    """ipctk's values on one case of `key`: positions x, activation distance dhat,
    velocities vel, edge-edge mollifier threshold epsx."""
    dim, _ = PAIRS[key]
    friction = ipctk.FrictionPotential(EPS_V)
    barrier = ipctk.ClampedLogBarrier()
    out = {}
    v = split(x, dim)
    n = len(x)
    if key.startswith("pp"):
        d, g, h, ty = ipctk.point_point_distance(*v), ipctk.point_point_distance_gradient(*v), ipctk.point_point_distance_hessian(*v), 0
        own, tangential = ipctk.VertexVertexNormalCollision(0, 1), ipctk.VertexVertexTangentialCollision
    elif key.startswith("pe"):
        ty = int(ipctk.point_edge_distance_type(*v))
        d, g, h = ipctk.point_edge_distance(*v), ipctk.point_edge_distance_gradient(*v), ipctk.point_edge_distance_hessian(*v)
        own, tangential = ipctk.EdgeVertexNormalCollision(0, 0), ipctk.EdgeVertexTangentialCollision
    elif key == "pt":
        ty = int(ipctk.point_triangle_distance_type(*v))
        d, g, h = ipctk.point_triangle_distance(*v), ipctk.point_triangle_distance_gradient(*v), ipctk.point_triangle_distance_hessian(*v)
        own, tangential = ipctk.FaceVertexNormalCollision(0, 0), ipctk.FaceVertexTangentialCollision
    else:
        ty = int(ipctk.edge_edge_distance_type(*v))
        d, g, h = ipctk.edge_edge_distance(*v), ipctk.edge_edge_distance_gradient(*v), ipctk.edge_edge_distance_hessian(*v)
        own, tangential = ipctk.EdgeEdgeNormalCollision(0, 1, epsx), ipctk.EdgeEdgeTangentialCollision
        out["m"] = ipctk.edge_edge_mollifier(*v, epsx)
        out["mg"] = ipctk.edge_edge_mollifier_gradient(*v, epsx)
        out["mh"] = ipctk.edge_edge_mollifier_hessian(*v, epsx)
    out.update(d=d, type=ty, g=g, h=h)
    # Barrier b(d^2, dhat^2) with stiffness one, on the collision ipctk would build.
    potential = ipctk.BarrierPotential(dhat, 1.0)
    if key == "ee":
        collision, verts = own, [0, 1, 2, 3]  # typed by ipctk itself (AUTO), mollified
    else:
        collision, verts = typed_collision(key, ty)
    xsub = np.concatenate([v[i] for i in verts])
    out["b"] = potential(collision, xsub)
    out["bg"] = scatter(potential.gradient(collision, xsub), verts, dim, n, False)
    out["bh"] = scatter(potential.hessian(collision, xsub), verts, dim, n, True)
    out["N"] = ipctk.barrier_force_magnitude(d, barrier, dhat, KAPPA)
    # Friction on the pair's own stencil: lagged frame, normal force and potential.
    t = tangential(own, x, ipctk.BarrierPotential(dhat, KAPPA))
    t.mu_s = t.mu_k = MU
    t.mu_s_effective_lagged = t.mu_k_effective_lagged = MU
    out["T"] = t.tangent_basis
    if not key.startswith("pp"):
        out["cp"] = np.atleast_1d(t.closest_point)
        out["cpj"] = np.atleast_2d(t.compute_closest_point_jacobian(x))
    out["G"] = t.relative_velocity_jacobian()
    out["Nfr"] = t.normal_force_magnitude
    out["f"] = friction(t, vel)
    out["fg"] = friction.gradient(t, vel)
    out["fh"] = friction.hessian(t, vel, ipctk.PSDProjectionMethod.NONE)
    try:
        out["fhp"] = friction.hessian(t, vel, ipctk.PSDProjectionMethod.CLAMP)
    except RuntimeError:  # "unable to project matrix onto positive semi-definite cone" (a NaN Hessian)
        out["fhp"] = np.full_like(out["fh"], np.nan)
    return out


def case_errors(ours, ref, scale=None):
    """max |ours - ref| / max(1, max |ref|, scale) per case."""
    n = ref.shape[0]
    o, r = ours.reshape(n, -1), ref.reshape(n, -1)
    denom = np.maximum(1.0, np.max(np.abs(r), axis=1))
    if scale is not None:
        denom = np.maximum(denom, scale)
    return np.max(np.abs(o - r), axis=1) / denom


def conditioned(key, xs):
    """Cases whose quantities are well-conditioned in f64 (the others lose accuracy in any
    implementation: unclamped closest points of nearly parallel lines, the tangent plane of a
    point almost on an edge's line)."""
    dim, verts = PAIRS[key]
    x = xs.reshape(len(xs), verts, dim)
    if dim == 2:
        x = np.concatenate([x, np.zeros((len(xs), verts, 1))], axis=2)
    if key == "ee":
        u, w = x[:, 1] - x[:, 0], x[:, 3] - x[:, 2]
        return np.sum(np.cross(u, w) ** 2, axis=1) / (np.sum(u * u, axis=1) * np.sum(w * w, axis=1)) >= 1e-3
    if key.startswith("pe"):
        r, e = x[:, 0] - x[:, 1], x[:, 2] - x[:, 1]
        return np.linalg.norm(np.cross(r, e), axis=1) / (np.linalg.norm(r, axis=1) * np.linalg.norm(e, axis=1)) >= 1e-4
    return np.ones(len(xs), dtype=bool)


def friction_hessian_scale(key, inputs, ref):
    """mu N f1(|tau|)/|tau| max |P^T P| per case, P = T^T Gamma: the size of the two terms
    whose difference is the friction Hessian (they cancel along tau when sliding)."""
    p = np.einsum("cki,ckn->cin", ref["T"].reshape(len(ref["T"]), PAIRS[key][0], -1), ref["G"])
    tau = np.linalg.norm(np.einsum("cin,cn->ci", p, inputs[f"{key}_v"]), axis=1)
    f1x = np.array([ipctk.smooth_friction_f1_over_x(t, EPS_V) for t in tau])
    ptp = np.abs(np.einsum("cin,cim->cnm", p, p)).reshape(len(tau), -1).max(axis=1)
    return MU * np.abs(ref["Nfr"]) * f1x * ptp


def primitive_cases(rng, n):
    """Random cases of every primitive pair and scalar function, and ipctk's values."""
    inputs = {"eps_v": np.array([EPS_V]), "mu": np.array([MU]), "kappa": np.array([KAPPA])}
    # Point-edge and edge-edge get more cases so that their well-conditioned subsets alone
    # hold at least `n`.
    more = int(1.6 * n)
    gens = {
        "pp2": lambda: gen_pp(rng, n, 2),
        "pp3": lambda: gen_pp(rng, n, 3),
        "pe2": lambda: gen_pe(rng, more, 2),
        "pe3": lambda: gen_pe(rng, more, 3),
        "pt": lambda: gen_pt(rng, n),
        "ee": lambda: gen_ee(rng, more),
    }
    refs = {}
    for key, gen in gens.items():
        xs = gen()
        dim, verts = PAIRS[key]
        # Activation distance 1.01 .. 4 times the reference distance, so every barrier acts.
        d = np.array([ipctk.point_point_distance(*split(x, dim)) if key.startswith("pp") else 0.0 for x in xs])
        if not key.startswith("pp"):
            fn = {"pe2": ipctk.point_edge_distance, "pe3": ipctk.point_edge_distance,
                  "pt": ipctk.point_triangle_distance, "ee": ipctk.edge_edge_distance}[key]
            d = np.array([fn(*split(x, dim)) for x in xs])
        dhats = np.sqrt(d) * rng.uniform(1.01, 4.0, len(xs))
        vs = rng.normal(size=xs.shape) * log_uniform(rng, -4, 0, len(xs))[:, None]
        epsx = np.array([ipctk.edge_edge_mollifier_threshold(*split(x, 3)) for x in xs]) if key == "ee" else None
        inputs[f"{key}_x"], inputs[f"{key}_dhat"], inputs[f"{key}_v"] = xs, dhats, vs
        if epsx is not None:
            inputs["ee_epsx"] = epsx
        refs[key] = reference(key, xs, dhats, vs, epsx)
        inputs[f"{key}_Nfr"] = refs[key]["Nfr"]
    # Scalar barrier and friction smoothing; stiffness.
    bar_dhat = log_uniform(rng, -6, 0, n)
    bar_d = bar_dhat * rng.uniform(1e-6, 1.2, n)
    inputs["bar_d"], inputs["bar_dhat"] = bar_d, bar_dhat
    refs["bar"] = np.array([[ipctk.barrier(a, b), ipctk.barrier_first_derivative(a, b), ipctk.barrier_second_derivative(a, b)]
                            for a, b in zip(bar_d, bar_dhat)])
    fr_y = rng.uniform(1e-6, 3 * EPS_V, n)
    inputs["fr_y"] = fr_y
    refs["fr"] = np.array([[ipctk.smooth_friction_f0(y, EPS_V), ipctk.smooth_friction_f1(y, EPS_V), ipctk.smooth_friction_f2(y, EPS_V),
                            ipctk.smooth_friction_f1_over_x(y, EPS_V), ipctk.smooth_friction_f2_x_minus_f1_over_x3(y, EPS_V)] for y in fr_y])
    k, m = 1000, 30
    ks_in = np.stack([log_uniform(rng, -1, 1, k), log_uniform(rng, -5, -1, k), log_uniform(rng, -2, 2, k), log_uniform(rng, 0, 12, k)], axis=1)
    ks_ge = rng.normal(size=(k, m)) * log_uniform(rng, -3, 6, k)[:, None]
    ks_gb = rng.normal(size=(k, m)) * log_uniform(rng, -3, 3, k)[:, None]
    ks_gb[: k // 10] = 0.0
    ks_ge[k // 10: k // 5] = -ks_gb[k // 10: k // 5] * log_uniform(rng, 0, 8, k // 10)[:, None]
    inputs["ks_in"], inputs["ks_ge"], inputs["ks_gb"] = ks_in, ks_ge, ks_gb
    barrier = ipctk.ClampedLogBarrier()
    refs["ks"] = np.array([ipctk.initial_barrier_stiffness(p[0], barrier, p[1], p[2], ge, gb, p[3]) for p, ge, gb in zip(ks_in, ks_ge, ks_gb)])
    diag = log_uniform(rng, -1, 1, k)
    lim = (1e-9 * diag) ** 2
    ku_in = np.stack([lim * rng.uniform(0, 2, k), lim * rng.uniform(0, 2, k), log_uniform(rng, 3, 5, k), log_uniform(rng, 1, 4, k), diag, np.full(k, 1e-9)], axis=1)
    inputs["ku_in"] = ku_in
    refs["ku"] = np.array([ipctk.update_barrier_stiffness(*p) for p in ku_in])
    return inputs, refs


def primitive_table(inputs, refs, ours):
    """Prints the primitives' table; returns whether every row passes."""
    rows = []
    labels = {"d": "distance", "g": "distance gradient", "h": "distance Hessian", "b": "barrier", "bg": "barrier gradient",
              "bh": "barrier Hessian", "m": "mollifier", "mg": "mollifier gradient", "mh": "mollifier Hessian",
              "T": "tangent basis", "cp": "closest point", "cpj": "closest point Jacobian", "G": "relative velocity Jacobian",
              "N": "normal force", "f": "friction", "fg": "friction gradient", "fh": "friction Hessian",
              "fhp": "friction Hessian (PSD)"}
    for key in PAIRS:
        ref = refs[key]
        cond = conditioned(key, inputs[f"{key}_x"])
        differ = ours[f"{key}_type"].astype(int) != ref["type"]
        rows.append((key, "closest-feature type", len(differ), f"{differ.sum()} differ", int(cond.sum()), f"{differ[cond].sum()} differ",
                     not differ[cond].any()))
        if differ.any():
            # Where the types differ (edges parallel to rounding), ours must not be the farther pair.
            closer = ours[f"{key}_d"][differ] <= ref["d"][differ] * (1 + 1e-12)
            rows.append((key, "distance <= ipctk's where types differ", int(differ.sum()), f"{closer.sum()} of {differ.sum()}",
                         int(differ.sum()), f"{closer.sum()} of {differ.sum()}", bool(closer.all())))
        for q, label in labels.items():
            if q not in ref:
                continue
            scale = friction_hessian_scale(key, inputs, ref) if q in ("fh", "fhp") else None
            err = case_errors(ours[f"{key}_{q}"], ref[q], scale)
            worst, worst_cond = float(np.max(err)), float(np.max(err[cond]))
            rows.append((key, label, len(err), f"{worst:.2e}", int(cond.sum()), f"{worst_cond:.2e}", worst_cond <= TOL))
    for key, label in [("bar", "b, b', b'' (scalar)"), ("fr", "f0, f1, f2, f1/x, (f2 x - f1)/x^3"), ("ks", "initial stiffness, max"), ("ku", "stiffness update")]:
        err = case_errors(ours[key], refs[key])
        worst = float(np.max(err))
        rows.append((key, label, len(err), f"{worst:.2e}", len(err), f"{worst:.2e}", worst <= TOL))
    print("| pair | quantity | cases | worst error, all cases | well-conditioned cases | worst error, well-conditioned | pass |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]} | {r[5]} | {'yes' if r[6] else 'NO'} |")
    failed = [r for r in rows if not r[6]]
    print(f"\n{len(rows) - len(failed)} of {len(rows)} rows pass: worst error over the well-conditioned cases <= {TOL:g}, "
          "error = max |ours - ref| / max(1, max |ref|) per case (friction Hessians: over max(1, max |ref|, mu N f1(|tau|)/|tau| max |P^T P|)).")
    print("Well-conditioned: ee with sin^2(angle between the edges) >= 1e-3 (outside the mollifier ramp at rest); pe with sin(angle between p - e0 and the edge) >= 1e-4; every other case.")
    return not failed


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("binary")
    ap.add_argument("work")
    ap.add_argument("--cases", type=int, default=10000)
    ap.add_argument("--seed", type=int, default=2020)
    ap.add_argument("--only", choices=["primitives", "ccd", "families"], help="check only the primitives, CCD or the families")
    ap.add_argument("--families", default=",".join(ipctk_families.FAMILIES),
                    help="comma-separated families to check (default all: " + ", ".join(ipctk_families.FAMILIES) + ")")
    args = ap.parse_args()
    families = [f for f in args.families.split(",") if f]
    unknown = set(families) - set(ipctk_families.FAMILIES)
    if unknown:
        ap.error(f"unknown families {sorted(unknown)}")
    rng = np.random.default_rng(args.seed)
    n = args.cases
    os.makedirs(args.work, exist_ok=True)
    inputs, refs, ccd_refs, fam_refs = {}, {}, {}, {}
    if args.only in (None, "primitives"):
        inputs, refs = primitive_cases(rng, n)
    if args.only in (None, "ccd"):
        ccd_inputs, ccd_refs = ipctk_ccd.inputs(rng, n)
        inputs.update(ccd_inputs)
    if args.only in (None, "families"):
        # Their own generator: the other tables' cases stay those of earlier seeds.
        fam_rng = np.random.default_rng([args.seed, 1])
        fam_inputs, fam_refs = ipctk_families.inputs(fam_rng, n, families, reference_one, ipctk_ccd.reference)
        inputs.update({k: v for k, v in fam_inputs.items() if k not in inputs})

    in_path, out_path = os.path.join(args.work, "cases.npz"), os.path.join(args.work, "ours.npz")
    np.savez(in_path, **inputs)
    subprocess.run([args.binary, in_path, out_path], check=True)
    ours = np.load(out_path)

    ok = True
    if refs:
        ok &= primitive_table(inputs, refs, ours)
    if ccd_refs:
        lines, ccd_ok = ipctk_ccd.table(ccd_refs, ours)
        print("\nAdditive CCD (default parameters: conservative rescaling 0.9), ours against ipctk's:\n")
        print("\n".join(lines))
        print(f"\nCCD passes: {'yes' if ccd_ok else 'NO'} (ipctk only = 0, ours after ipctk's = 0, "
              f"min ours / ipctk >= {ipctk_ccd.MIN_RATIO} over the cases both find with ipctk's time > 0).")
        ok &= ccd_ok
    if fam_refs:
        lines, fam_ok = ipctk_families.table(fam_refs, ours)
        print(f"\nFamilies against exact references (CCD floor {ipctk_families.CCD_FLOOR_ULPS:g} eps of the coordinates; "
              f"distances within {ipctk_families.TOL:g} relative or {ipctk_families.DISTANCE_FLOOR_ULPS:g} eps of the "
              f"stencil's diameter):\n")
        print("\n".join(lines))
        print(f"\nFamilies pass: {'yes' if fam_ok else 'NO'} (no NaN; distances, and gradients of degenerate, distance-0 and "
              "near-endpoint cases, within the bound; at distance 0 zero where ipctk's is zero; no CCD miss or time after the "
              "exact one above the floor).")
        ok &= fam_ok
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
