"""The geometry buffer as a vtkImageData: pixel space by default, or placed on the camera's
image plane in world space."""

from __future__ import annotations

import numpy as np
from vtkmodules.util.numpy_support import numpy_to_vtk
from vtkmodules.vtkCommonDataModel import vtkImageData

from .camera import Camera

__all__ = ["fill_image", "image_geometry", "place_image", "set_arrays"]


def image_geometry(camera: Camera | None, world_space: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Origin, spacing and direction matrix of the output image.

    In pixel space: origin 0, spacing 1, identity. In world space the image lies on the
    camera's image plane (distance ``d`` in front of the eye): the origin is the centre of
    pixel (0, 0) (bottom left), the spacing is the pixel size ``(w / nx, h / ny)``, and the
    direction matrix's columns are the camera's right, up and backward axes.
    """
    if not world_space:
        return np.zeros(3), np.ones(3), np.eye(3)
    sx, sy = camera.w / camera.nx, camera.h / camera.ny
    x0, y0 = camera.shift[0] - camera.w / 2 + sx / 2, camera.shift[1] - camera.h / 2 + sy / 2
    origin = camera.eye + x0 * camera.right + y0 * camera.up - camera.d * camera.backward
    direction = np.column_stack((camera.right, camera.up, camera.backward))
    return origin, np.array([sx, sy, 1.0]), direction


def fill_image(
    image: vtkImageData, camera: Camera, buffers: dict[str, np.ndarray], *, world_space: bool = False
) -> vtkImageData:
    """Sets ``image`` to ``camera``'s pixel grid and ``buffers`` as its point arrays
    (:func:`set_arrays`)."""
    return set_arrays(place_image(image, camera, world_space=world_space), buffers)


def place_image(image: vtkImageData, camera: Camera, *, world_space: bool = False) -> vtkImageData:
    """Sets ``image``'s dimensions, origin, spacing and direction to ``camera``'s pixel
    grid (:func:`image_geometry`)."""
    origin, spacing, direction = image_geometry(camera, world_space)
    image.SetDimensions(camera.nx, camera.ny, 1)
    image.SetOrigin(*origin)
    image.SetSpacing(*spacing)
    image.SetDirectionMatrix(*direction.ravel())
    return image


def set_arrays(image: vtkImageData, buffers: dict[str, np.ndarray]) -> vtkImageData:
    """Makes ``buffers`` the point arrays of ``image`` (shared, not copied). ``Depth`` (else
    the first array) becomes the active scalars, which VTK's image filters work on."""
    point_data = image.GetPointData()
    # A pipeline reuses its output image, and vtkImageData::PrepareForNewData keeps the old
    # active scalars (to reuse their memory): without this, the previous cast's Depth
    # survived as the first array, or as a stale array of the old size when no longer asked for.
    point_data.Initialize()
    for name, values in buffers.items():
        array = numpy_to_vtk(np.ascontiguousarray(values), deep=False)
        array.SetName(name)
        point_data.AddArray(array)
    if buffers:
        point_data.SetActiveScalars("Depth" if "Depth" in buffers else next(iter(buffers)))
    return image
