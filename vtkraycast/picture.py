"""A picture of a geometry buffer: barycentric colours shaded by the surface's slope."""

from __future__ import annotations

import numpy as np
from vtkmodules.util.numpy_support import numpy_to_vtk
from vtkmodules.vtkCommonDataModel import vtkImageData
from vtkmodules.vtkIOImage import vtkPNGWriter

__all__ = ["barycentric_rgba", "write_png"]


def barycentric_rgba(barycentric: np.ndarray, normal_dot_view: np.ndarray | None = None) -> np.ndarray:
    """``(n, 4)`` uint8 colours: a light tint of the weights as red, green, blue, shaded by
    ``|cos|`` of the angle between normal and view when given; misses are transparent."""
    hit = np.isfinite(barycentric).all(axis=1)
    rgb = 0.45 + 0.55 * np.clip(np.nan_to_num(barycentric), 0.0, 1.0)
    if normal_dot_view is not None:
        rgb = rgb * (0.15 + 0.85 * np.abs(np.nan_to_num(normal_dot_view)))[:, None]
    rgba = np.zeros((barycentric.shape[0], 4), np.uint8)
    rgba[:, :3] = np.round(rgb * 255.0)
    rgba[:, 3] = np.where(hit, 255, 0)
    return rgba


def write_png(path: str, rgba: np.ndarray, nx: int, ny: int) -> None:
    """Writes ``(nx * ny, 4)`` pixels in VTK image order (row 0 at the bottom) to ``path``."""
    image = vtkImageData()
    image.SetDimensions(nx, ny, 1)
    colours = numpy_to_vtk(np.ascontiguousarray(rgba, dtype=np.uint8), deep=True)
    colours.SetName("rgba")
    image.GetPointData().SetScalars(colours)
    writer = vtkPNGWriter()
    writer.SetFileName(str(path))
    writer.SetInputData(image)
    writer.Write()
    if writer.GetErrorCode():
        raise OSError(f"could not write {path}")
