"""Scenes that stress a ray caster, shared by the tests and the benchmarks: closed bumpy
spheres at any offset and scale, rays aimed exactly at their vertices and edges, an integer
grid and a star-shaped mesh whose vertices lie exactly on pixel rays."""

from __future__ import annotations

import numpy as np
import pyvista

from .fields import gather_at_hits

__all__ = [
    "bumpy_sphere",
    "camera_rays",
    "integer_grid",
    "rays_at_vertices_and_edges",
    "reference_arrays",
    "star_mesh",
]


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
    mesh = pyvista.Icosphere(radius=1.0, nsub=subdivisions)
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


def integer_grid(n: int = 8):
    """An n x n grid of unit squares with integer vertices on z = 0, each square split along
    a diagonal whose direction alternates like a checkerboard."""
    xs, ys = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    points = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)].astype(float)
    faces = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1
            faces += [3, a, b, c, 3, a, c, d] if (i + j) % 2 else [3, a, b, d, 3, b, c, d]
    return pyvista.PolyData(points, faces=faces)


def camera_rays(cam) -> tuple[np.ndarray, np.ndarray]:
    """The rays of every output pixel, built as the core does (exact for these cameras)."""
    rows, cols = np.arange(cam.ny).repeat(cam.nx), np.tile(np.arange(cam.nx), cam.ny)
    c = np.array([cam.pixel_center(i, cam.ny - 1 - r) for i, r in zip(cols, rows)])
    if cam.parallel:
        origins = cam.eye + c[:, :1] * cam.right + c[:, 1:2] * cam.up
        return origins, np.broadcast_to(-cam.backward, origins.shape)
    directions = c[:, :1] * cam.right + c[:, 1:2] * cam.up + c[:, 2:] * cam.backward
    return np.broadcast_to(cam.eye, directions.shape), directions


def star_mesh(cam, step: int = 2):
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
    return pyvista.PolyData(np.array(points), faces=faces)


#: The numpy gather of output arrays at given hits (fields.gather_at_hits): independent of
#: the core's C++ assembly, so the tests compare the core's arrays with it.
reference_arrays = gather_at_hits
