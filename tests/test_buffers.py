"""A scene reuses the output arrays of its earlier casts only once nothing refers to them."""

from __future__ import annotations

import gc

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
    depth_at = dropped_image_depth(scene, near)
    assert scene.kept_output_bytes >= 64 * 48 * 8
    again = scene.cast(far)
    assert address(again["Depth"]) == depth_at
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
    depth_at = dropped_image_depth(scene, near)
    kept = scene.kept_output_bytes
    rng = np.random.default_rng(6)
    for n in (1, 100, 1000):
        origins = rng.normal(size=(n, 3)) * 3
        hits = scene.intersect(origins, -origins)
        assert address(hits["t"]) != depth_at
        del hits
        gc.collect()
        assert scene.kept_output_bytes == kept
    assert address(scene.cast(near)["Depth"]) == depth_at
