"""The scenes and views the benchmarks share: meshes users cast (a segmented-volume contour,
a geological model's contour, a terrain with point arrays) and views of each from mostly
empty to filling the frame."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pyvista as pv
from pyvista import examples

import vtkraycast as vrc


def frog() -> pv.PolyData:
    """pyvista's frog_tissues.vti contoured by label: 1.5 M triangles, a uint8 cell array."""
    return examples.load_frog_tissues().contour_labels()


def channels() -> pv.PolyData:
    """channels.vti's facies (a cell array) as point data, contoured at 0.5: 1 M long thin
    triangles and a float point array."""
    return examples.load_channels().cell_data_to_point_data().contour([0.5])


def terrain(n: int = 1415) -> pv.PolyData:
    """An n x n height field (2 (n - 1)^2 triangles: 4 M at the default) with a scalar point
    array (``Elevation``, float32) and a 3-vector one (``Gradient``, float64)."""
    x = np.linspace(0.0, 10.0, n)
    xx, yy = np.meshgrid(x, x, indexing="xy")
    z = 0.6 * np.sin(1.3 * xx) * np.cos(0.9 * yy) + 0.25 * np.sin(4.1 * xx + 2.3 * yy) + 0.05 * xx
    grid = pv.StructuredGrid(xx, yy, z)
    surface = grid.extract_surface(algorithm="dataset_surface", pass_pointid=False, pass_cellid=False).triangulate()
    height = surface.points[:, 2]
    surface.point_data["Elevation"] = height.astype(np.float32)
    gx = 0.6 * 1.3 * np.cos(1.3 * surface.points[:, 0]) * np.cos(0.9 * surface.points[:, 1])
    gy = -0.6 * 0.9 * np.sin(1.3 * surface.points[:, 0]) * np.sin(0.9 * surface.points[:, 1])
    surface.point_data["Gradient"] = np.column_stack((gx, gy, np.ones_like(gx)))
    return surface


SCENES: dict[str, Callable[[], pv.PolyData]] = {"frog": frog, "channels": channels, "terrain": terrain}

#: Zoom factors of the framing camera: 1 frames the whole model (much of the frame empty),
#: larger ones come closer until the model fills the frame.
ZOOMS = {"framed": 1.0, "close": 1.8, "full": 3.5}
#: The views of each scene: the framing camera zoomed, then a walk-through (or, over the
#: terrain, a fly-over): the eye inside the model's box, triangles all around it.
VIEWS = (*ZOOMS, "inside")


def inside(mesh: pv.PolyData, scene: str) -> np.ndarray:
    """A point inside the box of scene ``scene``: its middle (the terrain's 2 above it)."""
    low, high = np.array(mesh.bounds[0::2]), np.array(mesh.bounds[1::2])
    return (low + high) / 2 + (np.array([0, 0, 2.0]) if scene == "terrain" else 0)


def view(mesh: pv.PolyData, name: str, pixels: int, scene: str = "") -> vrc.Camera:
    """The camera ``name`` (of VIEWS) of ``mesh`` (of scene ``scene``): the iso framing,
    zoomed, or from ``inside``, 90 degrees wide, looking a little down."""
    if name == "inside":
        eye = inside(mesh, scene)
        return vrc.Camera(eye, eye + [1.0, 0.3, -0.3], (0, 0, 1), view_angle=90, nx=pixels, ny=pixels)
    base = vrc.Camera.framing(mesh.bounds, view="iso", nx=pixels, ny=pixels)
    angle = math.degrees(2 * math.atan(math.tan(math.radians(base.view_angle) / 2) / ZOOMS[name]))
    return base.replace(view_angle=angle)
