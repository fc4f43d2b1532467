"""Of the voxels a model keeps whose corners do not change sign: how many hold a point where F = 0.

A model built by CSG from solids that share a face (fidget's colonnade: columns standing on a floor,
steps on steps) has F = 0 on that face with F > 0 (or F < 0) on both sides of it: the surface meets every
cell along the face, without a sign change at any corner. Voxels per sign-change cell then counts those
cells as spurious although no sound voxelizer may drop them. This script measures how many of a model's
extra voxels are of that kind: it samples F, by numpy's run of the .vm text (never implc's compiler),
on a 9³ grid in each such voxel and a 9² grid on every axis-aligned plane through it that the tape's
constants can place (c₁/c₂ for every pair of its constants, both signs), and counts the voxels where a sample is 0 to
within 1e-12 of F's range over the voxel, or the samples change sign. Example::

    python benchmarks/touching_cells.py colonnade --depth 8
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "support"))
import suite  # noqa: E402
import vm_sampling  # noqa: E402

import implc  # noqa: E402


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("model", help="a model's name in --models-dir (colonnade, bear, prospero, tanglecube)")
    p.add_argument("--models-dir", default=str(Path(__file__).resolve().parent.parent.parent / "shared" / "models"))
    p.add_argument("--depth", type=int, default=8)
    p.add_argument("--sample", type=int, default=1000, help="extra voxels sampled (at random)")
    args = p.parse_args(argv)
    path = Path(args.models_dir) / f"{args.model}.vm"
    rows = vm_sampling.parse(path.read_text())
    model = implc.load_vm(path)
    expr, _, extrude = suite._peer_surface(model, rows)
    s = implc.compile(expr, model.bounds)
    kept = implc.voxelize(s, args.depth, storage="coords").coords.astype(np.int64)
    changes = vm_sampling.sign_change_cells(vm_sampling.corner_values(rows, model.bounds, args.depth, extrude))
    extra = kept[~changes[tuple(kept.T)]]
    constants = np.array(sorted({float(a[0]) for _, op, a in rows if op == "const"} - {0.0}))
    planes = np.unique(np.concatenate([np.outer(constants, 1 / constants).ravel(),
                                       -np.outer(constants, 1 / constants).ravel(), [0.0]]))
    rng = np.random.default_rng(0)
    picked = extra[rng.choice(len(extra), min(args.sample, len(extra)), replace=False)]
    lo = np.array([b[0] for b in model.bounds])
    h = np.array([(b[1] - b[0]) for b in model.bounds]) / (1 << args.depth)
    t = np.linspace(0, 1, 9)
    grid = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)
    square = np.stack(np.meshgrid(t, t, indexing="ij"), -1).reshape(-1, 2)
    points, owner = [], []
    for index, cell in enumerate(picked):  # a 9³ grid, and a 9² grid on each plane that crosses the cell
        corner = lo + cell * h
        samples = [corner + grid * h]
        for a in range(3):
            others = [k for k in range(3) if k != a]
            for plane in planes[(planes >= corner[a]) & (planes <= corner[a] + h[a])]:
                q = np.empty((len(square), 3))
                q[:, a] = plane
                q[:, others] = corner[others] + square * h[others]
                samples.append(q)
        samples = np.concatenate(samples)
        points.append(samples)
        owner.append(np.full(len(samples), index))
    points, owner = np.concatenate(points), np.concatenate(owner)
    f = vm_sampling.evaluate(rows, *points.T)
    if extrude is not None:
        f = np.maximum(f, np.abs(points[:, 2]) - extrude)
    touching = crossing = 0
    for index in range(len(picked)):
        v = f[owner == index]
        span = np.nanmax(v) - np.nanmin(v)
        if np.nanmin(v) < 0 < np.nanmax(v):
            crossing += 1
        elif np.nanmin(np.abs(v)) <= 1e-12 * max(span, 1e-300):
            touching += 1
    n = len(picked)
    print("| model | depth | voxels | sign-change cells | extra voxels | sampled | F = 0 at a point | "
          "sign change inside | neither |")
    print("|---|---|---|---|---|---|---|---|---|")
    print(f"| {args.model} | {1 << args.depth}³ | {len(kept)} | {int(changes.sum())} | {len(extra)} | {n} | "
          f"{touching / n:.1%} | {crossing / n:.1%} | {(n - touching - crossing) / n:.1%} |")


if __name__ == "__main__":
    main()
