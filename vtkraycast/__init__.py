"""vtkraycast: exact, fast CPU ray casting of triangle meshes into VTK geometry buffers.

>>> import vtkraycast as vrc
>>> sorted(vrc.__all__)
['Camera', 'Scene', 'cast']
"""

from __future__ import annotations

from .camera import Camera
from .scene import Scene, cast

__all__ = ["Camera", "Scene", "cast"]
__version__ = "0.1.0"
