"""The commands that make things: implc scenes, voxelize, mesh, render and demo."""

from __future__ import annotations

import sys
import time
import typing
from pathlib import Path

from .arguments import (
    PAPER_SCENES,
    TIGHTNESS,
    UsageError,
    check_folder_writable,
    check_range,
    check_render_size,
    check_surface_options,
    check_writable,
    parse_color,
    parse_cut,
    parse_numbers,
    parse_tolerance,
    refuse_surface_options,
    surface_from_args,
    voxelize_with,
)


def cmd_scenes(args) -> int:
    from ..files.scene import available, load
    for name in available():
        print(f"{name:<20} {load(name).title}")
    return 0


def cmd_voxelize(args) -> int:
    from ..files import voxel_files
    from ..files.store_place import is_url, place_of
    remote = is_url(args.output)
    out: typing.Any = args.output if remote else Path(args.output)
    if remote and (args.slices or voxel_files.suffix_of(out) != ".zarr"):
        raise UsageError(f"{out}: an object store's URL takes a .zarr store (write other outputs to a file)")
    if remote:
        place_of(out)  # an unknown protocol, a missing library or credentials in the URL: refused before any work
    elif args.slices:
        check_folder_writable(out, "slices")
    else:
        check_writable(out, voxel_files.SUFFIXES)
    check_surface_options(args)
    name, surface, sc = surface_from_args(args)
    depth = args.depth if args.depth is not None else (sc.depth if sc else 9)
    zarr_out = voxel_files.suffix_of(out) == ".zarr" and not args.slices
    if args.resume and not zarr_out:
        raise UsageError("--resume finishes an interrupted .zarr run; other outputs are written whole or not at all")
    if args.cluster is not None:
        from ..cluster.tasks import parse_address
        parse_address(args.cluster)  # a bad address is refused before any work
    say = None if args.quiet else (lambda line: print(line, file=sys.stderr))
    if zarr_out:  # streamed: the voxels are never all in memory (on a cluster: tasks own their shards)
        from ..files.zarr_writer import write_zarr
        t0 = time.perf_counter()
        result: typing.Any
        kept = place_of(out if remote else out.with_name(out.name + ".partial"))
        refusable = kept.exists()  # a refusal to start over it is not a run that stopped
        try:
            result = write_zarr(surface, depth, out, solid=args.solid, workers=args.workers, cluster=args.cluster,
                                resume=args.resume, progress=not args.quiet and sys.stderr.isatty(), say=say,
                                **TIGHTNESS[args.tightness])
        except BaseException as exc:
            if kept.exists() and not (refusable and isinstance(exc, ValueError)):
                print(f"implc: the finished tasks are kept in {kept.url}: the same command with --resume "
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
            result, seconds = voxelize_with(surface, depth, args.workers, args.quiet, solid=args.solid,
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
    check_writable(out, (".png",))
    check_render_size(args.size)
    check_surface_options(args)
    view_angles = parse_numbers(args.view, 2, "--view", "azimuth,elevation") if args.view else None
    style = Style(color=parse_color(args.color)) if args.color else Style()
    if args.scene and Path(args.scene).suffix.lower() in (".npz", ".ply", ".npy", ".zarr"):
        refuse_surface_options(args, "voxel", "rendered")
        voxels = voxel_files.load(args.scene)
        default_view = None
    else:
        _, surface, sc = surface_from_args(args)
        depth = args.depth if args.depth is not None else (sc.depth if sc else 9)
        voxels, _ = voxelize_with(surface, depth, args.workers, args.quiet, solid=args.solid, tightness=args.tightness)
        default_view = sc.view if sc else None
    azimuth, elevation = view_angles or default_view or (35.0, 25.0)
    if args.lod is not None and not 1 <= args.lod <= voxels.depth:
        raise UsageError(f"--lod must be from 1 to {voxels.depth}, got {args.lod}")
    cut = parse_cut(args.cut, voxels) if args.cut else None
    if cut is not None and args.lod is not None:
        raise UsageError("--cut draws the voxels themselves; it cannot be combined with --lod")
    t0 = time.perf_counter()
    image = render_voxels(voxels, size=args.size, view=View(azimuth, elevation, perspective=args.perspective),
                          style=style, lod=args.lod, cut=cut)
    save_png(image, out)
    if not args.quiet:
        print(f"rendered {len(voxels)} voxels to {out} ({args.size}² in {time.perf_counter() - t0:.2f} s)")
    return 0


def cmd_mesh(args) -> int:
    from ..meshing.contour import MAX_DEPTH
    from ..meshing.triangle_mesh import MESH_SUFFIXES
    out = Path(args.output)
    check_writable(out, MESH_SUFFIXES)
    check_surface_options(args)
    check_range(args.depth, "--depth", 1, MAX_DEPTH)
    tolerance = parse_tolerance(args.simplify)
    name, surface, sc = surface_from_args(args)
    depth = args.depth if args.depth is not None else (sc.depth if sc else 8)
    voxels, seconds = voxelize_with(surface, depth, args.workers, args.quiet, tightness=args.tightness)
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


def cmd_demo(args) -> int:
    from ..engines.surface import compile as compile_surface
    from ..files.scene import load as load_scene
    from ..native import abi
    from ..view.render import View, render_voxels, save_png
    check_range(args.depth, "--depth", 1, 21)
    check_render_size(args.size)
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
        voxels, seconds = voxelize_with(surface, args.depth, None, quiet=False)
        t0 = time.perf_counter()
        image = render_voxels(voxels, size=args.size, view=View(*(sc.view or (35.0, 25.0))))
        save_png(image, out_dir / f"{name}.png")
        render_s = time.perf_counter() - t0
        print(f"{name:<18}{compile_ms:>11.0f}{seconds:>11.2f}{len(voxels):>10}"
              f"{voxels.stats.parallel_yield:>7.0%}{render_s:>10.2f}")
    return 0
