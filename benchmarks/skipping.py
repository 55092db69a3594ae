#!/usr/bin/env python
"""What each piece of skipped work saves, measured in one run: the seed's per-tile bounding
test (a model covering 1 % of the frame), the BVH reused across cameras, the one-shot cast
without a BVH, unrequested arrays, back-face culling, and camera-ray coherence (packets
against the same rays traversed one by one).

    python benchmarks/skipping.py [--pixels 1024] [--repeats 5] [--out benchmarks/results]

Frog contour (1.5 M triangles) from the iso camera of benchmarks/peers.py, unless said
otherwise; medians of repeats. Writes ``skipping.md``.
"""

from __future__ import annotations

import argparse
import sys
from functools import partial
from pathlib import Path

import numpy as np
from pyvista import examples

import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere, camera_rays

sys.path.insert(0, str(Path(__file__).parent))
from timing import machine_description, median_seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pixels", type=int, default=1024)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args()
    machine = machine_description()
    print(machine, flush=True)

    median_of = partial(median_seconds, repeats=args.repeats)

    n = args.pixels
    rows: list[tuple[str, str, float, str, float]] = []

    def compare(what: str, base_label: str, base: float, label: str, value: float) -> None:
        rows.append((what, base_label, base, label, value))
        print(rows[-1], flush=True)

    # The seed's bounding test per tile: a sphere filling most of the frame, then the same
    # sphere under a wider view angle that leaves it 1 % of the frame.
    sphere = vrc.Scene(bumpy_sphere(6))
    full = vrc.Camera((0, 0, 2.0), (0, 0, 0), (0, 1, 0), view_angle=62, nx=n, ny=n)

    def coverage(cam: vrc.Camera) -> float:
        return float(np.mean(np.asarray(sphere.cast(cam, arrays=["TriangleId"])["TriangleId"]) >= 0))

    widen = np.sqrt(coverage(full) / 0.01)
    small = full.replace(view_angle=2 * np.degrees(np.arctan(widen * np.tan(np.radians(31)))))
    covered = [coverage(full), coverage(small)]
    compare(
        f"model covering {covered[0]:.0%} -> {covered[1]:.1%} of the frame (bumpy sphere, {sphere.n_triangles:,} tris)",
        "full frame",
        median_of(lambda: sphere.cast(full, arrays=["TriangleId"])),
        "1 % of it",
        median_of(lambda: sphere.cast(small, arrays=["TriangleId"])),
    )
    away = full.replace(look_at=(0, 0, 4))  # the model behind the camera: only the misses to write
    compare(
        "the floor: writing a frame of misses (model behind the camera)",
        "full frame",
        rows[-1][2],
        "nothing in view",
        median_of(lambda: sphere.cast(away, arrays=["TriangleId"])),
    )
    o, d = camera_rays(small)
    compare(
        "the 1 % frame: per-tile bounding test and packets, against ray by ray",
        "ray by ray (intersect)",
        median_of(lambda: sphere.intersect(o, d)),
        "camera cast",
        median_of(lambda: sphere.cast(small, arrays=["TriangleId"])),
    )

    mesh = examples.load_frog_tissues().contour_labels()
    cam = vrc.Camera.framing(mesh.bounds, view="iso", nx=n, ny=n)
    scene = vrc.Scene(mesh)
    recast = median_of(lambda: scene.cast(cam, arrays=["TriangleId"]))
    first_image = median_of(lambda: vrc.Scene(mesh).cast(cam, arrays=["TriangleId"]))
    compare("BVH reused across cameras", "first image (Scene + cast)", first_image, "camera-only re-cast", recast)
    compare(
        "one-shot cast: no BVH",
        "Scene + cast",
        first_image,
        "vrc.cast (binned)",
        median_of(lambda: vrc.cast(mesh, cam, arrays=["TriangleId"])),
    )
    flat = vrc.Scene(mesh, bvh=False)
    flat.cast(cam, arrays=["TriangleId"])  # both after a cast: with the memory they keep for the next
    rows.append(
        (
            "one-shot cast: bytes per triangle after a cast",
            "Scene",
            scene.memory_bytes / scene.n_triangles,
            "no BVH",
            flat.memory_bytes / flat.n_triangles,
        )
    )
    compare(
        "arrays not requested",
        "TriangleId, Depth, Barycentric, Normal",
        median_of(lambda: scene.cast(cam, arrays=["TriangleId", "Depth", "Barycentric", "Normal"])),
        "TriangleId only",
        recast,
    )
    compare(
        "back-face culling",
        "off",
        recast,
        "on",
        median_of(lambda: scene.cast(cam, arrays=["TriangleId"], backface_culling=True)),
    )
    o, d = camera_rays(cam)
    compare(
        "coherence of camera rays",
        "same rays one by one (intersect)",
        median_of(lambda: scene.intersect(o, d)),
        "tiles as packets (cast)",
        recast,
    )

    lines = [
        f"`python benchmarks/skipping.py --pixels {n}` on {machine}: {n}x{n}, medians of {args.repeats} "
        "(seconds; bytes per triangle where said).",
        "",
        "| what is skipped | without | s | with | s | ratio |",
        "|---|---|---:|---|---:|---:|",
    ]
    for what, base_label, base, label, value in rows:
        lines.append(f"| {what} | {base_label} | {base:.4g} | {label} | {value:.4g} | {value / base:.3f} |")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "skipping.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
