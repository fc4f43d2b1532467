"""implc's benchmark suite (``implc bench``): the paper's Table 1, baselines, growth, tightness, kernels.

Every figure is measured in this run on this machine and printed, never asserted. Times are medians over
``--repeats`` runs; speedups are ratios of figures from the same run. Results go to stdout as Markdown
and to ``--out`` (default ``./implc-bench``) as ``latest.md`` and ``latest.json`` with the machine
described.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import implc
from implc.common.threads import default_workers
from implc.engines.surface import ALL_TERMS
from implc.files import scene

CHROMIUM_ARGS = ["--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--disable-background-networking", "--disable-component-update", "--no-first-run"]
"""Headless Chromium drawing WebGL2 in software (SwiftShader), as the viewer's benchmarks run it."""

PAPER_SCENES = ("paper_blobs", "paper_sin4_sin8", "paper_sin3_sin4")
PAPER_TABLE1 = {  # seconds on the SGI Challenge, 1..7 slaves (Stolte & Kaufman, Table 1)
    "paper_blobs": [88, 45, 34, 26, 21, 20, 14],
    "paper_sin4_sin8": [111, 58, 38, 31, 28, 24, 21],
    "paper_sin3_sin4": [71, 35, 23, 17, 16, 14, 11],
}
ORACLE = Path(__file__).resolve().parents[1] / "tests" / "support"
"""Where numpy's run of .vm text lives (``vm_sampling``): the tests' independent truth, shared with the
benchmarks' missed-cell counts."""


# -- measuring -------------------------------------------------------------------------------------
def median_time(fn, repeats):
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def machine() -> dict:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import llvmlite
    import sympy
    return {"cpu": cpu, "cores": default_workers(), "python": platform.python_version(),
            "llvmlite": llvmlite.__version__, "numpy": np.__version__, "sympy": sympy.__version__,
            "implc": implc.__version__, "platform": platform.platform(), "date": time.strftime("%Y-%m-%d %H:%M")}


def compiled(name):
    sc = scene.load(name)
    return implc.compile(sc.surface, sc.bounds)


def corner_grid(bounds, depth, k):
    """The (n+1)² corners of z-slab k of the grid, as (points, n + 1)."""
    n = 1 << depth
    xs, ys, zs = (np.linspace(lo, hi, n + 1) for lo, hi in bounds)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    return np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, zs[k])]), n + 1


def dense_sign_changes(evaluate, bounds, depth) -> int:
    """Cells with a sign change among their corners, F sampled slab by slab (the baseline a user writes)."""
    n = 1 << depth
    count = 0
    previous = None
    for k in range(n + 1):
        pts, m = corner_grid(bounds, depth, k)
        f = np.asarray(evaluate(pts), dtype=np.float64).reshape(m, m)
        if previous is not None:
            lo = np.minimum(previous, f)
            hi = np.maximum(previous, f)
            lo = np.minimum.reduce([lo[:-1, :-1], lo[1:, :-1], lo[:-1, 1:], lo[1:, 1:]])
            hi = np.maximum.reduce([hi[:-1, :-1], hi[1:, :-1], hi[:-1, 1:], hi[1:, 1:]])
            count += int(np.count_nonzero((lo <= 0) & (hi >= 0)))
        previous = f
    return count


def numpy_evaluator(expr):
    import sympy

    from implc.compiler.symbols import cartesian_form, x, y, z
    fn = sympy.lambdify((x, y, z), cartesian_form(expr), modules="numpy")

    def evaluate(pts):
        with np.errstate(all="ignore"):
            return np.broadcast_to(fn(pts[:, 0], pts[:, 1], pts[:, 2]), (len(pts),))
    return evaluate


def symengine_evaluator(expr):
    """symengine's LLVM-compiled Lambdify, or None when symengine is not installed."""
    try:
        import symengine
    except ImportError:
        return None
    from implc.compiler.symbols import cartesian_form, x, y, z
    fn = symengine.Lambdify([x, y, z], [cartesian_form(expr)], backend="llvm")
    return lambda pts: fn(pts)[:, 0]


# -- sections --------------------------------------------------------------------------------------
def table1(args, out):
    workers = args.workers or list(range(1, default_workers() + 1))
    rows = []
    for name in args.scenes:
        t0 = time.perf_counter()
        s = compiled(name)
        compile_s = time.perf_counter() - t0
        implc.voxelize(s, args.depth)  # warm: the runtime, and memory (fresh pages are slow on VMs)
        t1 = None
        for w in workers:
            seconds, v = median_time(lambda: implc.voxelize(s, args.depth, workers=w), args.repeats)
            t1 = seconds if w == 1 else t1
            st = v.stats
            busy, leaves = sum(st.worker_busy), sum(st.worker_leaves)
            paper = PAPER_TABLE1.get(name, [])
            rows.append({
                "scene": name, "workers": w, "seconds": seconds,
                "yield": (t1 / (w * seconds)) if t1 else None,
                "compile_s": compile_s, "subdivision_busy_s": busy - leaves, "leaves_busy_s": leaves,
                "octree_build_s": st.seconds.get("storage", 0.0) + st.seconds.get("finish", 0.0),
                "voxels": len(v), "interval_evaluations": st.interval_evaluations,
                "paper_seconds": paper[w - 1] if w <= len(paper) else None,
                "paper_speedup": (paper[w - 1] / seconds) if w <= len(paper) else None,
            })
    out["table1"] = rows
    md = [f"### Table 1 at {1 << args.depth}³ (paper: SGI Challenge, 1 to 7 slaves)", "",
          "| scene | workers | seconds | yield | compile s | walk s | drop s | octree s "
          "| voxels | interval evals | paper s | vs paper |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        paper = f"{r['paper_seconds']}" if r["paper_seconds"] else "-"
        ratio = f"{r['paper_speedup']:.0f}×" if r["paper_speedup"] else "-"
        yld = f"{r['yield']:.0%}" if r["yield"] is not None else "-"
        md.append(f"| {r['scene']} | {r['workers']} | {r['seconds']:.3f} | {yld} | {r['compile_s']:.3f} "
                  f"| {r['subdivision_busy_s']:.3f} | {r['leaves_busy_s']:.3f} | {r['octree_build_s']:.3f} "
                  f"| {r['voxels']} | {r['interval_evaluations']} | {paper} | {ratio} |")
    md += ["", "walk and drop: summed worker busy time (the walk: subdivision, normals and second look, and building "
           "each task's part of the octree; the drop: removing the leaves the second look proved empty); octree: "
           "the serial part, tasks claiming their place one at a time, and linking the tasks' subtrees; "
           "yield = t1 / (n · tn) from the wall times in this table."]
    return md


def baselines(args, out):
    rows = []
    for name in args.baseline_scenes:
        sc = scene.load(name)
        s = implc.compile(sc.surface, sc.bounds)
        implc.voxelize(s, 6)
        evaluators = {"numpy": numpy_evaluator(sc.surface)}
        se = symengine_evaluator(sc.surface)
        if se is not None:
            evaluators["symengine llvm"] = se
        for depth in args.baseline_depths:
            ours, v = median_time(lambda: implc.voxelize(s, depth), args.repeats)
            row = {"scene": name, "depth": depth, "implc_s": ours, "voxels": len(v)}
            for label, ev in evaluators.items():
                if label == "numpy" and depth > args.numpy_max_depth:
                    continue
                seconds, cells = median_time(lambda: dense_sign_changes(ev, s.bounds, depth), 1)
                row[f"{label}_s"] = seconds
                row[f"{label}_cells"] = cells
                row[f"{label}_speedup"] = seconds / ours
            rows.append(row)
    out["baselines"] = rows
    md = ["### Against dense sampling (what a Python user writes instead)", "",
          "| scene | grid | implc s | numpy s | implc vs numpy | symengine-LLVM s | implc vs symengine |",
          "|---|---|---|---|---|---|---|"]
    for r in rows:
        def cell(label):
            return (f"{r[label + '_s']:.2f} | {r[label + '_speedup']:.0f}×" if label + "_s" in r else "- | -")
        md.append(f"| {r['scene']} | {1 << r['depth']}³ | {r['implc_s']:.3f} | {cell('numpy')} "
                  f"| {cell('symengine llvm')} |")
    md += ["", "Dense sampling evaluates F at every cell corner, slab by slab, and marks sign-change cells; "
           "implc's time is voxelize end to end without compile, all cores."]
    return md


GROWTH_SCRIPT = """
import json, resource, statistics, sys, time, implc
from implc.files import scene
sc = scene.load(sys.argv[1]); s = implc.compile(sc.surface, sc.bounds)
implc.voxelize(s, 5)  # load the runtime module: the figure is the voxelization alone
times = []
for _ in range(int(sys.argv[3])):
    t0 = time.perf_counter(); v = implc.voxelize(s, int(sys.argv[2])); times.append(time.perf_counter() - t0)
    del v
v = implc.voxelize(s, int(sys.argv[2]))
seconds = statistics.median(times)
print(json.dumps({"seconds": seconds, "voxels": len(v),
                  "peak_rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))
"""


def growth(args, out):
    rows = []
    for name in args.growth_scenes:
        previous = None
        for depth in args.growth_depths:
            repeats = max(1, min(args.repeats, 3))
            proc = subprocess.run([sys.executable, "-c", GROWTH_SCRIPT, name, str(depth), str(repeats)],
                                  capture_output=True, text=True, check=True)
            r = json.loads(proc.stdout)
            r.update(scene=name, depth=depth, ratio=(r["seconds"] / previous["seconds"]) if previous else None)
            rows.append(r)
            previous = r
    out["growth"] = rows
    md = ["### Growth with resolution (a process per depth, median of up to 3 runs; ideal ratio per doubling "
          "for a surface: 4)", "",
          "| scene | grid | seconds | voxels | peak memory | time ratio per doubling |", "|---|---|---|---|---|---|"]
    for r in rows:
        ratio = f"{r['ratio']:.2f}" if r["ratio"] else "-"
        md.append(f"| {r['scene']} | {1 << r['depth']}³ | {r['seconds']:.2f} | {r['voxels']} "
                  f"| {r['peak_rss'] / 2**30:.2f} GiB | {ratio} |")
    return md


TIGHTNESS_MODES = {"natural": implc.NATURAL, "default": {}, "tightest": implc.TIGHTEST}
"""The settings the tightness table compares: no second look at leaves, the default, the tightest preset."""


def tightness(args, out):
    """Voxels per sign-change cell at the tightness depth, and CPU seconds at --depth with one worker
    (modes interleaved in each repeat, kernels compiled before the clock starts), for every scene and the
    peer models of --tightness-models (their cells counted by numpy on the .vm text)."""
    sys.path.insert(0, str(ORACLE))
    import vm_sampling

    cases = [(name, compiled(name), None) for name in args.tightness_scenes]
    folder = Path(args.models_dir)
    for stem in filter(None, args.tightness_models.split(",")):
        path = folder / f"{stem}.vm"
        if not path.is_file():
            continue
        rows_vm = vm_sampling.parse(path.read_text())
        model = implc.load_vm(path)
        expr, suffix, extrude = _peer_surface(model, rows_vm)
        cases.append((stem + suffix, implc.compile(expr, model.bounds), (rows_vm, extrude)))
    rows = []
    depth = args.tightness_depth
    for name, s, vm in cases:
        if vm is None:
            cells = dense_sign_changes(s.eval, s.bounds, depth)
        else:
            cells = int(vm_sampling.sign_change_cells(vm_sampling.corner_values(vm[0], s.bounds, depth, vm[1])).sum())
        row = {"scene": name, "engine": s.engine, "sign_change_cells": cells}
        for mode, options in TIGHTNESS_MODES.items():
            v = implc.voxelize(s, depth, storage="coords", **options)  # also builds the kernels the mode needs
            row[f"{mode}_ratio"] = len(v) / cells
        cpu = {mode: [] for mode in TIGHTNESS_MODES}
        for _ in range(args.repeats):
            for mode, options in TIGHTNESS_MODES.items():
                cpu[mode].append(_cpu_seconds(lambda: implc.voxelize(s, args.depth, workers=1, **options)))
        for mode in TIGHTNESS_MODES:
            row[f"{mode}_cpu_s"] = statistics.median(cpu[mode])
        rows.append(row)
    out["tightness"] = rows
    md = [f"### Tightness: voxels / sign-change cells at {1 << depth}³ (1.00 is exact), CPU s at "
          f"{1 << args.depth}³ with one worker", "",
          "| surface | engine | sign-change cells | natural | default | tightest | natural s | default s (×) "
          "| tightest s (×) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        n = r["natural_cpu_s"]
        md.append(f"| {r['scene']} | {r['engine']} | {r['sign_change_cells']} | {r['natural_ratio']:.3f} "
                  f"| {r['default_ratio']:.3f} | {r['tightest_ratio']:.3f} | {n:.3f} "
                  f"| {r['default_cpu_s']:.3f} ({r['default_cpu_s'] / n:.2f}×) "
                  f"| {r['tightest_cpu_s']:.3f} ({r['tightest_cpu_s'] / n:.2f}×) |")
    md += ["", "natural: voxelize(..., **implc.NATURAL) (mean_value_levels=0, refine_leaves=False), every leaf the "
           "natural enclosure keeps; default: refine_leaves='auto', the kept leaves the linear model at their centre "
           "misses tested again with the monotonicity form (over the leaf, then on the tape engine over its face in "
           "pieces, then over its eighths and theirs); tightest: voxelize(..., **implc.TIGHTEST) "
           "(mean_value_levels=1, refine_leaves='auto'). CPU seconds: process time, medians, the modes interleaved."]
    return md


def kernels(args, out):
    rows = []
    n = 1 << 20
    rng = np.random.default_rng(0)
    lo = rng.uniform(-1, 1, (n, 3))
    hi = lo + 2 / 512
    for name in args.scenes:
        sc = scene.load(name)
        s = implc.compile(sc.surface, sc.bounds)
        out_lo, out_hi, values, grads = np.empty(n), np.empty(n), np.empty(n), np.empty((n, 3))
        interval, gradient = s.kernel(implc.native.abi.INTERVAL), s.kernel(implc.native.abi.GRADIENT)
        vector_gradient = s.kernel(implc.native.abi.GRADIENT_LIVE)  # Surface.value_and_gradient(..., fast=True)
        interval_s, _ = median_time(lambda: interval(lo.ctypes.data, hi.ctypes.data, out_lo.ctypes.data,
                                                     out_hi.ctypes.data, n, None, None), args.repeats)
        gradient_s, _ = median_time(lambda: gradient(lo.ctypes.data, values.ctypes.data, grads.ctypes.data, n),
                                    args.repeats)
        vector_gradient_s, _ = median_time(lambda: vector_gradient(lo.ctypes.data, values.ctypes.data,
                                                                   grads.ctypes.data, n, ALL_TERMS), args.repeats)
        saved = os.environ.get("IMPLC_CACHE_DIR")
        try:
            os.environ["IMPLC_CACHE_DIR"] = "off"
            cold, _ = median_time(lambda: implc.compile(sc.surface, sc.bounds), max(1, args.repeats // 2))
            with tempfile.TemporaryDirectory() as tmp:
                os.environ["IMPLC_CACHE_DIR"] = tmp
                implc.compile(sc.surface, sc.bounds)
                cached, _ = median_time(lambda: implc.compile(sc.surface, sc.bounds), args.repeats)
        finally:
            os.environ.pop("IMPLC_CACHE_DIR", None) if saved is None else os.environ.update(IMPLC_CACHE_DIR=saved)
        rows.append({"scene": name, "ops": len(s.tape), "interval_per_s": n / interval_s,
                     "gradient_per_s": n / gradient_s, "vector_gradient_per_s": n / vector_gradient_s,
                     "compile_cold_s": cold, "compile_cached_s": cached})
    out["kernels"] = rows
    md = ["### Kernels, one core", "", "| scene | ops | interval evals/s | gradient evals/s (C library) "
          "| gradient evals/s (vector functions: fast=True, the mesher's) | compile cold | compile cached |",
          "|---|---|---|---|---|---|---|"]
    md += [f"| {r['scene']} | {r['ops']} | {r['interval_per_s'] / 1e6:.1f} M | {r['gradient_per_s'] / 1e6:.1f} M "
           f"| {r['vector_gradient_per_s'] / 1e6:.1f} M "
           f"| {r['compile_cold_s'] * 1e3:.0f} ms | {r['compile_cached_s'] * 1e3:.1f} ms |" for r in rows]
    return md


EXTRUDE = "1/10"
"""The half-thickness a 2-D peer model (prospero) is extruded by: max(F(x, y), |z| − 1/10)."""


def _peer_surface(model, rows):
    """A peer model's surface as the benchmarks voxelize it, its name's suffix, and the extrusion for
    :func:`vm_sampling.corner_values` (None for a model that uses z)."""
    import sympy
    import vm_sampling
    if vm_sampling.uses_z(rows):
        return model, "", None
    slab = sympy.Abs(implc.z) - sympy.Rational(EXTRUDE)
    return sympy.Max(model(implc.x, implc.y, implc.z), slab), " (extruded)", float(sympy.Rational(EXTRUDE))


def _fresh_process_compile(path, extrude, cache_dir, pycache) -> float:
    """Seconds to load and compile a model in a new Python process with the kernel cache at cache_dir
    (``extrude``: as :func:`_peer_surface` gives it, None for a 3-D model) and Python's bytecode cached
    at ``pycache``, as a user's process finds it after an install (with PYTHONDONTWRITEBYTECODE, which a
    development shell may set, each fresh process would compile implc's modules first: about 0.1 s more)."""
    code = ("import sys, time, sympy, implc\n"
            "t0 = time.perf_counter()\n"
            "m = implc.load_vm(sys.argv[1])\n"
            "e = m if sys.argv[2] == '-' else sympy.Max(m(implc.x, implc.y, implc.z), "
            "sympy.Abs(implc.z) - sympy.Rational(sys.argv[2]))\n"
            "implc.compile(e, m.bounds)\n"
            "print(time.perf_counter() - t0)\n")
    env = dict(os.environ, IMPLC_CACHE_DIR=str(cache_dir), PYTHONPYCACHEPREFIX=str(pycache))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    done = subprocess.run([sys.executable, "-c", code, str(path), "-" if extrude is None else EXTRUDE],
                          capture_output=True, text=True, env=env, check=True)
    return float(done.stdout.strip().splitlines()[-1])


def models(args, out):
    """The peer models (.vm tapes of fidget and MPR) from --models-dir: load and compile in a fresh process
    (empty cache; and with only the shared tape engine cached), compile again in-process, voxelize at the
    chosen depths with all cores, live ops per octant, CPU time against Scene 1, and missed cells at 128³
    against numpy's run of the .vm text (:mod:`vm_sampling`). A model without z (prospero) is extruded:
    max(F(x, y), |z| − 1/10)."""
    sys.path.insert(0, str(ORACLE))
    import vm_sampling

    folder = Path(args.models_dir)
    paths = sorted(folder.glob("*.vm")) if folder.is_dir() else []
    skip = set(args.models_skip.split(",")) if args.models_skip else set()
    sc = scene.load("paper_blobs")
    scene1 = implc.compile(sc.surface, sc.bounds)
    implc.voxelize(scene1, 9)
    scene1_cpu = statistics.median(_cpu_seconds(lambda: implc.voxelize(scene1, 9)) for _ in range(args.repeats))
    rows = []
    for path in paths:
        if path.stem in skip:
            continue
        program_rows = vm_sampling.parse(path.read_text())
        t0 = time.perf_counter()
        model = implc.load_vm(path)
        load_s = time.perf_counter() - t0
        expr, suffix, extrude = _peer_surface(model, program_rows)
        with tempfile.TemporaryDirectory() as tmp:
            kernels, pycache = Path(tmp, "kernels"), Path(tmp, "pycache")
            _fresh_process_compile(path, extrude, Path(tmp, "warm-up"), pycache)  # untimed: the bytecode
            fresh_empty = _fresh_process_compile(path, extrude, kernels, pycache)
            fresh_engine = _fresh_process_compile(path, extrude, kernels, pycache)  # the engine is cached now
        cached, s = median_time(lambda: implc.compile(expr, model.bounds), args.repeats)
        row = {"model": path.stem + suffix, "instructions": model.instructions,
               "ops": len(s.tape), "engine": s.engine, "load_s": load_s, "compile_fresh_empty_cache_s": fresh_empty,
               "compile_fresh_s": fresh_engine, "compile_cached_s": cached, "depths": {}}
        for depth in args.models_depths:
            implc.voxelize(s, depth)
            seconds, v = median_time(lambda: implc.voxelize(s, depth), args.repeats)
            live = [ops for ops in v.stats.mean_live_ops if ops is not None]
            row["depths"][depth] = {"seconds": seconds, "voxels": len(v),
                                    "live_ops": [round(ops, 1) for ops in live]}
        if 9 in args.models_depths:
            cpu = statistics.median(_cpu_seconds(lambda: implc.voxelize(s, 9)) for _ in range(args.repeats))
            row["cpu_512_s"], row["cpu_vs_scene1"] = cpu, cpu / scene1_cpu
        truth = vm_sampling.sign_change_cells(vm_sampling.corner_values(program_rows, s.bounds, 7, extrude))
        got = implc.voxelize(s, 7, storage="coords").to_dense()
        row["missed_128"] = int((truth & ~got).sum())
        row["sign_change_cells_128"] = int(truth.sum())
        row["voxels_128"] = int(got.sum())
        rows.append(row)
    out["models"] = {"scene1_cpu_512_s": scene1_cpu, "rows": rows}
    md = ["### Peer models (.vm tapes of fidget and MPR), all cores", ""]
    if not rows:
        return md + [f"(no .vm files in {folder})"]
    grids = "".join(f" {1 << d}³ s | voxels | live ops/octant |" for d in args.models_depths)
    md += [f"| model | ops | engine | compile: fresh process, empty cache s | fresh process, engine cached s "
           f"| in process ms |{grids} CPU at 512³ vs Scene 1 | missed at 128³ (sign-change cells) |",
           "|---" * (8 + 3 * len(args.models_depths)) + "|"]
    for r in rows:
        cells = "".join(f" {g['seconds']:.3f} | {g['voxels']} | "
                        + (f"{g['live_ops'][0]:.0f} → {g['live_ops'][-1]:.0f} |" if g["live_ops"] else "– |")
                        for g in r["depths"].values())
        ratio = f"{r['cpu_vs_scene1']:.1f}×" if "cpu_vs_scene1" in r else "–"
        md.append(f"| {r['model']} | {r['ops']} | {r['engine']} | {r['compile_fresh_empty_cache_s']:.2f} | "
                  f"{r['compile_fresh_s']:.2f} | {r['compile_cached_s'] * 1e3:.0f} |{cells} {ratio} | "
                  f"{r['missed_128']} ({r['sign_change_cells_128']}) |")
    md += ["", f"Live ops per octant (tape engine): the mean length of the program the octants ran, at the root → "
               f"one level above the leaves. Scene 1 (paper_blobs) at 512³: {scene1_cpu:.3f} CPU s. Fresh processes "
               "find Python's bytecode cached (as after an install) and the kernel cache empty, then holding what "
               "the first compiled (a tape model's: the shared tape engine)."]
    return md


def _cpu_seconds(fn) -> float:
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def sphere_union(count=50, seed=7):
    """The hard CSG case: a union (Min) of ``count`` small spheres at random rational centres."""
    import random

    import sympy

    from implc import shapes
    rng = random.Random(seed)

    def centre():
        return tuple(sympy.Rational(rng.randint(-75, 75), 100) for _ in range(3))

    return shapes.union(*[shapes.sphere(sympy.Rational(rng.randint(6, 14), 100), centre()) for _ in range(count)])


def techniques(args, out):
    """Each technique of the kernels switched off in turn, in one run (issue: tighter and faster)."""
    cases = {"paper_blobs": (scene.load("paper_blobs").surface, scene.load("paper_blobs").bounds),
             "union of 50 spheres": (sphere_union(), ((-1, 1),) * 3)}
    widen = {"rounding": "widen"}
    variants = {  # label -> (compile options, voxelize options)
        "all on (default)": ({}, {}),
        "no pruning": ({}, {"prune": False}),
        "scalar kernels": ({"vector_width": 1}, {}),
        "widened rounding": (widen, {}),
        "all off": ({"vector_width": 1, **widen}, {"prune": False, **implc.NATURAL}),
        "natural leaves (no second look)": ({}, implc.NATURAL),
        "mean-value leaves": ({}, {"mean_value_levels": 1, "refine_leaves": False}),
        "refined leaves": ({}, {"refine_leaves": True}),
        "tightest": ({}, implc.TIGHTEST),
    }
    rows = []
    for name, (expr, bounds) in cases.items():
        surfaces = {}
        cells = None
        for label, (copts, vopts) in variants.items():
            key = tuple(sorted(copts.items()))
            if key not in surfaces:
                surfaces[key] = implc.compile(expr, bounds, **copts)
            s = surfaces[key]
            implc.voxelize(s, args.depth, **vopts)  # warm: compile the mean-value kernel, touch the memory
            seconds, v = median_time(lambda: implc.voxelize(s, args.depth, workers=1, **vopts), args.repeats)
            if cells is None:
                cells = dense_sign_changes(s.eval, s.bounds, args.tightness_depth)
            tight = implc.voxelize(s, args.tightness_depth, storage="coords", **vopts)
            rows.append({"case": name, "variant": label, "seconds": seconds, "voxels": len(v),
                         "interval_evaluations": v.stats.interval_evaluations,
                         "over_inclusion": len(tight) / cells})
    for r in rows:
        base = next(q for q in rows if q["case"] == r["case"] and q["variant"] == "all off")["seconds"]
        r["speedup_vs_all_off"] = base / r["seconds"]
    out["techniques"] = rows
    md = [f"### Techniques at {1 << args.depth}³, one worker (each switched off in turn)", "",
          f"| case | variant | seconds | speedup vs all off | voxels "
          f"| over-inclusion at {1 << args.tightness_depth}³ |",
          "|---|---|---|---|---|---|"]
    md += [f"| {r['case']} | {r['variant']} | {r['seconds']:.3f} | {r['speedup_vs_all_off']:.1f}× | {r['voxels']} "
           f"| {r['over_inclusion']:.3f} |" for r in rows]
    md += ["", "pruning: terms dead below an octant skipped (implc/engines/compiled/plan.py); "
           "scalar kernels: compile(..., "
           "vector_width=1) instead of 8 lanes; widened rounding: compile(..., rounding='widen'), bounds rounded "
           "to nearest and then widened instead of rounded outward by AVX-512 instructions (the default where the "
           "CPU has them; elsewhere the default widens too); natural leaves: voxelize(..., **implc.NATURAL), no second "
           "look at the leaves the linear model misses; mean-value leaves: voxelize(..., mean_value_levels=1, "
           "refine_leaves=False); refined leaves: voxelize(..., refine_leaves=True), a leaf kept only if one of its "
           "eighths may meet F; tightest: voxelize(..., **implc.TIGHTEST)."]
    return md


def _folder_bytes(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) if path.is_dir() else path.stat().st_size


def solids(args, out):
    """Solid voxelization (inside octants kept whole) against the shell, all cores, at --solid-depths:
    medians of interleaved runs, the extra cost, inside octants, the width of the guaranteed volume bounds,
    and the exports: .vdb from the voxels in memory, .zarr voxelized straight into the store (voxelization included)."""
    from implc.files.vdb import save_vdb
    from implc.files.zarr_writer import write_zarr
    rows = []
    for name in args.solid_scenes.split(","):
        sc = scene.load(name)
        s = implc.compile(sc.surface, sc.bounds)
        for depth in args.solid_depths:
            implc.voxelize(s, depth, solid=True)
            times = {False: [], True: []}
            for _ in range(args.repeats):  # interleaved: the machine's load drifts alike for both
                for solid in (False, True):
                    t0 = time.perf_counter()
                    v = implc.voxelize(s, depth, solid=solid)
                    times[solid].append(time.perf_counter() - t0)
            shell_s, solid_s = statistics.median(times[False]), statistics.median(times[True])
            lo, hi = v.volume_bounds()
            with tempfile.TemporaryDirectory() as tmp:
                vdb_s, path = median_time(lambda: save_vdb(v, Path(tmp) / "s.vdb"), 1)
                vdb_mib = _folder_bytes(path) / 2**20
                zarr_s, result = median_time(lambda: write_zarr(s, depth, Path(tmp) / "s.zarr"), 1)
                zarr_mib = _folder_bytes(result.path) / 2**20
            rows.append({"scene": name, "depth": depth, "shell_s": shell_s, "solid_s": solid_s,
                         "voxels": len(v), "inside_octants": len(v.inside), "volume_lo": lo, "volume_hi": hi,
                         "vdb_s": vdb_s, "vdb_mib": vdb_mib, "zarr_s": zarr_s, "zarr_mib": zarr_mib})
    out["solids"] = rows
    md = ["### Solids: inside octants kept whole, against the shell (all cores), and their exports", "",
          "| scene | grid | shell s | solid s | extra | boundary voxels | inside octants | volume bounds "
          "| .vdb write s (MiB) | .zarr voxelize + write s (MiB) |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    md += [f"| {r['scene']} | {1 << r['depth']}³ | {r['shell_s']:.3f} | {r['solid_s']:.3f} | "
           f"{r['solid_s'] / r['shell_s'] - 1:+.0%} | {r['voxels']} | {r['inside_octants']} | "
           f"[{r['volume_lo']:.6g}, {r['volume_hi']:.6g}] | {r['vdb_s']:.2f} ({r['vdb_mib']:.1f}) | "
           f"{r['zarr_s']:.2f} ({r['zarr_mib']:.1f}) |" for r in rows]
    md += ["", "Exports: `implc voxelize --solid -o x.vdb` (OpenVDB occupancy with inside tiles, and normals) and "
           "`-o x.zarr` (streamed: solid Scene 1 at 4096³ peaks at 1.35 GiB RSS)."]
    return md


SCALE_RUN = """
import json, resource, sys, time
import implc
from implc.files.scene import load
sc = load(sys.argv[1])
surface = implc.compile(sc.surface, bounds=sc.bounds)
import implc.engines.walk
implc.engines.walk.Subdivider(surface, 4, 1, surface.runtime)  # its kernels built before the clock starts
t0 = time.perf_counter()
v = implc.voxelize(surface, int(sys.argv[2]), workers=int(sys.argv[3]))
wall = time.perf_counter() - t0
st = v.stats
print(json.dumps({"voxels": len(v), "wall_s": wall, "storage_s": st.seconds["storage"],
                  "subdivide_s": st.seconds["subdivide"], "yield": st.parallel_yield,
                  "peak_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
                  "estimated_bytes": st.estimated_bytes, "tasks": st.tasks}))
"""


def scale(args, out):
    """Each grid voxelized in a fresh process (as a user's first run: fresh memory from the kernel),
    medians of --repeats processes: wall time, the serial part (one task at a time storing), peak RSS and
    bytes per voxel, the up-front estimate against that peak, the parallel yield."""
    rows = []
    for name in args.scale_scenes.split(","):
        for depth in args.scale_depths:
            runs = []
            for _ in range(args.repeats):
                done = subprocess.run([sys.executable, "-c", SCALE_RUN, name, str(depth), str(args.scale_workers)],
                                      capture_output=True, text=True, check=True)
                runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
            row = {"scene": name, "depth": depth, "workers": args.scale_workers, "voxels": runs[0]["voxels"]}
            for key in ("wall_s", "storage_s", "subdivide_s", "yield", "peak_bytes", "estimated_bytes"):
                row[key] = statistics.median(r[key] for r in runs)
            row["yields"] = [r["yield"] for r in runs]
            rows.append(row)
    out["scale"] = rows
    md = [f"### Scale: fresh processes, {args.scale_workers} workers (medians of {args.repeats})", "",
          "| scene | grid | voxels | wall s | x per doubling | serial s (share) | peak RSS GiB | bytes/voxel "
          "| estimate GiB (/ peak) | yield |", "|---|---|---|---|---|---|---|---|---|---|"]
    previous = {}
    for r in rows:
        before = previous.get(r["scene"])
        growth = f"{r['wall_s'] / before['wall_s']:.1f}" if before and before["depth"] == r["depth"] - 1 else ""
        previous[r["scene"]] = r
        md.append(f"| {r['scene']} | {1 << r['depth']}³ | {r['voxels']} | {r['wall_s']:.2f} | {growth} | "
                  f"{r['storage_s']:.3f} ({r['storage_s'] / r['wall_s']:.1%}) | {r['peak_bytes'] / 2**30:.2f} | "
                  f"{r['peak_bytes'] / r['voxels']:.1f} | {r['estimated_bytes'] / 2**30:.2f} "
                  f"({r['estimated_bytes'] / r['peak_bytes']:.2f}) | {r['yield']:.0%} |")
    md += ["", "Peak RSS is the whole process's (Python, NumPy, LLVM and the kernels included); serial: the time "
           "tasks spent one at a time claiming their place in the output (the rest of storing runs in parallel)."]
    return md


def viewer(args, out):
    """implc view at --viewer-depths: building the levels of detail, a chunk's cost, and in headless
    Chromium (SwiftShader: software WebGL2, so frames are far slower than on a GPU) the first picture
    after navigation starts and the time until the page has fetched what the camera needs."""
    import shutil

    from implc.view.page import lod_chunks
    from implc.view.server import ViewServer
    chromium = shutil.which("chromium")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        sync_playwright = None
    rows = []
    for name in args.viewer_scenes.split(","):
        sc = scene.load(name)
        s = implc.compile(sc.surface, sc.bounds)
        for depth in args.viewer_depths:
            v = implc.voxelize(s, depth)
            build_s, chunks = median_time(lambda: lod_chunks(v, name=name, view=sc.view), 1)
            ids = list(chunks.chunk_ids())
            chunk_s, _ = median_time(lambda: [chunks.chunk(*c) for c in ids[:500]], args.repeats)
            row = {"scene": name, "depth": depth, "voxels": len(v), "build_s": build_s, "chunks": len(ids),
                   "chunk_ms": 1e3 * chunk_s / min(len(ids), 500), "first_ms": None, "script_first_ms": None,
                   "settled_s": None, "points": None}
            if chromium and sync_playwright:
                with sync_playwright() as p, ViewServer(chunks, port=0).start() as server:
                    browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
                    page = browser.new_page(viewport={"width": 1024, "height": 768})
                    t0 = time.perf_counter()
                    page.goto(server.url)
                    timings = page.evaluate("window.implcViewer.ready.then(() => window.implcViewer.timings)")
                    row["first_ms"] = timings["firstFrame"]
                    row["script_first_ms"] = timings["firstFrame"] - timings["script"]
                    while not page.evaluate("window.implcViewer.stats().settled"):
                        time.sleep(0.02)
                    row["settled_s"] = time.perf_counter() - t0
                    row["points"] = page.evaluate("window.implcViewer.stats().points")
                    browser.close()
            rows.append(row)
    out["viewer"] = rows
    md = ["### implc view: levels of detail and the page in headless Chromium (1024x768, software WebGL2)", "",
          "| scene | grid | voxels | build LOD s | chunks | ms per chunk | first picture ms (from the script) "
          "| settled s | points drawn |",
          "|---|---|---|---|---|---|---|---|---|"]
    fmt = lambda v, f: "n/a" if v is None else format(v, f)  # noqa: E731
    md += [f"| {r['scene']} | {1 << r['depth']}³ | {r['voxels']} | {r['build_s']:.2f} | {r['chunks']} | "
           f"{r['chunk_ms']:.2f} | {fmt(r['first_ms'], '.0f')} ({fmt(r['script_first_ms'], '.0f')}) | "
           f"{fmt(r['settled_s'], '.2f')} | "
           f"{fmt(r['points'], 'd')} |" for r in rows]
    md += ["", "First picture: milliseconds from navigation start to the first frame with the root chunk drawn "
           "(`performance.now()` in the page), and in brackets from the moment the viewer's script starts; settled: "
           "until the page fetches nothing more for the camera; n/a where no Chromium and Playwright are installed."]
    return md


MC_RUN = """
import json, resource, sys, time
import numpy as np
sys.path.insert(0, sys.argv[4])
from suite import mesh_surface
from skimage.measure import marching_cubes
surface, bounds, _ = mesh_surface(sys.argv[1], sys.argv[2])
depth = int(sys.argv[3])
n = (1 << depth) + 1
t0 = time.process_time()
axes = [np.linspace(lo, hi, n) for lo, hi in bounds]
values = np.empty((n, n, n), np.float32)
for i in range(n):  # one slab at a time, through implc's compiled point kernel (as the mesher samples)
    yz = np.stack(np.meshgrid(axes[1], axes[2], indexing="ij"), -1).reshape(-1, 2)
    values[i] = surface.eval(np.column_stack([np.full(len(yz), axes[0][i]), yz]), fast=True).reshape(n, n)
t1 = time.process_time()
spacing = tuple((hi - lo) / (n - 1) for lo, hi in bounds)
verts, faces, _, _ = marching_cubes(np.nan_to_num(values, nan=1.0), 0.0, spacing=spacing)
t2 = time.process_time()
verts += np.array([lo for lo, _ in bounds])
np.savez(sys.argv[5], v=verts, f=faces)  # its default (gradient descent) winds outward for F < 0 inside
peak = [line for line in open("/proc/self/status") if line.startswith("VmHWM")]  # ru_maxrss survives exec
peak = int(peak[0].split()[1]) * 1024 if peak else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
print(json.dumps({"sample_cpu_s": t1 - t0, "mc_cpu_s": t2 - t1, "triangles": len(faces), "peak_bytes": peak}))
"""


def mesh_surface(name, models_dir):
    """A scene's or peer model's compiled surface, its bounds and a numpy F of it (for the quality figures)."""
    sys.path.insert(0, str(ORACLE))
    import vm_sampling
    path = Path(models_dir) / f"{name}.vm"
    if path.is_file():
        rows = vm_sampling.parse(path.read_text())
        model = implc.load_vm(path)
        expr, _, extrude = _peer_surface(model, rows)
        s = implc.compile(expr, model.bounds)

        def f(p):
            v = vm_sampling.evaluate(rows, p[:, 0].copy(), p[:, 1].copy(), p[:, 2].copy())
            return v if extrude is None else np.maximum(v, np.abs(p[:, 2]) - extrude)
        return s, s.bounds, f
    sc = scene.load(name)
    s = implc.compile(sc.surface, sc.bounds)
    return s, s.bounds, numpy_evaluator(sc.surface)


def min_angles(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Each triangle's smallest angle, in degrees (0 for a degenerate one)."""
    p = vertices[faces]
    worst = np.full(len(faces), 180.0)
    for k in range(3):
        u, v = p[:, (k + 1) % 3] - p[:, k], p[:, (k + 2) % 3] - p[:, k]
        with np.errstate(all="ignore"):
            cosine = np.einsum("ij,ij->i", u, v) / np.linalg.norm(u, axis=1) / np.linalg.norm(v, axis=1)
        worst = np.minimum(worst, np.degrees(np.arccos(np.clip(np.nan_to_num(cosine, nan=1.0), -1, 1))))
    return worst


def mesh_quality(vertices, faces, surface, cell, self_intersections: bool) -> dict:
    """The figures the mesh table reports: closed and oriented (edges counted), manifold3d's status,
    pymeshlab's self-intersecting faces, the largest first-order distance |F| / |∇F| of a vertex from
    F = 0 in cells, and the angle between each vertex's area-weighted normal and ∇F there (both over the
    vertices off the bounds' faces: a cap's corners are not on F = 0)."""
    m = implc.Mesh(vertices, faces)
    check = m.check()
    row = {"open_edges": check["open_edges"] + check["overused_edges"],
           "flipped_edges": check["repeated_directed_edges"], "degenerate": check["degenerate"]}
    try:
        import manifold3d
        solid = manifold3d.Manifold(manifold3d.Mesh(vert_properties=vertices.astype(np.float32),
                                                    tri_verts=faces.astype(np.uint32)))
        row["manifold3d"] = str(solid.status()).split(".")[-1]
    except ImportError:
        row["manifold3d"] = None
    row["self_intersecting"] = None
    if self_intersections:
        try:
            import pymeshlab
            ms = pymeshlab.MeshSet()
            ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces.astype(np.int32)))
            ms.compute_selection_by_self_intersections_per_face()
            row["self_intersecting"] = int(ms.current_mesh().selected_face_number())
        except ImportError:
            pass
    lo, hi = np.array(surface.bounds).T
    off_bounds = ~np.any((vertices == lo) | (vertices == hi), axis=1)
    values, grads = surface.value_and_gradient(vertices)
    values[~off_bounds], grads[~off_bounds] = np.nan, np.nan
    length = np.linalg.norm(grads, axis=1)
    with np.errstate(all="ignore"):
        distance = np.abs(values) / length / cell
    row["max_distance_cells"] = float(np.nanmax(distance)) if off_bounds.any() else 0.0
    p = vertices[faces]
    area = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    summed = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(summed, faces[:, k], area)
    with np.errstate(all="ignore"):
        cosine = np.einsum("ij,ij->i", summed, grads) / np.linalg.norm(summed, axis=1) / length
    angle = np.degrees(np.arccos(np.clip(cosine[np.isfinite(cosine)], -1, 1)))
    row["normal_deviation_median_deg"] = float(np.median(angle)) if len(angle) else 0.0
    row["normal_deviation_p99_deg"] = float(np.percentile(angle, 99)) if len(angle) else 0.0
    worst = min_angles(vertices, faces)
    row["under_5_percent"] = float(np.mean(worst < 5) * 100) if len(faces) else 0.0
    row["min_angle_p1_deg"] = float(np.percentile(worst, 1)) if len(faces) else 0.0
    return row


SIMPLIFY_CELLS = 0.01
"""The mesh section's simplification tolerance, in cells."""


def mesh(args, out):
    """implc.mesh against scikit-image's marching cubes on the dense grid (sampled through implc's point
    kernel, in a fresh process for its peak memory): CPU time (voxelizing and contouring apart), triangles,
    and the quality figures of :func:`mesh_quality` (self-intersections up to --mesh-quality-depth)."""
    names = [n for n in args.mesh_scenes.split(",") if n]
    names += [n for n in args.mesh_models.split(",") if n and (Path(args.models_dir) / f"{n}.vm").is_file()]
    rows = []
    for name in names:
        surface, bounds, _ = mesh_surface(name, args.models_dir)
        for depth in args.mesh_depths:
            cell = max(hi - lo for lo, hi in bounds) / (1 << depth)
            implc.mesh(surface, depth)  # warm: kernels compiled, pages touched
            implc.voxelize(surface, depth)
            vox_cpu, natural_cpu, mesh_cpu, m = [], [], [], None
            for _ in range(args.repeats):
                t0 = time.process_time()
                implc.voxelize(surface, depth)  # the default voxelization: the figure meshing is compared with
                t1 = time.process_time()
                voxels = implc.voxelize(surface, depth, **implc.NATURAL)  # as implc.mesh voxelizes
                t2 = time.process_time()
                m = voxels.mesh()
                t3 = time.process_time()
                vox_cpu.append(t1 - t0)
                natural_cpu.append(t2 - t1)
                mesh_cpu.append(t3 - t2)
            quality = depth <= args.mesh_quality_depth
            row = {"surface": name, "depth": depth, "voxelize_cpu_s": statistics.median(vox_cpu),
                   "natural_voxelize_cpu_s": statistics.median(natural_cpu),
                   "mesh_cpu_s": statistics.median(mesh_cpu),
                   "implc_mesh_cpu_s": statistics.median(n + c for n, c in zip(natural_cpu, mesh_cpu)),
                   "triangles": len(m.faces),
                   "feature_cells": m.stats.feature_cells, "crossed_cells": m.stats.crossed_cells,
                   "unproven_cells": m.stats.unproven_cells,
                   "implc": mesh_quality(m.vertices, m.faces, surface, cell, quality)}
            simplify_cpu, simplified = [], None
            for _ in range(args.repeats):
                t0 = time.process_time()
                simplified = m.simplified(SIMPLIFY_CELLS * cell)
                simplify_cpu.append(time.process_time() - t0)
            row["simplified"] = {"cpu_s": statistics.median(simplify_cpu), "triangles": len(simplified.faces),
                                 "quality": mesh_quality(simplified.vertices, simplified.faces, surface, cell, quality)}
            row["libfive"] = None
            if args.mesh_libfive:  # libfive's Mesh::render side by side (benchmarks/peers/libfive), one thread
                sys.path.insert(0, str(Path(args.mesh_libfive).resolve()))
                import run as harness
                runs, lf = [], None
                for _ in range(args.repeats):
                    info, path, keep = harness.run_lfmesh(name, depth, 1, None, -1.0)
                    lf = lf if lf is not None else harness.read_mesh(path)
                    keep.cleanup()
                    runs.append(info)
                row["libfive"] = {"cpu_s": statistics.median(r["cpu_seconds"] for r in runs),
                                  "triangles": len(lf[1]),
                                  "quality": mesh_quality(np.array(lf[0]), lf[1], surface, cell, quality)}
            try:
                import skimage  # noqa: F401
                with tempfile.TemporaryDirectory() as tmp:
                    done = subprocess.run([sys.executable, "-c", MC_RUN, name, args.models_dir, str(depth),
                                           str(Path(__file__).resolve().parent), str(Path(tmp) / "mc.npz")],
                                          capture_output=True, text=True, check=True)
                    mc = json.loads(done.stdout.strip().splitlines()[-1])
                    data = np.load(Path(tmp) / "mc.npz")
                    mc["quality"] = mesh_quality(data["v"], data["f"], surface, cell, quality)
                row["marching_cubes"] = mc
            except ImportError:
                row["marching_cubes"] = None
            rows.append(row)
    out["mesh"] = rows
    md = ["### Meshes: implc.mesh against scikit-image's marching cubes on the dense grid (CPU seconds, medians)", "",
          "| surface | grid | voxelize s | implc.mesh s (voxelize natural + contour) | implc.mesh / voxelize "
          "| triangles | under 5°, 1st pct of min angle ° | unproven cells "
          "| open, flipped, degenerate "
          "| manifold3d "
          "| self-intersecting | max distance (cells) | normal vs ∇F median, p99 ° | marching cubes: sample + mc s "
          "| peak GiB | triangles | open edges | manifold3d | self-intersecting | max distance |",
          "|---" * 20 + "|"]
    fmt = lambda v: "–" if v is None else str(v)  # noqa: E731
    for r in rows:
        q, mc = r["implc"], r["marching_cubes"]
        cells = (f" {mc['sample_cpu_s']:.2f} + {mc['mc_cpu_s']:.2f} | {mc['peak_bytes'] / 2**30:.2f} | "
                 f"{mc['triangles']} | {mc['quality']['open_edges']} | {fmt(mc['quality']['manifold3d'])} | "
                 f"{fmt(mc['quality']['self_intersecting'])} | {mc['quality']['max_distance_cells']:.3f} |"
                 if mc else " – | – | – | – | – | – | – |")
        md.append(f"| {r['surface']} | {1 << r['depth']}³ | {r['voxelize_cpu_s']:.3f} | {r['implc_mesh_cpu_s']:.3f} "
                  f"({r['natural_voxelize_cpu_s']:.3f} + {r['mesh_cpu_s']:.3f}) | "
                  f"{r['implc_mesh_cpu_s'] / r['voxelize_cpu_s']:.1f}× | {r['triangles']} | "
                  f"{q['under_5_percent']:.2f}%, {q['min_angle_p1_deg']:.1f} | "
                  f"{r['unproven_cells']} of {r['crossed_cells']} | {q['open_edges']}, "
                  f"{q['flipped_edges']}, {q['degenerate']} | {fmt(q['manifold3d'])} | {fmt(q['self_intersecting'])} | "
                  f"{q['max_distance_cells']:.3f} | {q['normal_deviation_median_deg']:.1f}, "
                  f"{q['normal_deviation_p99_deg']:.1f} |{cells}")
    if any(r["libfive"] for r in rows):
        md += ["", "#### Side by side with libfive's `Mesh::render` (dual contouring, no merging; one thread, CPU s)",
               "", "| surface | grid | implc.mesh s | libfive s | libfive / implc | triangles implc, libfive "
               "| under 5° implc, libfive | 1st pct of min angle ° implc, libfive | self-intersecting implc, "
               "libfive | open edges libfive |", "|---" * 10 + "|"]
        for r in rows:
            lf = r["libfive"]
            if lf:
                q, lq = r["implc"], lf["quality"]
                md.append(f"| {r['surface']} | {1 << r['depth']}³ | {r['implc_mesh_cpu_s']:.3f} | {lf['cpu_s']:.3f} | "
                          f"{lf['cpu_s'] / r['implc_mesh_cpu_s']:.1f}× | {r['triangles']}, {lf['triangles']} | "
                          f"{q['under_5_percent']:.2f}%, {lq['under_5_percent']:.2f}% | {q['min_angle_p1_deg']:.1f}, "
                          f"{lq['min_angle_p1_deg']:.1f} | {fmt(q['self_intersecting'])}, "
                          f"{fmt(lq['self_intersecting'])} | {lq['open_edges']} |")
    md += ["", "voxelize: the default mode (the figure the issue's bar compares with); implc.mesh voxelizes in the "
           "natural mode (the same mesh, fewer tests) and contours. "
           "Unproven cells: crossed cells where no derivative of F (along an axis, or on the tape engine a "
           "face or body diagonal) keeps one sign wherever F may vanish (MeshStats; the others are proven to "
           "hold a graph of F = 0). "
           "Distance: |F| / |∇F| at each vertex (first order), in cells. Open edges: edges not in exactly two "
           "triangles (marching cubes leaves the solid open where it meets the grid's faces). Self-intersections "
           f"counted by pymeshlab up to {1 << args.mesh_quality_depth}³ (– above).", "",
           f"#### The same meshes simplified (`Mesh.simplified`, within {SIMPLIFY_CELLS} of a cell)", "",
           "| surface | grid | simplify s | triangles | of | open, flipped, degenerate | manifold3d "
           "| self-intersecting | max distance (cells) |", "|---" * 9 + "|"]
    for r in rows:
        q = r["simplified"]["quality"]
        md.append(f"| {r['surface']} | {1 << r['depth']}³ | {r['simplified']['cpu_s']:.3f} | "
                  f"{r['simplified']['triangles']} | {r['triangles']} | {q['open_edges']}, {q['flipped_edges']}, "
                  f"{q['degenerate']} | {fmt(q['manifold3d'])} | {fmt(q['self_intersecting'])} | "
                  f"{q['max_distance_cells']:.3f} |")
    md += ["", "Only flat parts merge (the paper's blobs and bear have none); every vertex stays one of the mesh's."]
    return md


def _noop(i):
    return i


def cluster(args, out):
    """Dask cluster runs against the single-process run at the same total cores: Scene 1 as a solid into
    Zarr at --cluster-depth (the cluster already started: its start-up is measured apart), interleaved,
    medians of --repeats; one run at --cluster-big-depth through two worker processes with each worker's
    peak memory; the tasks per second the scheduler sustains (no-op tasks); how the task count grows with
    the depth (the plan at the task level)."""
    import distributed

    from implc.cluster.tasks import local_cluster, plan_tasks
    from implc.files import zarr_store, zarr_writer
    sc = scene.load(args.cluster_scene)
    s = implc.compile(sc.surface, sc.bounds)
    workers = args.cluster_workers
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        local = local_cluster(workers)  # as implc's local:N starts it
        client = distributed.Client(local)
        startup = time.perf_counter() - t0
        try:
            depth = args.cluster_depth
            zarr_writer.write_zarr(s, depth, Path(tmp) / "warm.zarr", solid=True, cluster=client)  # workers compile
            times = {"here": [], "cluster": []}
            for _ in range(args.repeats):
                for where in ("here", "cluster"):
                    t0 = time.perf_counter()
                    result = zarr_writer.write_zarr(s, depth, Path(tmp) / f"{where}.zarr", solid=True, workers=workers,
                                                   cluster=client if where == "cluster" else None)
                    times[where].append(time.perf_counter() - t0)
            rows["overhead"] = {"depth": depth, "workers": workers, "here_s": statistics.median(times["here"]),
                                "cluster_s": statistics.median(times["cluster"]), "startup_s": startup,
                                "voxels": result.voxels, "tasks": result.tasks,
                                "store_mib": _folder_bytes(result.path) / 2**20}
            t0 = time.perf_counter()
            futures = client.map(_noop, range(args.cluster_noop_tasks), pure=False)
            client.gather(futures)
            rows["tasks_per_s"] = args.cluster_noop_tasks / (time.perf_counter() - t0)
            if args.cluster_big_depth:
                big = args.cluster_big_depth
                t0 = time.perf_counter()
                result = zarr_writer.write_zarr(s, big, Path(tmp) / "big.zarr", solid=True, cluster=client)
                seconds = time.perf_counter() - t0
                peaks = client.run(lambda: __import__("resource").getrusage(
                    __import__("resource").RUSAGE_SELF).ru_maxrss * 1024)
                rows["big"] = {"depth": big, "seconds": seconds, "voxels": result.voxels, "tasks": result.tasks,
                               "inside_voxels": result.inside_voxels, "store_mib": _folder_bytes(result.path) / 2**20,
                               "worker_peak_mib": [v / 2**20 for v in peaks.values()]}
        finally:
            client.close()
            local.close()
    growth = []
    for depth in args.cluster_plan_depths:
        level = zarr_store.Layout.of(depth, s.bounds, True).task_level
        cells, inside = plan_tasks(s, depth, level, solid=True, options={})
        growth.append({"depth": depth, "task_level": level, "tasks": len(cells), "inside_above": len(inside)})
    rows["plan"] = growth
    out["cluster"] = rows
    o = rows["overhead"]
    md = [f"### Cluster: {args.cluster_scene} as a solid into Zarr, {workers} worker processes against one process "
          f"with {workers} threads", "",
          "| grid | one process s | cluster s | overhead | voxels | tasks | store MiB | cluster start-up s |",
          "|---|---|---|---|---|---|---|---|",
          f"| {1 << o['depth']}³ | {o['here_s']:.2f} | {o['cluster_s']:.2f} | {o['cluster_s'] / o['here_s'] - 1:+.0%} "
          f"| {o['voxels']} | {o['tasks']} | {o['store_mib']:.0f} | {o['startup_s']:.1f} |", ""]
    if "big" in rows:
        b = rows["big"]
        md += [f"At {1 << b['depth']}³: {b['seconds']:.1f} s, {b['voxels']} boundary voxels, {b['tasks']} tasks, "
               f"store {b['store_mib']:.0f} MiB; each worker's peak memory "
               f"{', '.join(f'{p:.0f}' for p in b['worker_peak_mib'])} MiB.", ""]
    md += [f"The scheduler ran {rows['tasks_per_s']:.0f} no-op tasks per second.", "",
           "| grid | task level | tasks | inside octants above them |", "|---|---|---|---|"]
    md += [f"| {1 << g['depth']}³ | {g['task_level']} | {g['tasks']} | {g['inside_above']} |" for g in growth]
    return md


WRITER_RUN = r"""
import json, resource, runpy, sys, time
sys.argv = ["implc"] + sys.argv[1:]
t0, c0 = time.perf_counter(), time.process_time()
try:
    runpy.run_module("implc", run_name="__main__")
except SystemExit as exc:
    if exc.code:
        raise
print(json.dumps({"wall": time.perf_counter() - t0, "cpu": time.process_time() - c0,
                  "peak": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}), file=sys.stderr)
"""


def writers(args, out):
    """Whole ``implc voxelize SCENE -o OUT`` commands, one fresh process each, by output format: .npz (the
    voxelization and one uncompressed write), .zarr (streamed into the store by tasks) and .vdb (from
    the voxels in memory), shell and solid; the formats interleaved, medians of --repeats; wall and CPU
    seconds from the command's start to its end (the interpreter's start-up left out, implc's import
    in), and the process's peak memory."""
    rows = []
    formats = args.writer_formats.split(",")
    for name in args.writer_scenes.split(","):
        for depth in args.writer_depths:
            for solid in (False, True):
                runs: dict = {f: [] for f in formats}
                with tempfile.TemporaryDirectory() as tmp:
                    for _ in range(args.repeats):
                        for fmt in formats:
                            command = [sys.executable, "-c", WRITER_RUN, "voxelize", name, "--depth", str(depth),
                                       "-o", str(Path(tmp) / f"out.{fmt}"), "--quiet"] + (["--solid"] if solid else [])
                            done = subprocess.run(command, capture_output=True, text=True, check=True)
                            runs[fmt].append(json.loads(done.stderr.strip().splitlines()[-1]))
                row = {"scene": name, "depth": depth, "solid": solid}
                for fmt in formats:
                    row[fmt] = {key: statistics.median(r[key] for r in runs[fmt]) for key in ("wall", "cpu", "peak")}
                rows.append(row)
    out["writers"] = rows
    md = ["### Writers: whole `implc voxelize` commands by output format (one process, all cores)", "",
          "| scene | grid | | " + " | ".join(f".{f} wall s (×npz) | CPU s | peak MiB" for f in formats) + " |",
          "|---|---|---|" + "---|---|---|" * len(formats)]
    for r in rows:
        base = r[formats[0]]
        cells = []
        for f in formats:
            m = r[f]
            ratio = m["wall"] / base["wall"]
            cells.append(f"{m['wall']:.2f} ({ratio:.2f}×) | {m['cpu']:.2f} | {m['peak'] / 2**20:.0f}")
        md.append(f"| {r['scene']} | {1 << r['depth']}³ | {'solid' if r['solid'] else 'shell'} | " + " | ".join(cells)
                  + " |")
    md += ["", "The .zarr store is written as the tasks finish (its memory bounded by the tasks in flight); the "
           ".npz and .vdb writers take the voxels in memory."]
    return md


SECTIONS = {"table1": table1, "techniques": techniques, "baselines": baselines, "growth": growth,
            "tightness": tightness, "kernels": kernels, "models": models, "solids": solids, "viewer": viewer,
            "scale": scale, "mesh": mesh, "cluster": cluster, "writers": writers}


def parser():
    p = argparse.ArgumentParser(prog="implc bench", description="implc's benchmark suite")
    p.add_argument("--sections", default=",".join(SECTIONS), help=f"comma list of {', '.join(SECTIONS)}")
    p.add_argument("--scenes", default=",".join(PAPER_SCENES), help="scenes for Table 1 and the kernels")
    p.add_argument("--depth", type=int, default=9, help="Table 1 depth (default 9: 512³)")
    p.add_argument("--workers", help="comma list of worker counts (default 1..cores)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--baseline-scenes", default="paper_blobs")
    p.add_argument("--baseline-depths", default="8,9")
    p.add_argument("--numpy-max-depth", type=int, default=9, help="skip numpy sampling above this depth")
    p.add_argument("--growth-scenes", default="paper_blobs")
    p.add_argument("--growth-depths", default="7,8,9,10,11")
    p.add_argument("--tightness-scenes", default=None, help="default: every scene")
    p.add_argument("--tightness-depth", type=int, default=8)
    p.add_argument("--tightness-models", default="tanglecube,bear,colonnade,prospero",
                   help="peer models (in --models-dir) for the tightness table, comma-separated")
    p.add_argument("--models-dir", default=str(Path(__file__).resolve().parent.parent.parent / "shared" / "models"),
                   help="folder of .vm models for the 'models' section (default: ../shared/models of the checkout)")
    p.add_argument("--models-skip", default="", help="comma list of model names to leave out")
    p.add_argument("--models-depths", default="8,9", help="grid depths for the models (default 8,9: 256³, 512³)")
    p.add_argument("--solid-scenes", default="paper_blobs,torus", help="scenes for the 'solids' section")
    p.add_argument("--scale-scenes", default="paper_blobs", help="scenes for the 'scale' section")
    p.add_argument("--scale-depths", default="10,11,12", help="grid depths for the 'scale' section (1024³-4096³)")
    p.add_argument("--scale-workers", type=int, default=2, help="workers for the 'scale' section")
    p.add_argument("--viewer-scenes", default="paper_blobs,paper_sin4_sin8,paper_sin3_sin4",
                   help="scenes for the 'viewer' section")
    p.add_argument("--viewer-depths", default="9,11", help="grid depths for the 'viewer' section (512³, 2048³)")
    p.add_argument("--solid-depths", default="9,10", help="grid depths for the 'solids' section (default 512³, 1024³)")
    p.add_argument("--mesh-scenes", default="paper_blobs,paper_sin4_sin8,paper_sin3_sin4,csg_part",
                   help="scenes for the 'mesh' section")
    p.add_argument("--mesh-models", default="bear,colonnade", help="peer models (in --models-dir) for 'mesh'")
    p.add_argument("--mesh-depths", default="8,9", help="grid depths for the 'mesh' section (256³, 512³)")
    p.add_argument("--mesh-libfive", default=None,
                   help="the libfive harness (benchmarks/peers/libfive, lfmesh built): adds libfive's columns")
    p.add_argument("--mesh-quality-depth", type=int, default=8,
                   help="deepest grid whose meshes pymeshlab checks for self-intersections (slow above)")
    p.add_argument("--cluster-scene", default="paper_blobs", help="scene for the 'cluster' section")
    p.add_argument("--writer-scenes", default="paper_blobs,paper_sin4_sin8", help="scenes of the 'writers' section")
    p.add_argument("--writer-depths", default="10,11", help="grid depths of the 'writers' section (1024³, 2048³)")
    p.add_argument("--writer-formats", default="npz,zarr,vdb", help="output formats compared (the first is the base)")
    p.add_argument("--cluster-depth", type=int, default=11, help="grid of the overhead comparison (default 2048³)")
    p.add_argument("--cluster-big-depth", type=int, default=13, help="one run at this grid (0: none; 8192³)")
    p.add_argument("--cluster-workers", type=int, default=2, help="worker processes (one thread each)")
    p.add_argument("--cluster-noop-tasks", type=int, default=5000, help="no-op tasks timed on the scheduler")
    p.add_argument("--cluster-plan-depths", default="9,11,13,15,17", help="grids whose task counts are shown")
    p.add_argument("--out", default="implc-bench", help="folder for latest.md/.json (default ./implc-bench)")
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    args.scenes = args.scenes.split(",")
    args.workers = [int(w) for w in args.workers.split(",")] if args.workers else None
    args.baseline_scenes = args.baseline_scenes.split(",")
    args.baseline_depths = [int(d) for d in args.baseline_depths.split(",")]
    args.growth_scenes = args.growth_scenes.split(",")
    args.growth_depths = [int(d) for d in args.growth_depths.split(",")]
    args.models_depths = [int(d) for d in args.models_depths.split(",")]
    args.solid_depths = [int(d) for d in args.solid_depths.split(",")]
    args.writer_depths = [int(d) for d in args.writer_depths.split(",")]
    args.viewer_depths = [int(d) for d in args.viewer_depths.split(",")]
    args.scale_depths = [int(d) for d in args.scale_depths.split(",")]
    args.mesh_depths = [int(d) for d in args.mesh_depths.split(",")]
    args.cluster_plan_depths = [int(d) for d in args.cluster_plan_depths.split(",")]
    args.tightness_scenes = args.tightness_scenes.split(",") if args.tightness_scenes else scene.available()
    sections = args.sections.split(",")
    unknown = [s for s in sections if s not in SECTIONS]
    if unknown:
        raise ValueError(f"unknown benchmark section(s) {', '.join(unknown)}: use {', '.join(SECTIONS)}")
    out = {"machine": machine()}
    m = out["machine"]
    lines = ["## implc benchmarks", "", f"{m['cpu']}, {m['cores']} cores; Python {m['python']}, llvmlite "
             f"{m['llvmlite']}, numpy {m['numpy']}; {m['date']}; medians of {args.repeats}", ""]
    print("\n".join(lines), flush=True)
    for name in sections:
        section = SECTIONS[name](args, out)
        print("\n".join(section) + "\n", flush=True)
        lines += section + [""]
    folder = Path(args.out)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "latest.md").write_text("\n".join(lines))
    (folder / "latest.json").write_text(json.dumps(out, indent=1))
    print(f"wrote {folder / 'latest.md'} and {folder / 'latest.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
