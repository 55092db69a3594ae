#!/usr/bin/env python
"""A spinning lidar's scan against Open3D's cast_rays on the same beams, timed in
alternation in one run.

    python benchmarks/sensors.py [--rings 64] [--steps 2048] [--pairs 7]

Scenes: the frog contour and the generated terrain (benchmarks/scenes.py), the lidar inside
their boxes (the terrain's 2 above its middle). What is timed is what a user calls:
``Scene.scan(lidar)`` (a PolyData of the returns with Range, Elevation, Azimuth, Ring,
TriangleId, CellId, Barycentric and the mesh's arrays) against ``cast_rays`` of the same
rays (t, ids, uvs, normals) plus Open3D's own ray construction in numpy.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import open3d as o3d

import vtkraycast as vrc

sys.path.insert(0, str(Path(__file__).parent))
import scenes
from timing import alternated_ratio

ELEVATIONS = np.linspace(-25, 15, 64)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rings", type=int, default=64)
    parser.add_argument("--steps", type=int, default=2048)
    parser.add_argument("--pairs", type=int, default=7)
    args = parser.parse_args()
    elevations = np.linspace(ELEVATIONS[0], ELEVATIONS[-1], args.rings)
    print(f"{args.rings} rings x {args.steps} steps = {args.rings * args.steps:,} beams; "
          f"Open3D's time over vtkraycast's, median of {args.pairs} alternated pairs (quartiles)")  # fmt: skip
    for name in ("frog", "terrain"):
        compare(name, elevations, args)


def scene_lidar(mesh, name: str, elevations: np.ndarray = ELEVATIONS, steps: int = 2048) -> vrc.Lidar:
    """The lidar of scene ``name``: in the middle of its box (the terrain's 2 above it)."""
    return vrc.Lidar(scenes.inside(mesh, name), elevations, steps)


def compare(name: str, elevations: np.ndarray, args: argparse.Namespace) -> None:
    mesh = getattr(scenes, name)()
    scene = vrc.Scene(mesh)
    lidar = scene_lidar(mesh, name, elevations, args.steps)
    peer = o3d.t.geometry.RaycastingScene()
    prepared = scene.prepared
    peer.add_triangles(o3d.core.Tensor(prepared.points.astype(np.float32)),
                       o3d.core.Tensor(prepared.triangles.astype(np.uint32)))  # fmt: skip

    def theirs() -> None:
        origins, directions, _, _ = lidar.rays()
        peer.cast_rays(o3d.core.Tensor(np.hstack((origins, directions)).astype(np.float32)))

    ratio, q1, q3 = alternated_ratio(lambda: scene.scan(lidar), theirs, args.pairs)
    returns = scene.scan(lidar).n_points
    print(f"  {name}: {returns:,} returns; scan {ratio:.2f}x Open3D's cast_rays ({q1:.2f} to {q3:.2f})")


if __name__ == "__main__":
    main()
