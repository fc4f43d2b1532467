"""The point renderer: what is nearer hides what is behind, lit pixels face the light, LOD renders."""

import numpy as np
import pytest
import sympy

import implc
from implc import x, y, z
from implc.view.render import Style, View, render_points, render_voxels


def test_nearest_point_wins_its_pixel():
    bounds = ((-1, 1), (-1, 1), (-1, 1))
    view = View(azimuth=0, elevation=0)  # looking along -x
    centers = np.array([[0.5, 0, 0], [-0.5, 0, 0], [0, 0.9, 0.9], [0, -0.9, -0.9]])
    facing = np.array([[1, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 0]], dtype=np.float32)
    away = facing * -1
    style = Style(color=(1, 0, 0), ambient=0.0, specular=0.0)
    # the near point faces the camera; the far one is tilted: the centre pixel must have the near one's colour
    tilted = np.array([[1, 0, 0], [0, 0.2, 0.98], [1, 0, 0], [1, 0, 0]], dtype=np.float32)
    image = render_points(centers, tilted, np.array([0.1] * 3), bounds, size=64, view=view, style=style)
    near_only = render_points(centers[[0, 2, 3]], tilted[[0, 2, 3]], np.array([0.1] * 3), bounds, size=64,
                              view=view, style=style)
    np.testing.assert_array_equal(image, near_only)
    both_sides = render_points(centers, away, np.array([0.1] * 3), bounds, size=64, view=view, style=style)
    assert both_sides.max() > 0  # two-sided lighting: back-facing normals are lit too


def test_sphere_render_is_round_and_lit():
    v = implc.voxelize(implc.compile(x**2 + y**2 + z**2 - sympy.Rational(1, 2)), 6)
    image = render_voxels(v, size=128)
    background = image[0, 0]
    covered = np.any(image != background, axis=2)
    assert covered[64, 64] and not covered[2, 2] and not covered[125, 125]
    area = covered.mean()
    assert 0.5 < area < 0.75  # a disc filling ~92% of the width covers ~pi/4 * 0.92² of the image
    assert image[covered].max() > 150  # a highlight


def test_lod_and_bad_arguments():
    v = implc.voxelize(implc.compile(x**2 + y**2 + z**2 - sympy.Rational(1, 2)), 6)
    coarse = render_voxels(v, size=64, lod=3)
    assert coarse.shape == (64, 64, 3)
    with pytest.raises(ValueError, match="lod must be from 1 to 6"):
        render_voxels(v, size=64, lod=9)
    with pytest.raises(ValueError, match="image size"):
        render_voxels(v, size=4)
