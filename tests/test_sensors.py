"""Cameras users bring: intrinsics and extrinsics (COLMAP, OpenCV, Open3D), checked ray for
ray against Open3D's create_rays_pinhole and by casting against Open3D's cast_rays."""

from __future__ import annotations

import numpy as np
import pytest

import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere

o3d = pytest.importorskip("open3d")


def _look(eye, target, up) -> np.ndarray:
    """World-to-camera extrinsic (x right, y down, z forward)."""
    forward = np.asarray(target, float) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.vstack((right, down, forward))
    extrinsic = np.eye(4)
    extrinsic[:3, :3] = rotation
    extrinsic[:3, 3] = -rotation @ eye
    return extrinsic


K = np.array([[610.0, 0.0, 301.3], [0.0, 580.0, 255.9], [0.0, 0.0, 1.0]])  # off-centre, non-square
EXTRINSIC = _look(np.array([0.4, -2.7, 1.1]), [0.05, 0.0, -0.1], [0.0, 0.0, 1.0])
WIDTH, HEIGHT = 640, 480


def _open3d_rays() -> np.ndarray:
    rays = o3d.t.geometry.RaycastingScene.create_rays_pinhole(
        o3d.core.Tensor(K), o3d.core.Tensor(EXTRINSIC), WIDTH, HEIGHT
    )
    return rays.numpy().reshape(HEIGHT, WIDTH, 6)  # row-major from the top


def test_rays_equal_open3d_create_rays_pinhole():
    cam = vrc.Camera.from_intrinsics(K, EXTRINSIC, WIDTH, HEIGHT)
    origins, directions, _, _ = cam.rays()
    theirs = _open3d_rays()[::-1].reshape(-1, 6)  # VTK order: row 0 at the bottom
    np.testing.assert_allclose(origins, theirs[:, :3], atol=1e-6)
    # Open3D's directions reach the plane z = 1 in camera space, as ours do (float32 there)
    np.testing.assert_allclose(directions, theirs[:, 3:], rtol=1e-5, atol=1e-6)


def test_pixel_origin_center_is_opencv():
    corner = vrc.Camera.from_intrinsics(K, EXTRINSIC, WIDTH, HEIGHT)
    center = vrc.Camera.from_intrinsics(K - np.array([[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]]), EXTRINSIC, WIDTH, HEIGHT,
                                        pixel_origin="center")  # fmt: skip
    np.testing.assert_allclose(center.rays()[1], corner.rays()[1], atol=1e-12)


def test_round_trip_and_depth_is_camera_z():
    cam = vrc.Camera.from_intrinsics(K, EXTRINSIC, WIDTH, HEIGHT)
    k, extrinsic = cam.to_intrinsics()
    np.testing.assert_allclose(k, K, rtol=1e-12)
    np.testing.assert_allclose(extrinsic, EXTRINSIC, atol=1e-12)
    mesh = bumpy_sphere(4)
    image = vrc.cast(mesh, cam, arrays=["Depth", "TriangleId", "Position"])
    hit = image["TriangleId"] >= 0
    assert 0.1 < hit.mean() < 0.9
    camera_points = image["Position"][hit] @ EXTRINSIC[:3, :3].T + EXTRINSIC[:3, 3]
    np.testing.assert_allclose(image["Depth"][hit], camera_points[:, 2], rtol=1e-12)


def test_cast_agrees_with_open3d_cast_rays():
    mesh = bumpy_sphere(4)
    cam = vrc.Camera.from_intrinsics(K, EXTRINSIC, WIDTH, HEIGHT)
    image = vrc.Scene(mesh).cast(cam, arrays=["TriangleId", "Depth"])
    scene = o3d.t.geometry.RaycastingScene()
    prepared = vrc.Scene(mesh).prepared
    scene.add_triangles(o3d.core.Tensor(prepared.points.astype(np.float32)),
                        o3d.core.Tensor(prepared.triangles.astype(np.uint32)))  # fmt: skip
    result = scene.cast_rays(o3d.core.Tensor(_open3d_rays().astype(np.float32)))
    ids = result["primitive_ids"].numpy().astype(np.int64)[::-1].reshape(-1)
    ids[ids == np.iinfo(np.uint32).max] = -1
    assert (ids == image["TriangleId"]).mean() > 0.999
    depth = result["t_hit"].numpy()[::-1].reshape(-1)
    both = np.isfinite(depth) & np.isfinite(image["Depth"])
    np.testing.assert_allclose(image["Depth"][both], depth[both], rtol=1e-4)


def test_shifted_window_keeps_the_fast_path_exact():
    # the tile path (camera tree, sure hits) against per-pixel rays through intersect
    cam = vrc.Camera.from_intrinsics(K, EXTRINSIC, 200, 150)
    scene = vrc.Scene(bumpy_sphere(4))
    image = scene.cast(cam, arrays=["TriangleId", "Depth"])
    origins, directions, tmin, tmax = cam.rays()
    hits = scene.intersect(origins, directions, tmin=tmin, tmax=tmax, arrays=["triangle_id", "t"])
    np.testing.assert_array_equal(image["TriangleId"], hits["triangle_id"])
    np.testing.assert_array_equal(image["Depth"], hits["t"] * cam.d)


def test_bad_intrinsics_raise():
    with pytest.raises(ValueError, match="intrinsic matrix must be"):
        vrc.Camera.from_intrinsics([[500, 1, 320], [0, 500, 240], [0, 0, 1]], np.eye(4), 640, 480)
    with pytest.raises(ValueError, match="must be a rotation"):
        vrc.Camera.from_intrinsics(K, np.diag([2.0, 1, 1, 1]), 640, 480)
    with pytest.raises(ValueError, match="pixel_origin"):
        vrc.Camera.from_intrinsics(K, np.eye(4), 640, 480, pixel_origin="middle")
    with pytest.raises(ValueError, match="no intrinsic matrix"):
        vrc.Camera((0, 0, 1), (0, 0, 0), (0, 1, 0), parallel=True).to_intrinsics()


# -- panoramas and lidar, against the analytic distances to a box's walls ---------------

BOX = (-1.0, 3.0, -2.0, 1.5, -0.5, 2.5)


def _box() -> vrc.Scene:
    import pyvista as pv

    return vrc.Scene(pv.Box(bounds=BOX, level=2).triangulate())


def _wall_distance(point: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Distance from ``point`` (inside the box) along unit ``directions`` to its walls."""
    low, high = np.array(BOX[0::2]), np.array(BOX[1::2])
    with np.errstate(divide="ignore"):
        to_wall = np.where(directions > 0, (high - point) / directions, (low - point) / directions)
    return np.min(np.where(directions != 0, to_wall, np.inf), axis=1)


def test_lidar_returns_the_walls_of_a_box():
    position = np.array([0.3, -0.4, 0.7])
    lidar = vrc.Lidar(position, elevations=[-30, -7.5, 0, 12, 45], azimuth_steps=360, forward=(1, 1, 0))
    cloud, ranges = _box().scan(lidar, range_image=True)
    assert cloud.n_points == 5 * 360 and ranges.shape == (5, 360)
    _, directions, ring, azimuth = lidar.rays()
    np.testing.assert_allclose(ranges.reshape(-1), _wall_distance(position, directions), rtol=1e-12)
    np.testing.assert_allclose(cloud.points, position + ranges.reshape(-1, 1) * directions, atol=1e-12)
    np.testing.assert_array_equal(cloud["Ring"], ring)
    np.testing.assert_array_equal(cloud["Elevation"], np.array([-30, -7.5, 0, 12, 45])[ring])
    np.testing.assert_allclose(cloud["Azimuth"], azimuth)
    assert {"TriangleId", "CellId", "Barycentric", "Range"} <= set(cloud.point_data.keys())
    # beam 0 of ring "0 degrees" looks along forward, beam 90 (90 degrees) to its left
    horizontal = directions[2 * 360 : 3 * 360]
    np.testing.assert_allclose(horizontal[0], np.array([1, 1, 0]) / np.sqrt(2), atol=1e-15)
    np.testing.assert_allclose(horizontal[90], np.array([-1, 1, 0]) / np.sqrt(2), atol=1e-15)


def test_lidar_range_limits():
    position = np.array([0.3, -0.4, 0.7])
    lidar = vrc.Lidar(position, [0.0], 720, min_range=1.0, max_range=2.0)
    cloud, ranges = _box().scan(lidar, range_image=True)
    expected = _wall_distance(position, lidar.rays()[1])
    inside = (expected >= 1.0) & (expected <= 2.0)
    assert 0 < inside.sum() < len(inside)
    np.testing.assert_array_equal(np.isfinite(ranges.reshape(-1)), inside)
    assert cloud.n_points == inside.sum()
    # a range no beam returns within: an empty cloud, with every array
    cloud, ranges = _box().scan(vrc.Lidar(position, [0.0], 720, min_range=5.0), range_image=True)
    assert cloud.n_points == 0 and np.isnan(ranges).all()
    assert {"Range", "Ring", "Azimuth", "Elevation", "TriangleId", "Barycentric"} <= set(cloud.point_data.keys())
    assert cloud["Barycentric"].shape == (0, 3)
    with pytest.raises(ValueError, match="elevations"):
        vrc.Lidar(position, [100.0], 10)
    with pytest.raises(ValueError, match="azimuth_steps"):
        vrc.Lidar(position, [0.0], 0)


def test_scans_keep_their_own_arrays_and_the_lidar_its_own():
    # Inside a closed box every beam returns, and the cloud then holds the arrays the core
    # wrote: later scans must write elsewhere, the range image must not share them, and
    # the lidar keeps copies of what it was made with.
    elevations, position = np.array([-30.0, 0.0, 12.0]), np.array([0.3, -0.4, 0.7])
    scene, lidar = _box(), vrc.Lidar(position, elevations, 360)
    first, image = scene.scan(lidar, range_image=True)
    assert first.n_points == 3 * 360
    points, arrays = np.array(first.points), {name: np.array(first[name]) for name in first.point_data}
    image[:] = -1.0
    elevations[:] = 5.0
    position[:] = 0.0
    for moved in ((-0.5, 0.2, 0.1), (0.1, 0.1, -0.6)):
        scene.scan(vrc.Lidar(moved, [-30.0, 0.0, 12.0], 360))
        np.testing.assert_array_equal(first.points, points)
        for name, values in arrays.items():
            np.testing.assert_array_equal(first[name], values, err_msg=name)
    again = scene.scan(lidar)
    np.testing.assert_array_equal(again.points, points)
    np.testing.assert_array_equal(again["Elevation"], arrays["Elevation"])
    _, directions, ring, azimuth = lidar.rays()
    for kept in (directions, ring, azimuth, lidar.elevations, lidar.position):
        with pytest.raises(ValueError, match="read-only"):
            kept[0] = 0


def test_panorama_depth_is_the_distance_to_the_walls():
    eye = np.array([1.2, 0.1, 0.4])
    panorama = vrc.Panorama(eye, 96, 48, forward=(0, 1, 0))
    image = _box().cast(panorama)
    assert image.dimensions == (96, 48, 1)
    _, directions = panorama.rays()
    np.testing.assert_allclose(image["Depth"], _wall_distance(eye, directions), rtol=1e-12)
    assert (image["TriangleId"] >= 0).all()
    # the centre of the middle row looks forward; row 0 is the bottom
    centre = directions.reshape(48, 96, 3)
    np.testing.assert_allclose(centre[23:25, 47:49].mean(axis=(0, 1)), [0, 1, 0], atol=0.05)
    assert centre[0, 0, 2] < -0.99 and centre[-1, 0, 2] > 0.99


def test_cast_many_equals_separate_casts():
    scene = vrc.Scene(bumpy_sphere(3))
    views = [vrc.Camera.from_intrinsics(K, _look(np.array(eye), [0, 0, 0], [0, 0, 1]), 80, 60)
             for eye in ([0.4, -2.7, 1.1], [2.5, 0.3, -0.8], [-1.9, 1.9, 0.6])]  # fmt: skip
    many = scene.cast_many(views, arrays=["TriangleId", "Depth"])
    for camera, image in zip(views, many):
        single = scene.cast(camera, arrays=["TriangleId", "Depth"])
        np.testing.assert_array_equal(image["TriangleId"], single["TriangleId"])
        np.testing.assert_array_equal(image["Depth"], single["Depth"])


# -- sweeps are traced in bundles: the same answers as ray by ray ------------------------


def _sweep_cases():
    inside = ("inside", bumpy_sphere(5), vrc.Lidar((0.1, -0.05, 0.2), np.linspace(-40, 40, 24), 600))
    outside = (
        "outside",
        bumpy_sphere(5),
        vrc.Lidar((2.5, 0.4, 0.3), np.linspace(-30, 30, 40), 1000, forward=(-1, 0, 0)),
    )
    far = (
        "offset 1e6",
        bumpy_sphere(5, offset=1e6),
        vrc.Lidar((1e6 + 0.1, 1e6, 1e6 - 0.2), np.linspace(-40, 40, 24), 600),
    )
    ranged = (
        "range limits",
        bumpy_sphere(5),
        vrc.Lidar((0.013, -0.021, 0.007), [-5, 0, 5, 10], 900, min_range=0.9, max_range=1.0),
    )
    poles = ("wide tiles", bumpy_sphere(4), vrc.Lidar((0.21, -0.033, 0.017), [-90, -60, -20, 0, 20, 60, 90], 12))
    # a scene the core holds rescaled (lengths times 2**-41), most beams missing: the
    # returns' positions scaled back, the misses' rows, never written, not read
    scaled = (
        "scaled 1e12",
        bumpy_sphere(4).scale(1e12, inplace=False),
        vrc.Lidar((2.5e12, 0.4e12, 0.3e12), np.linspace(-30, 30, 20), 400, forward=(-1, 0, 0)),
    )
    import pyvista as pv

    # beams at multiples of 45 degrees pass within rounding of the box's edges and corners
    edges = ("box edges", pv.Box(level=3).triangulate(), vrc.Lidar((0, 0, 0), [-45, -35.26438968, 0, 45], 360))

    def height_field(n: int) -> pv.PolyData:
        x = np.linspace(0.0, 10.0, n)
        xx, yy = np.meshgrid(x, x, indexing="xy")
        ground = pv.StructuredGrid(xx, yy, 0.6 * np.sin(1.3 * xx) * np.cos(0.9 * yy) + 0.05 * xx)
        return ground.extract_surface(algorithm="dataset_surface").triangulate()

    # 64 steps put tiles of 90 degrees over a height field: some of them take more nodes
    # than their rays would and go ray by ray, the others stay bundles
    coarse = ("coarse steps", height_field(120), vrc.Lidar((5, 5, 2.3), np.linspace(-25, 15, 16), 64))
    # over a finer height field, the rows of tiles whose beams graze it: bundles cut short,
    # budgets from the row's rays, rows going on as bundles or ray by ray, whichever is cheaper
    grazing = ("grazing rows", height_field(400), vrc.Lidar((5, 5, 2.3), np.linspace(-25, 15, 32), 256))
    return [inside, outside, far, ranged, poles, scaled, edges, coarse, grazing]


@pytest.mark.parametrize("case", _sweep_cases(), ids=lambda case: case[0])
def test_scan_equals_intersect_bit_for_bit(case):
    """Scan's bundles against the ray-by-ray path on the same rays (every output), and the
    hits against Open3D's (Embree, float32: the same triangle, or the same distance where
    a beam passes within its rounding of an edge)."""
    import open3d as o3d

    name, mesh, lidar = case
    scene = vrc.Scene(mesh)
    cloud, ranges = scene.scan(lidar, range_image=True)
    origins, directions, ring, azimuth = lidar.rays()
    reference = scene.intersect(origins, directions, tmin=lidar.min_range, tmax=lidar.max_range,
                                arrays=["triangle_id", "t", "barycentric", "position"])  # fmt: skip
    hit = reference["triangle_id"] >= 0
    np.testing.assert_array_equal(cloud["Range"], reference["t"][hit])  # the returns' beams, in order
    np.testing.assert_array_equal(cloud["Ring"], ring[hit])
    np.testing.assert_array_equal(cloud["Azimuth"], azimuth[hit])
    np.testing.assert_array_equal(cloud["Elevation"], lidar.elevations[ring[hit]])
    assert 0 < hit.sum()
    if name in ("inside", "box edges"):  # from inside a closed surface every beam returns
        assert hit.all()
    np.testing.assert_array_equal(ranges.reshape(-1), reference["t"])
    np.testing.assert_array_equal(cloud["TriangleId"], reference["triangle_id"][hit])
    np.testing.assert_array_equal(cloud["Barycentric"], reference["barycentric"][hit])
    np.testing.assert_array_equal(cloud.points, reference["position"][hit])
    peer = o3d.t.geometry.RaycastingScene()
    peer.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(
        o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(mesh.points - mesh.center),
                                  o3d.utility.Vector3iVector(mesh.faces.reshape(-1, 4)[:, 1:]))))  # fmt: skip
    rays = np.hstack((origins - mesh.center, directions)).astype(np.float32)
    theirs = peer.cast_rays(o3d.core.Tensor(rays))
    t = theirs["t_hit"].numpy()
    found = np.isfinite(t) & (t >= lidar.min_range) & (t <= lidar.max_range)
    theirs_id = np.where(found, theirs["primitive_ids"].numpy().astype(np.int64), -1)
    # (Open3D's first hit may lie before min_range, where the lidar's search starts; on a
    # shared edge it may take the other triangle, at the same distance)
    same_point = np.abs(t - reference["t"]) <= 1e-5 * reference["t"]
    agree = (theirs_id == reference["triangle_id"]) | same_point | (lidar.min_range > 0) & (t < lidar.min_range)
    assert np.mean(agree) > 0.999


def test_panorama_equals_intersect_and_brute_force():
    scene = vrc.Scene(bumpy_sphere(3))
    panorama = vrc.Panorama((0.3, -0.2, 0.1), 64, 32, forward=(0, 1, 1))
    image = scene.cast(panorama, arrays=["TriangleId", "Depth", "Barycentric"])
    origins, directions = panorama.rays()
    for accel in ("bvh", "none"):  # the seed's every-triangle test: no hierarchy at all
        reference = scene.intersect(origins, directions, accel=accel)
        np.testing.assert_array_equal(image["TriangleId"], reference["triangle_id"])
        np.testing.assert_array_equal(image["Depth"], reference["t"])
        np.testing.assert_array_equal(image["Barycentric"], reference["barycentric"])
