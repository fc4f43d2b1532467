"""The ``implc`` command."""

from __future__ import annotations

import argparse
import sys
import time

from . import scene as scenes
from .surface import compile as compile_surface
from .voxelize import voxelize

PAPER_SCENES = ("paper_blobs", "paper_sin4_sin8", "paper_sin3_sin4")


def cmd_demo(args) -> int:
    n = 1 << args.depth
    print(f"implc demo: the paper's three scenes voxelized at {n}³ (paper, Table 1: 88 / 111 / 71 s on one "
          "SGI Challenge processor)")
    print(f"{'scene':<18}{'compile ms':>11}{'voxelize s':>11}{'voxels':>10}{'yield':>7}")
    for name in PAPER_SCENES:
        sc = scenes.load(name)
        t0 = time.perf_counter()
        surface = compile_surface(sc.surface, sc.bounds)
        compile_ms = (time.perf_counter() - t0) * 1e3
        t0 = time.perf_counter()
        voxels = voxelize(surface, args.depth, progress=sys.stderr.isatty())
        seconds = time.perf_counter() - t0
        print(f"{name:<18}{compile_ms:>11.0f}{seconds:>11.2f}{len(voxels):>10}{voxels.stats.parallel_yield:>7.0%}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="implc", description="symbolic implicit-surface compiler")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="voxelize the paper's three scenes")
    demo.add_argument("--depth", type=int, default=9, help="grid depth (default 9: 512³)")
    demo.set_defaults(run=cmd_demo)
    args = parser.parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
