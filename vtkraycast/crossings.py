"""Hits grouped into surface crossings: a ray through an edge or a vertex the triangles
share meets every triangle around it (the watertight kernel counts a zero edge function
as inside), but crosses the surface there once.

Rule: hits on a shared feature (an edge where one weight is exactly zero, a vertex where
two are) are grouped by ray, feature (its point ids) and facing (the exact sign of the
triangle's orientation to the ray); each group is one crossing, represented by its lowest
input triangle. A ray grazing a fold, where the triangles around the feature face it both
ways, is then reported twice at the same point (in and out): the parity of the crossings,
which inside/outside tests rest on, stays right. Features are recognised by point ids, so
triangles must share their points (``pyvista.PolyData.clean`` merges duplicates).
"""

from __future__ import annotations

import numpy as np

__all__ = ["crossings"]


def _feature(triangles: np.ndarray, triangle: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(n, 2) point ids of the feature each hit lies on: the edge's two points (sorted), the
    vertex (and -1), or (-1, -1) inside the triangle."""
    corners = triangles[triangle].astype(np.int64)
    zero = weights == 0
    key = np.full((len(triangle), 2), -1, np.int64)
    edge = zero.sum(axis=1) == 1
    if edge.any():
        others = corners[edge][~zero[edge]].reshape(-1, 2)
        key[edge] = np.sort(others, axis=1)
    vertex = zero.sum(axis=1) == 2
    if vertex.any():
        key[vertex, 0] = corners[vertex][~zero[vertex]]
    return key


def crossings(
    triangles: np.ndarray, ray: np.ndarray, triangle: np.ndarray, facing: np.ndarray, t: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """Indices of the hits that represent crossings, sorted by ray, then t, then triangle."""
    key = _feature(triangles, triangle, weights)
    on_feature = key[:, 0] >= 0
    keep = ~on_feature
    if on_feature.any():
        rows = np.flatnonzero(on_feature)
        # lowest triangle first within each (ray, feature, facing) group
        order = np.lexsort((triangle[rows], facing[rows], key[rows, 1], key[rows, 0], ray[rows]))
        rows = rows[order]
        group = np.column_stack((ray[rows], key[rows], facing[rows]))
        first = np.r_[True, (np.diff(group, axis=0) != 0).any(axis=1)]
        keep[rows[first]] = True
    kept = np.flatnonzero(keep)
    return kept[np.lexsort((triangle[kept], t[kept], ray[kept]))]
