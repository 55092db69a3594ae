"""Command line: cast a mesh (or the built-in frog scene) and write the geometry buffer."""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from vtkmodules.vtkCommonDataModel import vtkImageData

from .camera import _VIEWS, Camera
from .image import fill_image
from .picture import barycentric_rgba, write_png
from .scene import STRATEGIES, one_shot_scene


def default_scene() -> Any:
    """The contour of every tissue of pyvista's shipped ``frog_tissues.vti`` label volume:
    a real 1.5 M-triangle mesh that needs no download."""
    from pyvista import examples

    return examples.load_frog_tissues().contour_labels()


def _size(text: str) -> tuple[int, int]:
    try:
        nx, ny = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 800x600, got {text!r}") from None
    if nx < 1 or ny < 1:
        raise argparse.ArgumentTypeError(f"size must be at least 1x1, got {text!r}")
    return nx, ny


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="vtkraycast",
        description="Ray cast a triangle mesh into a VTK geometry buffer (.vti) and a picture (.png).",
    )
    p.add_argument("mesh", nargs="?", help="any file pyvista reads; default: the contour of pyvista's frog_tissues.vti")
    p.add_argument("-o", "--output", default="raycast.vti", help="geometry buffer to write (default: raycast.vti)")
    p.add_argument("--png", default="raycast.png", help="picture to write (default: raycast.png)")
    p.add_argument("--size", type=_size, default=(800, 600), help="pixels, WxH (default: 800x600)")
    p.add_argument("--view", choices=list(_VIEWS), default="iso", help="side the camera looks from (default: iso)")
    p.add_argument("--strategy", choices=STRATEGIES, default="auto", help="ray-triangle test (default: auto)")
    p.add_argument("--threads", type=int, default=None, help="worker threads (default: all cores)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = parser().parse_args(argv)
    import pyvista as pv

    start = time.perf_counter()
    try:
        mesh = pv.read(args.mesh) if args.mesh else default_scene()
    except (FileNotFoundError, ValueError, OSError) as error:
        print(f"vtkraycast: cannot read {args.mesh}: {error}", file=sys.stderr)
        return 2
    if not isinstance(mesh, pv.DataSet):
        mesh = mesh.combine() if isinstance(mesh, pv.MultiBlock) else mesh
    nx, ny = args.size
    camera = Camera.framing(np.asarray(mesh.points) if mesh.n_points else mesh.bounds, view=args.view, nx=nx, ny=ny)
    arrays = ["TriangleId", "CellId", "Barycentric", "Depth", "Normal", "vtkValidPointMask"]
    cast_start = time.perf_counter()
    scene = one_shot_scene(mesh, camera, threads=args.threads)
    bar = sys.stderr.isatty() and importlib.util.find_spec("tqdm") is not None  # (on long casts)
    camera, buffers = scene.buffers(
        camera, arrays=arrays, strategy=args.strategy, threads=args.threads, progress_bar=bar
    )
    elapsed = time.perf_counter() - cast_start
    pv.wrap(fill_image(vtkImageData(), camera, buffers)).save(args.output)
    facing = buffers["Normal"] @ camera.backward
    write_png(args.png, barycentric_rgba(buffers["Barycentric"], facing), nx, ny)
    hits = int(np.count_nonzero(buffers["vtkValidPointMask"]))
    print(
        f"{scene.n_triangles} triangles, {nx * ny} pixels ({nx}x{ny}), {hits} hits, "
        f"{elapsed:.3f} s prepare+cast ({time.perf_counter() - start:.3f} s total) -> {args.output}, {args.png}"
    )
    return 0
