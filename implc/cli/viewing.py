"""The commands that show things: implc view (the browser viewer, served or exported) and implc info."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from .arguments import (
    UsageError,
    check_folder_writable,
    check_range,
    check_surface_options,
    refuse_surface_options,
    surface_from_args,
    voxelize_with,
)


def cmd_view(args) -> int:
    from ..files import voxel_files
    from ..meshing.triangle_mesh import MeshFileError, is_mesh_file
    from ..meshing.triangle_mesh import load as load_mesh
    from ..view.mesh_payload import MeshPayload
    from ..view.page import lod_chunks
    if args.port is not None:
        check_range(args.port, "--port", 0, 65535)
    if args.budget is not None:
        check_range(args.budget, "--budget", 1000, 1_000_000_000)
    budget = args.budget or 1_000_000
    if args.export is not None:
        check_folder_writable(Path(args.export), "a static viewer")
    suffix = Path(args.scene).suffix.lower() if args.scene else ""
    if args.watch:
        return _watch(args, budget, suffix)
    if suffix in (".npz", ".zarr"):
        refuse_surface_options(args, "voxel", "shown")
        voxels, name, view = voxel_files.load(args.scene), Path(args.scene).stem, None
    elif suffix in (".ply", ".stl", ".obj", ".glb", ".3mf") and is_mesh_file(args.scene):
        refuse_surface_options(args, "mesh", "shown", ("--budget", args.budget))
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
        check_surface_options(args)
        name, surface, sc = surface_from_args(args)
        depth = args.depth if args.depth is not None else (sc.depth if sc else 9)
        voxels, _ = voxelize_with(surface, depth, args.workers, args.quiet, tightness=args.tightness)
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


def _watch(args, budget: int, suffix: str) -> int:
    """``implc view SCENE.py --watch``: the scene built in a child process, then rebuilt on every save."""
    from ..files.scene import SceneError
    from ..files.scene import load as load_scene
    from .arguments import TIGHTNESS, given_bounds, tightness_of
    from .watch import BuildError, Job, Watcher
    if suffix != ".py" or args.expr is not None:
        raise UsageError("--watch follows a scene file (a .py path): it rebuilds the file each time it is saved")
    if args.export is not None:
        raise UsageError("--watch serves the page: it cannot --export a static viewer")
    if not Path(args.scene).is_file():
        load_scene(args.scene)  # the scene loader's own line: no such file, or a folder
    check_surface_options(args)
    options = {"workers": args.workers, **TIGHTNESS[tightness_of(args)]}
    job = Job(str(Path(args.scene).resolve()), args.depth, given_bounds(args), args.mesh, options)
    name = Path(args.scene).name

    def say(line: str):
        print(f"{time.strftime('%H:%M:%S')} {line}", file=sys.stderr, flush=True)

    def serving(server):
        def built(build):
            server.replace(build.shown())
            if not args.quiet:
                say(f"{build.name}: {build.summary()}")

        def failed(line: str):
            server.report(error=line)
            say(f"{name}: {line} (the page keeps the last good model)")

        watcher.on_build, watcher.on_error = built, failed
        watcher.on_start = lambda: server.report(building=True)
        watcher.start()

    watcher = Watcher(job, on_build=None, on_error=None)
    try:
        try:
            first = watcher.first()
        except BuildError as error:
            raise SceneError(str(error)) from None
        return _view(first.shown(), args, budget, f"{first.summary()}; watching {name} for saves",
                     serving=serving)
    finally:
        watcher.close()


def _view(shown, args, budget: int, what: str, serving=None) -> int:
    """Export ``shown`` (the chunks of voxels, or a mesh's payload) as a static viewer, or serve it
    (``serving(server)``, where given, is called once the server listens: a live one)."""
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
        server = ViewServer(shown, port=args.port, budget=budget, live=serving is not None)
    except OSError as exc:
        raise UsageError(f"cannot listen on 127.0.0.1:{args.port if args.port is not None else DEFAULT_PORT}: "
                         f"{exc.strerror or exc}") from None
    try:
        print(f"implc view: {name}, {what}\n{server.url}\n"
              "(Ctrl-C stops the server)", flush=True)
        if serving is not None:
            serving(server)
        if not args.no_browser:
            import webbrowser
            webbrowser.open(server.url)
        server.serve_forever()
    finally:
        server.close()
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
    from ..files.store_place import is_url
    folder = Path(args.file)
    store = folder.is_dir() and (folder.suffix.lower() == ".zarr" or (folder / "zarr.json").is_file())  # .partial too
    if is_url(args.file) or store:
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
