"""Size stress: a 10-million-triangle mesh and an 8192 x 8192 image on this machine, with
build time, cast time and peak resident memory.

    python benchmarks/size.py [--triangles 10000000] [--pixels 8192] [--out benchmarks/results]

Writes ``size.md``. The mesh is a bumpy height field (two triangles per grid square), the
camera a perspective view that frames it; the cast computes TriangleId, Depth and
Barycentric.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import resource
import time
from pathlib import Path

import numpy as np
import pyvista as pv

import vtkraycast as vrc


def peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def height_field(n_triangles: int) -> pv.PolyData:
    side = math.ceil(math.sqrt(n_triangles / 2))
    mesh = pv.Plane(i_size=1, j_size=1, i_resolution=side, j_resolution=side)
    p = mesh.points
    p[:, 2] = 0.05 * np.sin(40 * p[:, 0]) * np.cos(30 * p[:, 1])
    return mesh.triangulate()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--triangles", type=int, default=10_000_000)
    parser.add_argument("--pixels", type=int, default=8192)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args()
    machine = (
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    )
    print(machine)

    t = time.perf_counter()
    mesh = height_field(args.triangles)
    made = time.perf_counter() - t
    print(f"mesh: {mesh.n_cells} triangles in {made:.1f} s, peak {peak_mib():.0f} MiB", flush=True)

    t = time.perf_counter()
    scene = vrc.Scene(mesh)
    build = time.perf_counter() - t
    del mesh  # the scene keeps its own copy
    print(
        f"scene: {build:.1f} s, {scene.memory_bytes / scene.n_triangles:.1f} bytes/triangle, peak {peak_mib():.0f} MiB"
    )

    n = args.pixels
    cam = vrc.Camera((0.3, -0.9, 0.8), (0, 0, 0), (0, 0, 1), view_angle=45, nx=n, ny=n)
    t = time.perf_counter()
    image = scene.cast(cam, arrays=["TriangleId", "Depth", "Barycentric"])
    cast = time.perf_counter() - t
    hits = int((image["TriangleId"] >= 0).sum())
    print(f"cast {n}x{n}: {cast:.1f} s ({n * n / cast / 1e6:.1f} Mrays/s), {hits} hits, peak {peak_mib():.0f} MiB")

    args.out.mkdir(parents=True, exist_ok=True)
    table = [
        "| scenario | triangles | pixels | build s | cast s | Mrays/s | bytes/triangle | peak RSS MiB |",
        "|---|---|---|---|---|---|---|---|",
        f"| height field | {scene.n_triangles:,} | {n}x{n} | {build:.1f} | {cast:.1f} | {n * n / cast / 1e6:.1f} | "
        f"{scene.memory_bytes / scene.n_triangles:.1f} | {peak_mib():,.0f} |",
    ]
    (args.out / "size.md").write_text(
        f"`python benchmarks/size.py --triangles {args.triangles} --pixels {args.pixels}` on {machine}\n\n"
        + "\n".join(table)
        + "\n"
    )
    print("\n".join(table))


if __name__ == "__main__":
    main()
