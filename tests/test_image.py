"""The geometry buffer's placement: pixel space, or the camera's image plane in world space."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc


@pytest.mark.parametrize("parallel", [False, True])
def test_world_space_puts_pixels_on_the_image_plane(parallel):
    cam = vrc.Camera((1, 2, 3), (0, 0, 0), (0, 0, 1), d=1.7, view_angle=40, nx=30, ny=20, parallel=parallel)
    image = vrc.cast(pv.Sphere(), cam, world_space=True, arrays=["Depth"])
    points = image.points
    assert points.shape == (600, 3)
    # every pixel centre is at distance d in front of the eye...
    np.testing.assert_allclose((points - cam.eye) @ -cam.backward, cam.d, rtol=1e-12)
    # ...at the seed's pixel centre (row 0 at the bottom)
    for k in (0, 29, 570, 599, 311):
        i, r = k % 30, k // 30
        c = cam.pixel_center(i, 19 - r)
        expected = cam.eye + c[0] * cam.right + c[1] * cam.up + c[2] * cam.backward
        np.testing.assert_allclose(points[k], expected, atol=1e-12)


def test_pixel_space_by_default():
    image = vrc.cast(pv.Sphere(), vrc.Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), nx=4, ny=3))
    assert image.origin == (0, 0, 0) and image.spacing == (1, 1, 1)
    assert image.points[5].tolist() == [1, 1, 0]


def test_depth_is_the_active_scalar():
    image = vrc.cast(pv.Sphere(), vrc.Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), nx=4, ny=3))
    assert image.active_scalars_name == "Depth"
