"""The ``implc`` command: list scenes, voxelize, render, inspect files, the kernel cache, and the demo.

Every failure the user can cause (a missing or broken scene or file, a bad formula, option or value, an
unwritable output) ends with one line on stderr and exit status 2, and creates or damages no file (every
output is written under a temporary name and renamed into place). Ctrl-C ends with status 130 and
SIGTERM with 143, at any moment, imports included: this module imports only the standard library at
load time and the rest of implc inside :func:`main`.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import os
import signal
import sys
import threading
import time
import typing
from pathlib import Path

from ..errors import shorten

PAPER_SCENES = ("paper_blobs", "paper_sin4_sin8", "paper_sin3_sin4")
MESSAGE_LIMIT = 300
"""Longest error message printed (a 10,000-character formula is not repeated in full)."""
DEFAULT_BOUNDS = "-1,1,-1,1,-1,1"


class UsageError(Exception):
    """A problem with what the user asked for: reported in one line, exit status 2."""


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread so that cleanup (temporary files, worker threads) runs."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse prints a usage block; the contract is one line
        raise UsageError(f"{message} (see '{self.prog} --help')")


# -- helpers ---------------------------------------------------------------------------------------
_COUNT_WORDS = {1: "one", 2: "two", 3: "three", 6: "six"}


def _numbers(text, count, what, example):
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != count:
        amount = "a number" if count == 1 else f"{_COUNT_WORDS[count]} numbers"
        raise UsageError(f"{what} must be {amount} '{example}', got {shorten(text, quoted=True)}")
    if not all(math.isfinite(v) for v in values):
        raise UsageError(f"{what} must be finite numbers, got {shorten(text, quoted=True)}")
    return values


def _bounds(text):
    v = _numbers(text, 6, "--bounds", "x0,x1,y0,y1,z0,z1")
    return ((v[0], v[1]), (v[2], v[3]), (v[4], v[5]))



def _check_writable(path: Path, suffixes):
    if path.is_dir() and path.suffix.lower() != ".zarr":  # a Zarr store is a folder, replaced whole
        raise UsageError(f"cannot write {path}: it is a folder")
    suffix = path.suffix.lower()
    if suffix not in suffixes:
        raise UsageError(f"unknown output format {path.suffix or '(none)'!r} for {path}: use {', '.join(suffixes)}")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise UsageError(f"cannot write {path}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise UsageError(f"cannot write {path}: permission denied")


def _check_render_size(size):
    """--size: 16 to the renderer's largest image, and its working memory available."""
    from ..view.render import BYTES_PER_PIXEL, MAX_SIZE
    from ..voxelizer.voxelize import available_memory
    _check_range(size, "--size", 16, MAX_SIZE)
    need = BYTES_PER_PIXEL * size * size
    if need > available_memory():
        raise UsageError(f"--size {size} needs about {need / 2**30:.1f} GiB to render, more than the "
                         f"{available_memory() / 2**30:.1f} GiB available")


def _check_range(value, name, lo, hi):
    if value is not None and not lo <= value <= hi:
        raise UsageError(f"{name} must be an integer from {lo} to {hi}, got {value}")


def _surface_from_args(args):
    """(name, compiled surface, scene or None) from SCENE or --expr (a .vm model never imports SymPy)."""
    from ..engines.surface import compile as compile_surface
    if args.expr is not None:
        from ..compiler.expr import ExprError
        from ..compiler.expr import parse as parse_expr
        if args.scene:
            raise UsageError("give either a SCENE or --expr, not both")
        if not args.expr.strip():
            raise UsageError("--expr is empty: give a formula such as 'x**2 + y**2 + z**2 - 1'")
        try:
            expr = parse_expr(args.expr)
        except ExprError as exc:
            raise UsageError(f"--expr: {exc}") from None
        return args.expr, compile_surface(expr, _bounds(args.bounds or DEFAULT_BOUNDS)), None
    if not args.scene:
        raise UsageError("name a SCENE (see 'implc scenes') or give --expr")
    if Path(args.scene).suffix.lower() == ".vm":  # a model from fidget or MPR
        from ..compiler.vm import load_vm
        model = load_vm(args.scene)
        return model.name, compile_surface(model, _bounds(args.bounds) if args.bounds else None), None
    if Path(args.scene).suffix.lower() in (".npz", ".ply", ".npy"):
        raise UsageError(f"{args.scene} is a voxel file: 'implc {args.command}' takes a scene or --expr"
                         + (" (render reads .npz files)" if args.command == "voxelize" else ""))
    from ..files.scene import load as load_scene
    sc = load_scene(args.scene)
    bounds = _bounds(args.bounds) if args.bounds else sc.bounds
    return sc.name, compile_surface(sc.surface, bounds), sc


TIGHTNESS: dict[str, dict] = {"natural": {"mean_value_levels": 0, "refine_leaves": False}, "default": {},
             "tightest": {"mean_value_levels": 1, "refine_leaves": "auto"}}
"""--tightness: implc.NATURAL, the default and implc.TIGHTEST (spelt out: importing them would load NumPy)."""


def _voxelize(surface, depth, workers, quiet, solid=False, tightness="default"):
    from ..voxelizer.voxelize import voxelize
    t0 = time.perf_counter()
    voxels = voxelize(surface, depth, workers=workers, progress=not quiet and sys.stderr.isatty(), solid=solid,
                      **TIGHTNESS[tightness])
    return voxels, time.perf_counter() - t0


def _tightness(args) -> str:
    """--tightness as given, or its default: the natural mode where the voxels are only meshed (the mesh is
    the same for every tightness, :func:`implc.mesh`), the default mode otherwise."""
    if args.tightness is not None:
        return args.tightness
    return "natural" if args.command == "mesh" or getattr(args, "mesh", False) else "default"


def _refuse_surface_options(args, kind: str, shown: str, *more):
    """One line naming the options given that only a surface takes, where ``args.scene`` is a ``kind`` file
    (``more``: further (flag, value) pairs that do not apply to it)."""
    given = [flag for flag, value in (("--expr", args.expr), ("--depth", args.depth), ("--bounds", args.bounds),
                                      ("--workers", args.workers), *more) if value is not None]
    if given:
        raise UsageError(f"{', '.join(given)} cannot apply to a {kind} file ({args.scene}): it is {shown} as saved")


def _check_surface_options(args):
    _check_range(args.depth, "--depth", 1, 21)
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")


# -- commands --------------------------------------------------------------------------------------
def cmd_scenes(args) -> int:
    from ..files.scene import available, load
    for name in available():
        print(f"{name:<20} {load(name).title}")
    return 0


def _check_folder_writable(path: Path, what: str):
    """A folder ``what`` goes to (slices, a static viewer): new, or an existing folder to replace; its
    parent must exist and be writable."""
    if path.exists() and not path.is_dir():
        raise UsageError(f"cannot write {what} to {path}: it is a file (name a folder)")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise UsageError(f"cannot write {path}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise UsageError(f"cannot write {path}: permission denied")


def cmd_voxelize(args) -> int:
    from ..files import voxel_files
    out = Path(args.output)
    if args.slices:
        _check_folder_writable(out, "slices")
    else:
        _check_writable(out, voxel_files.SUFFIXES)
    _check_surface_options(args)
    name, surface, sc = _surface_from_args(args)
    depth = args.depth if args.depth is not None else (sc.depth if sc else 9)
    zarr_out = out.suffix.lower() == ".zarr" and not args.slices
    if args.resume and not zarr_out:
        raise UsageError("--resume finishes an interrupted .zarr run; other outputs are written whole or not at all")
    if args.cluster is not None:
        from ..cluster.tasks import parse_address
        parse_address(args.cluster)  # a bad address is refused before any work
    say = None if args.quiet else (lambda line: print(line, file=sys.stderr))
    if zarr_out:  # streamed: the voxels are never all in memory (on a cluster: tasks own their shards)
        from ..files.zarr_store import write_zarr
        t0 = time.perf_counter()
        result: typing.Any
        try:
            result = write_zarr(surface, depth, out, solid=args.solid, workers=args.workers, cluster=args.cluster,
                                resume=args.resume, progress=not args.quiet and sys.stderr.isatty(), say=say,
                                **TIGHTNESS[args.tightness])
        except BaseException:
            partial = out.with_name(out.name + ".partial")
            if partial.is_dir():
                print(f"implc: the finished tasks are kept in {partial}: the same command with --resume "
                      "finishes the store", file=sys.stderr)
            raise
        count, inside, seconds = result.voxels, result.inside_octants, time.perf_counter() - t0
    else:
        if args.cluster is not None:
            from ..voxelizer.voxelize import voxelize
            t0 = time.perf_counter()
            result = voxelize(surface, depth, solid=args.solid, cluster=args.cluster, say=say,
                              progress=not args.quiet and sys.stderr.isatty(), **TIGHTNESS[args.tightness])
            seconds = time.perf_counter() - t0
        else:
            result, seconds = _voxelize(surface, depth, args.workers, args.quiet, solid=args.solid,
                                        tightness=args.tightness)
        count, inside = len(result), len(result.inside) if args.solid else 0
        if args.slices:
            from ..files.slices import save_slices
            save_slices(result, out, args.slices)
        else:
            voxel_files.save(result, out, compress=args.compress)
    if not args.quiet:
        solid = ""
        if args.solid:
            lo, hi = result.volume_bounds()
            solid = f", {inside} inside octants, volume in [{lo:.6g}, {hi:.6g}]"
        print(f"{name}: {count} voxels at {1 << depth}³{solid} in {seconds:.2f} s "
              f"(yield {result.stats.parallel_yield:.0%}) -> {out}")
    return 0


def cmd_render(args) -> int:
    from ..files import voxel_files
    from ..view.render import Style, View, render_voxels, save_png
    out = Path(args.output)
    _check_writable(out, (".png",))
    _check_render_size(args.size)
    _check_surface_options(args)
    view_angles = _numbers(args.view, 2, "--view", "azimuth,elevation") if args.view else None
    style = Style(color=_color(args.color)) if args.color else Style()
    if args.scene and Path(args.scene).suffix.lower() in (".npz", ".ply", ".npy", ".zarr"):
        _refuse_surface_options(args, "voxel", "rendered")
        voxels = voxel_files.load(args.scene)
        default_view = None
    else:
        _, surface, sc = _surface_from_args(args)
        depth = args.depth if args.depth is not None else (sc.depth if sc else 9)
        voxels, _ = _voxelize(surface, depth, args.workers, args.quiet, solid=args.solid, tightness=args.tightness)
        default_view = sc.view if sc else None
    azimuth, elevation = view_angles or default_view or (35.0, 25.0)
    if args.lod is not None and not 1 <= args.lod <= voxels.depth:
        raise UsageError(f"--lod must be from 1 to {voxels.depth}, got {args.lod}")
    cut = _cut(args.cut, voxels) if args.cut else None
    if cut is not None and args.lod is not None:
        raise UsageError("--cut draws the voxels themselves; it cannot be combined with --lod")
    t0 = time.perf_counter()
    image = render_voxels(voxels, size=args.size, view=View(azimuth, elevation, perspective=args.perspective),
                          style=style, lod=args.lod, cut=cut)
    save_png(image, out)
    if not args.quiet:
        print(f"rendered {len(voxels)} voxels to {out} ({args.size}² in {time.perf_counter() - t0:.2f} s)")
    return 0


def cmd_view(args) -> int:
    from ..files import voxel_files
    from ..meshing.triangle_mesh import MeshFileError, is_mesh_file
    from ..meshing.triangle_mesh import load as load_mesh
    from ..view.mesh_payload import MeshPayload
    from ..view.page import lod_chunks
    if args.port is not None:
        _check_range(args.port, "--port", 0, 65535)
    if args.budget is not None:
        _check_range(args.budget, "--budget", 1000, 1_000_000_000)
    budget = args.budget or 1_000_000
    if args.export is not None:
        _check_folder_writable(Path(args.export), "a static viewer")
    suffix = Path(args.scene).suffix.lower() if args.scene else ""
    if suffix in (".npz", ".zarr"):
        _refuse_surface_options(args, "voxel", "shown")
        voxels, name, view = voxel_files.load(args.scene), Path(args.scene).stem, None
    elif suffix in (".ply", ".stl", ".obj", ".glb", ".3mf") and is_mesh_file(args.scene):
        _refuse_surface_options(args, "mesh", "shown", ("--budget", args.budget))
        try:
            mesh = load_mesh(args.scene)
        except MeshFileError as error:
            raise UsageError(str(error)) from None
        return _view(MeshPayload(mesh, name=Path(args.scene).stem), args, budget,
                     f"{len(mesh.faces)} triangles, {len(mesh.vertices)} vertices")
    elif suffix in (".ply", ".npy", ".stl", ".obj", ".glb", ".3mf"):
        raise UsageError(f"{args.scene} is a {suffix} file: 'implc view' shows scenes, formulas, .vm models, "
                         "the .npz and .zarr voxel files implc writes and meshes ('implc info' describes it)")
    else:
        _check_surface_options(args)
        name, surface, sc = _surface_from_args(args)
        depth = args.depth if args.depth is not None else (sc.depth if sc else 9)
        voxels, _ = _voxelize(surface, depth, args.workers, args.quiet, tightness=args.tightness)
        view = sc.view if sc else None
        if args.mesh:
            t0 = time.perf_counter()
            mesh = voxels.mesh()
            if not args.quiet:
                print(f"{name}: meshed in {time.perf_counter() - t0:.2f} s", file=sys.stderr)
            return _view(MeshPayload(mesh, name=name, view=view), args, budget,
                         f"{len(mesh.faces)} triangles, {len(mesh.vertices)} vertices at {1 << voxels.depth}³")
    if args.mesh:
        raise UsageError(f"--mesh meshes a surface: {args.scene} is a voxel file (mesh its surface, or 'implc mesh')")
    return _view(lod_chunks(voxels, name=name, view=view), args, budget,
                 f"{len(voxels)} voxels at {1 << voxels.depth}³")


def _view(shown, args, budget: int, what: str) -> int:
    """Export ``shown`` (the chunks of voxels, or a mesh's payload) as a static viewer, or serve it."""
    from ..view.page import export
    from ..view.server import DEFAULT_PORT, ViewServer
    name = shown.name
    if args.export is not None:
        export(shown, args.export, budget=budget)
        if not args.quiet:
            print(f"wrote a static viewer of {name} ({what}) to {args.export}: "
                  f"any static file server shows it, e.g. python3 -m http.server -d {args.export}")
        return 0
    try:
        server = ViewServer(shown, port=args.port, budget=budget)
    except OSError as exc:
        raise UsageError(f"cannot listen on 127.0.0.1:{args.port if args.port is not None else DEFAULT_PORT}: "
                         f"{exc.strerror or exc}") from None
    try:
        print(f"implc view: {name}, {what}\n{server.url}\n"
              "(Ctrl-C stops the server)", flush=True)
        if not args.no_browser:
            import webbrowser
            webbrowser.open(server.url)
        server.serve_forever()
    finally:
        server.close()
    return 0


def _cut(text, voxels) -> tuple[int, float]:
    """--cut AXIS=VALUE (x, y or z, a number inside the bounds) as (axis, value)."""
    axis, sep, value = text.partition("=")
    if not sep or axis.strip() not in ("x", "y", "z"):
        raise UsageError(f"--cut must be AXIS=VALUE with AXIS x, y or z, got {text!r}")
    (number,) = _numbers(value, 1, "--cut", "AXIS=VALUE")
    a = "xyz".index(axis.strip())
    lo, hi = voxels.bounds[a]
    if not lo <= number <= hi:
        raise UsageError(f"--cut {text}: {axis.strip()} must lie within the bounds {lo}..{hi}")
    return a, number


def _color(text):
    rgb = _numbers(text, 3, "--color", "R,G,B")
    if not all(0 <= c <= 1 for c in rgb):
        raise UsageError(f"--color must be three numbers from 0 to 1 'R,G,B', got "
                         f"{shorten(text, quoted=True)}")
    return tuple(rgb)


def _simplify_tolerance(text):
    """--simplify's tolerance (None where not given); a usage error unless a positive finite number."""
    if text is None:
        return None
    from ..meshing.simplify import check_tolerance
    try:
        return check_tolerance(float(text))
    except ValueError:
        raise UsageError(f"--simplify takes a positive tolerance in the bounds' units, got "
                         f"{shorten(text, quoted=True)}") from None


def cmd_mesh(args) -> int:
    from ..meshing.contour import MAX_DEPTH
    from ..meshing.triangle_mesh import MESH_SUFFIXES
    out = Path(args.output)
    _check_writable(out, MESH_SUFFIXES)
    _check_surface_options(args)
    _check_range(args.depth, "--depth", 1, MAX_DEPTH)
    tolerance = _simplify_tolerance(args.simplify)
    name, surface, sc = _surface_from_args(args)
    depth = args.depth if args.depth is not None else (sc.depth if sc else 8)
    voxels, seconds = _voxelize(surface, depth, args.workers, args.quiet, tightness=args.tightness)
    t0 = time.perf_counter()
    mesh = voxels.mesh(simplify=tolerance, workers=args.workers)
    t1 = time.perf_counter()
    mesh.save(out)
    t2 = time.perf_counter()
    if not args.quiet:
        simplified = "" if tolerance is None else f" (simplified from {mesh.stats.simplified.triangles_before})"
        print(f"{name}: {len(mesh.faces)} triangles{simplified}, {len(mesh.vertices)} vertices at {1 << depth}³, "
              f"volume {mesh.volume:.6g} (voxelized in {seconds:.2f} s, meshed in {t1 - t0:.2f} s, written in "
              f"{t2 - t1:.2f} s) -> {out}")
    return 0


def cmd_info(args) -> int:
    from ..files import voxel_files
    from ..meshing.triangle_mesh import MESH_SUFFIXES, MeshFileError, describe, is_mesh_file
    if Path(args.file).suffix.lower() in MESH_SUFFIXES and is_mesh_file(args.file):
        try:
            lines = describe(args.file)
        except MeshFileError as exc:
            raise UsageError(str(exc)) from None
        print("\n".join(lines))
        return 0
    if Path(args.file).suffix.lower() == ".vm":
        from ..compiler.vm import load_vm
        model = load_vm(args.file)
        print(f"model    {args.file}: {model.instructions} instructions, {len(model.tape)} after sharing")
        print(f"bounds   {model.bounds} (suggested by its --scale, or [-1, 1]³)")
        return 0
    folder = Path(args.file)
    if folder.is_dir() and (folder.suffix.lower() == ".zarr" or (folder / "zarr.json").is_file()):  # NAME.partial too
        from ..files.zarr_store import describe_zarr
        try:
            lines = describe_zarr(args.file)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    else:
        lines = voxel_files.describe(args.file)
    for line in lines:
        print(line)
    return 0


def cmd_bench(argv) -> int:
    """Run the benchmark suite of the source checkout this package was imported from: benchmarks/ is a
    client of implc, not part of the package."""
    suite = Path(__file__).resolve().parents[2] / "benchmarks" / "suite.py"
    if not suite.is_file():
        raise UsageError("'implc bench' runs the benchmark suite of a source checkout (benchmarks/suite.py), which an "
                         "installed package does not carry: in a clone of implc, 'pip install -e .[bench]' then "
                         "'implc bench'")
    spec = importlib.util.spec_from_file_location("implc_benchmark_suite", suite)
    if spec is None or spec.loader is None:
        raise UsageError(f"cannot load the benchmark suite at {suite}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main(argv)


def cmd_cache(args) -> int:
    from ..native import kernel_cache
    if args.action == "clear":
        removed = kernel_cache.clear()
        folder = kernel_cache.directory()
        print(f"removed {removed} cached kernel modules from {folder}" if folder else "the kernel cache is off")
        return 0
    cache = kernel_cache.info()
    if cache.directory is None:
        print("kernel cache  off (IMPLC_CACHE_DIR=off)")
        return 0
    print(f"kernel cache  {cache.directory}")
    print(f"entries       {cache.entries}")
    print(f"size          {cache.bytes / 2**20:.2f} MiB of at most {cache.limit / 2**20:.0f} MiB "
          "(IMPLC_CACHE_MAX_MB; least recently used entries go first)")
    return 0


def cmd_demo(args) -> int:
    from ..engines.surface import compile as compile_surface
    from ..files.scene import load as load_scene
    from ..native import abi
    from ..view.render import View, render_voxels, save_png
    _check_range(args.depth, "--depth", 1, 21)
    _check_render_size(args.size)
    out_dir = Path(args.out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UsageError(f"--out-dir {out_dir} exists and is not a folder")
    out_dir.mkdir(parents=True, exist_ok=True)
    n = 1 << args.depth
    print(f"implc demo: the paper's three scenes voxelized at {n}³ and rendered to {out_dir}/ "
          f"(paper, Table 1: 88 / 111 / 71 s on one SGI Challenge processor)")
    print(f"{'scene':<18}{'compile ms':>11}{'voxelize s':>11}{'voxels':>10}{'yield':>7}{'render s':>10}")
    for name in PAPER_SCENES:
        sc = load_scene(name)
        t0 = time.perf_counter()
        surface = compile_surface(sc.surface, sc.bounds)
        surface.kernel(abi.BOUND_MONOTONE)  # the default's second look at leaves: compiled, or cached, here too
        compile_ms = (time.perf_counter() - t0) * 1e3
        voxels, seconds = _voxelize(surface, args.depth, None, quiet=False)
        t0 = time.perf_counter()
        image = render_voxels(voxels, size=args.size, view=View(*(sc.view or (35.0, 25.0))))
        save_png(image, out_dir / f"{name}.png")
        render_s = time.perf_counter() - t0
        print(f"{name:<18}{compile_ms:>11.0f}{seconds:>11.2f}{len(voxels):>10}"
              f"{voxels.stats.parallel_yield:>7.0%}{render_s:>10.2f}")
    return 0


# -- entry point -----------------------------------------------------------------------------------
def _version() -> str:
    from .. import __version__
    return __version__


def _parser():
    parser = _Parser(prog="implc", description="symbolic implicit-surface compiler and voxelizer")
    parser.add_argument("--version", action="version", version=f"implc {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    sub.add_parser("scenes", help="list the built-in scenes").set_defaults(run=cmd_scenes)

    def surface_args(p):
        p.add_argument("scene", nargs="?", help="scene name (see 'implc scenes'), a scene .py or a model .vm")
        p.add_argument("--expr", help="a formula instead of a scene, e.g. 'sin(4*theta)*sin(8*phi) - r'")
        p.add_argument("--bounds", help="x0,x1,y0,y1,z0,z1 (default: the scene's, or -1,1 on each axis)")
        p.add_argument("--depth", type=int, help="grid depth: 2^depth cells per axis (default: the scene's, or 9)")
        p.add_argument("--workers", type=int, help="threads (default: all usable cores)")
        p.add_argument("--quiet", action="store_true", help="no progress bar and no summary")
        p.add_argument("--tightness", choices=tuple(TIGHTNESS),
                       help="leaves kept: natural (every leaf its enclosure keeps), default (those the linear model "
                            "misses tested again: about 1.00-1.03 voxels per sign-change cell) or tightest (slowest); "
                            "a mesh is the same for each, and made from the natural mode's unless this says otherwise")

    v = sub.add_parser("voxelize", help="voxelize a scene or formula and write .npz, .ply, .npy, .vdb or .zarr")
    surface_args(v)
    v.add_argument("-o", "--output", required=True,
                   help="output: .npz, .ply (point cloud), .npy (dense), .vdb (OpenVDB occupancy and normals grids) "
                        "or .zarr (a Zarr v3 store: occupancy, levels of detail, voxels with normals; in shards)")
    v.add_argument("--compress", action="store_true", help="deflate the .npz (smaller, several times slower)")
    v.add_argument("--solid", action="store_true",
                   help="also classify the inside (whole octants where F < 0): volume bounds, solid occupancy")
    v.add_argument("--slices", choices=("png", "tiff"),
                   help="write one 1-bit image per z layer into the folder -o names (with --solid: the solid)")
    v.add_argument("--cluster", metavar="ADDRESS",
                   help="run the tasks on a Dask cluster: tcp://host:port (a running scheduler) or local:N (N worker "
                        "processes started here); .zarr is written by the workers (a shared folder), other outputs "
                        "are gathered here first")
    v.add_argument("--resume", action="store_true",
                   help="finish the interrupted .zarr run kept in OUT.partial (same surface and options)")
    v.set_defaults(run=cmd_voxelize)

    m = sub.add_parser("mesh", help="mesh a scene, formula or .vm model: a closed, oriented, intersection-free "
                                    "triangle mesh of {F < 0} within the bounds (.stl, .obj, .ply, .glb, .3mf)")
    surface_args(m)
    m.add_argument("-o", "--output", required=True, help="output: .stl, .obj, .ply, .glb or .3mf")
    m.add_argument("--simplify", metavar="TOLERANCE",
                   help="merge the flat parts' triangles, moving no point by more than TOLERANCE (in the bounds' "
                        "units; a hundredth of a cell is plenty for CSG faces): the mesh stays closed, manifold and on "
                        "the surface")
    m.set_defaults(run=cmd_mesh)

    w = sub.add_parser("view", help="view a scene, formula, .vm model, .npz or .zarr in the browser (levels of "
                                    "detail), or a mesh (.stl, .obj, .ply, .glb, .3mf; --mesh for a surface's)")
    surface_args(w)
    w.add_argument("--port", type=int, help="port on 127.0.0.1 (default: 8765 or the next free one; 0: any)")
    w.add_argument("--no-browser", action="store_true", help="print the URL only; open no browser")
    w.add_argument("--budget", type=int, help="points the page draws at most per frame (default 1000000)")
    w.add_argument("--export", metavar="DIR", help="write a static viewer folder (page, script, chunks) instead")
    w.add_argument("--mesh", action="store_true", help="show the surface's mesh (as 'implc mesh' makes it) instead "
                                                         "of its voxels; a mesh file is shown as a mesh anyway")
    w.set_defaults(run=cmd_view)

    r = sub.add_parser("render", help="render a scene, formula, .npz or .zarr to a PNG")
    surface_args(r)
    r.add_argument("-o", "--output", required=True, help="output .png")
    r.add_argument("--size", type=int, default=1024, help="image size in pixels (default 1024)")
    r.add_argument("--view", help="azimuth,elevation in degrees (default: the scene's, or 35,25)")
    r.add_argument("--lod", type=int, help="draw octree level K instead of the voxels")
    r.add_argument("--cut", help="cut-away: remove what lies beyond AXIS=VALUE (e.g. z=0) and draw the section")
    r.add_argument("--solid", action="store_true", help="voxelize a solid (the section of a cut is filled)")
    r.add_argument("--perspective", action="store_true", help="perspective camera (default orthographic)")
    r.add_argument("--color", help="surface colour R,G,B in 0..1")
    r.set_defaults(run=cmd_render)

    i = sub.add_parser("info", help="describe a voxel file (.npz, .ply, .npy, .vdb, .zarr), a mesh "
                                    "(.stl, .obj, .ply, .glb, .3mf) or a model (.vm)")
    i.add_argument("file")
    i.set_defaults(run=cmd_info)

    sub.add_parser("bench", help="run the benchmark suite (options: 'implc bench --help')", add_help=False)

    c = sub.add_parser("cache", help="show the kernel cache's location and size, or clear it")
    c.add_argument("action", nargs="?", choices=["info", "clear"], default="info",
                   help="info (default): where it is and how big; clear: remove every entry")
    c.set_defaults(run=cmd_cache)

    d = sub.add_parser("demo", help="voxelize the paper's three scenes at 512³ and render them")
    d.add_argument("--depth", type=int, default=9, help="grid depth (default 9: 512³)")
    d.add_argument("--size", type=int, default=1024, help="image size (default 1024)")
    d.add_argument("--out-dir", default="implc-demo", help="where the PNGs go (default ./implc-demo)")
    d.set_defaults(run=cmd_demo)
    return parser


NUMBER_LIST_OPTIONS = ("--bounds", "--view", "--color")


OPTIONS = ("-o", "--output", "--expr", "--bounds", "--depth", "--workers", "--quiet", "--compress", "--size",
           "--view", "--lod", "--perspective", "--color", "-h", "--help")


def _takes_dash_value(option: str, value: str) -> bool:
    if not value.startswith("-"):
        return False
    if option in NUMBER_LIST_OPTIONS:
        return value[1:2] in tuple("0123456789.,")
    # "-x + 1" is a formula; an option name is not
    return option == "--expr" and value.split("=")[0] not in OPTIONS


def _attach_negative_values(argv: list[str]) -> list[str]:
    """``--bounds -1,1,...`` as ``--bounds=-1,1,...`` (and ``--expr -x`` as ``--expr=-x``): argparse would
    read a value starting with '-' as an option (the README's own example failed)."""
    out, k = [], 0
    while k < len(argv):
        if k + 1 < len(argv) and _takes_dash_value(argv[k], argv[k + 1]):
            out.append(f"{argv[k]}={argv[k + 1]}")
            k += 2
        else:
            out.append(argv[k])
            k += 1
    return out


_signalled: list[int] = []
"""The signals main() saw: an import that an interrupt broke (numpy wraps it in an ImportError) is then
reported as the interrupt, not as a broken installation."""

_settled = False
"""True once main()'s outcome is decided: a signal then is only noted (raised there, it would escape main()
as a traceback). A plain global, set by one store that runs no Python code, so no signal handler can run
half-way through setting it (a CI run's SIGINT once landed inside threading.Event.set)."""


REDELIVER_SECONDS = 0.01
"""How soon a signal that landed in a callback is sent again (:func:`_deliver`)."""


def _on_sigterm(signum, frame):
    _deliver(signum, frame, _Terminated)


def _on_sigint(signum, frame):
    _deliver(signum, frame, KeyboardInterrupt)


def _deliver(signum, frame, exception: type[BaseException]) -> None:
    """Raise ``exception`` where the signal landed, unless the outcome is decided (:data:`_settled`: only
    noted) or it landed in a callback whose exceptions Python prints and drops (:func:`_in_a_callback`):
    raised there, it would be lost, printed as a traceback, and the command would go on. Then the signal
    is sent again a moment later, once the callback is done (a CI run's SIGTERM landed in an import lock's
    weakref callback)."""
    if not _settled and _in_a_callback(frame):
        timer = threading.Timer(REDELIVER_SECONDS, os.kill, (os.getpid(), signum))
        timer.daemon = True
        timer.start()
        return
    _signalled.append(signum)
    if not _settled:
        raise exception


def _in_a_callback(frame) -> bool:
    """Whether a frame on the stack runs a callback whose exceptions Python prints and drops instead of
    raising them: a finalizer (``__del__``) or importlib's module-lock weakref callback."""
    while frame is not None:
        code = frame.f_code
        if code.co_name == "__del__" or (code.co_name == "cb" and code.co_filename.startswith("<frozen importlib")):
            return True
        frame = frame.f_back
    return False


def _run(argv) -> int:
    if argv[:1] == ["bench"]:  # the suite parses its own options
        return cmd_bench(argv[1:])
    parser = _parser()
    args = parser.parse_args(_attach_negative_values(argv))
    if hasattr(args, "tightness"):
        args.tightness = _tightness(args)
    _check_no_empty_values(parser, args)
    global _output
    _output = getattr(args, "output", None) or getattr(args, "export", None)
    return args.run(args)


_output: str | None = None
"""The file or folder the running command writes last (None for commands that write none or several)."""


def _output_complete(done_before: int) -> str | None:
    """The command's output if it was put in place during this run (a signal came after that)."""
    atomic_file = sys.modules.get("implc.common.atomic_file")  # not imported: nothing was written
    if _output is None or atomic_file is None:
        return None
    done = atomic_file.COMPLETED[done_before:]
    return _output if any(Path(p) == Path(_output) for p in done) else None


def _check_no_empty_values(parser, args):
    """An option given an empty value (``--export ''``, ``--bounds ''``) is an error, never 'not given'."""
    actions = [a for a in parser._actions if a.option_strings]
    for sub in parser._subparsers._group_actions if parser._subparsers else []:
        for command in sub.choices.values():
            actions += [a for a in command._actions if a.option_strings]
    for action in actions:
        value = getattr(args, action.dest, None)
        if isinstance(value, str) and not value.strip():
            raise UsageError(f"{max(action.option_strings, key=len)} is empty: give it a value or leave it out")


def main(argv=None, *, restore_handlers: bool = True) -> int:
    """Run one command line; returns its exit status. ``python -m implc`` passes ``restore_handlers=False``:
    the process ends right after, and with main()'s handlers still in place a signal that lands then is
    noted, not raised as a traceback on the way out."""
    global _settled
    argv = sys.argv[1:] if argv is None else list(argv)
    in_main_thread = threading.current_thread() is threading.main_thread()
    _settled = False
    _signalled.clear()
    atomic_file = sys.modules.get("implc.common.atomic_file")
    done_before = len(atomic_file.COMPLETED) if atomic_file else 0
    previous: dict[signal.Signals, typing.Any] = {}
    try:
        if in_main_thread:
            previous[signal.SIGTERM] = signal.signal(signal.SIGTERM, _on_sigterm)
            previous[signal.SIGINT] = signal.signal(signal.SIGINT, _on_sigint)
        return _outcome(argv, done_before)
    except (KeyboardInterrupt, _Terminated) as exc:  # the signal came while an outcome was being reported
        return _interrupted(exc, done_before)
    finally:
        _settled = True  # first: the handlers below run with the outcome decided
        if restore_handlers:
            for signum, handler in previous.items():
                signal.signal(signum, handler)


def _outcome(argv, done_before: int) -> int:
    """Run the command; an error is one line on stderr and exit status 2, a signal 130 (SIGINT) or 143."""
    try:
        return _run(argv)
    except (UsageError, ValueError, MemoryError, OSError, RecursionError) as exc:
        # ValueError covers CompileError, SceneError, VoxelFileError and the API's own checks
        message = " ".join(str(exc).split()) or type(exc).__name__
        if isinstance(exc, RecursionError):
            message = "the input is nested too deeply"
        elif isinstance(exc, OSError) and exc.filename and exc.strerror:
            message = f"{exc.filename}: {exc.strerror}"
        if len(message) > MESSAGE_LIMIT:
            message = message[: MESSAGE_LIMIT - 3] + "..."
        print(f"implc: error: {message}", file=sys.stderr)
        return 2
    except ImportError:
        if not _signalled:
            raise
        # a signal during an import, wrapped by the importer
        terminated = _signalled[0] == signal.SIGTERM
        print(f"implc: {'terminated' if terminated else 'interrupted'}", file=sys.stderr)
        return 143 if terminated else 130
    except (KeyboardInterrupt, _Terminated) as exc:
        return _interrupted(exc, done_before)


def _interrupted(exc: BaseException, done_before: int) -> int:
    """The exit status after a signal: 0 where the output was written in full first, else 130 or 143."""
    complete = _output_complete(done_before)
    if complete is not None:  # the save finished first: the output is whole, the command succeeded
        print(f"implc: {complete} was written in full before the signal", file=sys.stderr)
        return 0
    print(f"implc: {'interrupted' if isinstance(exc, KeyboardInterrupt) else 'terminated'}", file=sys.stderr)
    return 130 if isinstance(exc, KeyboardInterrupt) else 143


def console() -> int:
    """The ``implc`` script: main() for a process that ends when it returns."""
    return main(restore_handlers=False)


if __name__ == "__main__":
    sys.exit(console())
