"""Camera: the seed's pixel formula, VTK round trips, and clear errors for bad cameras."""

from __future__ import annotations

import math

import numpy as np
import pytest
import pyvista as pv
from vtkmodules.vtkRenderingCore import vtkCamera

import vtkraycast as vrc


def seed_pixel(i: int, j: int, w: float, h: float, d: float, nx: int, ny: int) -> tuple[float, float, float]:
    """The lecture's formula, written out independently of the package."""
    return (-w * 0.5 + w / nx * (i + 0.5), h * 0.5 - h / ny * (j + 0.5), -d)


def test_pixel_centres_follow_the_seed_formula():
    cam = vrc.Camera((1, 2, 3), (1, 2, 0), (0, 1, 0), d=2.5, w=3.0, h=1.5, nx=7, ny=5)
    for i in range(7):
        for j in range(5):
            assert cam.pixel_center(i, j).tolist() == list(seed_pixel(i, j, 3.0, 1.5, 2.5, 7, 5))


def test_rays_of_the_core_pass_through_the_seed_pixel_centres():
    """The native core generates the rays itself: a hit on a plane at the image plane
    (t = 1) must land on the seed's pixel centre, row 0 of the output at the bottom."""
    import pyvista as pv

    nx, ny, d = 8, 6, 2.0
    cam = vrc.Camera((0, 0, 0), (0, 0, -1), (0, 1, 0), d=d, w=4.0, h=3.0, nx=nx, ny=ny)
    plane = pv.Plane(center=(0, 0, -d), direction=(0, 0, 1), i_size=10, j_size=10)
    image = vrc.cast(plane, cam, arrays=["Position", "Depth"])
    pos = image["Position"].reshape(ny, nx, 3)
    for r in range(ny):
        for i in range(nx):
            x, y, z = seed_pixel(i, ny - 1 - r, 4.0, 3.0, d, nx, ny)
            np.testing.assert_allclose(pos[r, i], (x, y, z), atol=1e-12)
    np.testing.assert_allclose(image["Depth"], d, rtol=1e-14)


def test_view_angle_sets_the_window():
    cam = vrc.Camera((0, 0, 1), (0, 0, 0), (0, 1, 0), d=2.0, view_angle=60, nx=200, ny=100)
    assert cam.h == pytest.approx(2 * 2.0 * math.tan(math.radians(30)))
    assert cam.w == pytest.approx(cam.h * 2)
    assert cam.view_angle == pytest.approx(60)


def test_one_window_side_follows_the_pixel_aspect():
    cam = vrc.Camera((0, 0, 1), (0, 0, 0), (0, 1, 0), w=4.0, nx=400, ny=100)
    assert cam.h == pytest.approx(1.0)


def test_view_up_is_orthogonalised_and_axes_are_right_handed():
    cam = vrc.Camera((0, 0, 0), (0, 0, -5), (0, 1, 1))
    np.testing.assert_allclose(cam.up, (0, 1, 0), atol=1e-15)
    np.testing.assert_allclose(np.cross(cam.right, cam.up), cam.backward, atol=1e-15)


@pytest.mark.parametrize("parallel", [False, True])
def test_from_vtk_round_trips_a_vtk_camera(parallel):
    vc = vtkCamera()
    vc.SetPosition(3, -4, 5)
    vc.SetFocalPoint(0.5, 1, -1)
    vc.SetViewUp(0, 0, 1)
    vc.OrthogonalizeViewUp()
    vc.SetViewAngle(42)
    vc.SetParallelProjection(parallel)
    vc.SetParallelScale(2.5)
    vc.SetClippingRange(0.5, 50)
    cam = vrc.Camera.from_vtk(vc, nx=320, ny=200)
    assert cam.parallel is parallel
    assert (cam.near, cam.far) == (0.5, 50)
    if parallel:
        assert cam.h == pytest.approx(5.0)
    else:
        assert cam.view_angle == pytest.approx(42)
    back = cam.to_vtk()
    np.testing.assert_allclose(back.GetPosition(), vc.GetPosition())
    np.testing.assert_allclose(back.GetFocalPoint(), vc.GetFocalPoint())
    np.testing.assert_allclose(back.GetViewUp(), vc.GetViewUp(), atol=1e-12)
    assert back.GetParallelProjection() == parallel
    if parallel:
        assert back.GetParallelScale() == pytest.approx(2.5)
    else:
        assert back.GetViewAngle() == pytest.approx(42)
    again = vrc.Camera.from_vtk(back, nx=320, ny=200)
    for name in ("eye", "look_at", "view_up", "d", "w", "h", "near", "far"):
        np.testing.assert_allclose(getattr(again, name), getattr(cam, name), rtol=1e-13, atol=1e-15)


def test_from_vtk_takes_a_plotter_window_size():
    import pyvista as pv

    plotter = pv.Plotter(off_screen=True, window_size=(123, 45))
    plotter.camera.position = (0, 0, 7)
    plotter.camera.focal_point = (0, 0, 0)
    plotter.camera.up = (0, 1, 0)
    cam = vrc.Camera.from_vtk(plotter)
    assert (cam.nx, cam.ny) == (123, 45)
    np.testing.assert_allclose(cam.eye, (0, 0, 7))
    assert vrc.Camera.from_vtk(plotter.camera, nx=10, ny=10).nx == 10
    plotter.close()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(view_up=(0, 0, 1)), "view_up is parallel"),
        (dict(view_up=(0, 0, 0)), "view_up is parallel"),
        (dict(nx=0), "nx must be at least 1"),
        (dict(ny=-3), "ny must be at least 1"),
        (dict(nx=2.5), "nx must be a whole number"),
        (dict(d=0.0), "d must be a positive"),
        (dict(d=-1.0), "d must be a positive"),
        (dict(w=0.0, h=1.0), "w must be a positive"),
        (dict(w=1.0, h=-2.0), "h must be a positive"),
        (dict(view_angle=0), "view_angle must be strictly between"),
        (dict(view_angle=180), "view_angle must be strictly between"),
        (dict(eye=(0, 0, np.nan)), "eye must be finite"),
        (dict(eye=(0, 0)), "eye must be a 3-vector"),
        (dict(look_at=(0, 0, 5)), "eye and look_at coincide"),
        (dict(near=2.0, far=1.0), "near < far"),
        (dict(view_angle=30, h=1.0), "either view_angle or"),
    ],
)
def test_bad_cameras_raise_value_errors_naming_the_problem(kwargs, message):
    args = dict(eye=(0, 0, 5), look_at=(0, 0, 0), view_up=(0, 1, 0))
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        vrc.Camera(args.pop("eye"), args.pop("look_at"), args.pop("view_up"), **args)


def test_cameras_are_immutable_and_replace_makes_copies():
    cam = vrc.Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), nx=10, ny=10)
    with pytest.raises(AttributeError):
        cam.nx = 3
    with pytest.raises(ValueError):
        cam.eye[0] = 1.0
    wider = cam.replace(view_angle=60)
    assert wider.view_angle == pytest.approx(60) and cam.view_angle == pytest.approx(30)


@pytest.mark.parametrize("view", ["iso", "+x", "-y", "xy", "xz", "yz"])
def test_framing_keeps_the_whole_box_in_view(view):
    bounds = (-1.0, 3.0, 0.0, 1.0, 10.0, 12.0)
    cam = vrc.Camera.framing(bounds, view=view, nx=64, ny=48)
    corners = np.array(np.meshgrid(*np.reshape(bounds, (3, 2)), indexing="ij")).reshape(3, -1).T
    rel = corners - cam.eye
    x, y, depth = rel @ cam.right, rel @ cam.up, -(rel @ cam.backward)
    assert (depth > 0).all()
    assert (np.abs(x / depth * cam.d) <= cam.w / 2).all()
    assert (np.abs(y / depth * cam.d) <= cam.h / 2).all()


@pytest.mark.parametrize("parallel", [False, True])
def test_cast_through_a_plotter_overlays_its_screenshot(parallel):
    """vrc.cast(mesh, plotter) uses the plotter's camera and window size: its hit mask
    matches the plotter's own depth image (rows top first) on at least 99% of pixels."""
    import pyvista as pv

    mesh = pv.examples.load_airplane()
    plotter = pv.Plotter(off_screen=True, window_size=(240, 160))
    plotter.add_mesh(mesh)
    plotter.camera_position = "xy" if parallel else "iso"
    plotter.enable_parallel_projection() if parallel else None
    plotter.camera.azimuth = 20
    plotter.screenshot()
    covered = np.isfinite(plotter.get_image_depth())
    image = vrc.cast(mesh, plotter, arrays=["vtkValidPointMask"])
    assert image.dimensions == (240, 160, 1)
    ours = image["vtkValidPointMask"].reshape(160, 240)[::-1].astype(bool)
    agreement = np.mean(ours == covered)
    plotter.close()
    iou = np.sum(ours & covered) / np.sum(ours | covered)
    print(f"coverage {covered.mean():.3f}, agreement {agreement:.4f}, IoU {iou:.4f}")
    assert covered.mean() > 0.02
    assert agreement >= 0.99, agreement
    assert iou > 0.9, iou  # the mask is thin: also compare on the covered pixels alone


def test_to_vtk_cameras_render(run_python):
    """A camera from to_vtk() made before any OpenGL module is loaded must still render
    (a plain vtkCamera would crash the renderer)."""
    code = (
        "import vtkraycast as vrc\n"
        "vc = vrc.Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), view_angle=40, nx=64, ny=48).to_vtk()\n"
        "from vtkmodules.vtkFiltersSources import vtkSphereSource\n"
        "from vtkmodules.vtkRenderingCore import vtkActor, vtkPolyDataMapper, vtkRenderer, vtkRenderWindow\n"
        "s = vtkSphereSource(); m = vtkPolyDataMapper(); m.SetInputConnection(s.GetOutputPort())\n"
        "a = vtkActor(); a.SetMapper(m); r = vtkRenderer(); r.AddActor(a); r.SetActiveCamera(vc)\n"
        "w = vtkRenderWindow(); w.SetOffScreenRendering(1); w.AddRenderer(r); w.Render(); print('rendered')\n"
    )
    done = run_python(code)
    assert "rendered" in done.stdout


@pytest.mark.parametrize("view", ["iso", "+x", "-z", "xz"])
def test_framing_points_fits_the_object_tightly(view):
    rng = np.random.default_rng(2)
    points = rng.normal(size=(2000, 3)) * [3.0, 1.0, 0.5] + [10.0, -4.0, 2.0]
    points = np.vstack((points, [[30.0, 20.0, 10.0]]))  # far from the rest: the box's corner is empty
    cam = vrc.Camera.framing(points, view=view, nx=200, ny=100)
    offset = points - cam.eye
    depth = offset @ -cam.backward
    x = (offset @ cam.right) / depth * cam.d / (cam.w / 2)  # -1 .. 1 across the window
    y = (offset @ cam.up) / depth * cam.d / (cam.h / 2)
    assert (depth > 0).all()
    assert np.abs(x).max() <= 1 / 1.05 + 1e-9 and np.abs(y).max() <= 1 / 1.05 + 1e-9
    assert max(np.abs(x).max(), np.abs(y).max()) > 0.9  # tight: touches the margin on one side
    image = vrc.cast(
        pv.PolyData(points).delaunay_3d().extract_surface(algorithm="dataset_surface"), cam, arrays=["TriangleId"]
    )
    assert (image["TriangleId"] >= 0).mean() > 0.05
