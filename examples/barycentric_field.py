"""The barycentric field of a mesh, shown as colour.
=================================================

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
import matplotlib.pyplot as plt
import numpy as np
import pyvista as pv
from vtkmodules.vtkCommonCore import reference
from vtkmodules.vtkCommonDataModel import vtkCellLocator

import vtkraycast as vrc

pv.OFF_SCREEN = True


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("."), help="output directory")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    mesh = pv.examples.load_ant()  # 912 triangles: large enough to see each one
    nx, ny = 640, 480
    # The seed's camera model: an eye, the point it looks at, the up direction, and a
    # window given by a vertical view angle (h = 2 d tan(angle / 2), w = h nx / ny).
    centre, radius = np.array(mesh.center) - (0.0, 2.0, 0.0), mesh.length / 2  # legs hang down
    side = np.array([-1.0, 0.7, 0.4]) / np.linalg.norm([-1.0, 0.7, 0.4])
    cam = vrc.Camera(centre + 2.7 * radius * side, centre, (0, 1, 0), view_angle=30, nx=nx, ny=ny)
    image = vrc.cast(mesh, cam, arrays=["TriangleId", "Barycentric"])

    tid = image["TriangleId"]
    bary = image["Barycentric"]
    hit = tid >= 0

    # -- the weights are a partition of unity on every hit, NaN on every miss ----------
    assert np.all(np.abs(bary[hit].sum(axis=1) - 1.0) <= 1e-12), "weights do not sum to 1"
    assert np.all((bary[hit] >= -1e-12) & (bary[hit] <= 1.0 + 1e-12)), "a weight outside [0, 1]"
    assert np.isnan(bary[~hit]).all(), "a miss has weights"
    # The window is a little larger than the ant's bounding sphere, and an ant is mostly
    # thin legs: it covers a twentieth to a half of the picture.
    coverage = hit.mean()
    assert 0.05 < coverage < 0.5, f"implausible coverage {coverage:.3f}"
    # Hundreds of the 912 triangles are in view, but not all: the far side is hidden.
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
    sample = rng.choice(nx * ny, size=400, replace=False)
    expected_hits = int(hit[sample].sum())
    agree = compared = 0
    for k in sample:
        i, row = k % nx, k // nx  # row 0 is the bottom of the image
        direction = to_world @ cam.pixel_center(i, ny - 1 - row)  # the seed's P_ij, j from the top
        end = cam.eye + far * direction / np.linalg.norm(direction)
        t, sub_id, cell_id = reference(0.0), reference(0), reference(0)
        x, pcoords = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        vtk_hit = locator.IntersectWithLine(cam.eye, end, 0.0, t, x, pcoords, sub_id, cell_id)
        agree += bool(vtk_hit) == bool(hit[k])
        if vtk_hit and hit[k] and int(cell_id) == tid[k]:
            r, s = pcoords[0], pcoords[1]  # x = p0 + r (p1 - p0) + s (p2 - p0)
            np.testing.assert_allclose(bary[k], (1.0 - r - s, r, s), atol=1e-6)
            np.testing.assert_allclose(bary[k] @ mesh.points[triangles[tid[k]]], x, atol=1e-6 * mesh.length)
            compared += 1
    # Pixels whose ray grazes an edge of the silhouette may go either way in VTK's
    # tolerance-based test; all others must agree.
    assert agree >= 0.98 * 400, f"hit/miss agrees with VTK on only {agree} of 400 rays"
    assert compared >= 0.9 * expected_hits, f"only {compared} of about {expected_hits:.0f} hit rays compared"

    # -- the picture ------------------------------------------------------------------
    rgb = np.full((nx * ny, 3), 0.12)
    rgb[hit] = bary[hit]
    rgb = rgb.reshape(ny, nx, 3)[::-1]  # row 0 of the cast is the bottom: flip for a picture
    path = args.out / "barycentric_field.png"
    plt.imsave(path, np.clip(rgb, 0.0, 1.0))
    print(
        f"{hit.sum()} of {nx * ny} pixels hit {seen.size} triangles; "
        f"{compared} rays match VTK's intersection; wrote {path}"
    )


if __name__ == "__main__":
    main()
