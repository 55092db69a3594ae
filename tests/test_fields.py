"""Every output array is assembled by the core's workers: checked against an independent
numpy reference (vtkraycast.testing.reference_arrays) on every numeric VTK type, any number
of components, both precisions, every path (BVH tiles, ray by ray, flat bins, the seed's
brute force, arbitrary rays), and against the geometry itself."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv
from vtkmodules.util.numpy_support import vtk_to_numpy

import vtkraycast as vrc
from vtkraycast import _core
from vtkraycast.testing import bumpy_sphere, reference_arrays

DTYPES = [np.int8, np.uint8, np.int16, np.uint16, np.int32, np.uint32, np.int64, np.uint64, np.float32, np.float64]


def fielded_sphere() -> pv.PolyData:
    """A bumpy sphere with point and cell arrays of every numeric type, 1, 3 and 9 components."""
    mesh = bumpy_sphere(3)
    rng = np.random.default_rng(7)
    for dtype in DTYPES:
        name = np.dtype(dtype).name
        info = np.iinfo(dtype) if np.issubdtype(dtype, np.integer) else None
        lo, hi = (info.min, info.max) if info else (-1e3, 1e3)
        for components in (1, 3):
            shape = (mesh.n_points,) if components == 1 else (mesh.n_points, components)
            if info is None:
                values = rng.uniform(lo, hi, shape).astype(dtype)
            else:
                values = rng.integers(lo, hi, shape, dtype=dtype, endpoint=True)
            mesh.point_data[f"p_{name}_{components}"] = values
        cells = rng.integers(0, 100, mesh.n_cells) if info else rng.uniform(-5, 5, mesh.n_cells)
        mesh.cell_data[f"c_{name}"] = cells.astype(dtype)
    mesh.point_data["tensor"] = rng.uniform(-1, 1, (mesh.n_points, 9))
    mesh.cell_data["cell_vector"] = rng.uniform(-1, 1, (mesh.n_cells, 3)).astype(np.float32)
    return mesh


def view(nx: int = 96, ny: int = 80, *, parallel: bool = False) -> vrc.Camera:
    window = {"h": 3.2} if parallel else {"view_angle": 45}
    return vrc.Camera((2.0, 1.4, 1.1), (0, 0, 0), (0, 0, 1), nx=nx, ny=ny, parallel=parallel, **window)


def assert_same(actual: np.ndarray, expected: np.ndarray, name: str) -> None:
    assert actual.dtype == expected.dtype, name
    assert actual.shape == expected.shape, name
    np.testing.assert_array_equal(actual, expected, err_msg=name)


@pytest.mark.parametrize("precision", ["float64", "float32"])
@pytest.mark.parametrize("parallel", [False, True])
def test_every_mesh_array_matches_numpy_reference(precision, parallel):
    mesh = fielded_sphere()
    scene = vrc.Scene(mesh)
    image = scene.cast(view(parallel=parallel), precision=precision)
    names = list(image.point_data.keys())
    assert set(mesh.point_data.keys()) | set(mesh.cell_data.keys()) <= set(names)
    ids, bary = np.asarray(image["TriangleId"]), np.asarray(image["Barycentric"])
    assert 0.2 < (ids >= 0).mean() < 0.9  # hits and misses both
    expected = reference_arrays(scene.prepared, names, ids, bary)
    for name in names:
        if name not in ("Barycentric", "Depth"):
            assert_same(np.asarray(image[name]), expected[name], name)


def test_arrays_follow_changes_to_the_mesh_between_casts():
    # The scene keeps its lookup of the mesh's arrays from cast to cast: an array added,
    # replaced, edited in place or removed between two casts must show in the next one.
    mesh = bumpy_sphere(3)
    scene = vrc.Scene(mesh)
    cam = view()
    assert "added" not in scene.cast(cam).point_data
    rng = np.random.default_rng(3)

    def check(image, name):
        ids, bary = np.asarray(image["TriangleId"]), np.asarray(image["Barycentric"])
        assert_same(np.asarray(image[name]), reference_arrays(scene.prepared, [name], ids, bary)[name], name)

    mesh.point_data["added"] = rng.uniform(-1, 1, mesh.n_points)
    check(scene.cast(cam), "added")
    mesh.point_data["added"] = rng.integers(0, 9, (mesh.n_points, 3)).astype(np.int16)  # replaced: new type and shape
    check(scene.cast(cam), "added")
    mesh.point_data["added"][:] *= 2  # edited in place (no Modified(): the kept view sees it)
    check(scene.cast(cam), "added")
    mesh.cell_data["cells"] = rng.uniform(-1, 1, mesh.n_cells)
    check(scene.cast(cam), "cells")
    mesh.point_data.remove("added")
    image = scene.cast(cam)
    assert "added" not in image.point_data and "cells" in image.point_data


@pytest.mark.parametrize("surface", ["triangles", "quads and a triangle strip"])
def test_cell_ids_and_cell_arrays_with_and_without_a_cell_per_triangle(surface):
    # An all-triangle mesh's CellId is its TriangleId, written without the cell map (the
    # core's shortcut); quads and strips give several triangles per cell (the map is read).
    mesh = pv.Sphere(theta_resolution=24, phi_resolution=16)
    if surface != "triangles":
        quads = pv.Plane(center=(0, 0, 0.2), i_resolution=9, j_resolution=7).rotate_x(30)
        mesh = (mesh + quads + pv.Cylinder(resolution=12).strip()).clean()
    rng = np.random.default_rng(3)
    mesh.cell_data["label"] = rng.integers(0, 1000, mesh.n_cells).astype(np.int32)
    mesh.cell_data["vector"] = rng.uniform(-1, 1, (mesh.n_cells, 3))
    scene = vrc.Scene(mesh)
    assert scene.prepared.cells_are_triangles == (surface == "triangles")
    for camera in (view(), view(parallel=True)):
        image = scene.cast(camera, arrays=["TriangleId", "CellId", "Barycentric", "label", "vector"])
        ids = np.asarray(image["TriangleId"])
        assert (ids >= 0).sum() > 300
        weights = np.asarray(image["Barycentric"])
        expected = reference_arrays(scene.prepared, ["CellId", "label", "vector"], ids, weights)
        for name in ("CellId", "label", "vector"):
            assert_same(np.asarray(image[name]), expected[name], name)
        if surface != "triangles":
            assert not np.array_equal(image["CellId"], ids)


def test_integer_point_arrays_take_the_largest_weight_and_floats_interpolate():
    # one triangle, a label per point: each pixel gets the label of its nearest corner
    tri = pv.PolyData(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]), faces=[3, 0, 1, 2])
    tri.point_data["label"] = np.array([10, 20, 30], np.int16)
    tri.point_data["x"] = np.array([0.0, 1.0, 0.0], np.float32)
    cam = vrc.Camera((0.3, 0.3, 2), (0.3, 0.3, 0), (0, 1, 0), parallel=True, h=1.2, nx=40, ny=40)
    image = vrc.cast(tri, cam, arrays=["label", "x", "Barycentric", "Position"])
    hit = ~np.isnan(image["x"])
    bary = image["Barycentric"][hit]
    np.testing.assert_array_equal(image["label"][hit], np.array([10, 20, 30])[np.argmax(bary, axis=1)])
    np.testing.assert_allclose(image["x"][hit], image["Position"][hit, 0], atol=1e-6)
    assert (image["label"][~hit] == 0).all() and image["label"].dtype == np.int16


def test_position_and_normal_against_the_geometry():
    mesh = fielded_sphere()
    scene = vrc.Scene(mesh)
    cam = view()
    image = scene.cast(cam, arrays=["TriangleId", "Barycentric", "Position", "Normal", "Depth"])
    ids, bary = np.asarray(image["TriangleId"]), np.asarray(image["Barycentric"])
    expected = reference_arrays(scene.prepared, ["Position", "Normal"], ids, bary)
    for name in ("Position", "Normal"):
        np.testing.assert_allclose(image[name], expected[name], rtol=1e-14, atol=1e-15, err_msg=name)
    hit = ids >= 0
    # the hit point lies on the pixel's ray at the depth the kernel found
    along = (image["Position"][hit] - cam.eye) @ -cam.backward
    np.testing.assert_allclose(along, image["Depth"][hit], rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(image["Normal"][hit], axis=1), 1, rtol=1e-14)


def test_misses_are_written_in_the_same_pass():
    mesh = fielded_sphere()
    image = vrc.Scene(mesh).cast(view(), arrays=["TriangleId", "CellId", "vtkValidPointMask", "Normal", "p_int8_3",
                                                  "p_float32_1", "c_uint16", "Position"])  # fmt: skip
    miss = np.asarray(image["TriangleId"]) < 0
    assert miss.any()
    assert (image["CellId"][miss] == -1).all() and (image["vtkValidPointMask"][miss] == 0).all()
    assert (image["vtkValidPointMask"][~miss] == 1).all()
    assert np.isnan(image["Normal"][miss]).all() and np.isnan(image["Position"][miss]).all()
    assert np.isnan(image["p_float32_1"][miss]).all()
    assert (image["p_int8_3"][miss] == 0).all() and (image["c_uint16"][miss] == 0).all()


@pytest.mark.parametrize(
    ("how", "options"),
    [("one-shot bins", {}), ("seed brute force", {"accel": "none"}), ("ray by ray", {"strategy": "moller-trumbore"})],
)
def test_every_path_writes_the_same_arrays(how, options):
    mesh = fielded_sphere()
    cam = view(48, 40)
    scene = vrc.Scene(mesh)
    reference = scene.cast(cam)
    image = vrc.cast(mesh, cam, **options) if how == "one-shot bins" else scene.cast(cam, **options)
    ids, bary = np.asarray(image["TriangleId"]), np.asarray(image["Barycentric"])
    np.testing.assert_array_equal(ids, reference["TriangleId"])
    expected = reference_arrays(scene.prepared, list(image.point_data.keys()), ids, bary)
    for name in expected:
        assert_same(np.asarray(image[name]), expected[name], f"{how}: {name}")


def test_arrays_decided_by_the_triangle_alone_skip_the_hit_point():
    # CellId, the mask, Normal and cell arrays need no depth or weights: the tiles may settle
    # pixels without rays (sure hits); the values must equal a cast that computes everything
    mesh = bumpy_sphere(6)
    mesh.cell_data["label"] = (np.arange(mesh.n_cells) % 251).astype(np.uint8)
    scene = vrc.Scene(mesh)
    cam = view(256, 256)
    alone = scene.cast(cam, arrays=["CellId", "vtkValidPointMask", "Normal", "label"])
    full = scene.cast(cam, arrays=["CellId", "vtkValidPointMask", "Normal", "label", "Depth", "TriangleId"])
    assert (np.asarray(full["TriangleId"]) >= 0).mean() > 0.5
    for name in ("CellId", "vtkValidPointMask", "Normal", "label"):
        np.testing.assert_array_equal(alone[name], full[name], err_msg=name)


def test_intersect_cell_ids_of_a_non_polygonal_input():
    grid = pv.ImageData(dimensions=(4, 3, 2))
    grid.cell_data["hex"] = np.arange(grid.n_cells) * 10
    scene = vrc.Scene(grid)
    hits = scene.intersect([[0.5, 0.5, 5], [2.5, 1.5, 5], [9, 9, 5]], [[0, 0, -1]] * 3)
    np.testing.assert_array_equal(hits["cell_id"], [0, 5, -1])
    image = scene.cast(vrc.Camera((0.5, 0.5, 5), (0.5, 0.5, 0), (0, 1, 0), nx=1, ny=1, view_angle=1))
    assert image["hex"].tolist() == [0] and image["CellId"].tolist() == [0]


def test_the_image_shares_the_arrays_the_core_wrote():
    mesh = fielded_sphere()
    scene = vrc.Scene(mesh)
    for given in (pv.ImageData(), scene._images):  # an image given, an image of the scene's pool
        _, buffers, image = scene._cast_into(given, view(32, 24))
        for name, values in buffers.items():
            assert np.shares_memory(vtk_to_numpy(image.GetPointData().GetArray(name)), values), name


def test_inputs_are_not_modified():
    mesh = fielded_sphere()
    before = {name: np.array(mesh.point_data[name]) for name in mesh.point_data.keys()}
    vrc.Scene(mesh).cast(view())
    for name, values in before.items():
        np.testing.assert_array_equal(mesh.point_data[name], values)


def test_bad_requests_raise_instead_of_writing_out_of_bounds():
    scene = vrc.Scene(pv.Sphere())
    cam = view(8, 8)

    def request(**outputs) -> _core.Request:
        q = _core.Request()
        q.frame, q.nx, q.ny = cam.frame, cam.nx, cam.ny
        q.width, q.height = cam.w, cam.h
        for name, value in outputs.items():
            setattr(q, name, value)
        return q

    with pytest.raises(ValueError, match="one row per ray"):
        _core.cast(scene._core, request(triangle_id=np.empty(63, np.int64)))
    with pytest.raises(ValueError, match="precision"):
        _core.cast(scene._core, request(depth=np.empty(64, np.float32)))
    with pytest.raises(ValueError, match="cell_ids"):
        _core.cast(scene._core, request(cell_id=np.empty(64, np.int64)))
    q = request()
    q.add_field(np.zeros(3), np.empty(64), True)  # a point field of the wrong length
    with pytest.raises(ValueError, match="point field"):
        _core.cast(scene._core, q)
    q = request()
    q.add_field(np.zeros(scene.prepared.points.shape[0], np.int32), np.empty(64, np.float32), True)
    with pytest.raises(ValueError, match="type"):
        _core.cast(scene._core, q)
