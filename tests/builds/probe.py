"""Run by tests/test_builds.py, in a fresh interpreter (possibly under qemu-user with an
older CPU): ``python probe.py OUT.npz``. Casts a few scenes with the build of the core
vtkraycast picked (or VTKRAYCAST_CORE forced) and saves every array, and the build's name."""

import sys

import numpy as np
import pyvista as pv

import vtkraycast as vrc
from vtkraycast import _core
from vtkraycast.testing import bumpy_sphere

mesh = bumpy_sphere(3, offset=1e3)
mesh.point_data["Height"] = mesh.points[:, 2].copy()
scene = vrc.Scene(mesh)
camera = vrc.Camera((1e3 + 0.3, 1e3 - 2.6, 1e3 + 1.1), (1e3, 1e3, 1e3), (0, 0, 1), nx=96, ny=72, view_angle=50)
image = scene.cast(camera)
flat = vrc.cast(pv.Sphere(), vrc.Camera((0.3, -2.5, 1.0), (0, 0, 0), (0, 0, 1), nx=64, ny=48, view_angle=45))
rng = np.random.default_rng(1)
origins, directions = rng.uniform(1e3 - 1.5, 1e3 + 1.5, (3000, 3)), rng.normal(size=(3000, 3))
hits = scene.intersect(origins, directions)
crossings = scene.intersect_all(origins, directions)
arrays = {f"image_{k}": image[k] for k in image.array_names}
arrays |= {f"flat_{k}": flat[k] for k in flat.array_names}
arrays |= {f"rays_{k}": v for k, v in hits.items()} | {f"all_{k}": v for k, v in crossings.items()}
np.savez(sys.argv[1], core=_core.name, module=vrc.__file__, occluded=scene.occluded(origins, directions), **arrays)
