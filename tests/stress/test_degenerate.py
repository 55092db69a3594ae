"""Degenerate geometry: slivers, zero-area and collinear triangles, duplicates and coplanar
overlaps, grazing rays, the eye on the surface, hits exactly at near and far."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc
from vtkraycast.validate import classify, exact_first_hits

STRATEGIES = vrc.STRATEGIES
PRECISIONS = ("float64", "float32")
DOWN = np.array([0.0, 0.0, -1.0])


def mesh_of(points, triangles) -> pv.PolyData:
    triangles = np.asarray(triangles)
    faces = np.c_[np.full(len(triangles), 3), triangles].ravel()
    return pv.PolyData(np.asarray(points, float), faces=faces)


def grid_rays(x0, x1, y0, y1, n, z=1.0):
    xs, ys = np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n))
    origins = np.c_[xs.ravel(), ys.ravel(), np.full(xs.size, z)]
    return origins, np.broadcast_to(DOWN, origins.shape)


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("strategy", STRATEGIES)
def test_zero_area_and_collinear_triangles_are_never_hit_and_never_nan(strategy, precision):
    points = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [0.5, 0.5, 0.5]]
    mesh = mesh_of(points, [[0, 1, 2], [0, 0, 3], [1, 1, 1], [4, 4, 3]])  # collinear, repeated points
    origins, directions = grid_rays(-0.5, 2.5, -0.5, 1.5, 41)
    origins = np.vstack((origins, [[0.5, 0, 1], [1, 0, 1], [0, 0.5, 1]]))  # exactly on the degenerate ones
    directions = np.broadcast_to(DOWN, origins.shape)
    hits = vrc.Scene(mesh).intersect(origins, directions, strategy=strategy, precision=precision)
    assert (hits["triangle_id"] == -1).all()
    assert np.isnan(hits["t"]).all() and np.isnan(hits["barycentric"]).all()


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("aspect", [1e-2, 1e-5, 1e-8])
def test_slivers(aspect, precision):
    """A fan of 200 slivers of width/length ``aspect`` tiling a thin triangle: every ray
    gets an accepted sliver (the exact strategy decides even 1e-8 slivers exactly), with
    finite weights summing to 1."""
    n = 200
    ys = np.linspace(0, n * aspect, n + 1)
    mesh = mesh_of([[0, 0, 0]] + [[1, y, 0] for y in ys], [[0, k + 1, k + 2] for k in range(n)])
    scene = vrc.Scene(mesh)
    xs = np.linspace(0.1, 0.9, 10)
    origins = np.array([[x, x * y, 1.0] for x in xs for y in np.linspace(0, n * aspect, 12)[1:-1]])
    directions = np.broadcast_to(DOWN, origins.shape)
    hits = scene.intersect(origins, directions, precision=precision)
    ref = exact_first_hits(scene.prepared.points, scene.prepared.triangles, origins, directions)
    assert classify(ref, hits["triangle_id"])["correct"].all()
    hit = hits["triangle_id"] >= 0
    assert hit.all() and np.isfinite(hits["barycentric"]).all()
    np.testing.assert_allclose(hits["barycentric"].sum(axis=1), 1, atol=1e-5)


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("strategy", STRATEGIES)
def test_duplicates_and_coplanar_overlaps_go_to_the_lowest_triangle_id(strategy, precision):
    points = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.1, 0], [1.3, 0.1, 0], [0.2, 1.2, 0], [0.1, 0.1, 0]]
    # 0 and 2 are the same triangle with rotated point order, 1 overlaps both in the plane,
    # 3 repeats 1 with its points in reverse order (opposite normal).
    triangles = [[4, 5, 3], [1, 2, 0], [0, 1, 2], [5, 4, 3]]
    origins, directions = grid_rays(0.25, 0.5, 0.15, 0.4, 11)  # inside all four
    for order in (triangles, triangles[::-1]):
        hits = vrc.Scene(mesh_of(points, order)).intersect(origins, directions, strategy=strategy, precision=precision)
        assert (hits["triangle_id"] == 0).all()


@pytest.mark.parametrize("gap", [0.0, 1e-12, 1e-7, 1e-3])
def test_camera_ids_alone_decide_stacked_and_duplicate_surfaces_as_the_kernel_does(gap):
    """A camera cast asking for ids alone settles most pixels without their rays (sure
    hits, src/traverse_tile.hpp): surfaces stacked within the sure hit's depth bounds, or
    duplicated, must still go to the kernel, and ties to the lowest triangle id."""
    plane = pv.Plane(i_size=1, j_size=1, i_resolution=7, j_resolution=5).triangulate()
    below = plane.translate((0, 0, -gap), inplace=False)
    mesh = below.merge(plane, merge_points=False) if gap else plane.merge(plane.copy(), merge_points=False)
    cam = vrc.Camera((0.013, 0.021, 2.0), (0.013, 0.021, 0.0), (0, 1, 0), view_angle=20, nx=61, ny=47)
    scene = vrc.Scene(mesh)
    ids = scene.cast(cam, arrays=["TriangleId"])["TriangleId"]
    np.testing.assert_array_equal(ids, scene.cast(cam, arrays=["TriangleId", "Depth"])["TriangleId"])
    upper = plane.n_cells if gap else 0  # the plane on top: the second copy, or the lower ids of two equal ones
    hit = ids >= 0
    assert hit.mean() > 0.5 and (ids[hit] >= upper).all() and (ids[hit] < upper + plane.n_cells).all()


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("strategy", STRATEGIES)
def test_rays_parallel_to_a_face_miss_it_cleanly(strategy, precision):
    mesh = mesh_of([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    origins = np.array([[-1, 0.2, 0.0], [-1, 0.2, 1e-300], [-1, 0.2, -1e-17], [0.2, -1, 0]])
    directions = np.array([[1, 0, 0.0], [1, 0, 0], [1, 0, 0], [0, 1, 0]])
    hits = vrc.Scene(mesh).intersect(origins, directions, strategy=strategy, precision=precision)
    assert (hits["triangle_id"] == -1).all()
    assert np.isnan(hits["t"]).all()


@pytest.mark.parametrize("precision", PRECISIONS)
def test_grazing_rays_are_decided_exactly(precision):
    """Rays at 1e-9 radians to a face: the exact strategy agrees with the exact reference."""
    mesh = pv.Plane(i_resolution=20, j_resolution=20).triangulate()
    scene = vrc.Scene(mesh)
    rng = np.random.default_rng(5)
    origins = np.c_[np.full(200, -0.6), rng.uniform(-0.5, 0.5, 200), np.full(200, 1e-9)]
    directions = np.c_[np.ones(200), rng.uniform(-0.1, 0.1, 200), -np.full(200, 1e-9) * rng.uniform(0.5, 3, 200)]
    hits = scene.intersect(origins, directions, precision=precision)
    ref = exact_first_hits(scene.prepared.points, scene.prepared.triangles, origins, directions)
    assert classify(ref, hits["triangle_id"])["correct"].all()
    assert np.isfinite(hits["t"][hits["triangle_id"] >= 0]).all()


def test_the_eye_on_the_surface():
    """An eye exactly on a face sees that face at depth 0 where its rays start inside it;
    with any near > 0 it sees past it. Either way, no NaN and no crash."""
    mesh = pv.Sphere(theta_resolution=16, phi_resolution=16)
    scene = vrc.Scene(mesh)
    tri = scene.prepared.points[scene.prepared.triangles[5]]
    eye = tri.mean(axis=0)
    cam = vrc.Camera(eye, np.zeros(3), (0, 0, 1) if abs(eye[2]) < 0.9 else (1, 0, 0), nx=16, ny=12, view_angle=60)
    image = scene.cast(cam, arrays=["TriangleId", "Depth"])
    assert np.isfinite(image["Depth"][image["TriangleId"] >= 0]).all()
    beyond = scene.cast(cam.replace(near=1e-9), arrays=["Depth"])["Depth"]
    assert np.nanmin(beyond) > 0.5


@pytest.mark.parametrize("precision", PRECISIONS)
def test_hits_exactly_at_near_and_far_count(precision):
    plane = mesh_of([[-9, -9, 0], [9, -9, 0], [0, 9, 0]], [[0, 1, 2]])
    for parallel in (True, False):
        cam = vrc.Camera((0, 0, 4), (0, 0, 0), (0, 1, 0), w=1, h=1, nx=1, ny=1, parallel=parallel, d=2.0)
        for near, far in [(4.0, 5.0), (3.0, 4.0), (4.0, 4.0 + 1e-12)]:
            image = vrc.cast(plane, cam.replace(near=near, far=far), arrays=["Depth"], precision=precision)
            assert image["Depth"][0] == 4.0
        outside = vrc.cast(plane, cam.replace(near=np.nextafter(4.0, 5), far=5.0), arrays=["Depth"])
        assert np.isnan(outside["Depth"][0])
