"""A notebook's viewer redraws in place: ``voxels.show()`` given a new surface replaces its own output."""

import html
import json
import re

import pytest

import implc
from implc import shapes

IPython = pytest.importorskip("IPython", reason="IPython runs notebooks; without it there is nothing to display")


def _meta(document: str) -> dict:
    embedded = re.search(r"window\.IMPLC_EMBED = (\{.*?\});</script>", document, re.S).group(1)
    return json.loads(embedded.replace("<\\/", "</"))["meta"]


def test_update_replaces_the_same_output_with_the_new_surface():
    from IPython.core.interactiveshell import InteractiveShell
    from IPython.utils.capture import capture_output
    InteractiveShell.instance()
    voxels = implc.voxelize(implc.compile(shapes.sphere(0.5)), 5)
    torus = shapes.torus(0.6, 0.2)
    with capture_output() as captured:
        view = voxels.show()
        view._ipython_display_()
        view.update(torus)
    first, second = captured.outputs
    assert not first.update and second.update
    assert first.transient["display_id"] == second.transient["display_id"]  # the same output, redrawn
    shown = html.unescape(re.search(r'srcdoc="(.*?)"', second.data["text/html"], re.S).group(1))
    meta = _meta(shown)
    assert meta["depth"] == 5 and meta["voxels"] == len(implc.voxelize(implc.compile(torus), 5))
    assert _meta(html.unescape(re.search(r'srcdoc="(.*?)"', first.data["text/html"], re.S).group(1)))["voxels"] \
        == len(voxels)


def test_a_mesh_view_takes_meshes_only():
    mesh = implc.voxelize(implc.compile(shapes.sphere(0.5)), 5).mesh()
    view = mesh.show()
    view.update(implc.voxelize(implc.compile(shapes.sphere(0.3)), 5).mesh())
    assert _meta(view.document)["kind"] == "mesh"
    with pytest.raises(TypeError, match="mesh"):
        view.update(shapes.sphere(0.3))
