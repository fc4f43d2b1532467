"""The ``implc`` command."""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from . import scene as scenes
from .surface import compile as compile_surface

PAPER_SCENES = ("paper_blobs", "paper_sin4_sin8", "paper_sin3_sin4")


def _cells(bounds, n):
    """Lower and upper corners of every cell of an n³ grid over ``bounds``."""
    axes = [np.linspace(lo, hi, n + 1) for lo, hi in bounds]
    i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    idx = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
    lo = np.stack([axes[a][idx[:, a]] for a in range(3)], axis=1)
    hi = np.stack([axes[a][idx[:, a] + 1] for a in range(3)], axis=1)
    return lo, hi


def cmd_demo(args) -> int:
    n = args.grid
    print(f"implc demo: the paper's scenes, every cell of a {n}³ grid classified by the compiled enclosure")
    print(f"{'scene':<18}{'ops':>6}{'compile ms':>12}{'kept cells':>12}{'M boxes/s':>11}")
    for name in PAPER_SCENES:
        sc = scenes.load(name)
        t0 = time.perf_counter()
        surface = compile_surface(sc.surface, sc.bounds)
        compile_ms = (time.perf_counter() - t0) * 1e3
        lo, hi = _cells(surface.bounds, n)
        t0 = time.perf_counter()
        f_lo, f_hi = surface.interval(lo, hi)
        rate = len(lo) / (time.perf_counter() - t0) / 1e6
        kept = int(np.count_nonzero((f_lo <= 0) & (f_hi >= 0)))
        print(f"{name:<18}{len(surface.tape):>6}{compile_ms:>12.1f}{kept:>12}{rate:>11.1f}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="implc", description="symbolic implicit-surface compiler")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="compile the paper's three scenes and classify a grid of cells")
    demo.add_argument("--grid", type=int, default=64, help="cells per axis (default 64)")
    demo.set_defaults(run=cmd_demo)
    args = parser.parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
