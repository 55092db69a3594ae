"""Mesh preparation: mixed cell types, the map back to input cells, data carried through,
and inputs left untouched."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc
from vtkraycast.mesh import prepare_mesh


def square(k: int) -> list[list[float]]:
    """Corners of unit square k, which lies at x in [2k, 2k + 1]: one cell per square."""
    return [[2 * k, 0, 0], [2 * k + 1, 0, 0], [2 * k + 1, 1, 0], [2 * k, 1, 0]]


def mixed_mesh() -> pv.PolyData:
    """A vertex, a line, two triangles, a quad, a concave pentagon and a 4-triangle strip,
    each cell on its own unit square of the plane z = 0 (square index = position on x)."""
    pts: list[list[float]] = []

    def add(points):
        start = len(pts)
        pts.extend(points)
        return list(range(start, start + len(points)))

    vert = add([[-5, -5, 0]])
    line = add([[-5, -4, 0], [-4, -4, 0]])
    a = add(square(0))
    b = add(square(1))
    quad = add(square(2))
    x = 6.0
    penta = add([[x, 0, 0], [x + 1, 0, 0], [x + 1, 1, 0], [x + 0.5, 0.3, 0], [x, 1, 0]])  # concave at (x+.5, .3)
    s = add([[8, 0, 0], [8, 1, 0], [8.5, 0, 0], [8.5, 1, 0], [9, 0, 0], [9, 1, 0]])
    mesh = pv.PolyData(
        np.array(pts, float),
        verts=[1, *vert],
        lines=[2, *line],
        faces=[3, a[0], a[1], a[2], 3, b[0], b[1], b[2], 4, *quad, 5, *penta],
        strips=[6, *s],
    )
    # vtkPolyData numbers cells verts, lines, polys, strips: 0 vertex, 1 line, 2 and 3 the
    # triangles, 4 the quad, 5 the pentagon, 6 the strip.
    mesh.cell_data["label"] = np.arange(mesh.n_cells, dtype=np.int32) * 10 + 7
    mesh.cell_data["weight"] = np.linspace(0.5, 1.5, mesh.n_cells)
    p = mesh.points
    mesh.point_data["linear"] = 3 * p[:, 0] - 2 * p[:, 1] + 1.0
    mesh.point_data["vector"] = np.c_[p[:, 0], -p[:, 1], 2 * p[:, 0] + p[:, 1]].astype(np.float32)
    mesh.point_data["ids"] = np.arange(mesh.n_points, dtype=np.int64)
    return mesh


CELL_OF_SQUARE = {0: 2, 1: 3, 2: 4, 3: 5, 4: 6}


def top_view(nx=200, ny=20):
    return vrc.Camera((5, 0.5, 10), (5, 0.5, 0), (0, 1, 0), d=10, w=10.0, h=1.0, nx=nx, ny=ny, parallel=True)


def inside_pentagon(x, y):
    from matplotlib.path import Path

    return Path([(6, 0), (7, 0), (7, 1), (6.5, 0.3), (6, 1)]).contains_points(np.c_[x, y], radius=1e-9)


def test_cell_ids_point_at_the_input_cell_of_every_hit():
    mesh = mixed_mesh()
    image = vrc.cast(mesh, top_view(), arrays=["CellId", "Position", "label", "weight", "TriangleId"])
    hit = image["CellId"] >= 0
    x = image["Position"][hit, 0]
    expected = np.vectorize(CELL_OF_SQUARE.get)(np.floor(x / 2).astype(int))
    np.testing.assert_array_equal(image["CellId"][hit], expected)
    # Cell data are copied from the hit cell; misses are 0 (integers) and NaN (floats).
    np.testing.assert_array_equal(image["label"][hit], expected * 10 + 7)
    np.testing.assert_array_equal(image["weight"][hit], mesh.cell_data["weight"][expected])
    assert (image["label"][~hit] == 0).all() and np.isnan(image["weight"][~hit]).all()
    # Hits on the pentagon lie in it (its boundary included: some pixel centres fall
    # exactly on the edges of its notch, and a ray on an edge is a hit).
    pos = image["Position"][hit]
    penta = expected == 5
    assert inside_pentagon(pos[penta, 0], pos[penta, 1]).all()


def test_concave_pentagon_coverage_matches_its_area():
    """Pixels hitting the pentagon / pixels of its square = area 0.65 (the notch removes 0.35)."""
    nx, ny = 400, 400
    cam = vrc.Camera((6.5, 0.5, 5), (6.5, 0.5, 0), (0, 1, 0), w=1.0, h=1.0, nx=nx, ny=ny, parallel=True)
    image = vrc.cast(mixed_mesh(), cam, arrays=["CellId"])
    assert np.mean(image["CellId"] == 5) == pytest.approx(0.65, abs=0.01)


def test_point_data_are_interpolated_linearly():
    mesh = mixed_mesh()
    image = vrc.cast(mesh, top_view(), arrays=["Position", "linear", "vector", "ids", "Barycentric", "TriangleId"])
    hit = image["TriangleId"] >= 0
    x, y = image["Position"][hit, 0], image["Position"][hit, 1]
    np.testing.assert_allclose(image["linear"][hit], 3 * x - 2 * y + 1.0, rtol=0, atol=1e-12)
    assert image["vector"].dtype == np.float32
    np.testing.assert_allclose(image["vector"][hit], np.c_[x, -y, 2 * x + y], rtol=0, atol=1e-5)
    # Integer point arrays take the value of the point with the largest weight.
    tris = vrc.Scene(mesh).prepared.triangles[image["TriangleId"][hit]]
    nearest = tris[np.arange(tris.shape[0]), np.argmax(image["Barycentric"][hit], axis=1)]
    np.testing.assert_array_equal(image["ids"][hit], nearest)
    assert np.isnan(image["linear"][~hit]).all()


def test_two_triangles_and_a_line_keep_their_cell_data():
    """vtkTriangleFilter was seen to mis-size cell arrays on exactly this mix (VTK 9.7)."""
    mesh = pv.PolyData(
        np.array(square(0) + [[0, 2, 0], [1, 2, 0]], float),
        faces=[3, 0, 1, 2, 3, 0, 2, 3],
        lines=[2, 4, 5],
    )
    mesh.cell_data["c"] = np.array([100, 200, 300])  # line first: cell 0 is the line
    prepared = prepare_mesh(mesh)
    assert prepared.cell_ids.tolist() == [1, 2]
    cam = vrc.Camera((0.5, 0.5, 1), (0.5, 0.5, 0), (0, 1, 0), w=1, h=1, nx=8, ny=8, parallel=True)
    image = vrc.cast(mesh, cam, arrays=["CellId", "c", "Position"])
    above = image["Position"][:, 1] > image["Position"][:, 0]  # triangle (0, 2, 3) lies above y = x
    np.testing.assert_array_equal(image["CellId"], np.where(above, 2, 1))
    np.testing.assert_array_equal(image["c"], np.where(above, 300, 200))


def test_other_datasets_contribute_their_surface_with_input_cell_ids():
    grid = pv.ImageData(dimensions=(3, 2, 2)).cast_to_unstructured_grid()  # two hexahedra side by side
    grid.cell_data["hex"] = np.array([11, 22])
    cam = vrc.Camera((1, 0.5, 5), (1, 0.5, 0), (0, 1, 0), w=2, h=1, nx=20, ny=10, parallel=True)
    image = vrc.cast(grid, cam, arrays=["CellId", "hex", "Position"])
    left = image["Position"][:, 0] < 1
    np.testing.assert_array_equal(image["CellId"], np.where(left, 0, 1))
    np.testing.assert_array_equal(image["hex"], np.where(left, 11, 22))


def test_the_input_is_not_modified():
    mesh = mixed_mesh()
    before = mesh.copy(deep=True)
    mtime = mesh.GetMTime()
    vrc.cast(mesh, top_view(), arrays=["CellId", "Position", "Normal", "label", "linear"])
    assert mesh == before
    assert mesh.GetMTime() == mtime


def test_non_finite_coordinates_raise_value_error():
    mesh = pv.Sphere()
    mesh.points[5] = (np.nan, 0, 0)
    with pytest.raises(ValueError, match="non-finite point coordinates"):
        vrc.Scene(mesh)
    mesh = pv.Sphere()
    mesh.points[7, 2] = np.inf
    with pytest.raises(ValueError, match="non-finite"):
        vrc.cast(mesh, top_view())


def test_non_finite_unused_points_are_harmless():
    mesh = pv.PolyData(np.array(square(0) + [[np.nan, 0, 0]], float), faces=[3, 0, 1, 2])
    assert vrc.Scene(mesh).n_triangles == 1


@pytest.mark.parametrize(
    "mesh",
    [pv.PolyData(), pv.PolyData(np.zeros((3, 3))), pv.PolyData(np.eye(3), lines=[2, 0, 1])],
    ids=["empty", "points only", "lines only"],
)
def test_meshes_without_polygons_give_all_miss_images(mesh):
    image = vrc.cast(mesh, top_view(nx=8, ny=4))
    assert (image["TriangleId"] == -1).all() and (image["CellId"] == -1).all()
    assert (image["vtkValidPointMask"] == 0).all()
    assert np.isnan(image["Depth"]).all() and np.isnan(image["Barycentric"]).all()


def test_non_datasets_are_rejected():
    with pytest.raises(TypeError, match="expected a vtkPolyData"):
        vrc.Scene(np.zeros((3, 3)))
