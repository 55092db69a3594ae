#!/usr/bin/env python
"""Scaling: build and cast time against the number of triangles (bumpy spheres, about 20
thousand to 5 million) and cast time against the number of pixels (256x256 to 4096x4096),
and the cost of a camera-only re-cast against a first cast.

    python benchmarks/scaling.py [--out benchmarks/results]

Writes ``scaling.md`` and ``scaling.png``. Medians of 3 casts; TriangleId only.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere

sys.path.insert(0, str(Path(__file__).parent))
from timing import machine_description, median_seconds


def timed(fn) -> float:
    return median_seconds(fn, 3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args()
    machine = machine_description()
    print(machine, flush=True)

    by_triangles = []
    for subdivisions in range(5, 10):  # 20 480 to 5 242 880 triangles
        mesh = bumpy_sphere(subdivisions)
        start = time.perf_counter()
        scene = vrc.Scene(mesh)
        build = time.perf_counter() - start
        cam = vrc.Camera((2.2, 1.6, 1.2), (0, 0, 0), (0, 0, 1), view_angle=40, nx=1024, ny=1024)
        first = time.perf_counter()
        scene.cast(cam, arrays=["TriangleId"])
        first = time.perf_counter() - first
        recast = timed(lambda scene=scene, cam=cam: scene.cast(cam, arrays=["TriangleId"]))
        by_triangles.append((scene.n_triangles, build, first, recast))
        print(by_triangles[-1], flush=True)

    mesh = bumpy_sphere(7)
    scene = vrc.Scene(mesh)
    by_pixels = []
    for n in (256, 512, 1024, 2048, 4096):
        cam = vrc.Camera((2.2, 1.6, 1.2), (0, 0, 0), (0, 0, 1), view_angle=40, nx=n, ny=n)
        by_pixels.append((n * n, timed(lambda cam=cam: scene.cast(cam, arrays=["TriangleId"]))))
        print(by_pixels[-1], flush=True)

    args.out.mkdir(parents=True, exist_ok=True)
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    tri = np.array(by_triangles)
    left.loglog(tri[:, 0], tri[:, 1], "o-", label="build")
    left.loglog(tri[:, 0], tri[:, 2], "s-", label="first cast")
    left.loglog(tri[:, 0], tri[:, 3], "^-", label="camera-only re-cast")
    left.set_xlabel("triangles (bumpy sphere)")
    left.set_ylabel("seconds (1024x1024, TriangleId)")
    left.legend()
    left.grid(True, which="both", alpha=0.3)
    pix = np.array(by_pixels)
    right.loglog(pix[:, 0], pix[:, 1], "o-", label=f"cast, {scene.n_triangles:,} triangles")
    right.loglog(pix[:, 0], pix[:, 1][0] * pix[:, 0] / pix[0, 0], "--", color="grey", label="linear in pixels")
    right.set_xlabel("pixels")
    right.set_ylabel("seconds")
    right.legend()
    right.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"vtkraycast scaling ({machine})", fontsize=9)
    fig.tight_layout()
    fig.savefig(args.out / "scaling.png", dpi=100)

    lines = [
        f"`python benchmarks/scaling.py` on {machine}.",
        "",
        "| triangles | build s | first cast s | re-cast s | re-cast Mrays/s |",
        "|---:|---:|---:|---:|---:|",
    ]
    for n, b, f, r in by_triangles:
        lines.append(f"| {int(n):,} | {b:.3f} | {f:.3f} | {r:.4f} | {1024 * 1024 / r / 1e6:.1f} |")
    lines += ["", "| pixels | cast s | Mrays/s |", "|---:|---:|---:|"]
    lines += [f"| {int(p):,} | {c:.4f} | {p / c / 1e6:.1f} |" for p, c in by_pixels]
    (args.out / "scaling.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
