"""The ``implc`` command: list scenes, voxelize, render, inspect files, the kernel cache, and the demo.

Every failure the user can cause (a missing or broken scene, a bad formula, depth or size, an unwritable
output) ends with one line on stderr and exit status 2; Ctrl-C ends with status 130.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from pathlib import Path

from . import kernel_cache, voxel_files
from . import scene as scenes
from .errors import CompileError
from .expr import ExprError
from .expr import parse as parse_expr
from .render import Style, View, render_voxels, save_png
from .surface import compile as compile_surface
from .voxelize import voxelize

PAPER_SCENES = ("paper_blobs", "paper_sin4_sin8", "paper_sin3_sin4")


class UsageError(Exception):
    """A problem with what the user asked for: reported in one line, exit status 2."""


# -- helpers ---------------------------------------------------------------------------------------
def _pair(text, what):
    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        raise UsageError(f"{what} must be two numbers 'A,B', got {text!r}") from None
    return a, b


def _bounds(text):
    try:
        v = [float(t) for t in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 6:
        raise UsageError(f"--bounds must be six numbers 'x0,x1,y0,y1,z0,z1', got {text!r}")
    return ((v[0], v[1]), (v[2], v[3]), (v[4], v[5]))


def _check_writable(path: Path, suffixes):
    if path.suffix not in suffixes:
        raise UsageError(f"unknown output format {path.suffix or '(none)'!r} for {path}: use {', '.join(suffixes)}")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise UsageError(f"cannot write {path}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise UsageError(f"cannot write {path}: permission denied")


def _surface_from_args(args):
    """(name, compiled surface, scene or None) from SCENE or --expr."""
    if getattr(args, "expr", None):
        if args.scene:
            raise UsageError("give either a SCENE or --expr, not both")
        expr = parse_expr(args.expr)
        bounds = _bounds(args.bounds) if args.bounds else ((-1, 1), (-1, 1), (-1, 1))
        return args.expr, compile_surface(expr, bounds), None
    if not args.scene:
        raise UsageError("name a SCENE (see 'implc scenes') or give --expr")
    sc = scenes.load(args.scene)
    bounds = _bounds(args.bounds) if getattr(args, "bounds", None) else sc.bounds
    return sc.name, compile_surface(sc.surface, bounds), sc


def _voxelize(name, surface, depth, workers, quiet):
    t0 = time.perf_counter()
    voxels = voxelize(surface, depth, workers=workers, progress=not quiet and sys.stderr.isatty())
    seconds = time.perf_counter() - t0
    return voxels, seconds


# -- commands --------------------------------------------------------------------------------------
def cmd_scenes(args) -> int:
    for name in scenes.available():
        sc = scenes.load(name)
        print(f"{name:<20} {sc.title}")
    return 0


def cmd_voxelize(args) -> int:
    out = Path(args.output)
    _check_writable(out, (".npz", ".ply", ".npy"))
    name, surface, sc = _surface_from_args(args)
    depth = args.depth if args.depth is not None else (sc.depth if sc else 9)
    voxels, seconds = _voxelize(name, surface, depth, args.workers, args.quiet)
    voxel_files.save(voxels, out)
    if not args.quiet:
        print(f"{name}: {len(voxels)} voxels at {1 << depth}³ in {seconds:.2f} s "
              f"(yield {voxels.stats.parallel_yield:.0%}) -> {out}")
    return 0


def cmd_render(args) -> int:
    out = Path(args.output)
    _check_writable(out, (".png",))
    if not 16 <= args.size <= 16384:
        raise UsageError(f"--size must be from 16 to 16384 pixels, got {args.size}")
    view_angles = _pair(args.view, "--view") if args.view else None
    if args.scene and args.scene.endswith(".npz"):
        voxels = voxel_files.load_npz(args.scene)
        default_view = None
    else:
        name, surface, sc = _surface_from_args(args)
        depth = args.depth if args.depth is not None else (sc.depth if sc else 9)
        voxels, _ = _voxelize(name, surface, depth, args.workers, args.quiet)
        default_view = sc.view if sc else None
    azimuth, elevation = view_angles or default_view or (35.0, 25.0)
    style = Style(color=_color(args.color)) if args.color else Style()
    if args.lod is not None and not 1 <= args.lod <= voxels.depth:
        raise UsageError(f"--lod must be from 1 to {voxels.depth}, got {args.lod}")
    t0 = time.perf_counter()
    image = render_voxels(voxels, size=args.size, view=View(azimuth, elevation, perspective=args.perspective),
                          style=style, lod=args.lod)
    save_png(image, out)
    if not args.quiet:
        print(f"rendered {len(voxels)} voxels to {out} ({args.size}² in {time.perf_counter() - t0:.2f} s)")
    return 0


def _color(text):
    rgb = [float(v) for v in text.split(",")] if text.count(",") == 2 else []
    if len(rgb) != 3 or not all(0 <= c <= 1 for c in rgb):
        raise UsageError(f"--color must be three numbers from 0 to 1 'R,G,B', got {text!r}")
    return tuple(rgb)


def cmd_info(args) -> int:
    voxels = voxel_files.load_npz(args.file)
    n = 1 << voxels.depth
    size = Path(args.file).stat().st_size
    lo = voxels.coords.min(axis=0) if len(voxels) else [0, 0, 0]
    hi = voxels.coords.max(axis=0) if len(voxels) else [0, 0, 0]
    print(f"file     {args.file} ({size / 2**20:.1f} MiB)")
    print(f"grid     {n}³ (depth {voxels.depth}) over {voxels.bounds}")
    print(f"voxels   {len(voxels)} ({len(voxels) / n**3:.4%} of the cells)")
    print(f"extent   cells {list(map(int, lo))} .. {list(map(int, hi))}")
    return 0


def cmd_bench(argv) -> int:
    """Run the benchmark suite of the source checkout this package was imported from: benchmarks/ is a
    client of implc, not part of the package."""
    suite = Path(__file__).resolve().parent.parent / "benchmarks" / "suite.py"
    if not suite.is_file():
        raise UsageError(f"'implc bench' runs the benchmark suite of a source checkout; there is none at {suite}")
    spec = importlib.util.spec_from_file_location("implc_benchmark_suite", suite)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main(argv)


def cmd_cache(args) -> int:
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
    out_dir = Path(args.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    n = 1 << args.depth
    print(f"implc demo: the paper's three scenes voxelized at {n}³ and rendered to {out_dir}/ "
          f"(paper, Table 1: 88 / 111 / 71 s on one SGI Challenge processor)")
    print(f"{'scene':<18}{'compile ms':>11}{'voxelize s':>11}{'voxels':>10}{'yield':>7}{'render s':>10}")
    for name in PAPER_SCENES:
        sc = scenes.load(name)
        t0 = time.perf_counter()
        surface = compile_surface(sc.surface, sc.bounds)
        compile_ms = (time.perf_counter() - t0) * 1e3
        voxels, seconds = _voxelize(name, surface, args.depth, None, quiet=False)
        t0 = time.perf_counter()
        image = render_voxels(voxels, size=args.size, view=View(*(sc.view or (35.0, 25.0))))
        save_png(image, out_dir / f"{name}.png")
        render_s = time.perf_counter() - t0
        print(f"{name:<18}{compile_ms:>11.0f}{seconds:>11.2f}{len(voxels):>10}"
              f"{voxels.stats.parallel_yield:>7.0%}{render_s:>10.2f}")
    return 0


# -- entry point -----------------------------------------------------------------------------------
def _parser():
    parser = argparse.ArgumentParser(prog="implc", description="symbolic implicit-surface compiler and voxelizer")
    sub = parser.add_subparsers(dest="command", required=True)

    sub.add_parser("scenes", help="list the built-in scenes").set_defaults(run=cmd_scenes)

    def surface_args(p):
        p.add_argument("scene", nargs="?", help="scene name (see 'implc scenes') or path to a scene .py")
        p.add_argument("--expr", help="a formula instead of a scene, e.g. 'sin(4*theta)*sin(8*phi) - r'")
        p.add_argument("--bounds", help="x0,x1,y0,y1,z0,z1 (default: the scene's, or -1,1 on each axis)")
        p.add_argument("--depth", type=int, help="grid depth: 2^depth cells per axis (default: the scene's, or 9)")
        p.add_argument("--workers", type=int, help="threads (default: all usable cores)")
        p.add_argument("--quiet", action="store_true", help="no progress bar and no summary")

    v = sub.add_parser("voxelize", help="voxelize a scene or formula and write .npz, .ply or .npy")
    surface_args(v)
    v.add_argument("-o", "--output", required=True, help="output file: .npz, .ply (point cloud) or .npy (dense)")
    v.set_defaults(run=cmd_voxelize)

    r = sub.add_parser("render", help="render a scene, formula or .npz to a PNG")
    surface_args(r)
    r.add_argument("-o", "--output", required=True, help="output .png")
    r.add_argument("--size", type=int, default=1024, help="image size in pixels (default 1024)")
    r.add_argument("--view", help="azimuth,elevation in degrees (default: the scene's, or 35,25)")
    r.add_argument("--lod", type=int, help="draw octree level K instead of the voxels")
    r.add_argument("--perspective", action="store_true", help="perspective camera (default orthographic)")
    r.add_argument("--color", help="surface colour R,G,B in 0..1")
    r.set_defaults(run=cmd_render)

    i = sub.add_parser("info", help="describe a voxel .npz")
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


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        if argv[:1] == ["bench"]:  # the suite parses its own options
            return cmd_bench(argv[1:])
        args = _parser().parse_args(argv)
        return args.run(args)
    except (UsageError, ExprError, CompileError, scenes.SceneError, voxel_files.VoxelFileError, MemoryError,
            ValueError, OSError) as exc:
        message = str(exc) or type(exc).__name__
        if isinstance(exc, ExprError):
            message = f"--expr: {message}"
        print(f"implc: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("implc: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
