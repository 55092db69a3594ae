"""A depth map from the ray caster next to VTK's own z-buffer of the same camera.
==============================================================================

The mesh is rendered by VTK (pyvista, off screen, no anti-aliasing) and ray cast through
the plotter's camera (``vrc.Camera.from_vtk(plotter)`` takes position, focal point, view
up, view angle, clipping range and window size). The cast's ``Depth`` is the distance from
the eye along the view direction; ``plotter.get_image_depth()`` turns the z-buffer into the
same quantity with a minus sign (camera-space z, negative in front of the eye), top row
first. The figure shows both maps and their difference.

Checks: the two coverage masks agree on at least 99 % of the pixels (they differ only
where a silhouette edge crosses a pixel centre), and on pixels both cover the median
relative depth difference is below 1e-5 (see the tolerance's reasoning below).

Run: ``python examples/depth_map.py [--out DIR]``, writes ``depth_map.png``.
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

pv.OFF_SCREEN = True


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("."), help="output directory")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    mesh = pv.examples.load_airplane()
    nx, ny = 640, 480

    # -- VTK's depth: render, then read the z-buffer -----------------------------------
    plotter = pv.Plotter(off_screen=True, window_size=(nx, ny))
    plotter.disable_anti_aliasing()  # multisampling would blend depths along edges
    plotter.add_mesh(mesh, color="white")
    plotter.camera_position = [(2300.0, -1900.0, 1700.0), (900.0, 676.0, 132.0), (0.0, 0.0, 1.0)]
    plotter.reset_camera()
    plotter.camera.zoom(1.6)
    plotter.reset_camera_clipping_range()
    plotter.show(auto_close=False)
    # Keep the clipping range the image was rendered with: the z-buffer is only
    # meaningful with the near/far planes that produced it.
    vtk_depth = -np.asarray(plotter.get_image_depth(reset_camera_clipping_range=False), dtype=np.float64)
    near, far = plotter.camera.clipping_range

    # -- the ray caster's depth through the very same camera ---------------------------
    cam = vrc.Camera.from_vtk(plotter)
    plotter.close()
    assert (cam.nx, cam.ny) == (nx, ny)
    image = vrc.cast(mesh, cam, arrays=["Depth"])
    depth = image["Depth"].reshape(ny, nx)[::-1]  # row 0 is the bottom: flip to top-first

    ours, theirs = np.isfinite(depth), np.isfinite(vtk_depth)
    agreement = (ours == theirs).mean()
    assert agreement >= 0.99, f"coverage masks agree on only {100 * agreement:.2f} % of pixels"
    assert ours.sum() > 0.05 * nx * ny, "the airplane should cover a good part of the picture"

    both = ours & theirs
    relative = np.abs(depth[both] - vtk_depth[both]) / depth[both]
    # The tolerance: a 24-bit z-buffer stores zw = f (z - n) / (z (f - n)) in steps of
    # 2**-24, i.e. steps in depth of dz = z**2 (f - n) / (f n) 2**-24, a relative step of
    # z (f - n) / (f n) 2**-24 (about 1e-7 here), and the read-back is float32 (6e-8).
    # A median of 1e-5 leaves two orders of magnitude for other GPUs and drivers, while a
    # camera off by one pixel or a wrong view angle gives relative errors of 1e-3 and more.
    quantum = np.median(depth[both] * (far - near) / (far * near)) * 2.0**-24
    median = float(np.median(relative))
    assert median < 1e-5, f"median relative depth difference {median:.2e} (z-buffer step {quantum:.1e})"

    # -- the figure -----------------------------------------------------------------------
    lo, hi = np.nanmin(depth), np.nanmax(depth)
    difference = depth - vtk_depth
    limit = float(np.nanpercentile(np.abs(difference), 99)) or 1e-12
    rows = np.flatnonzero((ours | theirs).any(axis=1))
    cols = np.flatnonzero((ours | theirs).any(axis=0))
    crop = np.s_[max(rows[0] - 8, 0) : rows[-1] + 9, max(cols[0] - 8, 0) : cols[-1] + 9]
    fig, axes = plt.subplots(1, 3, figsize=(8, 2.45), dpi=100, constrained_layout=True)
    panels = [
        (depth, "vtkraycast Depth", "viridis", lo, hi),
        (vtk_depth, "VTK z-buffer depth", "viridis", lo, hi),
        (difference, "Depth - z-buffer depth", "RdBu", -limit, limit),
    ]
    for ax, (values, title, cmap, vmin, vmax) in zip(axes, panels):
        shown = ax.imshow(values[crop], cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.set_axis_off()
        fig.colorbar(shown, ax=ax, shrink=0.8).ax.tick_params(labelsize=7)
    path = args.out / "depth_map.png"
    fig.savefig(path)
    plt.close(fig)
    print(
        f"masks differ on {int((ours != theirs).sum())} of {nx * ny} pixels; "
        f"median relative depth difference {median:.1e} (z-buffer step about {quantum:.1e}); "
        f"wrote {path}"
    )


if __name__ == "__main__":
    main()
