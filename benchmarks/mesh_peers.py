"""implc.mesh side by side with libfive's ``Mesh::render`` (dual contouring, merging off), in one run:
each mesher in a fresh process per round, the rounds interleaved, medians quoted. For each model, grid and
thread count: wall and CPU seconds of the mesh call (implc: voxelizing in the natural mode and contouring,
as ``implc.mesh`` does; libfive: ``Mesh::render``), the process's peak memory (and how far it rose during
the mesh call: implc's process holds Python, numpy, SymPy and LLVM before it starts), triangles, the
minimum angles (the share of triangles under 5°, the 1st percentile), and the validity figures: edges not
in exactly two triangles, directed edges used twice, manifold3d's status, pymeshlab's self-intersecting
faces on the float32 coordinates a file keeps (up to --check-depth). implc runs in both constructions: the
default (one vertex per dual cell) and ``lean=False`` (the tetrahedral construction everywhere, today's
mesh before the dual cells).

libfive comes from a harness folder (--libfive): ``lfmesh`` built against libfive's core library and
``run.py`` (``run_lfmesh(name, depth, threads, out, max_err)``), as benchmarks/peers/libfive/README.md
says; without it the libfive columns are left out.

    python benchmarks/mesh_peers.py --libfive /tmp/libfive_bench --models paper_blobs,bear --depths 8 \\
        --threads 1,2 --rounds 3
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from suite import min_angles  # benchmarks/, the script's folder, is first on sys.path

HERE = Path(__file__).resolve().parent
MODELS = HERE.parent.parent / "shared" / "models"

IMPLC_RUN = r"""
import json, resource, sys, time
import numpy as np
sys.path.insert(0, sys.argv[1])
import implc
from implc.common.threads import threads
from implc.meshing.contour import contour
from suite import mesh_surface
name, models, depth, workers, lean, out = sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5]), \
    sys.argv[6] == "1", sys.argv[7]
surface, bounds, _ = mesh_surface(name, models)

def run(d):
    voxels = implc.voxelize(surface, d, workers=workers, **implc.NATURAL)
    with threads(workers):
        return contour(surface, voxels.coords, d, voxels.bounds, lean=lean)

def high_water():  # VmHWM, MiB: ru_maxrss would carry the parent's peak across exec
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

run(5)  # kernels compiled (or read from the cache), pages touched
before = high_water()
t0, c0 = time.perf_counter(), time.process_time()
mesh = run(depth)
t1, c1 = time.perf_counter(), time.process_time()
np.savez(out, v=mesh.vertices, f=mesh.faces)
peak = high_water()
print(json.dumps({"seconds": t1 - t0, "cpu_seconds": c1 - c0, "peak_rss_mib": peak, "above_start_mib": peak - before,
                  "triangles": len(mesh.faces)}))
"""


def quality(vertices: np.ndarray, faces: np.ndarray, intersections: bool) -> dict:
    """Triangles, minimum angles and the validity figures of a mesh (its coordinates rounded to float32)."""
    import manifold3d

    v32 = vertices.astype(np.float32)
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, used = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    _, once = np.unique(directed, axis=0, return_counts=True)
    angles = min_angles(vertices, faces)
    row = {"triangles": len(faces), "under_5_percent": float(np.mean(angles < 5) * 100),
           "p1_degrees": float(np.percentile(angles, 1)), "bad_edges": int(np.sum(used != 2)),
           "flipped_edges": int(np.sum(once != 1)),
           "manifold3d": str(manifold3d.Manifold(manifold3d.Mesh(vert_properties=v32, tri_verts=faces.astype(
               np.uint32))).status()).split(".")[-1], "self_intersecting": None}
    if intersections:
        import pymeshlab
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v32.astype(np.float64), face_matrix=faces.astype(np.int32)))
        ms.compute_selection_by_self_intersections_per_face()
        row["self_intersecting"] = int(ms.current_mesh().selected_face_number())
    return row


def run_implc(name, depth, workers, lean, tmp):
    out = Path(tmp) / f"implc_{int(lean)}.npz"
    done = subprocess.run([sys.executable, "-c", IMPLC_RUN, str(HERE), name, str(MODELS), str(depth), str(workers),
                           "1" if lean else "0", str(out)], capture_output=True, text=True, check=True)
    info = json.loads(done.stdout.strip().splitlines()[-1])
    data = np.load(out)
    return info, data["v"], data["f"].astype(np.int64)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--libfive", default=None, help="the libfive harness folder (lfmesh, run.py)")
    ap.add_argument("--models", default="paper_blobs,paper_sin4_sin8,csg_part,colonnade,bear")
    ap.add_argument("--depths", default="8")
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--check-depth", type=int, default=8, help="pymeshlab's self-intersections up to this depth")
    ap.add_argument("--out", default=None, help="also write the rows as JSON here")
    args = ap.parse_args(argv)
    harness = None
    if args.libfive:
        sys.path.insert(0, str(Path(args.libfive).resolve()))
        import run as harness  # the libfive harness's run.py
    tools = ["implc", "implc tetrahedral"] + (["libfive"] if harness else [])
    rows = []
    for name in [n for n in args.models.split(",") if n]:
        for depth in map(int, args.depths.split(",")):
            for workers in map(int, args.threads.split(",")):
                times = {tool: [] for tool in tools}
                meshes = {}
                with tempfile.TemporaryDirectory() as tmp:
                    for _ in range(args.rounds):
                        for tool in tools:
                            if tool == "libfive":
                                info, path, keep = harness.run_lfmesh(name, depth, workers, None, -1.0)
                                if tool not in meshes:
                                    meshes[tool] = harness.read_mesh(path)
                                keep.cleanup()
                            else:
                                info, v, f = run_implc(name, depth, workers, tool == "implc", tmp)
                                meshes.setdefault(tool, (v, f))
                            times[tool].append(info)
                for tool in tools:
                    v, f = meshes[tool]
                    runs = times[tool]
                    row = {"model": name, "depth": depth, "threads": workers, "tool": tool,
                           "seconds": statistics.median(r["seconds"] for r in runs),
                           "cpu_seconds": statistics.median(r["cpu_seconds"] for r in runs),
                           "peak_mib": statistics.median(r["peak_rss_mib"] for r in runs),
                           "above_start_mib": statistics.median(r.get("above_start_mib", r["peak_rss_mib"])
                                                                for r in runs)}
                    row.update(quality(np.asarray(v, float), np.asarray(f, np.int64), depth <= args.check_depth))
                    rows.append(row)
                    print(json.dumps(row), file=sys.stderr, flush=True)
    print("| model | grid | threads | mesher | wall s | CPU s | peak MiB (above the process's start) | triangles "
          "| under 5° | 1st pct ° | bad edges, flipped | manifold3d | self-intersecting (float32) |")
    print("|---" * 13 + "|")
    for r in rows:
        si = "–" if r["self_intersecting"] is None else r["self_intersecting"]
        print(f"| {r['model']} | {1 << r['depth']}³ | {r['threads']} | {r['tool']} | {r['seconds']:.3f} | "
              f"{r['cpu_seconds']:.3f} | {r['peak_mib']:.0f} ({r['above_start_mib']:.0f}) | {r['triangles']:,} | "
              f"{r['under_5_percent']:.2f}% | "
              f"{r['p1_degrees']:.1f} | {r['bad_edges']}, {r['flipped_edges']} | {r['manifold3d']} | {si} |")
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
