"""Awkward topology: non-manifold edges, inconsistent orientation, unused points, large
point indices."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere, rays_at_vertices_and_edges
from vtkraycast.validate import classify, exact_first_hits

PRECISIONS = ("float64", "float32")


def check_exact(scene: vrc.Scene, origins, directions, precision: str) -> np.ndarray:
    hits = scene.intersect(origins, directions, precision=precision)
    ref = exact_first_hits(scene.prepared.points, scene.prepared.triangles, origins, directions)
    masks = classify(ref, hits["triangle_id"])
    assert masks["correct"].all(), f"{masks['leak'].sum()} leaks, {masks['wrong'].sum()} wrong"
    return hits["triangle_id"]


@pytest.mark.parametrize("precision", PRECISIONS)
def test_inconsistently_oriented_closed_mesh_does_not_leak(precision):
    mesh = bumpy_sphere(3)
    faces = mesh.faces.reshape(-1, 4).copy()
    flip = np.random.default_rng(2).random(len(faces)) < 0.5
    faces[flip, 1:] = faces[flip, 1:][:, ::-1]
    flipped = pv.PolyData(mesh.points, faces=faces.ravel())
    scene = vrc.Scene(flipped)
    origins, directions = rays_at_vertices_and_edges(
        scene.prepared.points, scene.prepared.triangles, [0.1, 0.05, -0.02]
    )
    ids = check_exact(scene, origins, directions, precision)
    assert (ids >= 0).all()


@pytest.mark.parametrize("precision", PRECISIONS)
def test_non_manifold_fins(precision):
    """Three and four triangles around one edge (a book with pages): rays at the spine."""
    spine = [[0, 0, -1], [0, 0, 1]]
    pages = [[np.cos(a), np.sin(a), 0] for a in np.linspace(0, 2 * np.pi, 7)[:-1]]
    points = np.array(spine + pages, float)
    faces = np.array([[3, 0, 1, 2 + k] for k in range(6)]).ravel()
    scene = vrc.Scene(pv.PolyData(points, faces=faces))
    angles = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    origins = np.c_[2 * np.cos(angles), 2 * np.sin(angles), np.linspace(-0.5, 0.5, 50)]
    directions = np.c_[-origins[:, 0], -origins[:, 1], np.zeros(50)]  # aimed at the spine
    ids = check_exact(scene, origins, directions, precision)
    assert (ids >= 0).all()


def test_unused_points_and_large_indices():
    """Three million points of which a triangle uses the last three (and NaN ones unused)."""
    n = 3_000_000
    points = np.zeros((n, 3))
    points[:-3] = np.nan  # unused, and not finite: harmless
    points[-3:] = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    mesh = pv.PolyData(points, faces=[3, n - 3, n - 2, n - 1])
    scene = vrc.Scene(mesh)
    hits = scene.intersect([[0.2, 0.2, 1]], [[0, 0, -1]])
    assert hits["triangle_id"][0] == 0 and hits["t"][0] == 1.0
    np.testing.assert_allclose(hits["barycentric"][0], [0.6, 0.2, 0.2])
