"""Rays exactly through vertices and edges: every pixel centre lands on a vertex, an edge
or a diagonal. The exact strategies must hit every one of them with an accepted triangle."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc
from vtkraycast.validate import classify, exact_first_hits

PRECISIONS = ("float64", "float32")


def integer_grid(n: int = 8) -> pv.PolyData:
    """An n x n grid of unit squares with integer vertices on z = 0, each square split along
    a diagonal whose direction alternates like a checkerboard."""
    xs, ys = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    points = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)].astype(float)
    faces = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1
            faces += [3, a, b, c, 3, a, c, d] if (i + j) % 2 else [3, a, b, d, 3, b, c, d]
    return pv.PolyData(points, faces=faces)


def camera_rays(cam: vrc.Camera) -> tuple[np.ndarray, np.ndarray]:
    """The rays of every output pixel, built as the core does (exact for these cameras)."""
    rows, cols = np.arange(cam.ny).repeat(cam.nx), np.tile(np.arange(cam.nx), cam.ny)
    c = np.array([cam.pixel_center(i, cam.ny - 1 - r) for i, r in zip(cols, rows)])
    if cam.parallel:
        origins = cam.eye + c[:, :1] * cam.right + c[:, 1:2] * cam.up
        return origins, np.broadcast_to(-cam.backward, origins.shape)
    directions = c[:, :1] * cam.right + c[:, 1:2] * cam.up + c[:, 2:] * cam.backward
    return np.broadcast_to(cam.eye, directions.shape), directions


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


def star_mesh(cam: vrc.Camera, step: int = 2) -> pv.PolyData:
    """A closed mesh around the eye, star-shaped from it: a height field whose vertices lie
    exactly on the pixel rays of every `step`-th pixel (scaled by powers of two, so exactly),
    closed by a fan to an apex behind the eye."""
    rng = np.random.default_rng(3)
    ii = np.arange(0, cam.nx, step)
    jj = np.arange(0, cam.ny, step)
    grid = np.zeros((ii.size, jj.size), int)
    points = []
    for a, i in enumerate(ii):
        for b, j in enumerate(jj):
            c = cam.pixel_center(i, j)
            direction = c[0] * cam.right + c[1] * cam.up + c[2] * cam.backward
            grid[a, b] = len(points)
            points.append(cam.eye + 2.0 ** rng.integers(0, 3) * direction)
    faces = []
    for a in range(ii.size - 1):
        for b in range(jj.size - 1):
            p, q, r, s = grid[a, b], grid[a + 1, b], grid[a + 1, b + 1], grid[a, b + 1]
            faces += [3, p, q, r, 3, p, r, s] if (a + b) % 2 else [3, p, q, s, 3, q, r, s]
    apex = len(points)
    points.append(cam.eye + 5 * cam.backward)
    ring = [*grid[:, 0], *grid[-1, 1:], *grid[-2::-1, -1], *grid[0, -2:0:-1]]
    for k in range(len(ring)):
        faces += [3, ring[k], ring[(k + 1) % len(ring)], apex]
    return pv.PolyData(np.array(points), faces=faces)


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
