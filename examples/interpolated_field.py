"""A point field interpolated through the barycentric weights, next to VTK's rendering of it.
==========================================================================================

The nut gets two point fields: ``Linear``, a linear function of the coordinates, and
``Wave``, a smooth non-linear one. A cast interpolates every point array of the mesh at
the hit points with the barycentric weights. The picture shows ``Wave`` from the cast,
coloured through the lookup table of the VTK actor, beside VTK's own rendering of the
same field (same camera, same colormap and range, no lighting, colours interpolated
before mapping) and the colour difference of the two.

Checks: the interpolated ``Linear`` equals the linear function evaluated at the hit
``Position`` to 1e-9 (barycentric interpolation reproduces linear functions exactly); and
on pixels both images cover, the median colour difference is at most 2 levels out of 255
and 95 % of the pixels differ by at most 8 levels (the lookup table has 256 colours; VTK
samples it as a texture).

Run: ``python examples/interpolated_field.py [--out DIR]``, writes ``interpolated_field.png``.
"""

from __future__ import annotations

import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pyvista as pv
from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
from vtkmodules.vtkCommonCore import VTK_RGBA

import vtkraycast as vrc

pv.OFF_SCREEN = True


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("."), help="output directory")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    mesh = pv.examples.load_nut()
    points = np.asarray(mesh.points, dtype=np.float64)
    centre, size = points.mean(axis=0), mesh.length
    a = np.array([1.0, -0.5, 0.8]) / size  # Linear = a . x + b, values of order 1
    b = 0.25
    mesh.point_data["Linear"] = points @ a + b
    u = (points - centre) / size
    wave = np.sin(16.0 * u[:, 0]) * np.cos(13.0 * u[:, 1]) + 0.5 * np.sin(19.0 * u[:, 2])
    mesh.point_data["Wave"] = wave

    nx, ny = 400, 300
    plotter = pv.Plotter(off_screen=True, window_size=(nx, ny))
    plotter.disable_anti_aliasing()
    actor = plotter.add_mesh(
        mesh,
        scalars="Wave",
        cmap="viridis",
        clim=(-1.5, 1.5),
        lighting=False,
        interpolate_before_map=True,
        show_scalar_bar=False,
    )
    plotter.camera_position = "iso"
    plotter.reset_camera()
    plotter.camera.zoom(1.1)
    plotter.show(auto_close=False)
    screenshot = np.asarray(plotter.screenshot(return_img=True))  # top row first
    vtk_rgb = screenshot[..., :3].astype(np.int16)
    vtk_cover = np.isfinite(plotter.get_image_depth(reset_camera_clipping_range=False))
    cam = vrc.Camera.from_vtk(plotter)
    lut = actor.mapper.lookup_table
    plotter.close()

    image = vrc.cast(mesh, cam, arrays=["TriangleId", "Position", "Linear", "Wave"])
    hit = image["TriangleId"] >= 0
    assert 0.2 < hit.mean() < 0.9, f"implausible coverage {hit.mean():.2f}"

    # -- exactness on a linear field ------------------------------------------------------
    linear, position = image["Linear"][hit], image["Position"][hit]
    error = np.abs(linear - (position @ a + b))
    assert error.max() < 1e-9, f"Linear differs from a . x + b by up to {error.max():.1e}"
    assert np.isnan(image["Linear"][~hit]).all()

    # -- the cast's Wave through the actor's own lookup table ---------------------------
    colours = lut.MapScalars(numpy_to_vtk(np.ascontiguousarray(image["Wave"]), deep=True), 0, -1, VTK_RGBA)
    ours = vtk_to_numpy(colours).reshape(ny, nx, 4)[::-1, :, :3].astype(np.int16)  # top-first
    ours_cover = hit.reshape(ny, nx)[::-1]
    background = np.round(np.array(plotter.background_color.float_rgb) * 255).astype(np.int16)
    ours[~ours_cover] = background

    both = ours_cover & vtk_cover
    assert (ours_cover == vtk_cover).mean() > 0.99, "the two images cover different pixels"
    difference = np.abs(ours - vtk_rgb).max(axis=2)  # worst channel, 0..255
    median, p95 = np.median(difference[both]), np.percentile(difference[both], 95)
    assert median <= 2, f"median colour difference {median} of 255"
    assert p95 <= 8, f"95th percentile colour difference {p95} of 255"

    # -- the picture ------------------------------------------------------------------------
    fig, axes = plt.subplots(1, 3, figsize=(8, 2.3), dpi=100, constrained_layout=True)
    axes[0].imshow(ours.astype(np.uint8))
    axes[0].set_title("vtkraycast: Wave interpolated", fontsize=9)
    axes[1].imshow(vtk_rgb.astype(np.uint8))
    axes[1].set_title("VTK rendering of Wave", fontsize=9)
    shown = axes[2].imshow(np.where(both, difference, np.nan), cmap="magma", vmin=0, vmax=16)
    axes[2].set_title("colour difference (of 255)", fontsize=9)
    fig.colorbar(shown, ax=axes[2], shrink=0.8).ax.tick_params(labelsize=7)
    for ax in axes:
        ax.set_axis_off()
    path = args.out / "interpolated_field.png"
    fig.savefig(path)
    plt.close(fig)
    print(
        f"Linear exact to {error.max():.1e}; colours differ by median {median:.0f}, "
        f"95th percentile {p95:.0f}, at most {difference[both].max()} of 255 "
        f"on {both.sum()} pixels; wrote {path}"
    )


if __name__ == "__main__":
    main()
