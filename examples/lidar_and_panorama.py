"""A spinning lidar's scan and a 360-degree panorama of the same scene.
====================================================================

A generated street of boxes on a ground plane is scanned by a 32-ring lidar
(``vrc.Lidar`` and ``Scene.scan``) and seen by an equirectangular panorama
(``vrc.Panorama``) from the same point. The figure shows the returns from above coloured
by ring, and the panorama's depth.

Checks: every beam aimed more than 3 degrees down returns (the ground reaches past it);
every return lies on the scene (its Range equals its distance from the lidar, and a
return's height is either the ground's or within a box); the panorama's bottom row sees
the ground at the lidar's height straight below.

Run: ``python examples/lidar_and_panorama.py [--out DIR]``, writes ``lidar_and_panorama.png``.
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


def street() -> pv.PolyData:
    ground = pv.Plane(center=(0, 0, 0), i_size=200, j_size=200, i_resolution=20, j_resolution=20).triangulate()
    rng = np.random.default_rng(4)
    boxes = [
        pv.Box(bounds=(x, x + 6, *sorted((side * 12, side * 20)), 0, h)).triangulate()
        for x, h, side in zip(np.arange(-40, 40, 10), rng.uniform(4, 15, 8), np.tile([1, -1], 4))
    ]
    return pv.merge([ground, *boxes])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("."), help="output directory")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    scene = vrc.Scene(street())
    position = np.array([0.0, 0.0, 1.8])
    lidar = vrc.Lidar(position, elevations=np.linspace(-25, 10, 32), azimuth_steps=1024, max_range=100)
    cloud, ranges = scene.scan(lidar, range_image=True)
    below = lidar.elevations < -3  # (the ground within 35 m, well inside its 100 m)
    assert np.isfinite(ranges[below]).all(), "a beam aimed at the ground returned nothing"
    np.testing.assert_allclose(np.linalg.norm(cloud.points - position, axis=1), cloud["Range"], rtol=1e-9)
    heights = cloud.points[:, 2]
    assert ((np.abs(heights) < 1e-9) | (heights > 0)).all()

    panorama = vrc.Panorama(position, 720, 360)
    image = scene.cast(panorama)
    depth = np.asarray(image["Depth"]).reshape(360, 720)
    np.testing.assert_allclose(depth[0], position[2], rtol=1e-3)  # straight down: the ground

    figure, (top, pano) = plt.subplots(1, 2, figsize=(13, 5), gridspec_kw={"width_ratios": [1, 1.6]})
    top.scatter(cloud.points[:, 0], cloud.points[:, 1], c=cloud["Ring"], s=0.3, cmap="turbo")
    top.set_aspect("equal")
    top.set_xlim(-45, 45)
    top.set_ylim(-45, 45)
    top.set_title(f"lidar returns from above, coloured by ring ({cloud.n_points:,})")
    shown = pano.imshow(depth, origin="lower", cmap="magma_r", extent=(-180, 180, -90, 90), vmax=60)
    pano.set_title("equirectangular panorama: Depth (distance)")
    pano.set_xlabel("azimuth (degrees, left of forward)")
    pano.set_ylabel("elevation (degrees)")
    figure.colorbar(shown, ax=pano, shrink=0.7)
    figure.tight_layout()
    figure.savefig(args.out / "lidar_and_panorama.png", dpi=100)
    print(f"wrote {args.out / 'lidar_and_panorama.png'}")


if __name__ == "__main__":
    main()
