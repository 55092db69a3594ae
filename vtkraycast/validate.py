"""Exact reference: the true first hit of a ray, decided in exact integer arithmetic.

Every double is an integer times a power of two, so after scaling by a common power of two
all coordinates of a ray and its candidate triangles are Python integers, and the
orientation signs, the ray parameter ``t`` and the barycentric weights are exact
(``t`` and the weights as fractions, rounded once at the end).

A ray through an edge or a vertex hits every triangle sharing it at the same ``t``: each of
them is a right answer (a tie); a miss there is a leak.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

__all__ = ["ExactHits", "classify", "exact_first_hits"]


@dataclass(frozen=True)
class ExactHits:
    """The exact first hits of ``n`` rays.

    Attributes
    ----------
    accepted : list of frozenset of int
        Triangles hit at the smallest ``t`` (several on an edge, a vertex, or with
        duplicate faces); empty for a miss.
    t : numpy.ndarray
        ``(n,)`` exact ``t`` rounded to float64, NaN on a miss.
    barycentric : numpy.ndarray
        ``(n, 3)`` exact weights of the lowest accepted triangle, rounded; NaN on a miss.
    on_edge : numpy.ndarray
        ``(n,)`` bool: the ray passes exactly through an edge or vertex of a hit triangle.
    """

    accepted: list[frozenset[int]]
    t: np.ndarray
    barycentric: np.ndarray
    on_edge: np.ndarray


def _scaled_integers(values: np.ndarray) -> list[int]:
    """Integers ``k`` with ``values == k * 2**-s`` exactly, for one shift ``s``."""
    mantissa, exponent = np.frexp(values)
    ints = (mantissa * 2.0**53).astype(np.int64)  # exact: 53-bit mantissas
    exps = exponent.astype(np.int64) - 53
    nonzero = ints != 0
    shift = int(-exps[nonzero].min()) if nonzero.any() else 0
    return [int(i) << int(e + shift) if i else 0 for i, e in zip(ints.tolist(), exps.tolist())]


def _candidates(
    o: np.ndarray, d: np.ndarray, tmin: float, tmax: float, centres: np.ndarray, radii: np.ndarray
) -> np.ndarray:
    """Triangles whose bounding sphere the ray may touch (a conservative float filter, in
    units of the direction's length so that tiny or huge directions cannot underflow)."""
    scale = float(np.abs(d).max())
    unit = d / scale
    length = scale * float(np.linalg.norm(unit))
    unit = unit / np.linalg.norm(unit)
    oc = centres - o
    along = oc @ unit
    oc2 = np.einsum("ij,ij->i", oc, oc)
    miss2 = oc2 - along * along  # cancels: the margin below covers its rounding
    r = radii * (1 + 1e-6) + 1e-300
    close = miss2 <= r * r + 1e-12 * oc2
    return np.flatnonzero(close & (along + r >= tmin * length) & (along - r <= tmax * length))


def _det(a: list[int], b: list[int], c: list[int]) -> int:
    return a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0])


def exact_first_hits(
    points: np.ndarray,
    triangles: np.ndarray,
    origins: np.ndarray,
    directions: np.ndarray,
    *,
    tmin: float = 0.0,
    tmax: float = math.inf,
    tie_tolerance: float = 0.0,
) -> ExactHits:
    """The exact first hit of each ray ``origin + t direction``, ``tmin <= t <= tmax``.

    With ``tie_tolerance`` > 0, triangles hit within that relative distance of the first
    hit (``t <= t_first (1 + tol)``) are accepted too: vtkraycast treats hits closer than
    its arithmetic can separate as ties (32 eps of the precision).

    A triangle is hit when the signed volumes ``det[B-O, C-O, d]``, ``det[C-O, A-O, d]``,
    ``det[A-O, B-O, d]`` share a sign (zeros allowed, not all zero) and their sum
    ``d . ((B-A) x (C-A))`` is not zero (a ray in the triangle's plane misses).

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])
    >>> tris = np.array([[0, 1, 2], [1, 3, 2]])
    >>> hits = exact_first_hits(pts, tris, np.array([[0.5, 0.5, 1.0]]), np.array([[0, 0, -1.0]]))
    >>> sorted(hits.accepted[0]), float(hits.t[0]), bool(hits.on_edge[0])
    ([0, 1], 1.0, True)
    """
    points = np.asarray(points, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    origins = np.atleast_2d(np.asarray(origins, dtype=np.float64))
    directions = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    corners = points[triangles] if triangles.size else np.zeros((0, 3, 3))
    centres = 0.5 * (corners.min(axis=1) + corners.max(axis=1)) if triangles.size else np.zeros((0, 3))
    radii = np.linalg.norm(corners - centres[:, None, :], axis=2).max(axis=1) if triangles.size else np.zeros(0)
    n = origins.shape[0]
    accepted: list[frozenset[int]] = []
    t_out = np.full(n, np.nan)
    bary_out = np.full((n, 3), np.nan)
    on_edge = np.zeros(n, bool)
    for k in range(n):
        o, d = origins[k], directions[k]
        cand = _candidates(o, d, tmin, tmax, centres, radii)
        best: Fraction | None = None
        hits: list[tuple[int, Fraction, tuple[Fraction, Fraction, Fraction], bool]] = []  # all hits in range
        if cand.size:
            tri_pts = corners[cand].reshape(-1, 3)
            ints = _scaled_integers(np.concatenate((o, d, tri_pts.ravel())))
            oi, di = ints[0:3], ints[3:6]
            for j, tri in enumerate(cand.tolist()):
                base = 6 + 9 * j
                a, b, c = ([ints[base + 3 * m + q] - oi[q] for q in range(3)] for m in range(3))
                wa, wb, wc = _det(b, c, di), _det(c, a, di), _det(a, b, di)
                if (wa < 0 or wb < 0 or wc < 0) and (wa > 0 or wb > 0 or wc > 0):
                    continue
                total = wa + wb + wc
                if total == 0:
                    continue
                # t = (A . n) / (d . n) with n = (B - A) x (C - A) and d . n = wa + wb + wc;
                # A . n = det[A, B, C] since A . (A x .) = 0. The common 2**shift cancels.
                t = Fraction(_det(a, b, c), total)
                if not (tmin <= t <= tmax):
                    continue
                weights = (Fraction(wa, total), Fraction(wb, total), Fraction(wc, total))
                hits.append((tri, t, weights, 0 in (wa, wb, wc)))
                best = t if best is None else min(best, t)
        if hits:
            reach = best + abs(best) * Fraction(float(tie_tolerance))
            hits = [h for h in hits if h[1] <= reach]
        accepted.append(frozenset(h[0] for h in hits))
        if hits:
            first = min(hits)
            t_out[k] = float(first[1])
            bary_out[k] = [float(w) for w in first[2]]
            on_edge[k] = any(h[3] for h in hits)
    return ExactHits(accepted, t_out, bary_out, on_edge)


def classify(reference: ExactHits, triangle_id: np.ndarray) -> dict[str, np.ndarray]:
    """Masks of a caster's answers against the exact reference: ``leak`` (the ray hit a
    surface, the caster missed it), ``wrong`` (both hit, the caster's triangle is not one
    of the accepted), ``false_hit`` (the ray misses, the caster hit), ``correct``."""
    ids = np.asarray(triangle_id)
    hit_ref = np.array([bool(a) for a in reference.accepted])
    hit = ids >= 0
    right = np.array([i in a for i, a in zip(ids.tolist(), reference.accepted)])
    return {
        "leak": hit_ref & ~hit,
        "wrong": hit_ref & hit & ~right,
        "false_hit": ~hit_ref & hit,
        "correct": (hit_ref & right) | (~hit_ref & ~hit),
    }
