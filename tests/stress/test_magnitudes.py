"""The whole exponent range of float64 and float32: a scene and its rays scaled together by
a power of two give the same hits, t scaled exactly, on every path (intersect with and
without a BVH, camera casts through the tiles and the one-shot binned cast), every
strategy, both precisions; beyond the supported range a ValueError names the limit. Never
a hit with t = 0, inf or NaN, never a silent miss."""

from __future__ import annotations

import math

import numpy as np
import pytest
import pyvista as pv
from hypothesis import given, settings
from hypothesis import strategies as st

import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere, rays_at_vertices_and_edges
from vtkraycast.validate import classify, exact_first_hits

TRIANGLE = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]) + [0.1, 0.2, 3.0]
ORIGIN, DIRECTION = np.array([[0.3, 0.45, 0.0]]), np.array([[0.0, 0.0, 1.0]])
WEIGHTS = [0.55, 0.2, 0.25]  # of the ray's crossing (0.3, 0.45) on TRIANGLE
RTOL = {"float64": 1e-14, "float32": 1e-6}


def one_triangle(scale: float) -> vrc.Scene:
    return vrc.Scene(pv.PolyData(TRIANGLE * scale, faces=[3, 0, 1, 2]))


@pytest.mark.parametrize("exponent", range(-300, 301, 20))
@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_one_triangle_at_every_decimal_magnitude(exponent, precision):
    """The issue's case: a triangle and its ray scaled by 10**e (origin and direction
    alike, so t stays 3): right at every magnitude float64 holds, in both precisions."""
    s = 10.0**exponent
    scene = one_triangle(s)
    for strategy in vrc.STRATEGIES:
        for accel in ("bvh", "none"):
            hit = scene.intersect(ORIGIN * s, DIRECTION * s, precision=precision, strategy=strategy, accel=accel)
            assert hit["triangle_id"][0] == 0, (strategy, accel)
            np.testing.assert_allclose(hit["t"][0], 3.0, rtol=RTOL[precision] * 8)
            np.testing.assert_allclose(hit["barycentric"][0], WEIGHTS, atol=RTOL[precision] * 8)


@settings(max_examples=150, deadline=None, derandomize=True)  # CI sees the same inputs every run
@given(
    m=st.integers(-990, 990),
    n=st.integers(-990, 990),
    corners=st.lists(st.floats(-4, 4), min_size=9, max_size=9),
    offset=st.lists(st.floats(-(2.0**20), 2.0**20), min_size=3, max_size=3),
    aim=st.tuples(st.floats(0.05, 0.9), st.floats(0.05, 0.9)),
    precision=st.sampled_from(["float64", "float32"]),
)
def test_power_of_two_scaling_is_exact(m, n, corners, offset, aim, precision):
    """Positions scaled by 2**m and the direction by 2**n: the same triangle, the same
    weights bit for bit, and t scaled by exactly 2**(m - n)."""
    points = np.reshape(corners, (3, 3)) + offset
    normal = np.cross(points[1] - points[0], points[2] - points[0])
    if np.linalg.norm(normal) < 1e-3 or abs(m - n) > {"float64": 900, "float32": 100}[precision]:
        return  # (t itself would leave the output type's range: test_a_t_beyond_the_range_is_refused)
    target = points[0] + aim[0] * (points[1] - points[0]) + aim[1] * (1 - aim[0]) * (points[2] - points[0])
    origin = target + 2.5 * normal / np.linalg.norm(normal) + [0.3, -0.2, 0.1]
    direction = target - origin
    results = []
    for a, b in ((0, 0), (m, n)):
        scene = vrc.Scene(pv.PolyData(np.ldexp(points, a), faces=[3, 0, 1, 2]))
        results.append(scene.intersect(np.ldexp(origin, a)[None], np.ldexp(direction, b)[None], precision=precision))
    base, scaled = results
    assert base["triangle_id"][0] == 0 and scaled["triangle_id"][0] == 0
    assert np.array_equal(scaled["barycentric"], base["barycentric"])
    assert scaled["t"][0] == math.ldexp(float(base["t"][0]), m - n)


@pytest.mark.parametrize("exponent", [-1000, -500, -120, -60, 0, 60, 120, 500, 1000])
@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_camera_casts_scale_exactly(exponent, precision):
    """A sphere, its camera and its window scaled by 2**e: the same image, Depth and
    Position scaled exactly, through the BVH's tiles and the one-shot binned cast."""
    check_camera_scaling(exponent, precision, "auto")


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    exponent=st.integers(-1020, 1000),
    precision=st.sampled_from(["float64", "float32"]),
    strategy=st.sampled_from(vrc.STRATEGIES),
    parallel=st.booleans(),
)
def test_camera_casts_scale_exactly_at_any_exponent(exponent, precision, strategy, parallel):
    check_camera_scaling(exponent, precision, strategy, parallel)


def check_camera_scaling(exponent: int, precision: str, strategy: str, parallel: bool = False) -> None:
    mesh = bumpy_sphere(3)
    camera = vrc.Camera((2.2, 1.6, 1.2), (0, 0, 0), (0, 0, 1), view_angle=40, nx=64, ny=48, parallel=parallel)
    arrays = ["TriangleId", "Barycentric", "Depth", "Position"]
    base = vrc.Scene(mesh).cast(camera, arrays=arrays, precision=precision, strategy=strategy)
    assert (np.asarray(base["TriangleId"]) >= 0).mean() > 0.3
    scaled_mesh = mesh.copy()
    scaled_mesh.points = np.ldexp(mesh.points, exponent)
    nonzero = np.abs(scaled_mesh.points[mesh.points != 0])
    if (nonzero < np.finfo(np.float64).tiny).any():
        return  # the scaled mesh itself lost digits in the subnormals: not the same mesh
    f = math.ldexp(1.0, exponent)
    scaled_camera = camera.replace(
        eye=camera.eye * f, look_at=camera.look_at * f, d=camera.d * f, w=camera.w * f, h=camera.h * f
    )
    depth = np.ldexp(np.asarray(base["Depth"], np.float64), exponent)
    position = np.ldexp(np.asarray(base["Position"], np.float64), exponent)
    hit = np.isfinite(depth)
    limits = np.finfo(np.float32)
    fits = (
        (depth[hit] >= limits.tiny).all()
        and (depth[hit] <= limits.max).all()
        and (abs(position[hit]) <= limits.max).all()
    )
    if precision == "float32" and not fits:  # Depth or Position itself leaves float32's range
        with pytest.raises(ValueError, match="beyond the range of float32"):
            vrc.Scene(scaled_mesh).cast(scaled_camera, arrays=arrays, precision=precision, strategy=strategy)
        return
    for image in (
        vrc.Scene(scaled_mesh).cast(scaled_camera, arrays=arrays, precision=precision, strategy=strategy),
        vrc.cast(scaled_mesh, scaled_camera, arrays=arrays, precision=precision, strategy=strategy),
    ):
        assert np.array_equal(image["TriangleId"], base["TriangleId"])
        assert np.array_equal(image["Barycentric"], base["Barycentric"], equal_nan=True)
        # (ids alone: most pixels settled by sure hits, without their rays)
        ids = vrc.Scene(scaled_mesh).cast(scaled_camera, arrays=["TriangleId"], precision=precision, strategy=strategy)
        assert np.array_equal(ids["TriangleId"], base["TriangleId"])
        assert np.array_equal(image["Depth"], np.ldexp(base["Depth"], exponent), equal_nan=True)
        # (a coordinate near 0 may scale into the subnormals, where it keeps fewer digits)
        expected = np.ldexp(base["Position"], exponent)
        normal = ~(np.abs(expected) < np.finfo(expected.dtype).tiny)
        assert np.array_equal(image["Position"][normal], expected[normal], equal_nan=True)
        np.testing.assert_allclose(
            image["Position"][~normal], expected[~normal], rtol=0, atol=4 * np.finfo(expected.dtype).tiny
        )


@pytest.mark.parametrize("window", [1e-300, 1e-30, 1e30, 1e300])
def test_the_window_distance_changes_nothing(window):
    """d, w and h scaled together describe the same rays: the same image at any d."""
    mesh = bumpy_sphere(3)
    camera = vrc.Camera((2.2, 1.6, 1.2), (0, 0, 0), (0, 0, 1), view_angle=40, nx=64, ny=48)
    base = vrc.Scene(mesh).cast(camera)
    f = math.ldexp(1.0, math.frexp(window)[1])
    image = vrc.Scene(mesh).cast(camera.replace(d=camera.d * f, w=camera.w * f, h=camera.h * f))
    for name in ("TriangleId", "Barycentric", "Depth"):
        assert np.array_equal(image[name], base[name], equal_nan=True), name


def test_a_scene_spanning_beyond_float32_is_hit_on_every_path():
    """The issue's case: a sphere 3e38 across seen from 5e38 away hit on the same pixels
    by Scene.cast, vrc.cast and intersect on the camera's rays (no empty image)."""
    mesh = pv.Sphere(radius=1.5e38, theta_resolution=24, phi_resolution=24)
    camera = vrc.Camera((5e38, 0, 0), (0, 0, 0), (0, 0, 1), view_angle=40, nx=48, ny=48)
    ids = np.asarray(vrc.Scene(mesh).cast(camera)["TriangleId"])
    assert (ids >= 0).mean() > 0.3
    assert np.array_equal(np.asarray(vrc.cast(mesh, camera)["TriangleId"]), ids)
    depth = np.asarray(vrc.Scene(mesh).cast(camera)["Depth"])
    assert np.all(np.isfinite(depth[ids >= 0])) and np.all(depth[ids >= 0] > 3e38)


EXTREMES = [(1e300, 1e290), (-1e200, 1e195), (1e-300, 1e-305), (0.0, 1e-300), (1e-200, 1e-203)]


@pytest.mark.parametrize(("offset", "scale"), EXTREMES)
@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_extreme_offsets_and_scales_against_the_exact_reference(offset, scale, precision):
    """A closed mesh far out in the exponent range, seen from inside at every vertex and
    edge: no leak, no wrong triangle, t to the precision's accuracy (exact reference)."""
    scene = vrc.Scene(bumpy_sphere(2, offset=offset, scale=scale))
    eye = np.full(3, offset) + scale * np.array([0.11, -0.07, 0.05])
    origins, directions = rays_at_vertices_and_edges(scene.prepared.points, scene.prepared.triangles, eye)
    # The reference's float prefilter squares lengths: it is given the scene scaled to about
    # 1 by a power of two, which is exact and leaves the ranking of the hits unchanged.
    k = -math.frexp(scale)[1]
    points, triangles = scene.prepared.points, scene.prepared.triangles
    ref = exact_first_hits(np.ldexp(points, k), triangles, np.ldexp(origins, k), directions)
    hits = scene.intersect(origins, directions, precision=precision)
    masks = classify(ref, hits["triangle_id"])
    assert masks["leak"].sum() == 0 and masks["wrong"].sum() == 0
    np.testing.assert_allclose(hits["t"], np.ldexp(ref.t, -k), rtol={"float64": 1e-12, "float32": 2e-6}[precision])


def test_negative_tmin_is_refused():
    scene = one_triangle(1.0)
    with pytest.raises(ValueError, match="tmin must be >= 0"):
        scene.intersect(ORIGIN, DIRECTION, tmin=-5)


def test_origins_beyond_the_precision_range_are_refused():
    """A float32 cast multiplies float32 differences: an origin 2**45 scene sizes away
    is refused by name; float64 reaches it (and is right)."""
    scene = one_triangle(1.0)
    far = ORIGIN - [0, 0, 2.0**45]
    with pytest.raises(ValueError, match="float32 casts support"):
        scene.intersect(far, DIRECTION, precision="float32")
    hit = scene.intersect(far, DIRECTION, precision="float64")
    assert hit["triangle_id"][0] == 0 and hit["t"][0] == 2.0**45 + 3
    camera = vrc.Camera((0.3, 0.45, -(2.0**45)), (0.3, 0.45, 3), (0, 1, 0), view_angle=1e-9, nx=4, ny=4)
    with pytest.raises(ValueError, match="the camera's eye"):
        scene.cast(camera, precision="float32")


def test_directions_of_any_lengths_in_one_call():
    """Each ray's direction is scaled on its own: lengths 1e-300 to 1e300 in one call give
    t in each one's units. With tmin or tmax the rays share one scale, and directions
    more than 2**32 apart in length are refused by name."""
    scene = one_triangle(1.0)
    lengths = np.array([1e-300, 1e-100, 1.0, 1e100, 1e300])
    hits = scene.intersect(np.repeat(ORIGIN, 5, axis=0), DIRECTION * lengths[:, None])
    np.testing.assert_allclose(hits["t"], 3 / lengths, rtol=1e-15)
    np.testing.assert_allclose(hits["barycentric"], np.tile(WEIGHTS, (5, 1)), atol=1e-15)
    bounded = scene.intersect(np.repeat(ORIGIN, 2, axis=0), DIRECTION * [[1e100], [1e105]], tmax=3.5e-100)
    np.testing.assert_array_equal(bounded["triangle_id"], [0, 0])
    with pytest.raises(ValueError, match="differ in length by at most"):
        scene.intersect(np.vstack((ORIGIN, ORIGIN)), np.vstack((DIRECTION, DIRECTION * 1e-300)), tmax=10)


def test_a_t_beyond_the_range_is_refused():
    """A direction 1e-300 long reaching a triangle 3 away: t = 3e300 in float64; the same
    t in float32, or 1e-308's t = 3e308 in float64, is refused rather than inf. A t that
    would underflow float32 is refused rather than 0."""
    scene = one_triangle(1.0)
    assert scene.intersect(ORIGIN, DIRECTION * 1e-300)["t"][0] == pytest.approx(3e300)
    for direction, precision in ((1e-308, "float64"), (1e-300, "float32"), (1e300, "float32")):
        with pytest.raises(ValueError, match="beyond the range"):
            scene.intersect(ORIGIN, DIRECTION * direction, precision=precision)
