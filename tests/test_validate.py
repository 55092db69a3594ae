"""The exact reference itself, checked against hand-made cases and exact rational geometry."""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from vtkraycast.validate import classify, exact_first_hits

SQUARE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])
TWO = np.array([[0, 1, 2], [1, 3, 2]])


def test_a_ray_through_the_shared_edge_accepts_both_triangles():
    hits = exact_first_hits(SQUARE, TWO, [[0.5, 0.5, 1.0]], [[0, 0, -1.0]])
    assert hits.accepted[0] == {0, 1} and hits.on_edge[0]
    hits = exact_first_hits(SQUARE, TWO, [[0.25, 0.25, 1.0]], [[0, 0, -1.0]])
    assert hits.accepted[0] == {0} and not hits.on_edge[0]


def test_a_ray_a_hair_off_the_edge_is_decided_exactly():
    off = np.nextafter(0.5, 1.0)  # the smallest step towards triangle 1
    hits = exact_first_hits(SQUARE, TWO, [[off, 0.5, 1.0]], [[0, 0, -1.0]])
    assert hits.accepted[0] == {1}


def test_t_and_weights_are_exact():
    tri = np.array([[1.0, 0.1, 0.3], [0.2, 2.0, 0.7], [-0.5, -0.4, 3.0]])
    o, d = np.array([0.1, 0.2, -1.0]), np.array([0.05, 0.3, 1.0])
    hits = exact_first_hits(tri, [[0, 1, 2]], [o], [d])
    # Exact rational solution of o + t d = sum w_i P_i, sum w_i = 1.
    F = [[Fraction(x) for x in row] for row in tri]
    fo, fd = [Fraction(x) for x in o], [Fraction(x) for x in d]
    # Solve [P1-P3 | P2-P3 | -d] (w1, w2, t) = o - P3 by Cramer's rule.
    cols = [[F[0][k] - F[2][k] for k in range(3)], [F[1][k] - F[2][k] for k in range(3)], [-x for x in fd]]
    rhs = [fo[k] - F[2][k] for k in range(3)]

    def det(c0, c1, c2):
        return (
            c0[0] * (c1[1] * c2[2] - c1[2] * c2[1])
            - c1[0] * (c0[1] * c2[2] - c0[2] * c2[1])
            + c2[0] * (c0[1] * c1[2] - c0[2] * c1[1])
        )

    full = det(*cols)
    w1, w2, t = det(rhs, cols[1], cols[2]) / full, det(cols[0], rhs, cols[2]) / full, det(cols[0], cols[1], rhs) / full
    assert hits.t[0] == float(t)
    assert hits.barycentric[0].tolist() == [float(w1), float(w2), float(1 - w1 - w2)]


def test_nearest_of_stacked_triangles_and_range():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1.0]])
    tris = np.array([[0, 1, 2], [3, 4, 5]])
    hits = exact_first_hits(pts, tris, [[0.2, 0.2, 5.0]], [[0, 0, -1.0]])
    assert hits.accepted[0] == {1} and hits.t[0] == 4.0
    hits = exact_first_hits(pts, tris, [[0.2, 0.2, 5.0]], [[0, 0, -1.0]], tmin=4.5)
    assert hits.accepted[0] == {0}
    hits = exact_first_hits(pts, tris, [[0.2, 0.2, 5.0]], [[0, 0, -1.0]], tmax=3.9)
    assert hits.accepted[0] == frozenset() and np.isnan(hits.t[0])


def test_classify():
    hits = exact_first_hits(SQUARE, TWO, [[0.5, 0.5, 1], [0.2, 0.2, 1], [5, 5, 1], [5, 5, 1]], [[0, 0, -1.0]] * 4)
    masks = classify(hits, np.array([1, 1, -1, 0]))
    assert masks["correct"].tolist() == [True, False, True, False]
    assert masks["wrong"].tolist() == [False, True, False, False]
    assert masks["false_hit"].tolist() == [False, False, False, True]
    masks = classify(hits, np.array([-1, 0, -1, -1]))
    assert masks["leak"].tolist() == [True, False, False, False]
