"""``mesh.raycast(camera, ...)`` on every pyvista dataset, registered through the
``pyvista.accessors`` entry point so that ``import pyvista`` alone makes it available."""

from __future__ import annotations

from typing import Any

import pyvista as pv

from .scene import cast

__all__ = ["RaycastAccessor"]


@pv.register_dataset_accessor("raycast", pv.DataSet)
class RaycastAccessor:
    """Casts the dataset from a camera: ``mesh.raycast(camera, **options)``.

    Same keyword-only options as :func:`vtkraycast.cast`.

    Examples
    --------
    >>> import numpy as np
    >>> import pyvista as pv
    >>> import vtkraycast as vrc
    >>> cam = vrc.Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), nx=32, ny=24)
    >>> image = pv.Sphere().raycast(cam, arrays=["Depth"])
    >>> image.dimensions, round(float(image["Depth"][~np.isnan(image["Depth"])].min()), 2)
    ((32, 24, 1), 2.5)
    """

    def __init__(self, mesh: pv.DataSet) -> None:
        self._mesh = mesh

    def __call__(self, camera: Any, **options: Any) -> pv.ImageData:
        return cast(self._mesh, camera, **options)
