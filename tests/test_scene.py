"""Scene and cast options: array selection, precision, threads, progress, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc


@pytest.fixture(scope="module")
def sphere():
    mesh = pv.Sphere(radius=1.0, theta_resolution=40, phi_resolution=40)
    mesh.point_data["height"] = mesh.points[:, 2].copy()
    return mesh


@pytest.fixture(scope="module")
def scene(sphere):
    return vrc.Scene(sphere)


def camera(nx=96, ny=64, **kw):
    return vrc.Camera((0.3, -0.2, 4.0), (0, 0, 0), (0, 1, 0), view_angle=35, nx=nx, ny=ny, **kw)


def test_depth_of_a_sphere_matches_the_analytic_one():
    """Depth = t d along the pixel ray; for a sphere the exact t solves a quadratic. The
    tessellation lies inside the sphere, so depth is a bit larger, by at most the sagitta."""
    mesh = pv.Sphere(radius=1.0, theta_resolution=200, phi_resolution=200)
    cam = camera()
    image = vrc.cast(mesh, cam, arrays=["Depth", "vtkValidPointMask"])
    r = np.arange(cam.ny).repeat(cam.nx)
    i = np.tile(np.arange(cam.nx), cam.ny)
    pc = np.array([cam.pixel_center(a, cam.ny - 1 - b) for a, b in zip(i, r)])
    dirs = pc[:, :1] * cam.right + pc[:, 1:2] * cam.up + pc[:, 2:] * cam.backward
    b = dirs @ cam.eye
    a = (dirs * dirs).sum(1)
    disc = b * b - a * (cam.eye @ cam.eye - 1.0)
    t = (-b - np.sqrt(np.maximum(disc, 0))) / a
    solid = disc > 0.02 * a  # away from the silhouette
    hit = image["vtkValidPointMask"] == 1
    assert hit[solid].all()
    sagitta = 1 - np.cos(np.pi / 200)
    err = image["Depth"][solid] - t[solid] * cam.d
    assert (err >= -1e-12).all()
    assert err.max() < 4 * sagitta * cam.d / np.sqrt(disc[solid] / a[solid]).min()


def test_default_arrays_and_interpolation_switch(sphere, scene):
    cam = camera()
    names = set(scene.cast(cam).point_data.keys())
    assert {"TriangleId", "CellId", "Barycentric", "Depth", "vtkValidPointMask", "height", "Normals"} <= names
    assert not {"Position", "Normal"} & names
    bare = set(scene.cast(cam, interpolate=False).point_data.keys())
    assert bare == {"TriangleId", "CellId", "Barycentric", "Depth", "vtkValidPointMask"}


def test_arrays_selects_exactly_what_is_computed(scene):
    image = scene.cast(camera(), arrays=["TriangleId"])
    assert list(image.point_data.keys()) == ["TriangleId"]
    image = scene.cast(camera(), arrays="Depth")
    assert list(image.point_data.keys()) == ["Depth"]


def test_position_and_normal(scene, sphere):
    cam = camera()
    image = scene.cast(cam, arrays=["Position", "Normal", "Depth", "TriangleId"])
    hit = image["TriangleId"] >= 0
    pos, normal = image["Position"][hit], image["Normal"][hit]
    # The hit point lies at the camera depth along the view direction...
    np.testing.assert_allclose(-(pos - cam.eye) @ cam.backward, image["Depth"][hit], rtol=1e-12)
    # ...on the triangle's plane, whose unit normal points away from the centre here.
    np.testing.assert_allclose(np.linalg.norm(normal, axis=1), 1.0, rtol=1e-12)
    tri = scene.prepared.triangles[image["TriangleId"][hit]]
    p0 = scene.prepared.points[tri[:, 0]]
    np.testing.assert_allclose(((pos - p0) * normal).sum(1), 0.0, atol=1e-12)
    assert ((pos * normal).sum(1) > 0).all()


def test_float32_precision_agrees_with_float64(scene):
    a = scene.cast(camera(), arrays=["TriangleId", "Depth", "Barycentric"])
    b = scene.cast(camera(), arrays=["TriangleId", "Depth", "Barycentric"], precision="float32")
    assert b["Depth"].dtype == np.float32 and b["Barycentric"].dtype == np.float32
    same = a["TriangleId"] == b["TriangleId"]
    assert same.mean() > 0.995
    hit = same & (a["TriangleId"] >= 0)
    np.testing.assert_allclose(b["Depth"][hit], a["Depth"][hit], rtol=1e-5)
    np.testing.assert_allclose(b["Barycentric"][hit], a["Barycentric"][hit], atol=1e-4)


def test_thread_count_does_not_change_the_result(scene):
    one = scene.cast(camera(), threads=1)
    two = scene.cast(camera(), threads=2)
    for name in one.point_data.keys():
        np.testing.assert_array_equal(one[name], two[name])


def test_progress_is_reported_and_can_abort():
    mesh = pv.Sphere(theta_resolution=300, phi_resolution=300)
    scene = vrc.Scene(mesh)
    calls = []

    def progress(done, total):
        calls.append((done, total))

    scene.cast(camera(nx=1500, ny=1500), arrays=["TriangleId"], progress=progress, threads=1)
    total = calls[0][1]
    assert calls[0] == (0, total) and all(0 <= d <= t == total for d, t in calls)
    # called as the cast starts, so even a short cast can be stopped
    for nx in (1500, 8):
        with pytest.raises(InterruptedError, match="aborted"):
            scene.cast(camera(nx=nx, ny=nx), arrays=["TriangleId"], progress=lambda d, t: False, threads=1)


def test_an_exception_in_the_progress_callback_reaches_the_caller(scene):
    def progress(done, total):
        raise KeyError("from the callback")

    with pytest.raises(KeyError, match="from the callback"):
        vrc.Scene(pv.Sphere(theta_resolution=300, phi_resolution=300)).cast(
            camera(nx=1500, ny=1500), arrays=["TriangleId"], progress=progress, threads=1
        )


def test_near_and_far_bound_the_depth(scene):
    near = scene.cast(camera(), arrays=["Depth"])["Depth"]
    closest = np.nanmin(near)
    clipped = scene.cast(camera(near=closest + 0.3), arrays=["Depth"])["Depth"]
    assert np.nanmin(clipped) >= closest + 0.3  # the far side of the sphere shows through
    assert np.isfinite(clipped).sum() > 0
    far = scene.cast(camera(far=closest - 1e-9), arrays=["Depth"])["Depth"]
    assert np.isnan(far).all()


def test_parallel_camera_depth_is_distance_from_the_eye_plane():
    plane = pv.Plane(center=(0, 0, -3), direction=(0, 0, 1), i_size=10, j_size=10)
    cam = vrc.Camera((0, 0, 2), (0, 0, 0), (0, 1, 0), w=2, h=2, nx=8, ny=8, parallel=True)
    np.testing.assert_allclose(vrc.cast(plane, cam)["Depth"], 5.0, rtol=1e-15)


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        (dict(arrays=["NoSuchArray"]), ValueError, "unknown array 'NoSuchArray'"),
        (dict(arrays=[3]), TypeError, "array names must be strings"),
        (dict(strategy="fastest"), ValueError, "unknown strategy 'fastest'"),
        (dict(precision="float16"), ValueError, "unknown precision"),
        (dict(threads=0), ValueError, "threads must be a positive integer"),
        (dict(threads=-2), ValueError, "threads must be a positive integer"),
    ],
)
def test_bad_options_raise_clear_errors(scene, kwargs, error, message):
    with pytest.raises(error, match=message):
        scene.cast(camera(), **kwargs)


def test_buffers_refuse_world_space_and_unknown_options(scene):
    with pytest.raises(TypeError, match="world_space is an option of cast"):
        scene.buffers(camera(), world_space=True)
    with pytest.raises(TypeError, match="bogus"):
        scene.buffers(camera(), bogus=1)


def test_images_too_large_to_allocate_are_refused_before_allocation(scene):
    with pytest.raises(MemoryError, match="100000x100000 image needs about"):
        scene.cast(camera(nx=100_000, ny=100_000))


def test_cast_accepts_vtk_cameras(scene, sphere):
    cam = camera()
    image = scene.cast(cam.to_vtk(), arrays=["TriangleId"])
    assert image.dimensions == (640, 480, 1)  # a bare vtkCamera has no window size
    assert (image["TriangleId"] >= 0).any()


@pytest.mark.parametrize(
    ("origins", "directions", "message"),
    [
        (np.zeros((4, 2)), np.ones((4, 3)), r"origins must have shape \(\.\.\., 3\)"),
        (np.zeros((4, 3)), np.ones((3, 3)), "do not broadcast"),
        (np.zeros((2, 3)), [[0, 0, 1], [0, 0, 0]], "directions must be non-zero"),
        (np.zeros((2, 3)), [[0, 0, 1], [0, np.nan, 1]], "directions must be finite"),
        (np.zeros((1, 3, 1)), np.ones((1, 3)), r"origins must have shape"),
    ],
)
def test_bad_rays_raise_value_errors(scene, origins, directions, message):
    with pytest.raises(ValueError, match=message):
        scene.intersect(origins, directions)


def test_intersect_returns_hits_and_misses(scene):
    hits = scene.intersect([[0, 0, 5], [0, 0, 5], [5, 5, 5]], [[0, 0, -1], [0, 0, -2], [0, 0, -1]])
    assert hits["triangle_id"][0] >= 0 and hits["triangle_id"][2] == -1
    assert hits["t"][0] == pytest.approx(4.0, abs=0.01)
    assert hits["t"][1] == pytest.approx(hits["t"][0] / 2)  # t in units of the direction's length
    assert np.isnan(hits["t"][2]) and np.isnan(hits["barycentric"][2]).all()
    np.testing.assert_array_equal(hits["cell_id"], scene.prepared.cell_ids[hits["triangle_id"]] * [1, 1, 0] - [0, 0, 1])
    tmax = scene.intersect([[0, 0, 5]], [[0, 0, -1]], tmax=3.9)
    assert tmax["triangle_id"][0] == -1
    back = scene.intersect([[0, 0, 5]], [[0, 0, -1]], tmin=4.5)
    assert back["t"][0] == pytest.approx(6.0, abs=0.01)


def test_the_scene_keeps_its_own_copy_of_the_mesh():
    mesh = pv.Sphere()
    scene = vrc.Scene(mesh)
    before = scene.intersect([[0, 0, 5]], [[0, 0, -1]])
    mesh.points[:] *= 3.0
    after = scene.intersect([[0, 0, 5]], [[0, 0, -1]])
    assert before["t"][0] == after["t"][0]


def test_back_face_culling_keeps_front_faces_only(sphere, scene):
    outside = scene.cast(camera(), arrays=["TriangleId"])
    culled = scene.cast(camera(), arrays=["TriangleId"], backface_culling=True)
    np.testing.assert_array_equal(outside["TriangleId"], culled["TriangleId"])  # closed, outward normals
    inside = vrc.Camera((0, 0, 0.2), (0, 0, -1), (0, 1, 0), nx=32, ny=32)
    assert (scene.cast(inside, arrays=["TriangleId"])["TriangleId"] >= 0).all()
    assert (scene.cast(inside, arrays=["TriangleId"], backface_culling=True)["TriangleId"] == -1).all()
    flipped = sphere.copy()
    flipped.flip_faces(inplace=True)
    assert (vrc.cast(flipped, inside, arrays=["TriangleId"], backface_culling=True)["TriangleId"] >= 0).all()


@pytest.mark.parametrize("parallel", [False, True])
def test_back_face_culling_of_a_lone_sheet(parallel):
    """A sheet alone in view, from its front and from its back: asked for ids alone, most
    pixels settle without a ray (sure hits), and a sure hit must still face the eye."""
    sheet = pv.Plane(i_resolution=9, j_resolution=7).triangulate()  # normal +z
    scene = vrc.Scene(sheet)
    for side, visible in ((1.0, True), (-1.0, False)):
        eye = (0.031, 0.017, 2.0 * side)
        cam = vrc.Camera(eye, (0.031, 0.017, 0.0), (0, 1, 0), view_angle=30, nx=64, ny=48, parallel=parallel)
        ids = scene.cast(cam, arrays=["TriangleId"], backface_culling=True)["TriangleId"]
        unculled = scene.cast(cam, arrays=["TriangleId"])["TriangleId"]
        assert (unculled >= 0).mean() > 0.5
        np.testing.assert_array_equal(ids, unculled if visible else np.full_like(ids, -1))


def test_progress_bar(capsys):
    scene = vrc.Scene(pv.Sphere(theta_resolution=200, phi_resolution=200))
    scene.cast(camera(nx=1200, ny=1200), arrays=["TriangleId"], progress_bar=True, threads=1)
    err = capsys.readouterr().err
    assert "Ray casting 1200x1200" in err and "100%" in err


def test_ctrl_c_stops_a_cast_and_leaves_the_scene_usable(run_python):
    """SIGINT during a long cast raises KeyboardInterrupt between tiles; the scene then
    casts normally."""
    code = (
        "import os, signal, threading, time, pyvista as pv, vtkraycast as vrc\n"
        "scene = vrc.Scene(pv.Sphere(theta_resolution=400, phi_resolution=400))\n"
        # the sphere fills the frame: 36 M hits take seconds even in packets
        "cam = vrc.Camera((0, 0, 0.9), (0, 0, 0), (0, 1, 0), nx=6000, ny=6000)\n"
        "threading.Timer(0.3, lambda: os.kill(os.getpid(), signal.SIGINT)).start()\n"
        "start = time.perf_counter()\n"
        "try:\n"
        "    scene.cast(cam, arrays=['TriangleId'], threads=1)\n"
        "    print('finished')\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted after', round(time.perf_counter() - start, 2))\n"
        "small = scene.cast(cam.replace(nx=8, ny=8), arrays=['TriangleId'])\n"
        "print('usable', int((small['TriangleId'] >= 0).sum()))\n"
    )
    done = run_python(code)
    lines = done.stdout.split("\n")
    assert lines[0].startswith("interrupted after"), done.stdout
    assert float(lines[0].split()[-1]) < 2.0
    assert lines[1].startswith("usable") and int(lines[1].split()[1]) > 0


@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize("look", [(0, 0, 0), (0.9, 0.6, 0), (1.6, 1.1, 0)])
def test_tiles_outside_the_projected_bounds_are_skipped_exactly(parallel, look):
    """Tiles whose rays cannot reach the scene's box are filled as misses without traversal:
    the image equals the same rays cast one by one (no tile logic) for a mesh in the middle,
    at the edge and in a corner of the frame."""
    mesh = pv.Sphere(radius=0.3, theta_resolution=20, phi_resolution=20)
    window = dict(h=2.0, parallel=True) if parallel else dict(view_angle=30)
    cam = vrc.Camera((look[0], look[1], 4), look, (0, 1, 0), nx=131, ny=97, **window)
    scene = vrc.Scene(mesh)
    image = scene.cast(cam, arrays=["TriangleId"])
    rows, cols = np.arange(cam.ny).repeat(cam.nx), np.tile(np.arange(cam.nx), cam.ny)
    c = np.array([cam.pixel_center(i, cam.ny - 1 - r) for i, r in zip(cols, rows)])
    if parallel:
        origins = cam.eye + c[:, :1] * cam.right + c[:, 1:2] * cam.up
        directions = np.broadcast_to(-cam.backward, origins.shape)
    else:
        directions = c[:, :1] * cam.right + c[:, 1:2] * cam.up + c[:, 2:] * cam.backward
        origins = np.broadcast_to(cam.eye, directions.shape)
    np.testing.assert_array_equal(image["TriangleId"], scene.intersect(origins, directions)["triangle_id"])
    assert 0 < (image["TriangleId"] >= 0).mean() < 0.5
