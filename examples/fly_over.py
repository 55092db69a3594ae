"""A fly-over: the camera inside the terrain's box, the ground running out behind it.
==================================================================================

A 500 x 500 height field with an ``Elevation`` point array is seen by a camera 1.5 above
it, looking a little down along it (90 degrees wide): most of the terrain's triangles
lie beside or behind the eye, many reaching across its plane. The figure shows the
interpolated ``Elevation`` and the ``Depth`` of the cast.

Checks: every hit lies on the height field (its z is the surface's at its x and y, to the
triangles' own flatness); the interpolated Elevation is the hit's z (the array is the
points' z, and a plane interpolates its own height exactly); the pixels that see
the terrain are those whose rays, cast one by one with ``Scene.intersect``, hit it too.

Run: ``python examples/fly_over.py [--out DIR]``, writes ``fly_over.png``.
"""

from __future__ import annotations

import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pyvista as pv

import vtkraycast as vrc


def height(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return 0.6 * np.sin(1.3 * x) * np.cos(0.9 * y) + 0.25 * np.sin(4.1 * x + 2.3 * y)


def terrain(n: int = 500) -> pv.PolyData:
    x = np.linspace(0.0, 20.0, n)
    xx, yy = np.meshgrid(x, x, indexing="xy")
    grid = pv.StructuredGrid(xx, yy, height(xx, yy))
    surface = grid.extract_surface(algorithm="dataset_surface").triangulate()
    surface.point_data["Elevation"] = surface.points[:, 2].copy()
    return surface


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("."), help="output directory")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    mesh = terrain()
    scene = vrc.Scene(mesh)
    eye = np.array([10.0, 10.0, 1.5])
    camera = vrc.Camera(eye, eye + [1.0, 0.4, -0.25], (0, 0, 1), view_angle=90, nx=480, ny=320)
    image = scene.cast(camera, arrays=["TriangleId", "Depth", "Position", "Elevation"])

    ids = np.asarray(image["TriangleId"])
    hit = ids >= 0
    position = np.asarray(image["Position"])[hit]
    # On the height field: a triangle's z departs from the surface by at most its curvature
    # over the grid step (0.04): well under 1e-2 here.
    assert np.abs(position[:, 2] - height(position[:, 0], position[:, 1])).max() < 1e-2
    np.testing.assert_allclose(np.asarray(image["Elevation"])[hit], position[:, 2], atol=1e-9)
    origins, directions = camera.rays()[:2]
    alone = scene.intersect(origins, directions, arrays=["triangle_id"])["triangle_id"]
    np.testing.assert_array_equal(ids, alone)
    assert 0.3 < hit.mean() < 0.9  # ground below, sky above

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    shape = (camera.ny, camera.nx)
    for ax, name, cmap in zip(axes, ("Elevation", "Depth"), ("terrain", "viridis_r")):
        values = np.where(hit, np.asarray(image[name], dtype=float), np.nan).reshape(shape)
        shown = ax.imshow(values, origin="lower", cmap=cmap)
        ax.set_title(f"{name}, eye 1.5 above the terrain")
        ax.set_axis_off()
        fig.colorbar(shown, ax=ax, shrink=0.8)
    fig.tight_layout()
    fig.savefig(args.out / "fly_over.png", dpi=90)
    print(f"{hit.mean():.0%} of the pixels see the terrain; wrote {args.out / 'fly_over.png'}")


if __name__ == "__main__":
    main()
