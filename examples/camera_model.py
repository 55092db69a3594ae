"""The seed lecture's camera model, drawn in 3D.
=============================================

The camera of the seed is an eye, a view-up direction and an image window ``w x h`` at
distance ``d`` in front of the eye, cut into ``nx x ny`` pixels; the ray through pixel
``(i, j)`` is ``P(t) = t P_ij`` in camera space, ``t = 1`` on the window. This script draws
that model next to the mesh it looks at: the eye (a black ball), the window (a black
rectangle), a few rays from the eye through pixel centres to their hits, and the geometry
buffer itself lying on the window (``world_space=True`` places the cast image on the image
plane in world coordinates), coloured by ``Depth`` with the same colours as the mesh's
own distance from the eye.

Checks: every point of the world-space image lies on the plane at distance ``d`` from the
eye along the view direction, inside the window, at the pixel centre ``eye + R P_ij``; and
for each drawn ray the hit ``eye + t R P_ij`` with ``t = Depth / d`` is the cast's
``Position`` at that pixel and ``t`` is what ``Scene.intersect`` finds along that ray.

Run: ``python examples/camera_model.py [--out DIR]``, writes ``camera_model.png``.
"""

from __future__ import annotations

import argparse
import pathlib

import numpy as np
import pyvista as pv

import vtkraycast as vrc

pv.OFF_SCREEN = True


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("."), help="output directory")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    mesh = pv.examples.load_nut()
    centre, size = np.array(mesh.center), mesh.length

    # The seed's camera: eye, look-at point, view up, window w x h at distance d, pixels.
    nx, ny = 96, 72
    eye = centre + np.array([0.3, -2.0, 0.9]) * size
    d = 1.2 * size
    cam = vrc.Camera(eye, centre, (0, 0, 1), d=d, w=0.533 * d, h=0.4 * d, nx=nx, ny=ny)
    to_world = np.column_stack((cam.right, cam.up, cam.backward))  # camera space -> world
    view = -cam.backward

    scene = vrc.Scene(mesh)
    image = scene.cast(cam, arrays=["TriangleId", "Depth", "Position"], world_space=True)
    hit = image["TriangleId"] >= 0
    assert 0.2 < hit.mean() < 0.9, f"implausible coverage {hit.mean():.2f}"

    # -- the image lies on the window: distance d along the view direction ---------------
    offset = np.asarray(image.points) - cam.eye
    np.testing.assert_allclose(offset @ view, d, rtol=1e-12)
    assert (np.abs(offset @ cam.right) < cam.w / 2).all(), "outside the window"
    assert (np.abs(offset @ cam.up) < cam.h / 2).all(), "outside the window"
    # ... each point at its pixel's centre (output row 0 is the bottom, j counts from the top)
    for i, j in [(0, 0), (nx - 1, 0), (0, ny - 1), (17, 40), (nx - 1, ny - 1)]:
        k = i + (ny - 1 - j) * nx
        np.testing.assert_allclose(image.points[k], cam.eye + to_world @ cam.pixel_center(i, j), atol=1e-12 * size)

    # -- a few rays through pixel centres, from the eye to their hits ---------------------
    rays = []
    for i, j in [(40, 12), (24, 33), (70, 36), (45, 48), (60, 57), (50, 24)]:
        k = i + (ny - 1 - j) * nx
        assert hit[k], f"pixel ({i}, {j}) was meant to hit the nut"
        direction = to_world @ cam.pixel_center(i, j)  # the seed's P_ij, in world axes
        t = image["Depth"][k] / d  # P(t) = t P_ij: depth is t d
        assert t > 1.0, "hits lie beyond the image plane"
        end = cam.eye + t * direction
        np.testing.assert_allclose(end, image["Position"][k], atol=1e-9 * size)
        found = scene.intersect(cam.eye, direction)  # one ray in, one value out per array
        assert found["triangle_id"] == image["TriangleId"][k]
        np.testing.assert_allclose(found["t"], t, rtol=1e-12)
        rays.append((cam.eye, end))

    # -- the picture -------------------------------------------------------------------------
    depth_range = (float(np.nanmin(image["Depth"])), float(np.nanmax(image["Depth"])))
    mesh["Depth"] = (np.asarray(mesh.points, dtype=np.float64) - cam.eye) @ view  # same quantity
    corners = np.array(
        [
            cam.eye + to_world @ np.array([sx * cam.w / 2, sy * cam.h / 2, -d])
            for sx, sy in [(-1, -1), (1, -1), (1, 1), (-1, 1)]
        ]
    )
    # The frustum edges: from the eye through the window's corners, on past the nut.
    beyond = (centre - cam.eye) @ view / d + 0.3 * size / d
    frustum = np.vstack([(cam.eye, cam.eye + beyond * (c - cam.eye)) for c in corners])

    plotter = pv.Plotter(off_screen=True, window_size=(800, 520))
    plotter.add_mesh(mesh, scalars="Depth", cmap="viridis", clim=depth_range, show_scalar_bar=False)
    plotter.add_mesh(
        image,
        scalars="Depth",
        cmap="viridis",
        clim=depth_range,
        nan_color="lightgrey",
        lighting=False,
        show_scalar_bar=False,
    )
    plotter.add_lines(corners[[0, 1, 1, 2, 2, 3, 3, 0]], color="black", width=3)
    plotter.add_lines(frustum, color="grey", width=1)
    for start, end in rays:
        plotter.add_lines(np.array([start, end]), color="red", width=2)
        plotter.add_mesh(pv.Sphere(radius=0.012 * size, center=end), color="red")
    plotter.add_mesh(pv.Sphere(radius=0.03 * size, center=cam.eye), color="black")
    plotter.add_point_labels(
        [cam.eye + 0.08 * size * cam.up, corners[3] + 0.04 * size * cam.up],
        ["eye", f"window w x h at distance d, {nx} x {ny} pixels"],
        font_size=14,
        shape=None,
        show_points=False,
        always_visible=True,
    )
    # Looking over the eye's shoulder, from behind the window and off to the side.
    focus = cam.eye + 1.1 * d * view
    position = cam.eye + size * (1.4 * cam.right + 0.7 * cam.up + 0.5 * cam.backward)
    plotter.camera_position = [position, focus, (0, 0, 1)]
    plotter.reset_camera()
    plotter.camera.zoom(1.7)
    path = args.out / "camera_model.png"
    plotter.screenshot(path)
    plotter.close()
    print(f"image on the plane at d = {d:.2f}; {len(rays)} rays agree with Position; wrote {path}")


if __name__ == "__main__":
    main()
