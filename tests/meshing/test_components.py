"""The mesh's connected components are the sampled signs' own: no closed bubble around a single cell or face
point that the fans add (Scene 2 at 256³ had 298 of its 318 components so); with the Kuhn split
everywhere, and in the default mesh, the components are the borders of the grid's sampled sign regions,
counted by scipy's labelling (tests/support/components.py)."""

import pytest

import implc
from implc.files.scene import load as load_scene
from implc.meshing import features
from implc.meshing.contour import contour

from ..support.components import components, lone_point_bubbles, sign_regions


@pytest.fixture(scope="module")
def scene2():
    sc = load_scene("paper_sin4_sin8")
    return implc.compile(sc.surface, sc.bounds), sc.bounds


def test_no_bubble_around_an_added_point(scene2, monkeypatch):
    """Scene 2 at 64³, where the fans' points near the singular axis took signs none of their corners had:
    no component is a bubble around one of them now; left where the QEF and the centres put them (the
    control), 90 were."""
    surface, bounds = scene2
    voxels = implc.voxelize(surface, 6)

    def fanned():  # the tetrahedral construction everywhere: every crease cell fanned
        return contour(surface, voxels.coords, 6, voxels.bounds, witnesses=True, lean=False)

    mesh = fanned()
    assert mesh.stats.feature_cells > 0 and lone_point_bubbles(mesh, 6, bounds) == 0
    assert lone_point_bubbles(implc.mesh(surface, 6, witnesses=True), 6, bounds) == 0
    monkeypatch.setattr(features, "_joined", lambda grid, points, corners: points)
    assert lone_point_bubbles(fanned(), 6, bounds) > 50


def test_kuhn_components_are_the_borders_of_the_sampled_regions(scene2):
    """With the Kuhn split everywhere (the tetrahedral construction, features off), the mesh has one
    component per border between the sampled sign regions: their count less one (the bounds are a ball, so
    the borders form a tree); so does the default mesh, whose dual cells hold one sheet each and whose
    other cells are the Kuhn split's."""
    surface, bounds = scene2
    voxels = implc.voxelize(surface, 6)
    count, _ = components(contour(surface, voxels.coords, 6, voxels.bounds, features=False, lean=False))
    inside, outside = sign_regions(surface, bounds, 6)
    assert count == inside + outside - 1 and count > 2
    assert components(implc.mesh(surface, 6))[0] == count
