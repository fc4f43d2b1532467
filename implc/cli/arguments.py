"""The command line's arguments: usage errors, numbers and bounds parsed, outputs checked writable before any
work, the surface a command names (a scene, a file, an --expr formula), the tightness presets."""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

from ..errors import shorten

PAPER_SCENES = ("paper_blobs", "paper_sin4_sin8", "paper_sin3_sin4")


DEFAULT_BOUNDS = "-1,1,-1,1,-1,1"


class UsageError(Exception):
    """A problem with what the user asked for: reported in one line, exit status 2."""


class Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse prints a usage block; the contract is one line
        raise UsageError(f"{message} (see '{self.prog} --help')")


_COUNT_WORDS = {1: "one", 2: "two", 3: "three", 6: "six"}


def parse_numbers(text, count, what, example):
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
    v = parse_numbers(text, 6, "--bounds", "x0,x1,y0,y1,z0,z1")
    return ((v[0], v[1]), (v[2], v[3]), (v[4], v[5]))


def given_bounds(args):
    """--bounds as ((x0, x1), (y0, y1), (z0, z1)), or None where it is not given."""
    return _bounds(args.bounds) if args.bounds else None


def check_writable(path: Path, suffixes):
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


def check_render_size(size):
    """--size: 16 to the renderer's largest image, and its working memory available."""
    from ..view.render import BYTES_PER_PIXEL, MAX_SIZE
    from ..voxelizer.voxelize import available_memory
    check_range(size, "--size", 16, MAX_SIZE)
    need = BYTES_PER_PIXEL * size * size
    if need > available_memory():
        raise UsageError(f"--size {size} needs about {need / 2**30:.1f} GiB to render, more than the "
                         f"{available_memory() / 2**30:.1f} GiB available")


def check_range(value, name, lo, hi):
    if value is not None and not lo <= value <= hi:
        raise UsageError(f"{name} must be an integer from {lo} to {hi}, got {value}")


def surface_from_args(args):
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
        return model.name, compile_surface(model, given_bounds(args)), None
    if Path(args.scene).suffix.lower() in (".npz", ".ply", ".npy"):
        raise UsageError(f"{args.scene} is a voxel file: 'implc {args.command}' takes a scene or --expr"
                         + (" (render reads .npz files)" if args.command == "voxelize" else ""))
    from ..files.scene import load as load_scene
    sc = load_scene(args.scene)
    bounds = given_bounds(args) or sc.bounds
    return sc.name, compile_surface(sc.surface, bounds), sc


TIGHTNESS: dict[str, dict] = {"natural": {"mean_value_levels": 0, "refine_leaves": False}, "default": {},
             "tightest": {"mean_value_levels": 1, "refine_leaves": "auto"}}
"""--tightness: implc.NATURAL, the default and implc.TIGHTEST (spelt out: importing them would load NumPy)."""


def voxelize_with(surface, depth, workers, quiet, solid=False, tightness="default"):
    from ..voxelizer.voxelize import voxelize
    t0 = time.perf_counter()
    voxels = voxelize(surface, depth, workers=workers, progress=not quiet and sys.stderr.isatty(), solid=solid,
                      **TIGHTNESS[tightness])
    return voxels, time.perf_counter() - t0


def tightness_of(args) -> str:
    """--tightness as given, or its default: the natural mode where the voxels are only meshed (the mesh is
    the same for every tightness, :func:`implc.mesh`), the default mode otherwise."""
    if args.tightness is not None:
        return args.tightness
    return "natural" if args.command == "mesh" or getattr(args, "mesh", False) else "default"


def refuse_surface_options(args, kind: str, shown: str, *more):
    """One line naming the options given that only a surface takes, where ``args.scene`` is a ``kind`` file
    (``more``: further (flag, value) pairs that do not apply to it)."""
    given = [flag for flag, value in (("--expr", args.expr), ("--depth", args.depth), ("--bounds", args.bounds),
                                      ("--workers", args.workers), *more) if value is not None]
    if given:
        raise UsageError(f"{', '.join(given)} cannot apply to a {kind} file ({args.scene}): it is {shown} as saved")


def check_surface_options(args):
    check_range(args.depth, "--depth", 1, 21)
    if args.workers is not None:
        from ..common.threads import max_workers
        if not 1 <= args.workers <= max_workers():
            raise UsageError(f"--workers must be from 1 to {max_workers()} (four per usable core here), "
                             f"got {args.workers}")


def check_folder_writable(path: Path, what: str):
    """A folder ``what`` goes to (slices, a static viewer): new, or an existing folder to replace; its
    parent must exist and be writable."""
    if path.exists() and not path.is_dir():
        raise UsageError(f"cannot write {what} to {path}: it is a file (name a folder)")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise UsageError(f"cannot write {path}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise UsageError(f"cannot write {path}: permission denied")


def parse_cut(text, voxels) -> tuple[int, float]:
    """--cut AXIS=VALUE (x, y or z, a number inside the bounds) as (axis, value)."""
    axis, sep, value = text.partition("=")
    if not sep or axis.strip() not in ("x", "y", "z"):
        raise UsageError(f"--cut must be AXIS=VALUE with AXIS x, y or z, got {text!r}")
    (number,) = parse_numbers(value, 1, "--cut", "AXIS=VALUE")
    a = "xyz".index(axis.strip())
    lo, hi = voxels.bounds[a]
    if not lo <= number <= hi:
        raise UsageError(f"--cut {text}: {axis.strip()} must lie within the bounds {lo}..{hi}")
    return a, number


def parse_color(text):
    rgb = parse_numbers(text, 3, "--color", "R,G,B")
    if not all(0 <= c <= 1 for c in rgb):
        raise UsageError(f"--color must be three numbers from 0 to 1 'R,G,B', got "
                         f"{shorten(text, quoted=True)}")
    return tuple(rgb)


def parse_tolerance(text):
    """--simplify's tolerance (None where not given); a usage error unless a positive finite number."""
    if text is None:
        return None
    from ..meshing.simplify import check_tolerance
    try:
        return check_tolerance(float(text))
    except ValueError:
        raise UsageError(f"--simplify takes a positive tolerance in the bounds' units, got "
                         f"{shorten(text, quoted=True)}") from None
