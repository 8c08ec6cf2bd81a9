"""The XPBD peer's library side: a case driven through Bender's PositionBasedDynamics (`pypbd`),
its constants and the measurements of its runs. How it is driven, the constraints per body kind
and the contact setup are in scripts/xpbd_run.py's docstring, which runs it."""

import ctypes
import math
import sys
import time

import numpy as np

PYPBD_VERSION = "2.2.2"
# Default unit scaling of masses and moduli (see the module docstring).
MASS_SCALE = 1e-12
# The library's threshold under which a constraint is skipped (eps in XPBD.cpp).
PBD_EPS = 1e-6
# A run stops once a vertex is this many rest diagonals off the reference (or non-finite).
DIVERGED = 10.0
# Bending stiffnesses tuned on test-01, 150 frames (the results are on test-00), before
# mass_scale; docs/notes/2026-11-28-xpbd-peer.md. Cloth: 0, no bending constraint (see the
# docstring).
DEFAULT_BENDING = {"cloth": 0.0, "rod": 10.0}
# Contact with the case's obstacles (the library's particle-rigid body contacts). tolerance None:
# the case's dhat. stiffness and velocity_iterations are the library's defaults
# (SimulationModel's contact stiffness 100, TimeStepController's maxIterationsV 5); restitution
# 0, the implicit-Euler reference's contacts being inelastic.
CONTACT_DEFAULTS = {"tolerance": None, "stiffness": 100.0, "stiffness_h": None, "velocity_iterations": 5,
                    "restitution": 0.0}


def scalar(d, key, default=None):
    if key not in d.files:
        return default
    v = d[key]
    return v.item() if v.shape == () else v


def load_case(path):
    d = np.load(path, allow_pickle=False)
    case = {key: d[key] for key in d.files}
    for key in ["kind", "material_model"]:
        case[key] = str(scalar(d, key, ""))
    for key in ["dt", "youngs", "poisson", "density", "thickness", "radius", "diagonal"]:
        case[key] = float(scalar(d, key, float("nan")))
    case["cells"] = case["cells"].astype(np.int64)
    case["handles"] = case["handles"].astype(np.int64)
    if case["kind"] not in ("solid", "cloth", "rod"):
        sys.exit(f"{path}: kind {case['kind']!r}: this peer drives solid, cloth and rod cases only")
    if not np.allclose(case["gravity"], [0.0, -9.81, 0.0]):
        sys.exit(f"{path}: gravity {case['gravity']} is not pypbd's fixed (0, -9.81, 0)")
    if "obstacle_kinds" in d.files:
        case["obstacle_kinds"] = [str(k) for k in d["obstacle_kinds"]]
        for key in ["contact_dhat", "contact_friction", "contact_epsv"]:
            case[key] = float(scalar(d, key))
        if case["kind"] != "solid":
            sys.exit(f"{path}: obstacles on a {case['kind']} case: this peer collides tet models only")
        if any(k != "box" for k in case["obstacle_kinds"]):
            sys.exit(f"{path}: obstacle kinds {case['obstacle_kinds']}: this peer drives boxes only")
        if np.any(case["obstacle_rotations"] != 0):
            sys.exit(f"{path}: a rotated obstacle box: this peer drives axis-aligned boxes only")
    return case


def has_obstacles(case):
    return "obstacle_kinds" in case and len(case["obstacle_kinds"]) > 0


def box_mesh(pbd, extents):
    """The library's vertex data and face mesh of a box of `extents` centred at the origin (its
    rigid body needs a mesh; collisions use the box's analytic distance field)."""
    vd = pbd.VertexData()
    half = 0.5 * np.asarray(extents, dtype=np.float64)
    for k in range(8):
        vd.addVertex(np.array([half[i] if (k >> i) & 1 else -half[i] for i in range(3)]))
    mesh = pbd.IndexedFaceMesh()
    mesh.initMesh(8, 18, 12)
    for q in ([0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]):
        mesh.addFace([q[0], q[1], q[2]])
        mesh.addFace([q[0], q[2], q[3]])
    mesh.buildNeighbors()
    return vd, mesh


def interior_hinges(tris):
    """(opposite0, opposite1, edge0, edge1) for every edge shared by two triangles."""
    faces = {}
    for t in tris:
        for a, b, c in ((t[0], t[1], t[2]), (t[1], t[2], t[0]), (t[2], t[0], t[1])):
            faces.setdefault((min(a, b), max(a, b)), []).append(c)
    return [(o[0], o[1], e[0], e[1]) for e, o in faces.items() if len(o) == 2]


def strands(edges, n):
    """Polylines (vertex lists from the root) of a rod case's edges, in the order of `edges`."""
    nxt, has_prev = {}, np.zeros(n, bool)
    for a, b in edges:
        nxt[int(a)] = int(b)
        has_prev[b] = True
    out = []
    for a, _ in edges:
        if not has_prev[a] and int(a) not in {s[0] for s in out}:
            s = [int(a)]
            while s[-1] in nxt:
                s.append(nxt[s[-1]])
            out.append(s)
    return out


def fem_threshold_fraction(case, positions, h, mass_scale):
    """Fraction of (tet, frame) pairs where the library's XPBD FEM tet constraint would be skipped
    (sum_i w_i |grad U/E|^2 + C^2 alpha < 1e-6), evaluated on `positions` (frames, n, 3) with the
    library's formulas (Green strain, StVK stress, mass and modulus scaled by `mass_scale`)."""
    rest, tets = case["rest"], case["cells"]
    nu = case["poisson"]
    mu, lam = 0.5 / (1 + nu), nu / (1 + nu) / (1 - 2 * nu)
    Dm = np.stack([rest[tets[:, i]] - rest[tets[:, 3]] for i in range(3)], axis=2)
    vol = np.abs(np.linalg.det(Dm)) / 6
    inv = np.linalg.inv(Dm)
    w = np.zeros(len(rest))
    free = case["mass"] > 0
    w[free] = 1.0 / (case["mass"][free] * mass_scale)
    w[case["handles"]] = 0.0
    alpha = 1.0 / (case["youngs"] * mass_scale * h * h)
    skipped = 0
    for x in positions:
        Ds = np.stack([x[tets[:, i]] - x[tets[:, 3]] for i in range(3)], axis=2)
        F = Ds @ inv
        Eg = 0.5 * (np.swapaxes(F, 1, 2) @ F - np.eye(3))
        tr = np.trace(Eg, axis1=1, axis2=2)
        S = 2 * mu * Eg + lam * tr[:, None, None] * np.eye(3)
        U = vol * (mu * np.sum(Eg * Eg, axis=(1, 2)) + 0.5 * lam * tr**2)
        H = vol[:, None, None] * (F @ S) @ np.swapaxes(inv, 1, 2)
        g = [H[:, :, 0], H[:, :, 1], H[:, :, 2]]
        g.append(-(g[0] + g[1] + g[2]))
        total = sum(w[tets[:, i]] * np.sum(g[i] ** 2, axis=1) for i in range(4)) + 2 * U * alpha
        skipped += int(np.sum(total < PBD_EPS))
    return skipped / (len(positions) * len(tets))


class Peer:
    """One pypbd simulation of a case at one setting."""

    def __init__(self, case, substeps, iterations, mass_scale=MASS_SCALE, bending=None, velocity_order=1,
                 contact=None):
        import pypbd as pbd

        self.pbd = pbd
        self.case = case
        self.substeps, self.iterations = substeps, iterations
        self.mass_scale = mass_scale
        kind = case["kind"]
        self.bending = DEFAULT_BENDING.get(kind, 0.0) if bending is None else bending
        rest, cells, n = case["rest"], case["cells"], len(case["rest"])
        E, nu = case["youngs"], case["poisson"]

        sim = pbd.Simulation.getCurrent()
        sim.initDefault()
        model = sim.getModel()
        self.sim, self.model = sim, model
        ts = sim.getTimeStep()
        ts.setValueUInt(pbd.TimeStepController.NUM_SUB_STEPS, 1)
        ts.setValueUInt(pbd.TimeStepController.MAX_ITERATIONS, iterations)
        obstacles = has_obstacles(case)
        self.contact = dict(CONTACT_DEFAULTS, **(contact or {})) if obstacles else None
        velocity_iterations = self.contact["velocity_iterations"] if obstacles else 0
        ts.setValueUInt(pbd.TimeStepController.MAX_ITERATIONS_V, velocity_iterations)
        # 0: first-order velocity update v = (x - x_old) / h (the library's default), 1: second order.
        ts.setValueInt(pbd.TimeStepController.VELOCITY_UPDATE_METHOD, velocity_order - 1)
        self.h = case["dt"] / substeps
        pbd.TimeManager.getCurrent().setTimeStepSize(self.h)

        points = [np.array(p, dtype=np.float64) for p in rest]
        if kind == "solid":
            tets = cells.copy()
            x = rest[tets]
            signed = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])
            flip = signed < 0  # the library's inversion test expects positive orientation
            tets[flip] = tets[flip][:, [0, 1, 3, 2]]
            if not nu <= 0.49:
                sys.exit(f"Poisson ratio {nu} > 0.49: pypbd's FEM tet constraint skips every tet")
            # testMesh: the library puts the tet model's vertices into its collision detection
            # (a collision object without geometry, tested against the boxes' distance fields).
            tm = model.addTetModel(points, tets.ravel().tolist(), testMesh=obstacles)
            assert tm.getIndexOffset() == 0
            model.addSolidConstraints(tm, 3, E * mass_scale, nu, E * mass_scale, False, False)
            self.constraint = (
                f"solid: XPBD FEM tet (StVK, Green strain; addSolidConstraints method 3) on {len(tets)} tets,"
                f" E {E:g} Pa, nu {nu:g}; masses and E scaled by {mass_scale:g}"
                f" (pypbd's 1e-6 skip threshold)"
            )
        elif kind == "cloth":
            tm = model.addTriangleModel(points, cells.ravel().tolist())
            assert tm.getIndexOffset() == 0
            t = case["thickness"]
            area = 0.5 * np.linalg.norm(np.cross(rest[cells[:, 1]] - rest[cells[:, 0]], rest[cells[:, 2]] - rest[cells[:, 0]]), axis=1)
            share = {}
            for tri, a in zip(cells, area):
                for i, j in ((0, 1), (1, 2), (2, 0)):
                    e = (min(tri[i], tri[j]), max(tri[i], tri[j]))
                    share[e] = share.get(e, 0.0) + a / 3
            for (a, b), ae in share.items():
                length2 = float(np.sum((rest[a] - rest[b]) ** 2))
                k = 2 * E * t / (1 - nu) * ae / length2
                model.addDistanceConstraint_XPBD(int(a), int(b), k * mass_scale)
            hinges = interior_hinges(cells)
            if self.bending > 0:
                for o0, o1, e0, e1 in hinges:
                    model.addIsometricBendingConstraint_XPBD(int(o0), int(o1), int(e0), int(e1), self.bending * mass_scale)
            bending = (f"XPBD isometric bending on {len(hinges)} hinges, stiffness {self.bending:g}"
                       if self.bending > 0 else "no bending constraint")
            self.constraint = (
                f"cloth: XPBD distance on {len(share)} edges, k_e = 2 E t / (1 - nu) A_e / |e|^2"
                f" (E {E:g} Pa, nu {nu:g}, t {t:g} m); {bending}; masses and stiffnesses scaled by {mass_scale:g}"
            )
        else:
            r = case["radius"]
            pd = model.getParticles()
            for p in points:
                pd.addVertex(p)
            edges = cells
            for a, b in edges:
                length = float(np.linalg.norm(rest[a] - rest[b]))
                model.addDistanceConstraint_XPBD(int(a), int(b), E * math.pi * r * r / length * mass_scale)
            bends = 0
            if self.bending > 0:
                for s in strands(edges, n):
                    for i in range(1, len(s) - 1):
                        model.addDistanceConstraint_XPBD(s[i - 1], s[i + 1], self.bending * mass_scale)
                        bends += 1
            self.constraint = (
                f"rod: XPBD distance on {len(edges)} edges, k = E pi r^2 / |e| (E {E:g} Pa, r {r:g} m);"
                f" bending: XPBD distance across {bends} interior vertices, stiffness {self.bending:g} N/m"
                f" (tuned); masses and stiffnesses scaled by {mass_scale:g}"
            )

        pd = model.getParticles()
        assert pd.getNumberOfParticles() == n, (pd.getNumberOfParticles(), n)
        self.pd = pd
        mass = case["mass"] * mass_scale
        is_handle = np.zeros(n, bool)
        is_handle[case["handles"]] = True
        for i in range(n):
            pd.setMass(i, 0.0 if is_handle[i] else float(mass[i]))
            pd.setPosition(i, case["initial"][i])
            pd.setVelocity(i, np.zeros(3))
        # A writable view of the library's position array (see the module docstring).
        view = np.asarray(pd.getVertices())
        assert view.shape == (n, 3) and view.dtype == np.float64 and view.strides == (24, 8)
        buf = (ctypes.c_double * (3 * n)).from_address(view.__array_interface__["data"][0])
        self.x = np.frombuffer(buf, dtype=np.float64).reshape(n, 3)
        probe = case["handles"][0] if len(case["handles"]) else 0
        saved = self.x[probe].copy()
        self.x[probe] = saved + 0.25
        assert np.array_equal(np.asarray(pd.getPosition(int(probe))).ravel(), saved + 0.25)
        self.x[probe] = saved
        self.boxes = []
        if obstacles:
            self._add_obstacles(tm)
        model.initConstraintGroups()

    def _add_obstacles(self, tm):
        """Each of the case's boxes as a static rigid body (mass 0) with the library's analytic
        box distance field as its collision object; the moving ones are placed before every
        substep (`_place_boxes`)."""
        pbd, case, c = self.pbd, self.case, self.contact
        cd = self.sim.getTimeStep().getCollisionDetection()
        tolerance = c["tolerance"] if c["tolerance"] is not None else case["contact_dhat"]
        cd.setTolerance(tolerance)
        # stiffness_h: the stiffness as a multiple of 1 / h (h the substep), instead of a number.
        stiffness = c["stiffness_h"] / self.h if c["stiffness_h"] is not None else c["stiffness"]
        self.model.setContactStiffnessParticleRigidBody(stiffness)
        # A contact's friction coefficient is the sum of its two bodies' (DistanceFieldCollisionDetection),
        # its restitution the product.
        tm.setFrictionCoeff(case["contact_friction"])
        tm.setRestitutionCoeff(c["restitution"])
        centres = case["obstacle_centres"]
        self.keep = []
        for k, extents in enumerate(case["obstacle_extents"]):
            # The body's mesh only bounds the box for the broad phase (the collision test is the
            # analytic distance field of `extents`). The library moves the mesh of a body of mass 0
            # never, and the binding's `getGeometry` returns a copy (pybind11's default for a
            # reference), so a moving box's mesh spans its whole path from the start.
            sweep = np.abs(centres[:, k] - centres[0, k]).max(axis=0)
            vd, mesh = box_mesh(pbd, extents + 2 * sweep)
            rb = self.model.addRigidBody(1.0, vd, mesh, centres[0, k], np.identity(3), np.ones(3))
            rb.setMass(0.0)
            rb.setFrictionCoeff(0.0)
            rb.setRestitutionCoeff(1.0)
            # The distance query's world-to-box transform is the identity rotation about the centre.
            assert np.allclose(rb.getTransformationR(), np.identity(3)) and np.allclose(rb.getTransformationV1(), 0)
            index = len(self.model.getRigidBodies()) - 1
            local = rb.getGeometry().getVertexDataLocal()
            self.keep.append(local)  # the collision object keeps a pointer into it
            cd.addCollisionBox(index, pbd.CollisionObject.RigidBodyCollisionObjectType, local, 0, local.size(),
                               np.asarray(extents, dtype=np.float64), False, False)
            moving = bool(np.any(sweep > 0))
            self.boxes.append((rb, k, moving))
        assert cd.getTolerance() == tolerance
        self.tolerance = tolerance
        moving = sum(m for _, _, m in self.boxes)
        self.contact_text = (
            f"{len(self.boxes)} boxes ({moving} moving, placed before every substep) as static rigid bodies"
            f" with the library's box distance field (DistanceFieldCollisionDetection.addCollisionBox),"
            f" tet vertices tested against them (addTetModel testMesh); collision tolerance {tolerance:g} m"
            f" (the case's dhat {case['contact_dhat']:g}), friction {case['contact_friction']:g},"
            f" restitution {c['restitution']:g}, contact stiffness {stiffness:g}"
            + (f" ({c['stiffness_h']:g} / h)" if c["stiffness_h"] is not None else "") + ","
            f" {c['velocity_iterations']} velocity iterations")
        self.constraint += "; contact: " + self.contact_text

    def _place_boxes(self, f, fraction, h):
        """Moves the moving boxes to where they are `fraction` of the way through frame f
        (linear between the frame's centres), with the velocity that takes them there from the
        previous substep; the library's contact solve uses the box's velocity."""
        centres = self.case["obstacle_centres"]
        for rb, k, moving in self.boxes:
            if not moving:
                continue
            a, b = centres[f, k], centres[f + 1, k]
            x = a + fraction * (b - a)
            rb.setVelocity((b - a) / (h * self.substeps))
            rb.setPosition(x)
            rb.updateInverseTransformation()

    def run(self, frames=None, diverged=None):
        """Simulates `frames` frames (default: all of the case's targets); stops early when
        `diverged(frame, positions)` says so, leaving NaN after that frame."""
        case, S = self.case, self.substeps
        targets, handles = case["targets"], case["handles"]
        frames = len(targets) - 1 if frames is None else frames
        step = self.sim.getTimeStep().step
        model = self.model
        positions = np.empty((frames + 1, len(self.x), 3))
        positions[0] = self.x
        step_seconds = np.empty(frames)
        solver_seconds = np.empty(frames)
        cpu_seconds = np.empty(frames)
        fractions = (np.arange(1, S + 1) / S)[:, None, None]
        clock, cpu = time.perf_counter, time.thread_time
        for f in range(frames):
            a, b = targets[f], targets[f + 1]
            sub = a + fractions * (b - a)  # (S, k, 3): handle positions at the end of each substep
            solver = 0.0
            c0 = cpu()
            t0 = clock()
            for s in range(S):
                self.x[handles] = sub[s]
                if self.boxes:
                    self._place_boxes(f, (s + 1) / S, self.h)
                t1 = clock()
                step(model)
                solver += clock() - t1
            step_seconds[f] = clock() - t0
            cpu_seconds[f] = cpu() - c0
            solver_seconds[f] = solver
            positions[f + 1] = self.x
            if diverged is not None and diverged(f + 1, positions[f + 1]):
                positions[f + 2 :] = np.nan
                step_seconds[f + 1 :] = np.nan
                solver_seconds[f + 1 :] = np.nan
                cpu_seconds[f + 1 :] = np.nan
                break
        self.cpu_seconds = cpu_seconds
        return positions, step_seconds, solver_seconds


def errors(case, positions):
    ref = case["reference"][: len(positions)]
    return 100.0 * np.linalg.norm(positions - ref, axis=2).mean(axis=1) / case["diagonal"]
