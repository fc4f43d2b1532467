"""What a modelled part costs per surface cell, against a single sphere: the library's enclosures are as
tight as its primitives allow when a part of many operations costs about what a sphere costs per voxel.

The part is built from ``implc.shapes`` with ``--operations`` library calls (a rounded plate, a smooth union
with a row of ribs and a polar array of bosses, holes drilled through): each call counted once, however
many SymPy nodes it makes. Both are compiled once (not timed), then voxelized at ``--depth`` in turns,
``--repeats`` times; the table gives the median CPU seconds (all threads) and wall seconds, the voxels
(cells the surface may cross) and the CPU microseconds per voxel, beside a sphere on each engine and the
part's plate (a rounded box: its most expensive primitive) alone. Example::

    python benchmarks/part_cost.py --depth 9 --repeats 5
"""

from __future__ import annotations

import argparse
import statistics
import time

import sympy

import implc
from implc import shapes


def part(operations: int):
    """A part of ``operations`` library calls: (expression, calls made)."""
    calls = 0

    def count(value, n=1):
        nonlocal calls
        calls += n
        return value

    plate = count(shapes.rounded_box((0.8, 0.5, 0.1), 0.04))
    features = []
    while calls + 4 <= operations - 2:  # each feature: a primitive and a move; a hole also its difference
        k = len(features)
        if k % 2 == 0:
            rib = count(shapes.box((0.03, 0.4, 0.12)))
            features.append(count(shapes.translate(rib, (-0.7 + 0.1 * (k % 15), 0, 0.15))))
        else:
            boss = count(shapes.capped_cylinder(0.05, 0.3))
            angle = sympy.pi * k / 12
            features.append(count(shapes.translate(boss, (0.3 * sympy.cos(angle), 0.3 * sympy.sin(angle), 0.1))))
    body = count(shapes.smooth_union(0.02, plate, count(shapes.union(*features))))
    holes = []
    while calls + 2 < operations:
        hole = count(shapes.capped_cylinder(0.02, 1))
        holes.append(count(shapes.translate(hole, (-0.75 + 0.05 * len(holes), -0.45, 0))))
    return count(shapes.difference(body, *holes)), calls


def timed(surface, depth):
    cpu, wall = time.process_time(), time.perf_counter()
    voxels = implc.voxelize(surface, depth)
    return time.process_time() - cpu, time.perf_counter() - wall, len(voxels)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--depth", type=int, default=9)
    parser.add_argument("--operations", type=int, default=50)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    expr, calls = part(args.operations)
    cases = {"sphere": implc.compile(shapes.sphere(0.8)),
             "sphere, tape engine": implc.compile(shapes.sphere(0.8), engine="tape"),
             "its plate alone": implc.compile(shapes.rounded_box((0.8, 0.5, 0.1), 0.04)),
             f"part of {calls} operations": implc.compile(expr)}
    results: dict = {name: [] for name in cases}
    for name, surface in cases.items():
        timed(surface, max(args.depth - 3, 3))  # warm: kernels and engines loaded
    for _ in range(args.repeats):
        for name, surface in cases.items():
            results[name].append(timed(surface, args.depth))
    print(f"voxelization at {1 << args.depth}³, medians of {args.repeats} (interleaved)")
    print(f"| {'surface':<24} | {'tape':>5} | {'voxels':>10} | {'CPU s':>7} | {'wall s':>7} | {'CPU µs/voxel':>12} "
          f"| {'engine':>6} |")
    print(f"|{'-' * 26}|{'-' * 7}|{'-' * 12}|{'-' * 9}|{'-' * 9}|{'-' * 14}|{'-' * 8}|")
    per_voxel = {}
    for name, runs in results.items():
        cpu = statistics.median(r[0] for r in runs)
        wall = statistics.median(r[1] for r in runs)
        count = runs[0][2]
        per_voxel[name] = cpu / count * 1e6
        print(f"| {name:<24} | {len(cases[name].tape):>5} | {count:>10,} | {cpu:7.3f} | {wall:7.3f} | "
              f"{per_voxel[name]:12.3f} | {cases[name].engine:>6} |")
    sphere, tape_sphere, plate, modelled = per_voxel.values()
    print(f"per voxel, the part costs {modelled / sphere:.2f}× the sphere (engines chosen as compile does), "
          f"{modelled / tape_sphere:.2f}× the sphere on the tape engine, {modelled / plate:.2f}× its plate alone")


if __name__ == "__main__":
    main()
