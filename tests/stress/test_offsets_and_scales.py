"""The same closed mesh translated far from the origin and scaled from tiny to huge, seen
from inside (rays at every vertex and edge midpoint) and from outside (camera rays): no
leaks, no wrong triangles, and float32 as accurate as its precision allows, because every
kernel works relative to the ray origin."""

from __future__ import annotations

import numpy as np
import pytest

import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere, rays_at_vertices_and_edges
from vtkraycast.validate import classify, exact_first_hits

CASES = [(1e3, 1.0), (1e5, 1.0), (1e6, 1.0), (1e7, 1.0), (1e8, 1.0), (0.0, 1e-8), (0.0, 1e-4), (0.0, 1e4), (0.0, 1e8),
         (1e8, 1e-2), (1e-3, 1e-6)]  # fmt: skip
RTOL = {"float64": 1e-12, "float32": 2e-6}


def case_id(case):
    return f"offset{case[0]:g}-scale{case[1]:g}"


@pytest.fixture(scope="module", params=CASES, ids=case_id)
def case(request):
    offset, scale = request.param
    scene = vrc.Scene(bumpy_sphere(2, offset=offset, scale=scale))
    return offset, scale, scene


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_from_inside(case, precision):
    offset, scale, scene = case
    eye = np.full(3, offset) + scale * np.array([0.11, -0.07, 0.05])
    origins, directions = rays_at_vertices_and_edges(scene.prepared.points, scene.prepared.triangles, eye)
    ref = exact_first_hits(scene.prepared.points, scene.prepared.triangles, origins, directions)
    hits = scene.intersect(origins, directions, precision=precision)
    masks = classify(ref, hits["triangle_id"])
    assert masks["leak"].sum() == 0 and masks["wrong"].sum() == 0
    np.testing.assert_allclose(hits["t"], ref.t, rtol=RTOL[precision])


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_from_outside(case, precision):
    offset, scale, scene = case
    centre = np.full(3, offset)
    cam = vrc.Camera(centre + scale * np.array([2.0, 1.5, 1.0]), centre, (0, 0, 1), view_angle=50, nx=40, ny=30)
    image = scene.cast(cam, arrays=["TriangleId", "Depth"], precision=precision)
    rows = np.arange(cam.ny).repeat(cam.nx)
    cols = np.tile(np.arange(cam.nx), cam.ny)
    centres = np.array([cam.pixel_center(i, cam.ny - 1 - r) for i, r in zip(cols, rows)])
    directions = centres @ np.vstack((cam.right, cam.up, cam.backward))
    origins = np.broadcast_to(cam.eye, directions.shape)
    ref = exact_first_hits(scene.prepared.points, scene.prepared.triangles, origins, directions)
    masks = classify(ref, image["TriangleId"])
    assert masks["correct"].all()
    # ids alone: most pixels settled by sure hits, without their rays (traverse_tile.hpp)
    ids_only = scene.cast(cam, arrays=["TriangleId"], precision=precision)["TriangleId"]
    assert classify(ref, ids_only)["correct"].all()
    hit = image["TriangleId"] >= 0
    assert hit.mean() > 0.3
    np.testing.assert_allclose(image["Depth"][hit], ref.t[hit] * cam.d, rtol=RTOL[precision])
