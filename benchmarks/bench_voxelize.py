"""Voxelization benchmark: the paper's scenes at one depth, per worker count, and the octree's cost.

Run: python3 benchmarks/bench_voxelize.py [--depth 9] [--workers 1,2] [--repeats 5]
Times are medians over the repeats, compile excluded (surfaces are compiled first).
"""

from __future__ import annotations

import argparse
import statistics
import time

import implc
from implc import scene
from implc.storage.octree import OctreeBuilder
from implc.subdivide import default_workers

SCENES = ("paper_blobs", "paper_sin4_sin8", "paper_sin3_sin4")
PAPER_SECONDS = {"paper_blobs": (88, 14), "paper_sin4_sin8": (111, 21), "paper_sin3_sin4": (71, 11)}


def timed(fn, repeats):
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def _build_octree(v):
    """Insert all voxels into a fresh octree (Fig. 2), as the octree backend does batch by batch."""
    builder = OctreeBuilder()
    builder.begin(v.depth, v.bounds)
    builder.reserve(len(v))
    builder.add(v.coords, v.normals)
    return builder.finish()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--depth", type=int, default=9)
    parser.add_argument("--workers", default=f"1,{default_workers()}")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    counts = [int(w) for w in args.workers.split(",")]
    n = 1 << args.depth
    print(f"{n}³, medians of {args.repeats}; paper: SGI Challenge, 1 and 7 processors\n")
    print("| scene | workers | seconds | yield t1/(n·tn) | voxels | interval evals | octree build / total | paper 1 / 7 proc |")
    print("|---|---|---|---|---|---|---|---|")
    for name in SCENES:
        sc = scene.load(name)
        s = implc.compile(sc.surface, sc.bounds)
        implc.voxelize(s, min(args.depth, 6))  # warm the runtime and caches
        t1 = None
        for w in counts:
            seconds, v = timed(lambda: implc.voxelize(s, args.depth, workers=w), args.repeats)
            build, _ = timed(lambda: _build_octree(v), args.repeats)
            t1 = seconds if w == 1 else t1
            yield_ = f"{t1 / (w * seconds):.0%}" if t1 else "-"
            share = build / seconds
            paper = PAPER_SECONDS[name]
            print(f"| {name} | {w} | {seconds:.3f} | {yield_} | {len(v)} | {v.stats.interval_evaluations} "
                  f"| {share:.0%} | {paper[0]} s / {paper[1]} s |")


if __name__ == "__main__":
    main()
