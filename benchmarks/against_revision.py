"""Voxelization (or meshing) time of this working tree against an older git revision, measured in one run.

Each case runs in a fresh process per revision (its own JIT cache), the two revisions interleaved so
that the machine's drift hits both alike; the table shows medians and their ratio. Example, the state
before the issue "tighter and faster" against now::

    python benchmarks/against_revision.py ee2b892 --depth 9 --repeats 5

With ``--workers 1,2`` each process times every worker count in turn, and the table adds the parallel
yield t1 / (n · tn) of each revision (the wall-time yield of the paper's Table 1).

With ``--task mesh`` each process voxelizes once and times ``Voxels.mesh()`` in CPU seconds (the
contouring, which runs on one thread), the count column then being triangles; ``--task implc.mesh`` times
what a user calls, ``implc.mesh(surface, depth)`` (its voxelization and the contouring, CPU seconds).
With ``--task compile`` each process finds the kernel cache empty (Python's bytecode cached, as after an
install) and times loading and compiling the case (wall seconds: a first compile spreads its parts over
processes), the count column then being voxels at ``--depth`` from that compile; ``--task first-voxelize``
times the same and the first voxelization at ``--depth`` (what compiled kernels compile on their first
voxelization included); ``--repeats`` is ignored by both. ``--task write-zarr`` (``write-npz``,
``write-vdb``) times whole ``implc voxelize CASE -o OUT`` commands run in the process (wall seconds: the
voxelization on every core and the writer), with ``--solid`` as solids; the case is then a scene name.

A case is a scene name, "union of 50 spheres", "blend of 90 blobs" or the path of a ``.vm`` model (read
with ``implc.load_vm`` where the revision has it, else converted to SymPy with ``evaluate=False``, keeping
the DAG).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

PROBE = r"""
import json, random, statistics, sys, time
import sympy, implc
from implc import shapes
try:
    from implc.files import scene  # the layout by concern
except ImportError:
    from implc import scene  # revisions before it
case, depth, repeats = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
workers = [int(w) for w in sys.argv[4].split(",")]
task = sys.argv[5]
solid = sys.argv[6:] == ["--solid"]
started = time.perf_counter()
rng = random.Random(7)  # the random cases' centres: the same sequence in every process
centre = lambda: tuple(sympy.Rational(rng.randint(-75, 75), 100) for _ in range(3))
if case == "union of 50 spheres":
    expr = shapes.union(*[shapes.sphere(sympy.Rational(rng.randint(6, 14), 100), centre()) for _ in range(50)])
    s = implc.compile(expr, ((-1, 1),) * 3)
elif case == "blend of 90 blobs":  # the tape engine's (over 1,000 instructions): its far terms decided 0
    s = implc.compile(shapes.blobs([centre() for _ in range(90)], sympy.Rational(1, 5), sympy.Rational(1, 4)),
                      ((-1, 1),) * 3)
elif case.endswith(".vm"):  # a peer model: load_vm where the revision has it, else SymPy with the DAG kept
    text = open(case).read()
    if hasattr(implc, "load_vm"):
        model = implc.load_vm(case)
        expr, bounds = model, model.bounds
    else:
        import re
        v, S = {}, sympy.S
        unary = {"neg": lambda a: sympy.Mul(-1, a, evaluate=False), "square": lambda a: sympy.Pow(a, 2, evaluate=False),
                 "sqrt": lambda a: sympy.Pow(a, S.Half, evaluate=False), "exp": lambda a: sympy.exp(a, evaluate=False),
                 "ln": lambda a: sympy.log(a, evaluate=False), "sin": lambda a: sympy.sin(a, evaluate=False),
                 "cos": lambda a: sympy.cos(a, evaluate=False), "abs": lambda a: sympy.Abs(a, evaluate=False)}
        binary = {"add": lambda a, b: sympy.Add(a, b, evaluate=False),
                  "mul": lambda a, b: sympy.Mul(a, b, evaluate=False),
                  "sub": lambda a, b: sympy.Add(a, sympy.Mul(-1, b, evaluate=False), evaluate=False),
                  "div": lambda a, b: sympy.Mul(a, sympy.Pow(b, -1, evaluate=False), evaluate=False),
                  "min": lambda a, b: sympy.Min(a, b, evaluate=False),
                  "max": lambda a, b: sympy.Max(a, b, evaluate=False)}
        for line in text.splitlines():
            w = line.split("#")[0].split()
            if not w:
                continue
            name, op, args = w[0], w[1], w[2:]
            if op.startswith("var-"):
                v[name] = getattr(implc, op[4:])
            elif op == "const":
                v[name] = sympy.Float(args[0])
            else:
                v[name] = (unary[op] if op in unary else binary[op])(*[v[a] for a in args])
            last = v[name]
        found = re.search(r"--scale\s+([0-9.]+)", text)
        half = 1 / float(found.group(1)) if found else 1.0
        expr, bounds = last, ((-half, half),) * 3
    if "var-z" not in text:  # a 2-D model (prospero): extruded
        f = expr(implc.x, implc.y, implc.z) if hasattr(expr, "tape") else expr
        expr = sympy.Max(f, sympy.Abs(implc.z) - sympy.Rational(1, 10))
    s = implc.compile(expr, bounds)
else:
    sc = scene.load(case)
    s = implc.compile(sc.surface, sc.bounds)
compiled = time.perf_counter() - started
v = implc.voxelize(s, depth, workers=1)  # warm: runtime module, memory
if task in ("compile", "first-voxelize"):
    seconds = compiled if task == "compile" else time.perf_counter() - started
    print(json.dumps({"seconds": {workers[0]: seconds}, "voxels": len(v)}))
    sys.exit(0)
times = {w: [] for w in workers}
if task.startswith("write-"):
    import tempfile
    from implc.cli.commands import main
    with tempfile.TemporaryDirectory() as tmp:
        command = ["voxelize", case, "--depth", str(depth), "-o", f"{tmp}/out.{task[6:]}", "--quiet"]
        command += ["--solid"] if solid else []
        main(command)  # warm
        for _ in range(repeats):
            t0 = time.perf_counter(); assert main(command) == 0; times[workers[0]].append(time.perf_counter() - t0)
    print(json.dumps({"seconds": {workers[0]: statistics.median(times[workers[0]])}, "voxels": len(v)}))
    sys.exit(0)
if task == "implc.mesh":
    implc.mesh(s, depth)  # warm
    for _ in range(repeats):
        t0 = time.process_time(); n = len(implc.mesh(s, depth).faces)
        times[workers[0]].append(time.process_time() - t0)
    print(json.dumps({"seconds": {w: statistics.median(t) for w, t in times.items() if t}, "voxels": n}))
    sys.exit(0)
if task == "mesh":
    v.mesh()  # warm
    for _ in range(repeats):
        t0 = time.process_time(); n = len(v.mesh().faces); times[workers[0]].append(time.process_time() - t0)
    print(json.dumps({"seconds": {w: statistics.median(t) for w, t in times.items() if t}, "voxels": n}))
    sys.exit(0)
for _ in range(repeats):
    for w in workers:  # interleaved, so that drift hits every worker count alike
        t0 = time.perf_counter(); v = implc.voxelize(s, depth, workers=w); times[w].append(time.perf_counter() - t0)
        n = len(v)
        del v
print(json.dumps({"seconds": {w: statistics.median(t) for w, t in times.items()}, "voxels": n}))
"""

CASES = ("paper_blobs", "union of 50 spheres", "blend of 90 blobs", "paper_sin4_sin8", "paper_sin3_sin4")


def run(tree: Path, case: str, depth: int, repeats: int, workers: list, cache: Path, task: str,
        solid: bool = False) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree), IMPLC_CACHE_DIR=str(cache))
    out = subprocess.run([sys.executable, "-c", PROBE, case, str(depth), str(repeats), ",".join(map(str, workers)),
                          task] + (["--solid"] if solid else []),
                         env=env, check=True, capture_output=True, text=True, cwd=tree)
    return json.loads(out.stdout)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("revision", help="the older git revision (e.g. a commit hash)")
    p.add_argument("--depth", type=int, default=9)
    p.add_argument("--repeats", type=int, default=5, help="timed voxelizations per process")
    p.add_argument("--rounds", type=int, default=3, help="processes per revision and case, interleaved")
    p.add_argument("--cases", default=",".join(CASES))
    p.add_argument("--workers", default="1", help="worker counts, comma-separated (e.g. 1,2: adds the yield)")
    p.add_argument("--task", choices=("voxelize", "mesh", "implc.mesh", "compile", "first-voxelize", "write-npz",
                                      "write-zarr", "write-vdb"),
                   default="voxelize",
                   help="what is timed: voxelize (wall seconds), mesh (Voxels.mesh(), CPU seconds), implc.mesh "
                        "(voxelizing and meshing, CPU seconds), compile (loading and compiling with an empty "
                        "kernel cache, wall seconds), first-voxelize (the same and a first voxelization) or "
                        "write-FORMAT (whole 'implc voxelize -o OUT.FORMAT' commands, wall seconds)")
    p.add_argument("--solid", action="store_true", help="with write-FORMAT: write solids")
    args = p.parse_args(argv)
    workers = [int(w) for w in args.workers.split(",")]
    if args.task != "voxelize":
        workers = workers[:1]
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "old"
        subprocess.run(["git", "worktree", "add", "--detach", str(old), args.revision], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            rows = []
            for case in args.cases.split(","):
                times = {(label, w): [] for label in ("old", "new") for w in workers}
                voxels = {}
                fresh = args.task in ("compile", "first-voxelize")
                if fresh:  # untimed: each tree's bytecode written once
                    for label, tree in (("old", old), ("new", ROOT)):
                        run(tree, case, 1, 1, workers, Path(tempfile.mkdtemp(dir=tmp)), args.task)
                for _ in range(args.rounds):
                    for label, tree in (("old", old), ("new", ROOT)):
                        cache = Path(tempfile.mkdtemp(dir=tmp)) if fresh else Path(tmp) / f"cache-{label}"
                        r = run(tree, case, args.depth, args.repeats, workers, cache, args.task, args.solid)
                        for w in workers:
                            times[label, w].append(r["seconds"][str(w)])
                        voxels[label] = r["voxels"]
                medians = {key: statistics.median(t) for key, t in times.items()}
                rows.append((case, medians, voxels["old"], voxels["new"]))
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(old)], cwd=ROOT, capture_output=True,
                           check=False)  # best effort: the temporary folder goes anyway
    what = {"voxelize": "Voxelize (wall s)", "mesh": "Mesh (CPU s)", "implc.mesh": "implc.mesh (CPU s)",
            "compile": "Load and compile, empty kernel cache (wall s)",
            "first-voxelize": "Load, compile and voxelize once, empty kernel cache (wall s)",
            **{f"write-{f}": f"`implc voxelize -o OUT.{f}`{' --solid' if args.solid else ''} (wall s)"
               for f in ("npz", "zarr", "vdb")}}[args.task]
    print(f"### {what} at {1 << args.depth}³: {args.revision} against this tree "
          f"(medians of {args.rounds} processes x {args.repeats} runs)\n")
    header = ["case"]
    for w in workers:
        header += [f"{w}w {args.revision} s", f"{w}w now s", f"{w}w speedup"]
        if w > 1 and workers[0] == 1:
            header += [f"{w}w yield {args.revision}", f"{w}w yield now"]
    count = "triangles" if args.task in ("mesh", "implc.mesh") else "voxels"
    print("| " + " | ".join(header + [f"{count} then", f"{count} now"]) + " |")
    print("|" + "---|" * (len(header) + 2))
    for case, m, v_old, v_new in rows:
        cells = [case]
        for w in workers:
            cells += [f"{m['old', w]:.4f}", f"{m['new', w]:.4f}", f"{m['old', w] / m['new', w]:.2f}×"]
            if w > 1 and workers[0] == 1:
                cells += [f"{m[label, 1] / (w * m[label, w]):.0%}" for label in ("old", "new")]
        print("| " + " | ".join(cells + [str(v_old), str(v_new)]) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
