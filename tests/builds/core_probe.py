"""Run by tests/test_builds.py, possibly under qemu-user as a CPU that numpy's wheels no longer
run on (numpy 2.4 and later need more than a Westmere has): ``python core_probe.py PACKAGE_DIR
OUT.bin``. Loads the core as the package picks it, without numpy, pyvista or the rest of the
package (the package directory stands for the package, its ``__init__`` not run), casts a
camera and arbitrary rays at a sphere through buffers of the standard library's memoryviews,
and writes the build's name, then every output's bytes."""

import math
import struct
import sys
import types

package = types.ModuleType("vtkraycast")
package.__path__ = [sys.argv[1]]
sys.modules["vtkraycast"] = package
from vtkraycast import _core  # noqa: E402  (after the stand-in package)


def buffer(fmt: str, values: list, shape: list[int]) -> memoryview:
    return memoryview(bytearray(struct.pack(f"{len(values)}{fmt}", *values))).cast(fmt, shape)


def empty(fmt: str, shape: list[int]) -> memoryview:
    return memoryview(bytearray(struct.calcsize(fmt) * math.prod(shape))).cast(fmt, shape)


# A UV sphere of radius 1, its centre 1000 from the origin (far from its own size).
rings, sectors, centre = 24, 48, 1e3
points = [centre, centre, centre + 1, centre, centre, centre - 1]
for i in range(1, rings):
    theta = math.pi * i / rings
    for j in range(sectors):
        phi = 2 * math.pi * j / sectors
        points += [
            centre + math.sin(theta) * math.cos(phi),
            centre + math.sin(theta) * math.sin(phi),
            centre + math.cos(theta),
        ]
triangles = []
for j in range(sectors):
    k = (j + 1) % sectors
    triangles += [0, 2 + j, 2 + k]
    triangles += [1, 2 + (rings - 2) * sectors + k, 2 + (rings - 2) * sectors + j]
for i in range(rings - 2):
    for j in range(sectors):
        a, b = 2 + i * sectors + j, 2 + i * sectors + (j + 1) % sectors
        triangles += [a, a + sectors, b, b, a + sectors, b + sectors]
scene = _core.Scene(buffer("d", points, [len(points) // 3, 3]), buffer("I", triangles, [len(triangles) // 3, 3]), 2)


def outputs(request, n: int) -> list[memoryview]:
    arrays = [empty("q", [n]), empty("q", [n]), empty("d", [n]), empty("d", [n, 3]), empty("B", [n])]
    request.triangle_id, request.cell_id, request.depth, request.barycentric, request.valid = arrays
    request.cells_are_triangles = True
    return arrays


camera = _core.Request()
camera.frame = buffer(
    "d", [centre + 0.3, centre - 2.6, centre + 1.1, 1, 0, 0, 0, 0.6, 0.8, 0, -0.8, 0.6], [4, 3]
)  # (orthonormal)
camera.d, camera.width, camera.height, camera.near, camera.far = 1.0, 0.9, 0.7, 0.0, math.inf
camera.nx, camera.ny = 96, 72
images = outputs(camera, 96 * 72)
_core.cast(scene, camera)

rays = _core.Request()
n = 2000
origins = [centre + 2.5 * math.sin(3.1 * k + m) for k in range(n) for m in range(3)]
targets = [centre + math.cos(7.3 * k + 2.1 * m) for k in range(n) for m in range(3)]  # (most within the sphere)
directions = [t - o for t, o in zip(targets, origins)]
rays.origins, rays.directions = buffer("d", origins, [n, 3]), buffer("d", directions, [n, 3])
rays.tmin, rays.tmax = 0.0, math.inf
hits = outputs(rays, n)
_core.cast(scene, rays)

with open(sys.argv[2], "wb") as out:
    out.write(_core.name.encode() + b"\n")
    for array in images + hits:
        out.write(array.tobytes())
