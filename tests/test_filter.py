"""RayCastFilter in VTK pipelines: same arrays as cast(), re-execution rules, abort,
progress, errors."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkCommonCore import vtkCommand
from vtkmodules.vtkFiltersSources import vtkSphereSource
from vtkmodules.vtkImagingGeneral import vtkImageGradientMagnitude
from vtkmodules.vtkRenderingCore import vtkCamera

import vtkraycast as vrc


def make_camera(position=(0.2, -0.4, 3.0)) -> vtkCamera:
    camera = vtkCamera()
    camera.SetPosition(*position)
    camera.SetFocalPoint(0, 0, 0)
    camera.SetViewUp(0, 1, 0)
    camera.SetViewAngle(35)
    camera.SetClippingRange(0.1, 100)
    return camera


def make_filter(camera, nx=80, ny=60) -> vrc.RayCastFilter:
    caster = vrc.RayCastFilter()
    caster.SetCamera(camera)
    caster.SetResolution(nx, ny)
    return caster


def arrays_of(image) -> dict[str, np.ndarray]:
    pd = image.GetPointData()
    return {pd.GetArrayName(k): vtk_to_numpy(pd.GetArray(k)) for k in range(pd.GetNumberOfArrays())}


def assert_same(a: dict, b: dict) -> None:
    assert set(a) == set(b)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_output_equals_cast_array_for_array():
    source = vtkSphereSource()
    source.SetThetaResolution(30)
    source.SetPhiResolution(30)
    source.Update()
    camera = make_camera()
    caster = make_filter(camera)
    caster.SetInputConnection(source.GetOutputPort())
    caster.SetArrays(["TriangleId", "CellId", "Barycentric", "Depth", "Normal", "Position", "vtkValidPointMask"])
    caster.Update()
    out = caster.GetOutput()
    expected = vrc.cast(source.GetOutput(), vrc.Camera.from_vtk(camera, nx=80, ny=60), arrays=caster.GetArrays())
    assert out.GetDimensions() == (80, 60, 1)
    assert_same(arrays_of(out), arrays_of(expected))


def test_camera_change_recasts_without_rebuilding_and_mesh_change_rebuilds():
    source = vtkSphereSource()
    camera = make_camera()
    caster = make_filter(camera)
    caster.SetArrays(["Depth"])
    pipeline = source >> caster
    first = vtk_to_numpy(pipeline.update().output.GetPointData().GetArray("Depth")).copy()
    assert caster.GetNumberOfSceneBuilds() == 1
    mtime = caster.GetOutput().GetMTime()
    pipeline.update()  # nothing changed: no execution at all
    assert caster.GetOutput().GetMTime() == mtime
    camera.Azimuth(10)
    second = vtk_to_numpy(pipeline.update().output.GetPointData().GetArray("Depth"))
    assert caster.GetNumberOfSceneBuilds() == 1
    assert not np.array_equal(np.isnan(first), np.isnan(second)) or np.nanmax(np.abs(first - second)) > 0
    source.SetRadius(0.25)  # new mesh data
    third = vtk_to_numpy(pipeline.update().output.GetPointData().GetArray("Depth"))
    assert caster.GetNumberOfSceneBuilds() == 2
    assert np.nanmin(third) > np.nanmin(second) + 0.2


def test_setters_modify_only_on_change():
    caster = vrc.RayCastFilter()
    for setter, value in [
        ("SetResolution", (10, 20)),
        ("SetStrategy", ("watertight",)),
        ("SetPrecision", ("float32",)),
        ("SetArrays", (["Depth"],)),
        ("SetInterpolate", (False,)),
        ("SetBackfaceCulling", (True,)),
        ("SetThreads", (1,)),
        ("SetWorldSpace", (True,)),
    ]:
        getattr(caster, setter)(*value)
        mtime = caster.GetMTime()
        getattr(caster, setter)(*value)
        assert caster.GetMTime() == mtime, setter
    assert caster.GetResolution() == (10, 20) and caster.GetArrays() == ("Depth",)
    camera = make_camera()
    caster.SetCamera(camera)
    mtime = caster.GetMTime()
    caster.SetCamera(camera)
    assert caster.GetMTime() == mtime


@pytest.mark.parametrize(
    ("setter", "args", "message"),
    [
        ("SetResolution", (0, 10), "nx must be at least 1"),
        ("SetStrategy", ("bogus",), "unknown strategy"),
        ("SetPrecision", ("float16",), "unknown precision"),
        ("SetThreads", (-1,), "threads must be"),
    ],
)
def test_bad_settings_raise_at_once(setter, args, message):
    with pytest.raises(ValueError, match=message):
        getattr(vrc.RayCastFilter(), setter)(*args)


def test_errors_inside_the_pipeline_raise_in_python():
    caster = make_filter(make_camera())
    caster.SetArrays(["NoSuchArray"])
    errors = []
    from vtkmodules.vtkCommonCore import vtkOutputWindow

    window = vtkOutputWindow.GetInstance()
    tag = window.AddObserver(vtkCommand.ErrorEvent, lambda obj, event: errors.append(event))
    # Sources are kept in variables: a VTK consumer does not keep its producer alive.
    first, second = vtkSphereSource(), vtkSphereSource()
    try:
        with pytest.raises(ValueError, match="unknown array 'NoSuchArray'"):
            (first >> caster).update()
        caster.SetInputConnection(second.GetOutputPort())
        with pytest.raises(ValueError, match="unknown array"):
            caster.Update()
    finally:
        window.RemoveObserver(tag)
    assert errors  # reported as a VTK error too


def test_unstructured_grid_input_names_its_cells():
    grid = pv.ImageData(dimensions=(4, 2, 2)).cast_to_unstructured_grid()  # three hexahedra along x
    camera = vtkCamera()
    camera.SetPosition(1.5, 0.5, 10)
    camera.SetFocalPoint(1.5, 0.5, 0)
    camera.SetParallelProjection(True)
    camera.SetParallelScale(0.5)
    caster = make_filter(camera, nx=90, ny=30)
    caster.SetInputData(grid)
    caster.SetArrays(["CellId", "Position"])
    caster.Update()
    arrays = arrays_of(caster.GetOutput())
    np.testing.assert_array_equal(arrays["CellId"], np.floor(arrays["Position"][:, 0]).astype(int))


def test_progress_events_and_abort():
    source = vtkSphereSource()
    source.SetThetaResolution(400)
    source.SetPhiResolution(400)
    camera = make_camera()
    caster = make_filter(camera, nx=3000, ny=3000)
    # (with depths: ids alone settle this sphere's pixels without rays, too fast to stop
    # after the first progress event, at 50 ms)
    caster.SetArrays(["TriangleId", "Depth"])
    caster.SetThreads(1)
    caster.SetInputConnection(source.GetOutputPort())
    progress = []
    caster.AddObserver(vtkCommand.ProgressEvent, lambda obj, event: progress.append(obj.GetProgress()))
    caster.Update()
    assert len(progress) >= 2 and progress[-1] == pytest.approx(1.0)
    full = (vtk_to_numpy(caster.GetOutput().GetPointData().GetArray("TriangleId")) >= 0).sum()
    assert full > 0

    def abort(obj, event):
        if 0 < obj.GetProgress() < 1:
            obj.AbortExecuteOn()

    n_full = len(progress)
    tag = caster.AddObserver(vtkCommand.ProgressEvent, abort)
    camera.Azimuth(5)
    caster.Update()
    assert caster.GetOutput().GetNumberOfPoints() == 0  # stopped before the end: no partial image
    # stopped at the very event that asked (the cast's share done by then is the machine's)
    assert len([p for p in progress[n_full:] if 0 < p < 1]) == 1
    caster.RemoveObserver(tag)
    camera.Azimuth(5)
    caster.Update()  # the next update runs to the end again
    assert caster.GetOutput().GetNumberOfPoints() == 3000 * 3000


def test_pv_wrap_of_the_output():
    caster = make_filter(make_camera())
    caster.SetInputData(pv.Sphere())
    caster.Update()
    image = pv.wrap(caster.GetOutput())
    assert isinstance(image, pv.ImageData) and (image["vtkValidPointMask"] == 1).any()


def test_image_filter_downstream():
    caster = make_filter(make_camera())
    caster.SetArrays(["Depth"])
    gradient = vtkImageGradientMagnitude()
    gradient.SetDimensionality(2)
    out = (vtkSphereSource() >> caster >> gradient).update().output
    assert out.GetDimensions() == (80, 60, 1)


def test_the_filter_does_not_import_pyvista(run_python):
    code = (
        "import sys, vtkraycast\n"
        "from vtkmodules.vtkFiltersSources import vtkSphereSource\n"
        "from vtkmodules.vtkRenderingCore import vtkCamera\n"
        "c = vtkCamera(); c.SetPosition(0, 0, 3)\n"
        "f = vtkraycast.RayCastFilter(); f.SetCamera(c); f.SetResolution(16, 16)\n"
        "s = vtkSphereSource(); f.SetInputConnection(s.GetOutputPort()); f.Update()\n"
        "assert f.GetOutput().GetNumberOfPoints() == 256\n"
        "assert 'pyvista' not in sys.modules, 'pyvista was imported'\n"
    )
    run_python(code)
