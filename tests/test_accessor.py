"""The pyvista accessor: ``mesh.raycast(...)`` after ``import pyvista`` alone."""

from __future__ import annotations

import numpy as np
import pyvista as pv

import vtkraycast as vrc


def test_raycast_is_available_in_a_fresh_interpreter_without_importing_vtkraycast(run_python):
    code = (
        "import sys\n"
        "import pyvista as pv\n"
        "camera = pv.Camera(); camera.position = (0, 0, 4); camera.focal_point = (0, 0, 0); camera.up = (0, 1, 0)\n"
        "assert 'vtkraycast' not in sys.modules\n"
        "image = pv.Sphere().raycast(camera, arrays=['Depth'])\n"
        "print(image.dimensions, 'vtkraycast' in sys.modules)\n"
    )
    done = run_python(code)
    assert done.stdout.strip() == "(640, 480, 1) True"


def test_accessor_equals_cast_with_keywords():
    mesh = pv.Sphere()
    cam = vrc.Camera((0.5, 0.5, 3), (0, 0, 0), (0, 1, 0), nx=50, ny=40)
    a = mesh.raycast(cam, arrays=["TriangleId", "Depth"], precision="float32")
    b = vrc.cast(mesh, cam, arrays=["TriangleId", "Depth"], precision="float32")
    np.testing.assert_array_equal(a["TriangleId"], b["TriangleId"])
    np.testing.assert_array_equal(a["Depth"], b["Depth"])


def test_accessor_works_on_other_datasets():
    grid = pv.ImageData(dimensions=(3, 3, 3)).cast_to_unstructured_grid()
    cam = vrc.Camera.framing(grid.bounds, nx=20, ny=20)
    image = grid.raycast(cam, arrays=["CellId"])
    assert set(np.unique(image["CellId"])) - {-1} <= set(range(grid.n_cells))
    assert (image["CellId"] >= 0).any()
