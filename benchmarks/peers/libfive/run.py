"""Run libfive's dual-contouring mesher (lfmesh) on an implc scene or a fidget .vm model.

    python run.py --model NAME --depth D --threads T [--out PATH] [--max-err E]

NAME: an implc scene (paper_blobs, paper_sin4_sin8, csg_part, ...), or colonnade / bear / tanglecube /
any NAME with ../shared/models/NAME.vm, or a path to a .vm file.  Cells per axis = 2**D over the model's
bounds (implc's: the scene's bounds; for .vm files implc.compiler.vm.load_vm's, i.e. [-1/S, 1/S]^3 from a
header "--scale S", else [-1, 1]^3).  Prints lfmesh's JSON line (its "peak_rss_mib" is lfmesh's own
VmHWM) with "ru_maxrss_children_mib" (inflated by the parent's RSS, see run_lfmesh), "model", "depth",
"threads", "bounds", "max_err" added.  --out keeps lfmesh's mesh file (format: see
lfmesh.cpp: "LFMESH01", uint64 V, uint64 F, V*3 float64, F*3 int32), otherwise it goes to a temp dir.

Library: libfive_mesh(name, depth, threads, max_err=1e-8) -> (verts float64 (V, 3), faces int64 (F, 3), info).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
LFMESH = Path(os.environ.get("LFMESH", HERE / "lfmesh"))  # where build.sh put it
MODELS = HERE.parents[3] / "shared" / "models"
sys.path.insert(0, str(HERE))


def model_vm(name: str):
    """(.vm text, bounds ((lo, hi),) * 3) for a scene name, a shared model name or a .vm path."""
    path = Path(name) if name.endswith(".vm") else MODELS / f"{name}.vm"
    if path.is_file():
        from implc.compiler.vm import load_vm

        return path.read_text(), tuple(tuple(float(v) for v in b) for b in load_vm(path).bounds)
    from to_vm import scene_to_vm

    return scene_to_vm(name)


def read_mesh(path):
    with open(path, "rb") as f:
        if f.read(8) != b"LFMESH01":
            raise ValueError(f"{path}: not an lfmesh file")
        v, t = np.frombuffer(f.read(16), dtype="<u8")
        verts = np.frombuffer(f.read(int(v) * 24), dtype="<f8").reshape(-1, 3)
        faces = np.frombuffer(f.read(int(t) * 12), dtype="<i4").reshape(-1, 3).astype(np.int64)
    return verts, faces


def run_lfmesh(name: str, depth: int, threads: int, out: str | None = None, max_err: float = 1e-8):
    """Run lfmesh in a child process; returns (info dict, mesh path, temp dir or None)."""
    text, bounds = model_vm(name)
    tmp = tempfile.TemporaryDirectory(prefix="lfmesh_")
    vm = Path(tmp.name) / "model.vm"
    vm.write_text(text)
    mesh_path = out or str(Path(tmp.name) / "mesh.bin")
    lo = [b[0] for b in bounds]
    hi = [b[1] for b in bounds]
    cmd = [str(LFMESH), str(vm), *map(repr, lo), *map(repr, hi), str(2 ** depth), str(threads), mesh_path,
           repr(max_err)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    rss_kib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    if proc.returncode != 0:
        raise RuntimeError(f"lfmesh failed ({proc.returncode}): {proc.stderr.strip()}")
    info = json.loads(proc.stdout.strip().splitlines()[-1])
    # peak_rss_mib comes from lfmesh itself (VmHWM after Mesh::render).  getrusage(RUSAGE_CHILDREN).ru_maxrss
    # is also given, but on Linux it includes this Python parent's own RSS at fork time (subprocess uses
    # vfork; the kernel carries the pre-exec high-water mark into the child), so it is only an upper bound.
    info.update(ru_maxrss_children_mib=round(rss_kib / 1024, 1), model=name, depth=depth, threads=threads,
                bounds=bounds, max_err=max_err)
    return info, mesh_path, tmp


def libfive_mesh(name: str, depth: int, threads: int, max_err: float = 1e-8):
    """(vertices float64 (V, 3), faces int64 (F, 3), info dict) of libfive's mesh of ``name`` at ``depth``."""
    info, mesh_path, tmp = run_lfmesh(name, depth, threads, None, max_err)
    try:
        verts, faces = read_mesh(mesh_path)
        return verts.copy(), faces, info
    finally:
        tmp.cleanup()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", required=True)
    ap.add_argument("--depth", type=int, required=True)
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--out", default=None, help="keep the mesh file here")
    ap.add_argument("--max-err", type=float, default=1e-8,
                    help="libfive BRepSettings.max_err (1e-8: merge only linear regions; -1: no merging)")
    args = ap.parse_args(argv)
    info, _, tmp = run_lfmesh(args.model, args.depth, args.threads, args.out, args.max_err)
    tmp.cleanup()
    print(json.dumps(info))


if __name__ == "__main__":
    main()
