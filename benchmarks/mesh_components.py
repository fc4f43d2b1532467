"""Why a mesh has the components it has: the mesh's connected components (sharing a vertex), against the
regions of the grid's sampled signs (F < 0 at a corner: inside; NaN and the outside of the bounds:
outside, as the mesher takes them) joined along the Kuhn split's edges, whose borders the Kuhn split's mesh
(the tetrahedral construction everywhere, ``lean=False, features=False``) has one closed surface each; and
the components that are bubbles around one point the fans added (none is expected). Example::

    python benchmarks/mesh_components.py paper_sin4_sin8 --depth 8
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import implc
from implc.files import scene
from implc.meshing.contour import contour

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the checkout: its tests' helpers
from tests.support.components import components, lone_point_bubbles, sign_regions  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="+")
    p.add_argument("--depth", type=int, default=8)
    args = p.parse_args(argv)
    print("| scene | grid | components | of them bubbles around an added point | Kuhn split everywhere | "
          "sampled regions in + out | their borders |")
    print("|---|---|---|---|---|---|---|")
    for name in args.scenes:
        sc = scene.load(name)
        surface = implc.compile(sc.surface, sc.bounds)
        mesh = implc.mesh(surface, args.depth, witnesses=True)
        count = components(mesh)[0]
        voxels = implc.voxelize(surface, args.depth, **implc.NATURAL)
        kuhn = components(contour(surface, voxels.coords, args.depth, voxels.bounds, features=False, lean=False))[0]
        inside, outside = sign_regions(surface, sc.bounds, args.depth)
        print(f"| {name} | {1 << args.depth}³ | {count} | {lone_point_bubbles(mesh, args.depth, sc.bounds)} | {kuhn} | "
              f"{inside} + {outside} | {inside + outside - 1} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
