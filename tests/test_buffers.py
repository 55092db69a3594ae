"""A scene reuses the output arrays and images of its earlier casts only once nothing refers to them."""

from __future__ import annotations

import gc
import weakref

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc


@pytest.fixture(scope="module")
def scene_and_cameras():
    mesh = pv.Sphere(theta_resolution=40, phi_resolution=40)
    mesh.point_data["Elevation"] = mesh.points[:, 2].copy()
    near = vrc.Camera.framing(mesh.bounds, view="xy", nx=64, ny=48)
    far = near.replace(view_angle=60.0)
    return vrc.Scene(mesh), near, far


def snapshot(image) -> dict[str, np.ndarray]:
    return {name: np.array(image[name]) for name in image.point_data.keys()}


def address(array) -> int:
    return np.asarray(array).__array_interface__["data"][0]


def dropped_image_depth(scene, camera) -> int:
    """The address of the Depth array of an image cast and dropped (its arrays now the pool's alone)."""
    image = scene.cast(camera)
    depth_at = address(image["Depth"])
    del image
    gc.collect()
    return depth_at


def test_images_held_are_never_written_again(scene_and_cameras):
    scene, near, far = scene_and_cameras
    held = [scene.cast(near), scene.cast(far)]
    before = [snapshot(image) for image in held]
    for k in range(6):  # casts alternating between the views, their images dropped at once
        scene.cast(near if k % 2 else far)
    for image, values in zip(held, before):
        for name, array in values.items():
            np.testing.assert_array_equal(image[name], array)
    assert not np.array_equal(before[0]["Depth"], before[1]["Depth"], equal_nan=True)  # (the views differ)


def test_arrays_and_views_outlive_their_image(scene_and_cameras):
    scene, near, far = scene_and_cameras
    image = scene.cast(near)
    depth = np.asarray(image["Depth"])  # a view of the cast's array
    weights = image.point_data["Barycentric"]  # pyvista's wrapper of the VTK array
    keep_depth, keep_weights = depth.copy(), np.array(weights)
    del image
    gc.collect()
    for _ in range(4):
        scene.cast(far)
    np.testing.assert_array_equal(depth, keep_depth)
    np.testing.assert_array_equal(weights, keep_weights)


def test_dropped_images_lend_their_memory(scene_and_cameras):
    scene, near, far = scene_and_cameras
    dropped = {dropped_image_depth(scene, near) for _ in range(2)}  # (two images take turns)
    assert scene.kept_output_bytes >= 2 * 64 * 48 * 8
    again = scene.cast(far)
    assert address(again["Depth"]) in dropped
    reference = vrc.Scene(scene.prepared.surface).cast(far)
    for name in reference.point_data.keys():
        np.testing.assert_array_equal(again[name], reference[name])


def test_a_loop_holding_the_last_image_reuses_the_one_before(scene_and_cameras):
    scene, near, far = scene_and_cameras
    addresses = []
    image = None
    for k in range(6):
        image = scene.cast(near if k % 2 else far)  # (the previous image lives during the cast)
        addresses.append(address(image["Depth"]))
    assert len(set(addresses[2:])) == 2  # two arrays take turns
    np.testing.assert_array_equal(image["Depth"], vrc.Scene(scene.prepared.surface).cast(near)["Depth"])


def test_filter_outputs_copied_downstream_keep_their_arrays():
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkRenderingCore import vtkCamera

    flt = vrc.RayCastFilter()
    flt.SetInputData(pv.Sphere(theta_resolution=40, phi_resolution=40))
    camera = vtkCamera()
    camera.SetPosition(0, 0, 3)
    flt.SetCamera(camera)
    flt.Update()
    downstream = vtkImageData()
    downstream.ShallowCopy(flt.GetOutput())  # shares the arrays, as a pipeline's consumers do
    kept = snapshot(pv.wrap(downstream))
    for angle in (10, 20, 30):
        camera.Azimuth(angle)
        flt.Modified()
        flt.Update()
    for name, array in kept.items():
        np.testing.assert_array_equal(pv.wrap(downstream)[name], array)
    assert not np.array_equal(pv.wrap(flt.GetOutput())["Depth"], kept["Depth"], equal_nan=True)


def test_intersect_results_held_are_never_written_again(scene_and_cameras):
    scene = scene_and_cameras[0]
    rng = np.random.default_rng(5)
    origins = rng.normal(size=(5000, 3)) * 3
    first = scene.intersect(origins, -origins)
    kept = {name: array.copy() for name, array in first.items()}
    dropped = {address(scene.intersect(origins, rng.normal(size=(5000, 3)))["t"]) for _ in range(4)}
    assert address(first["t"]) not in dropped
    for name, array in kept.items():
        np.testing.assert_array_equal(first[name], array)
    again = scene.intersect(origins, -origins)
    assert address(again["t"]) in dropped  # (the dropped results lend their memory)
    for name, array in kept.items():
        np.testing.assert_array_equal(again[name], array)


def test_small_batches_leave_the_kept_arrays_alone(scene_and_cameras):
    # A few rays' arrays are made fresh, not kept: they neither take an image's dropped
    # arrays nor push them out of the pool.
    scene, near, _ = scene_and_cameras
    dropped = {dropped_image_depth(scene, near) for _ in range(2)}
    kept = scene.kept_output_bytes
    rng = np.random.default_rng(6)
    for n in (1, 100, 1000):
        origins = rng.normal(size=(n, 3)) * 3
        hits = scene.intersect(origins, -origins)
        assert address(hits["t"]) not in dropped
        del hits
        gc.collect()
        assert scene.kept_output_bytes == kept
    assert address(scene.cast(near)["Depth"]) in dropped


def fresh_cast(scene, camera, **options):
    return vrc.Scene(scene.prepared.surface).cast(camera, **options)


def assert_same_image(image, reference):
    assert image.dimensions == reference.dimensions
    np.testing.assert_allclose(image.origin, reference.origin)
    np.testing.assert_allclose(image.spacing, reference.spacing)
    assert image.point_data.keys() == reference.point_data.keys()
    assert image.point_data.active_scalars_name == reference.point_data.active_scalars_name
    assert image.cell_data.keys() == [] and image.field_data.keys() == []
    for name in reference.point_data.keys():
        np.testing.assert_array_equal(image[name], reference[name])
        got, want = image.GetPointData().GetArray(name), reference.GetPointData().GetArray(name)
        assert got.GetRange() == want.GetRange(), name  # (VTK caches ranges until an array is modified)


def test_dropped_images_are_handed_back_refilled():
    scene = vrc.Scene(pv.Sphere(theta_resolution=30, phi_resolution=30))
    near = vrc.Camera.framing(scene.prepared.surface.bounds, view="xy", nx=40, ny=30)
    far = near.replace(view_angle=70.0)
    dropped = set()
    for _ in range(2):
        image = scene.cast(near)
        image.GetPointData().GetArray("Depth").GetRange()  # (a range VTK then keeps)
        dropped.add(id(image))
        del image
    for camera, world_space in ((far, False), (near, True), (far, True)):
        image = scene.cast(camera, world_space=world_space)
        assert id(image) in dropped  # (the two images take turns)
        assert_same_image(image, fresh_cast(scene, camera, world_space=world_space))
        del image


IMAGE_NAMES = ["TriangleId", "CellId", "Barycentric", "Depth", "vtkValidPointMask", "Normals", "Elevation"]


def hold_weakref(image):
    """A weak reference: what it sees, once its image is dropped (nothing if it died)."""
    ref = weakref.ref(image)
    return lambda: {} if ref() is None else snapshot(ref())


def hold_shallow_copy(image):
    other = pv.ImageData()
    other.ShallowCopy(image)
    return lambda: snapshot(other)


def hold_pipeline(image):
    from vtkmodules.vtkFiltersCore import vtkPassThrough

    consumer = vtkPassThrough()
    consumer.SetInputData(image)
    return lambda: snapshot(pv.wrap(consumer.GetInputDataObject(0, 0)))


def hold_point_data(image):
    point_data = image.GetPointData()
    return lambda: {name: np.array(pv.convert_array(point_data.GetArray(name))) for name in IMAGE_NAMES}


def hold_pyvista_point_data(image):
    point_data = image.point_data
    return lambda: {name: np.array(point_data[name]) for name in point_data.keys()}


def hold_array(get, name):
    def hold(image):
        held = get(image)
        return lambda: {name: np.array(pv.convert_array(held) if hasattr(held, "GetRange") else held)}

    return hold


HOLDS = {  # each holds part of an image and returns what that part shows, by array name
    "weak reference": hold_weakref,
    "point data": hold_point_data,
    "pyvista point data": hold_pyvista_point_data,
    "VTK array": hold_array(lambda image: image.GetPointData().GetArray("Depth"), "Depth"),
    "pyvista array": hold_array(lambda image: image["Depth"], "Depth"),
    "numpy view": hold_array(lambda image: np.asarray(image.point_data["Barycentric"]), "Barycentric"),
    "shallow copy": hold_shallow_copy,
    "pipeline": hold_pipeline,
}


@pytest.mark.parametrize("hold", HOLDS.values(), ids=HOLDS.keys())
def test_images_anything_observes_are_not_handed_back(scene_and_cameras, hold):
    scene, near, far = scene_and_cameras
    image = scene.cast(near)
    assert list(image.point_data.keys()) == IMAGE_NAMES
    look, before = hold(image), snapshot(image)
    del image
    gc.collect()
    for _ in range(4):
        scene.cast(far)  # (dropped at once: the image held would be the next but one)
    for name, values in look().items():
        np.testing.assert_array_equal(values, before[name])


CHANGES = {
    "origin": lambda image: image.SetOrigin(1.0, 2.0, 3.0),
    "point array added": lambda image: image.point_data.set_array(np.zeros(image.n_points), "Extra"),
    "array removed": lambda image: image.GetPointData().RemoveArray("CellId"),
    "array renamed": lambda image: image.GetPointData().GetArray("Depth").SetName("Range"),
    "field data": lambda image: image.field_data.set_array(np.arange(3.0), "Note"),
    "cell data": lambda image: image.cell_data.set_array(np.zeros(image.n_cells), "Mark"),
    "active scalars": lambda image: image.GetPointData().SetActiveScalars("TriangleId"),
    "tuples": lambda image: image.GetPointData().GetArray("Depth").SetNumberOfTuples(7),
    "components": lambda image: image.GetPointData().GetArray("Barycentric").SetNumberOfComponents(1),
    "memory": lambda image: image.GetPointData().GetArray("Depth").SetNumberOfTuples(2 * image.n_points),
}


@pytest.mark.parametrize("change", CHANGES.values(), ids=CHANGES.keys())
def test_images_changed_through_vtk_are_made_anew(scene_and_cameras, change):
    scene, near, far = scene_and_cameras
    image = scene.cast(near)
    change(image)
    del image
    for camera in (near, far, near):
        assert_same_image(scene.cast(camera), fresh_cast(scene, camera))
