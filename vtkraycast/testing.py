"""Scenes that stress a ray caster, shared by the tests and the benchmarks: closed bumpy
spheres at any offset and scale, and rays aimed exactly at their vertices and edges."""

from __future__ import annotations

import numpy as np

__all__ = ["bumpy_sphere", "rays_at_vertices_and_edges"]


def bumpy_sphere(subdivisions: int = 4, *, offset: float = 0.0, scale: float = 1.0, bumps: float = 0.15):
    """A closed, consistently oriented triangle mesh: an icosphere (``20 * 4**subdivisions``
    triangles) with its vertices moved radially by ``bumps * sin(5 x) sin(4 y) sin(3 z)``,
    scaled by ``scale`` and moved to ``(offset, offset, offset)``.

    Examples
    --------
    >>> mesh = bumpy_sphere(2, offset=1e6)
    >>> mesh.n_cells, mesh.is_manifold, bool(abs(mesh.center[0] - 1e6) < 0.2)
    (320, True, True)
    """
    import pyvista as pv

    mesh = pv.Icosphere(radius=1.0, nsub=subdivisions)
    p = mesh.points.astype(np.float64)
    unit = p / np.linalg.norm(p, axis=1, keepdims=True)
    radius = 1.0 + bumps * np.sin(5 * unit[:, 0]) * np.sin(4 * unit[:, 1]) * np.sin(3 * unit[:, 2])
    mesh.points = unit * radius[:, None] * scale + offset
    return mesh


def rays_at_vertices_and_edges(
    points: np.ndarray, triangles: np.ndarray, eye: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Rays from ``eye`` aimed at every point a triangle uses and every edge midpoint.

    Directions are ``target - eye`` in double precision: exact (the ray passes exactly
    through the target) whenever the two are within a factor of two of each other
    coordinate by coordinate (Sterbenz), as for an eye inside a mesh far from the origin.
    Midpoints ``(a + b) / 2`` may round off the edge; the exact reference judges the ray
    as given either way.
    """
    triangles = np.asarray(triangles, dtype=np.int64)
    used = np.unique(triangles)
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    edges = np.unique(edges, axis=0)
    targets = np.concatenate((points[used], 0.5 * (points[edges[:, 0]] + points[edges[:, 1]])))
    eye = np.asarray(eye, dtype=np.float64)
    directions = targets - eye
    return np.broadcast_to(eye, directions.shape).copy(), directions
