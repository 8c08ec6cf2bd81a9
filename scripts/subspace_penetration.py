#!/usr/bin/env python3
"""How far a linear subspace lets a body into its run-time colliders.

Projects every frame of a scene's test sequences onto the leading PCA modes of its training
frames (the best any linear decoder of that size can do, in least squares) and measures how
deep the projected vertices go into the colliders the frames were simulated with: the largest
depth and the share of frames with a vertex deeper than the barrier distance. The reference
itself never enters a collider (IPC), so what this prints is the subspace's own penetration.

    python3 scripts/subspace_penetration.py out/poke/dataset --sizes 8,16,32,64 --dhat 1e-3

Reads the `positions`, `collider_shapes` and `collider_states` arrays of `train-*.npz` and
`test-*.npz` (numpy only).
"""
import argparse
import glob
import os

import numpy as np


def rotation(w):
    """The rotation matrix of the rotation vector `w` (Rodrigues)."""
    angle = np.linalg.norm(w)
    if angle < 1e-12:
        return np.eye(3)
    k = w / angle
    skew = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * skew + (1 - np.cos(angle)) * skew @ skew


def signed_distances(x, state, shape):
    """Signed distance of every vertex of `x` (n x 3) to one collider (negative inside)."""
    q = (x - state[:3]) @ rotation(state[3:6])
    code, a, b, c = shape
    if code == 0:
        return np.linalg.norm(q, axis=1) - a
    if code == 1:
        r = q.copy()
        r[:, 1] -= np.clip(q[:, 1], -b, b)
        return np.linalg.norm(r, axis=1) - a
    excess = np.abs(q) - np.array([a, b, c])
    return np.linalg.norm(np.maximum(excess, 0), axis=1) + np.minimum(excess.max(axis=1), 0)


def depth(x, states, shapes):
    """Largest depth of a vertex of `x` inside any collider (0 when none is inside)."""
    x = x.reshape(-1, 3)
    states = states.reshape(len(shapes), -1)
    return max(0.0, max(-signed_distances(x, s, sh).min() for s, sh in zip(states, shapes)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", help="a scene's dataset folder (train-*.npz, test-*.npz)")
    parser.add_argument("--sizes", default="8,16,32,64", help="PCA sizes, comma-separated")
    parser.add_argument("--dhat", type=float, default=1e-3, help="barrier distance (m)")
    args = parser.parse_args()
    train = sorted(glob.glob(os.path.join(args.dataset, "train-*.npz")))
    tests = sorted(glob.glob(os.path.join(args.dataset, "test-*.npz")))
    if not train or not tests:
        raise SystemExit(f"{args.dataset}: no train-*.npz or test-*.npz")
    frames = np.concatenate([np.load(f)["positions"].reshape(len(np.load(f)["positions"]), -1) for f in train])
    mean = frames.mean(axis=0)
    _, _, modes = np.linalg.svd(frames - mean, full_matrices=False)
    print("| PCA modes | largest depth (mm) | frames with a vertex deeper than dhat |")
    print("|---|---|---|")
    for k in [0] + [int(s) for s in args.sizes.split(",")]:
        depths = []
        for f in tests:
            d = np.load(f)
            positions = d["positions"].reshape(len(d["positions"]), -1)
            basis = modes[:k]
            for x, states in zip(positions, d["collider_states"]):
                projected = mean + (x - mean) @ basis.T @ basis if k > 0 else x
                depths.append(depth(projected, states, d["collider_shapes"]))
        depths = np.array(depths)
        label = "reference" if k == 0 else str(k)
        print(f"| {label} | {1e3 * depths.max():.2f} | {100 * (depths > args.dhat).mean():.1f}% |")


if __name__ == "__main__":
    main()
