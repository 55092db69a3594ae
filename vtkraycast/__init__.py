"""vtkraycast: exact, fast CPU ray casting of triangle meshes into VTK geometry buffers.

>>> import vtkraycast as vrc
>>> sorted(vrc.__all__)
['Camera', 'Lidar', 'PRECISIONS', 'Panorama', 'RayCastFilter', 'STRATEGIES', 'Scene', 'cast']
"""

from __future__ import annotations

from .camera import Camera
from .filter import RayCastFilter
from .scene import PRECISIONS, STRATEGIES, Scene, cast
from .sensors import Lidar, Panorama

__all__ = ["PRECISIONS", "STRATEGIES", "Camera", "Lidar", "Panorama", "RayCastFilter", "Scene", "cast"]
__version__ = "0.1.0"
