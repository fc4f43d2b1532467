"""The implc command's parser: its subcommands and options, negative numbers taken as option values, empty
values refused."""

from __future__ import annotations

from .arguments import (
    TIGHTNESS,
    Parser,
    UsageError,
)
from .outputs import cmd_demo, cmd_mesh, cmd_render, cmd_scenes, cmd_voxelize
from .upkeep import cmd_cache
from .viewing import cmd_info, cmd_view


def _version() -> str:
    from .. import __version__
    return __version__


def build_parser():
    parser = Parser(prog="implc", description="symbolic implicit-surface compiler and voxelizer")
    parser.add_argument("--version", action="version", version=f"implc {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

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
                        "or .zarr (a Zarr v3 store: occupancy, levels of detail, voxels with normals; in shards), "
                        "also at an object store's URL (s3://bucket/run.zarr; credentials from the environment)")
    v.add_argument("--compress", action="store_true", help="deflate the .npz (smaller, several times slower)")
    v.add_argument("--solid", action="store_true",
                   help="also classify the inside (whole octants where F < 0): volume bounds, solid occupancy")
    v.add_argument("--slices", choices=("png", "tiff"),
                   help="write one 1-bit image per z layer into the folder -o names (with --solid: the solid)")
    v.add_argument("--cluster", metavar="ADDRESS",
                   help="run the tasks on a Dask cluster: tcp://host:port (a running scheduler) or local:N (N worker "
                        "processes started here); .zarr is written by the workers (to a shared folder or an object "
                        "store's URL), other outputs are gathered here first")
    v.add_argument("--resume", action="store_true",
                   help="finish the interrupted .zarr run kept in OUT.partial, or under the URL (same surface "
                        "and options)")
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
    w.add_argument("--watch", action="store_true", help="rebuild the scene file each time it (or a module beside "
                                                          "it) is saved and update the open page in place; an error "
                                                          "shows there, the last good model stays")
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


def attach_negative_values(argv: list[str]) -> list[str]:
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


def check_no_empty_values(parser, args):
    """An option given an empty value (``--export ''``, ``--bounds ''``) is an error, never 'not given'."""
    actions = [a for a in parser._actions if a.option_strings]
    for sub in parser._subparsers._group_actions if parser._subparsers else []:
        for command in sub.choices.values():
            actions += [a for a in command._actions if a.option_strings]
    for action in actions:
        value = getattr(args, action.dest, None)
        if isinstance(value, str) and not value.strip():
            raise UsageError(f"{max(action.option_strings, key=len)} is empty: give it a value or leave it out")
