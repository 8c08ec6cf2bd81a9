"""Tet meshes of a closed surface with fTetWild (PyPI `pytetwild`) or TetGen (Debian's `tetgen`
program), written as MEDIT `.mesh` files that mochi's scene loader reads. Run by
scripts/tetwild.sh, which makes the virtual environment:

    python tetwild_run.py SURFACE.npz OUT.mesh [--edge-length L] [--epsilon E] [--threads N]
    python tetwild_run.py SURFACE.npz OUT.mesh --mesher tetgen [--edge-length L]
    python tetwild_run.py --self-check
    python tetwild_run.py --check-render NAME.mesh NAME.render.npz

SURFACE.npz: `vertices` (n, 3) float64, `faces` (m, 3) integer, the surface `mochi mesh`
repaired (welded, outward). `--edge-length` is the target tet edge length in the surface's
units (default: 1/20 of the bounding-box diagonal, fTetWild's default); `--epsilon` fTetWild's
envelope, the largest distance of the tet mesh's surface from the input's, relative to the
bounding-box diagonal (default 1e-3).

OUT.mesh: `Vertices` and `Tetrahedra` (reference 0), every tet positively oriented (tets the
mesher gives the other way round are flipped, and counted); written into a temporary file
beside OUT and renamed, so a failed run leaves no half-written mesh. One JSON line goes to
stdout: mesher, vertices, tets, seconds (the mesher's call alone, wall time), min_volume
(smallest tet volume over the mean), flipped (tets flipped), version.

--self-check: a sphere (an icosahedron subdivided three times, 1,280 triangles) meshed by
fTetWild at two edge lengths: the tets must be consistently oriented with no flat ones, the
mesh volume within 2% of the surface's, the finer mesh must have more vertices, and every input
vertex must lie within the envelope of the tet mesh's boundary, and no file may be left
behind. Prints
`tetwild self-check: N passed, F failed`.

--check-render: a `mochi mesh` output's render embedding against its tet mesh, read with numpy
alone: every weight within [-1e-9, 1 + 1e-9] and summing to one, every render vertex's rest
position rebuilt from its tet within its stored `distance`; prints the largest distance
relative to the diagonal and exits non-zero on a failure.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np


def load_surface(path):
    with np.load(path) as data:
        vertices = np.asarray(data["vertices"], dtype=np.float64)
        faces = np.asarray(data["faces"], dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise SystemExit(f"{path}: `vertices` must be (n, 3) and `faces` (m, 3)")
    if len(faces) == 0 or faces.min() < 0 or faces.max() >= len(vertices):
        raise SystemExit(f"{path}: `faces` empty or out of range")
    return vertices, faces


def diagonal(vertices):
    return float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))


def tet_volumes(points, tets):
    a, b, c, d = (points[tets[:, k]] for k in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def surface_volume(vertices, faces):
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def mesh_tetwild(vertices, faces, edge_length, epsilon, threads):
    import pytetwild

    # fTetWild writes a `__tracked_surface.stl` into the working directory: run it in a
    # temporary one.
    here = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        os.chdir(tmp)
        try:
            start = time.perf_counter()
            points, tets = pytetwild.tetrahedralize(
                vertices,
                faces.astype(np.int32),
                edge_length_abs=edge_length,
                epsilon=epsilon,
                num_threads=threads,
                quiet=True,
            )
            seconds = time.perf_counter() - start
        finally:
            os.chdir(here)
    return np.asarray(points, np.float64), np.asarray(tets, np.int64), seconds


def mesh_tetgen(vertices, faces, edge_length):
    """TetGen on an OFF file: -p (a piecewise linear complex), -q1.414 (radius-edge bound),
    -a (largest volume: a regular tet of the edge length), -Q (quiet)."""
    volume = edge_length**3 / (6.0 * np.sqrt(2.0))
    with tempfile.TemporaryDirectory() as tmp:
        off = os.path.join(tmp, "surface.off")
        with open(off, "w") as f:
            f.write(f"OFF\n{len(vertices)} {len(faces)} 0\n")
            np.savetxt(f, vertices, fmt="%.17g")
            np.savetxt(f, np.hstack([np.full((len(faces), 1), 3), faces]), fmt="%d")
        start = time.perf_counter()
        run = subprocess.run(
            ["tetgen", f"-pq1.414a{volume:.6g}Q", off], capture_output=True, text=True, timeout=600
        )
        seconds = time.perf_counter() - start
        if run.returncode != 0 or not os.path.exists(os.path.join(tmp, "surface.1.ele")):
            message = (run.stdout + run.stderr).strip().splitlines()
            raise RuntimeError("tetgen failed: " + (" | ".join(message[-3:]) or f"exit {run.returncode}"))
        node = np.loadtxt(os.path.join(tmp, "surface.1.node"), comments="#", skiprows=1, ndmin=2)
        ele = np.loadtxt(os.path.join(tmp, "surface.1.ele"), comments="#", skiprows=1, ndmin=2, dtype=np.int64)
        first = int(node[0, 0])
        return node[:, 1:4], ele[:, 1:5] - first, seconds


def oriented(points, tets):
    """Every tet positively oriented; the number flipped and the smallest volume over the mean."""
    volumes = tet_volumes(points, tets)
    negative = volumes < 0
    tets = tets.copy()
    tets[negative] = tets[negative][:, [0, 1, 3, 2]]
    volumes = np.abs(volumes)
    return tets, int(negative.sum()), float(volumes.min() / volumes.mean())


def largest_component(points, tets):
    """The tets of the largest connected piece by volume (tets sharing a vertex), and how many other
    pieces were dropped with how many vertices. A surface made of separate meshes that only
    touch (a character's head beside its body) meshes into islands that nothing holds
    together; the dropped pieces' render vertices then ride on the nearest kept tet."""
    n = int(tets.max()) + 1
    parent = np.arange(n)

    def find(a):
        root = a
        while parent[root] != root:
            root = parent[root]
        while parent[a] != root:
            parent[a], a = root, parent[a]
        return root

    for t in tets:
        r0 = find(t[0])
        for v in t[1:]:
            r = find(v)
            if r != r0:
                parent[r] = r0
    roots = np.array([find(v) for v in range(n)])
    piece_of = roots[tets[:, 0]]
    pieces, inverse = np.unique(piece_of, return_inverse=True)
    if len(pieces) == 1:
        return tets, 0, 0
    volumes = np.bincount(inverse, weights=np.abs(tet_volumes(points, tets)))
    kept = inverse == np.argmax(volumes)
    dropped = len(np.setdiff1d(np.unique(tets[~kept]), np.unique(tets[kept])))
    return tets[kept], int(len(pieces) - 1), int(dropped)


def write_medit(path, points, tets):
    """MEDIT text, 1-based, into a temporary file beside `path` and then renamed over it."""
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".tetwild-", suffix=".mesh", dir=directory)
    try:
        with os.fdopen(fd, "w") as f:
            f.write("MeshVersionFormatted 2\nDimension 3\n")
            f.write(f"Vertices\n{len(points)}\n")
            np.savetxt(f, np.hstack([points, np.zeros((len(points), 1))]), fmt="%.17g %.17g %.17g %d")
            f.write(f"Tetrahedra\n{len(tets)}\n")
            np.savetxt(f, np.hstack([tets + 1, np.zeros((len(tets), 1), np.int64)]), fmt="%d")
            f.write("End\n")
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def mesh(vertices, faces, mesher, edge_length, epsilon, threads):
    if mesher == "tetgen":
        points, tets, seconds = mesh_tetgen(vertices, faces, edge_length)
        query = subprocess.run(["dpkg-query", "-W", "-f", "${Version}", "tetgen"], capture_output=True, text=True)
        version = f"tetgen {query.stdout.strip() or 'unknown'}"
    else:
        import pytetwild

        points, tets, seconds = mesh_tetwild(vertices, faces, edge_length, epsilon, threads)
        version = f"pytetwild {pytetwild.__version__}"
    if len(tets) == 0:
        raise RuntimeError(f"{mesher} returned no tets")
    tets, flipped, min_volume = oriented(points, tets)
    tets, islands, island_vertices = largest_component(points, tets)
    used = np.unique(tets)
    if len(used) != len(points):
        # Keep only vertices that tets use (the scene loader refuses unused ones).
        remap = np.full(len(points), -1, np.int64)
        remap[used] = np.arange(len(used))
        points, tets = points[used], remap[tets]
    stats = dict(
        mesher=mesher,
        vertices=int(len(points)),
        tets=int(len(tets)),
        seconds=round(seconds, 3),
        min_volume=min_volume,
        flipped=flipped,
        islands_dropped=islands,
        island_vertices=island_vertices,
        version=version,
    )
    return points, tets, stats


def icosphere(subdivisions):
    t = (1.0 + 5.0**0.5) / 2.0
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    vertices = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(subdivisions):
        midpoint = {}

        def middle(a, b):
            key = (min(a, b), max(a, b))
            if key not in midpoint:
                p = vertices[a] + vertices[b]
                vertices.append(p / np.linalg.norm(p))
                midpoint[key] = len(vertices) - 1
            return midpoint[key]

        f = [g for a, b, c in f for g in ([a, middle(a, b), middle(c, a)], [b, middle(b, c), middle(a, b)],
                                           [c, middle(c, a), middle(b, c)], [middle(a, b), middle(b, c), middle(c, a)])]
    return np.array(vertices), np.array(f, np.int64)


def boundary_distance(points, tets, queries):
    """Distance from each query point to the nearest boundary vertex of the tet mesh (an upper
    bound of the distance to the boundary surface, enough for a sphere's fine mesh)."""
    faces = np.sort(np.vstack([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]], tets[:, [0, 1, 2]]]), axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    boundary = points[np.unique(unique[counts == 1])]
    return np.array([np.min(np.linalg.norm(boundary - q, axis=1)) for q in queries])


def self_check():
    vertices, faces = icosphere(3)
    passed, failed = 0, 0

    def check(ok, what):
        nonlocal passed, failed
        passed += bool(ok)
        failed += not ok
        print(("ok   " if ok else "FAIL ") + what)

    before = sorted(os.listdir("."))
    runs = {}
    for edge in (0.5, 0.25):
        points, tets, stats = mesh(vertices, faces, "ftetwild", edge, 1e-3, 0)
        runs[edge] = (points, tets, stats)
        print(json.dumps(stats))
        volume = float(tet_volumes(points, tets).sum())
        expected = surface_volume(vertices, faces)
        check(stats["flipped"] in (0, stats["tets"]), f"edge {edge}: tets consistently oriented ({stats['flipped']} flipped)")
        check(stats["min_volume"] > 1e-6, f"edge {edge}: no flat tet (smallest volume / mean {stats['min_volume']:.2e})")
        check(abs(volume / expected - 1.0) < 0.02, f"edge {edge}: volume {volume:.4f} within 2% of {expected:.4f}")
    check(runs[0.25][2]["vertices"] > runs[0.5][2]["vertices"], "a shorter edge gives more vertices")
    gap = boundary_distance(runs[0.25][0], runs[0.25][1], vertices).max() / diagonal(vertices)
    check(gap < 0.05, f"input vertices lie near the tet mesh's boundary (largest gap {gap:.2e} of the diagonal)")
    # Two spheres apart: the smaller piece is dropped and counted.
    small = 0.5 * vertices + np.array([3.0, 0.0, 0.0])
    apart = np.vstack([vertices, small]), np.vstack([faces, faces + len(vertices)])
    points, tets, stats = mesh(*apart, "ftetwild", 0.5, 1e-3, 0)
    big = runs[0.5][2]["vertices"]
    check(
        stats["islands_dropped"] == 1 and points[:, 0].max() < 1.5 and abs(stats["vertices"] - big) < 0.2 * big,
        f"two separate spheres: the smaller dropped ({stats['islands_dropped']} island of {stats['island_vertices']} vertices), "
        f"{stats['vertices']} vertices kept",
    )
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "sphere.mesh")
        write_medit(out, runs[0.5][0], runs[0.5][1])
        check(sorted(os.listdir(tmp)) == ["sphere.mesh"], "the mesh is written with no temporary file left")
    check(sorted(os.listdir(".")) == before, "the mesher leaves no file in the working directory")
    print(f"tetwild self-check: {passed} passed, {failed} failed")
    return failed == 0


def read_medit_vertices(path):
    lines = open(path).read().split("\n")
    start = [l.strip() for l in lines].index("Vertices")
    count = int(lines[start + 1])
    return np.array([[float(x) for x in l.split()[:3]] for l in lines[start + 2 : start + 2 + count]])


def check_render(mesh_path, render_path):
    points = read_medit_vertices(mesh_path)
    with np.load(render_path) as d:
        positions, weights, tet_vertices, distance = (d[k] for k in ("positions", "weights", "tet_vertices", "distance"))
    diag = diagonal(positions)
    rebuilt = (weights[:, :, None] * points[tet_vertices]).sum(axis=1)
    error = np.linalg.norm(rebuilt - positions, axis=1)
    ok = (
        weights.min() >= -1e-9
        and weights.max() <= 1 + 1e-9
        and np.allclose(weights.sum(axis=1), 1.0, atol=1e-12)
        and np.all(error <= distance + 1e-9 * diag)
    )
    print(
        f"{render_path}: {len(positions)} render vertices, weights in [{weights.min():.2e}, {weights.max():.6f}], "
        f"rest positions within their distance: {bool(np.all(error <= distance + 1e-9 * diag))}, "
        f"largest distance {distance.max() / diag:.2e} of the diagonal"
    )
    return bool(ok)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("surface", nargs="?")
    parser.add_argument("out", nargs="?")
    parser.add_argument("--mesher", choices=["ftetwild", "tetgen"], default="ftetwild")
    parser.add_argument("--edge-length", type=float)
    parser.add_argument("--epsilon", type=float, default=1e-3)
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--self-check", action="store_true")
    parser.add_argument("--check-render", action="store_true")
    args = parser.parse_args()
    if args.check_render:
        sys.exit(0 if check_render(args.surface, args.out) else 1)
    if args.self_check:
        sys.exit(0 if self_check() else 1)
    if not args.surface or not args.out:
        parser.error("SURFACE.npz and OUT.mesh are needed")
    vertices, faces = load_surface(args.surface)
    edge = args.edge_length or diagonal(vertices) / 20.0
    try:
        points, tets, stats = mesh(vertices, faces, args.mesher, edge, args.epsilon, args.threads)
    except Exception as e:  # the mesher's own failure, reported as one line
        print(f"{args.surface}: {args.mesher} failed: {e}", file=sys.stderr)
        sys.exit(1)
    write_medit(args.out, points, tets)
    print(json.dumps(stats))


if __name__ == "__main__":
    main()
