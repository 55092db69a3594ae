"""Rays exactly through vertices and edges: every pixel centre lands on a vertex, an edge
or a diagonal. The exact strategies must hit every one of them with an accepted triangle."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv

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


@pytest.mark.parametrize("offset", [0.0, 1e5])
def test_segments_to_every_vertex_of_a_lattice_box(offset):
    # visible_points' queries: a segment from an eye to each vertex of a box subdivided on
    # an integer lattice, ending just before it or just past it. The edges through the
    # vertex give determinants exactly zero (the direction is the vertex less the eye,
    # exactly), and so do the lattice's edges collinear with them: the exact signs'
    # shortcuts and their stages (double-double, then expansions of single doubles) must
    # agree with the exact reference, hit for hit.
    box = pv.Box((0, 6, 0, 6, 0, 6), level=5).triangulate().translate((offset, offset, offset))
    scene = vrc.Scene(box)
    points = scene.prepared.points
    for eye in ([-7.25, 3.0, 2.5], [3.0, 3.0, 20.0], [9.5, -4.0, 6.0]):
        origins = np.broadcast_to(np.add(eye, offset), points.shape)
        directions = points - origins
        for tmax in (1 - 1e-9, 1 + 1e-9):
            ref = exact_first_hits(points, scene.prepared.triangles, origins, directions, tmax=tmax)
            hits = scene.intersect(origins, directions, tmax=tmax)
            masks = classify(ref, hits["triangle_id"])
            assert masks["correct"].all(), f"{masks['leak'].sum()} leaks, {masks['wrong'].sum()} wrong"
            expected = np.array([bool(a) for a in ref.accepted])
            np.testing.assert_array_equal(scene.occluded(origins, directions, tmax=tmax), expected)


def test_orientation_signs_against_rational_arithmetic():
    # The predicate every kernel settles near-zero edge functions with, det[c - o, b - o, d],
    # on exactly zero, nearly zero (1e-16 and 1e-32 of its terms: the double-double stage,
    # then integers or expansions) and generic cases, at offsets 0 and 1e5, against
    # fractions. (No subnormal entries: their products underflow, which no double
    # arithmetic survives.)
    from fractions import Fraction

    from vtkraycast import _core

    rng = np.random.default_rng(5)
    n = 3000
    rows = []
    for offset in (0.0, 1e5):
        o = offset + rng.integers(-8, 8, (n, 3)) * 0.25
        v = rng.choice([-2.0, -1.5, -1.0, -0.5, 0.5, 1.0, 1.5, 2.0], (n, 3))
        w = rng.choice([-2.0, -1.5, -1.0, -0.5, 0.5, 1.0, 1.5, 2.0], (n, 3))
        nudge = np.zeros((n, 3))
        nudge[np.arange(n), rng.integers(0, 3, n)] = 1.0
        b = o + 2 * v
        nudge[b == 0] = 0  # (the ulp after 0 is subnormal)
        rows += [
            (o + v, b, o, v),  # b - o along c - o: zero
            (o + v, o + w, o, v + w),  # d in the plane of the two: zero
            (o + v, np.nextafter(b, b + nudge), o, v),  # b off the line by an ulp: about 1e-16
            (o + v, np.nextafter(b, b + nudge), o, np.nextafter(v, v + np.roll(nudge, 1, axis=1))),  # about 1e-32
            (o + rng.normal(size=(n, 3)), o + rng.normal(size=(n, 3)), o, rng.normal(size=(n, 3))),
        ]
    # columns whose entries span more than 61 bits (1e6 beside full 53-bit fractions): zero
    wide = np.column_stack((rng.integers(1, 9, n) * 1e6, 1 + rng.integers(1, 2**40, n) * 2.0**-52, np.full(n, 0.5)))
    rows.append((wide, 2 * wide, np.zeros((n, 3)), rng.normal(size=(n, 3))))
    c, b, o, d = (np.concatenate(part) for part in zip(*rows))

    def exact_sign(ci, bi, oi, di):
        x = [Fraction(p) - Fraction(q) for p, q in zip(ci, oi)]
        y = [Fraction(p) - Fraction(q) for p, q in zip(bi, oi)]
        z = [Fraction(p) for p in di]
        det = (
            x[0] * (y[1] * z[2] - y[2] * z[1]) - x[1] * (y[0] * z[2] - y[2] * z[0]) + x[2] * (y[0] * z[1] - y[1] * z[0])
        )
        return (det > 0) - (det < 0)

    expected = np.array([exact_sign(*r) for r in zip(c, b, o, d)])
    signs = _core.orientation_signs(c, b, o, d)
    np.testing.assert_array_equal(signs, expected)
    assert (expected == 0).mean() > 0.3 and (expected != 0).mean() > 0.3
