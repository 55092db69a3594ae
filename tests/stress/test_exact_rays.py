"""Rays exactly through vertices and edges: every pixel centre lands on a vertex, an edge
or a diagonal. The exact strategies must hit every one of them with an accepted triangle."""

from __future__ import annotations

import numpy as np
import pytest

import vtkraycast as vrc
from vtkraycast.testing import camera_rays, integer_grid, star_mesh
from vtkraycast.validate import classify, exact_first_hits

PRECISIONS = ("float64", "float32")


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("strategy", ["auto", "watertight"])
def test_parallel_camera_with_pixel_centres_on_vertices_edges_and_diagonals(strategy, precision):
    mesh = integer_grid(8)
    # Pixel pitch 0.5 and centres at -4 + 0.5 i relative to the eye at x = y = 4: every
    # centre is on a vertex (integer, integer), an edge (integer, half) or a square's centre.
    cam = vrc.Camera((4, 4, 10), (4, 4, 0), (0, 1, 0), w=8.5, h=8.5, nx=17, ny=17, parallel=True)
    image = vrc.cast(mesh, cam, arrays=["TriangleId", "Depth"], strategy=strategy, precision=precision)
    origins, directions = camera_rays(cam)
    np.testing.assert_array_equal(origins[:, :2] % 0.5, 0)  # the pixel centres really are on the lattice
    scene = vrc.Scene(mesh)
    ref = exact_first_hits(scene.prepared.points, scene.prepared.triangles, origins, directions)
    assert ref.on_edge.all()
    masks = classify(ref, image["TriangleId"])
    assert masks["correct"].all(), f"{masks['leak'].sum()} leaks, {masks['wrong'].sum()} wrong"
    assert (image["Depth"] == 10).all()


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("offset", [0.0, 1e5])
def test_perspective_camera_inside_a_star_mesh_with_vertices_on_pixel_rays(precision, offset):
    # Dyadic pixel centres (w / nx = h / ny = 1/16) and eye: eye + 2**k P_ij is exact, so
    # each vertex lies exactly on its pixel's ray, and the pixels between two vertices'
    # pixels look exactly along the edge joining them.
    eye = np.full(3, offset) + [0.25, -0.5, 0.125]
    cam = vrc.Camera(eye, eye + [0, 0, -1], (0, 1, 0), d=1.0, w=2.0, h=1.5, nx=33, ny=25)
    cam = cam.replace(w=33 / 16, h=25 / 16)
    mesh = star_mesh(cam)
    assert mesh.is_manifold
    scene = vrc.Scene(mesh)
    image = scene.cast(cam, arrays=["TriangleId"], precision=precision)
    origins, directions = camera_rays(cam)
    ref = exact_first_hits(scene.prepared.points, scene.prepared.triangles, origins, directions)
    inside = np.array([bool(a) for a in ref.accepted])
    assert inside.mean() > 0.8 and ref.on_edge[inside].mean() > 0.5
    masks = classify(ref, image["TriangleId"])
    assert masks["correct"].all(), f"{masks['leak'].sum()} leaks, {masks['wrong'].sum()} wrong"
