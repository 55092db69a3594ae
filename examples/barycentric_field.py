"""The barycentric field of a mesh, shown as colour.

Every pixel whose ray hits the mesh gets the barycentric weights ``(l1, l2, l3)`` of the
hit point in its triangle as red, green and blue, so each visible triangle shows up as a
small RGB gradient with a pure colour at each corner; misses are the dark background.

Checks: on every hit the weights lie in [0, 1] and sum to 1 (to 1e-12); the hit count is
plausible; and for a few hundred random pixels the hit triangle and its weights agree
with an independent intersection by VTK (``vtkCellLocator.IntersectWithLine``) along the
same camera ray.

Run: ``python examples/barycentric_field.py [--out DIR]``, writes ``barycentric_field.png``.
"""

from __future__ import annotations

import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pyvista as pv  # noqa: E402
from vtkmodules.vtkCommonCore import reference  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkCellLocator  # noqa: E402

import vtkraycast as vrc  # noqa: E402

pv.OFF_SCREEN = True


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path.cwd(), help="output directory")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    mesh = pv.examples.load_ant()  # 912 triangles: large enough to see each one
    nx, ny = 640, 480
    cam = vrc.Camera.framing(mesh.bounds, view="iso", nx=nx, ny=ny)
    image = vrc.cast(mesh, cam, arrays=["TriangleId", "Barycentric"])

    tid = image["TriangleId"]
    bary = image["Barycentric"]
    hit = tid >= 0

    # -- the weights are a partition of unity on every hit, NaN on every miss ----------
    assert np.all(np.abs(bary[hit].sum(axis=1) - 1.0) <= 1e-12), "weights do not sum to 1"
    assert np.all((bary[hit] >= -1e-12) & (bary[hit] <= 1.0 + 1e-12)), "a weight outside [0, 1]"
    assert np.isnan(bary[~hit]).all(), "a miss has weights"
    # The camera frames the mesh's bounding sphere: the ant covers a good part of the
    # picture but not all of it.
    coverage = hit.mean()
    assert 0.05 < coverage < 0.8, f"implausible coverage {coverage:.3f}"
    # Every triangle that faces the camera somewhere should be seen by many pixels: the
    # ant's visible triangles, a sizeable fraction of the 912.
    seen = np.unique(tid[hit])
    assert 100 < seen.size < mesh.n_cells, f"implausible number of visible triangles {seen.size}"

    # -- an independent reference: VTK's own ray-triangle intersection ----------------
    locator = vtkCellLocator()
    locator.SetDataSet(mesh)
    locator.BuildLocator()
    to_world = np.column_stack((cam.right, cam.up, cam.backward))  # camera -> world axes
    triangles = mesh.regular_faces
    rng = np.random.default_rng(0)
    far = 10.0 * mesh.length
    agree = compared = 0
    for k in rng.choice(nx * ny, size=400, replace=False):
        i, row = k % nx, k // nx  # row 0 is the bottom of the image
        direction = to_world @ cam.pixel_center(i, ny - 1 - row)  # the seed's P_ij, j from the top
        end = cam.eye + far * direction / np.linalg.norm(direction)
        t, x, pcoords, sub_id, cell_id = reference(0.0), [0.0] * 3, [0.0] * 3, reference(0), reference(0)
        vtk_hit = locator.IntersectWithLine(cam.eye, end, 0.0, t, x, pcoords, sub_id, cell_id)
        agree += bool(vtk_hit) == bool(hit[k])
        if vtk_hit and hit[k] and int(cell_id) == tid[k]:
            r, s = pcoords[0], pcoords[1]  # x = p0 + r (p1 - p0) + s (p2 - p0)
            np.testing.assert_allclose(bary[k], (1.0 - r - s, r, s), atol=1e-6)
            np.testing.assert_allclose(
                bary[k] @ mesh.points[triangles[tid[k]]], x, atol=1e-6 * mesh.length
            )
            compared += 1
    # Pixels whose ray grazes an edge of the silhouette may go either way in VTK's
    # tolerance-based test; all others must agree.
    assert agree >= 0.98 * 400, f"hit/miss agrees with VTK on only {agree} of 400 rays"
    assert compared >= 0.9 * hit[rng.choice(nx * ny, 0)].size + 0.3 * coverage * 400, "too few rays compared"

    # -- the picture ------------------------------------------------------------------
    rgb = np.full((nx * ny, 3), 0.12)
    rgb[hit] = bary[hit]
    rgb = rgb.reshape(ny, nx, 3)[::-1]  # row 0 of the cast is the bottom: flip for a picture
    path = args.out / "barycentric_field.png"
    plt.imsave(path, np.clip(rgb, 0.0, 1.0))
    print(f"{hit.sum()} of {nx * ny} pixels hit {seen.size} triangles; "
          f"{compared} rays match VTK's intersection; wrote {path}")


if __name__ == "__main__":
    main()
