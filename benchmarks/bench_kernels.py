"""Kernel micro-benchmark: interval and gradient evaluations per second on one core, compile times.

Run: python3 benchmarks/bench_kernels.py [--boxes N] [--repeats K]
Prints a Markdown table; figures are medians over K runs (the machines are shared and noisy).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import numpy as np

import implc
from implc import scene

SCENES = ("paper_blobs", "paper_sin4_sin8", "paper_sin3_sin4")


def median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def compile_times(expr, bounds, repeats):
    """(cold, cached) compile seconds: cold with the cache off, cached from a warm private cache."""
    saved = os.environ.get("IMPLC_CACHE_DIR")
    try:
        os.environ["IMPLC_CACHE_DIR"] = "off"
        cold = median_time(lambda: implc.compile(expr, bounds), max(1, repeats // 2))
        with tempfile.TemporaryDirectory() as tmp:
            os.environ["IMPLC_CACHE_DIR"] = tmp
            implc.compile(expr, bounds)
            cached = median_time(lambda: implc.compile(expr, bounds), repeats)
    finally:
        if saved is None:
            os.environ.pop("IMPLC_CACHE_DIR", None)
        else:
            os.environ["IMPLC_CACHE_DIR"] = saved
    return cold, cached


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--boxes", type=int, default=1 << 20)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    n = args.boxes
    rng = np.random.default_rng(0)
    print(f"{n} boxes of a 512³ grid's cell size per batch, one thread, medians of {args.repeats} runs\n")
    print("| scene | ops | interval M/s (kernel) | interval M/s (API) | gradient M/s | point M/s "
          "| compile cold ms | compile cached ms |")
    print("|---|---|---|---|---|---|---|---|")
    for name in SCENES:
        sc = scene.load(name)
        s = implc.compile(sc.surface, sc.bounds)
        lo = rng.uniform(-1, 1, (n, 3))
        hi = lo + 2 / 512
        out_lo, out_hi, values, grads = np.empty(n), np.empty(n), np.empty(n), np.empty((n, 3))
        raw_interval = median_time(lambda: s._interval(lo.ctypes.data, hi.ctypes.data, out_lo.ctypes.data,
                                                       out_hi.ctypes.data, n), args.repeats)
        api_interval = median_time(lambda: s.interval(lo, hi), args.repeats)
        raw_gradient = median_time(lambda: s._gradient(lo.ctypes.data, values.ctypes.data, grads.ctypes.data, n),
                                   args.repeats)
        raw_point = median_time(lambda: s._point(lo.ctypes.data, values.ctypes.data, n), args.repeats)
        cold, cached = compile_times(sc.surface, sc.bounds, args.repeats)
        print(f"| {name} | {len(s.tape)} | {n / raw_interval / 1e6:.1f} | {n / api_interval / 1e6:.1f} "
              f"| {n / raw_gradient / 1e6:.1f} | {n / raw_point / 1e6:.1f} | {cold * 1e3:.0f} | {cached * 1e3:.1f} |")


if __name__ == "__main__":
    main()
