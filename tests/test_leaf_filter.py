"""The single-ray filter (src/triangle_filter.hpp) rejects a leaf's triangle only when the
exact test would miss it: its quantized single-precision verdicts never drop a hit. Rays
aimed at the edges and corners of small triangles (where the exact decision is closest)
from far away, at offsets and scales from 1e-300 to 1e300, find through the BVH the hits
found by testing every triangle (accel="none", no filter), bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc


def crumpled_sheet(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """An n x n grid of points, jittered and folded, split into 2 (n - 1)^2 triangles."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    points = np.column_stack([u.ravel(), v.ravel(), 0.1 * np.sin(9 * u.ravel()) * np.cos(7 * v.ravel())])
    points += rng.normal(scale=0.2 / n, size=points.shape)
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    triangles = np.concatenate([np.column_stack([i, i + 1, i + n + 1]), np.column_stack([i, i + n + 1, i + n])])
    return points, triangles


def edge_rays(points: np.ndarray, triangles: np.ndarray, n: int, rng: np.random.Generator):
    """Rays from 1.5 to 1000 sizes away aimed at points of triangles' edges and corners,
    some of them nudged off by a few units in the last place."""
    size = np.ptp(points, axis=0).max()
    corners = points[triangles[rng.integers(0, len(triangles), n)]]
    w = rng.uniform(0, 1, n)
    weights = np.zeros((n, 3))
    weights[:, 0], weights[:, 1] = w, 1 - w
    weights[: n // 5] = [1, 0, 0]  # corners
    weights = np.take_along_axis(weights, rng.permuted(np.tile([0, 1, 2], (n, 1)), axis=1), axis=1)
    targets = np.einsum("nk,nkc->nc", weights, corners)
    nudge = rng.integers(-4, 5, (n, 3)) * np.spacing(np.abs(targets).max(axis=1, keepdims=True))
    targets[n // 2 :] += nudge[n // 2 :]
    direction = rng.normal(size=(n, 3))
    direction[:, 2] = np.abs(direction[:, 2]) + 0.3
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    distance = size * np.exp(rng.uniform(np.log(1.5), np.log(1000), (n, 1)))
    return targets + distance * direction, -direction


@pytest.mark.parametrize(
    "scale, offset",
    [(1.0, 0.0), (1e-3, 1e3), (1e5, -3e9), (1e-300, 1e-297), (1e300, 0.0), (1e-303, 0.0), (1e302, 0.0)],
    ids=["unit", "small far", "large offset", "tiny", "huge", "tinier", "huger"],
)
def test_hits_on_edges_and_corners_equal_every_triangle_tested(scale, offset):
    rng = np.random.default_rng(11)
    points, triangles = crumpled_sheet(40, rng)
    origins, directions = edge_rays(points, triangles, 4000, rng)
    points, origins = points * scale + offset, origins * scale + offset
    mesh = pv.PolyData(points, np.column_stack([np.full(len(triangles), 3), triangles]).ravel())
    scene = vrc.Scene(mesh)
    for tmin in (0.0, float(np.ptp(points, axis=0).max()) * 2):  # (the second cuts some hits off)
        through_bvh = scene.intersect(origins, directions, tmin=tmin, arrays=["triangle_id", "t"])
        every = scene.intersect(origins, directions, tmin=tmin, arrays=["triangle_id", "t"], accel="none")
        np.testing.assert_array_equal(through_bvh["triangle_id"], every["triangle_id"])
        np.testing.assert_array_equal(through_bvh["t"], every["t"])
        assert (every["triangle_id"] >= 0).mean() > (0.5 if tmin == 0 else 0.1)
        occluded = scene.occluded(origins, directions, tmin=tmin)
        np.testing.assert_array_equal(occluded, every["triangle_id"] >= 0)
