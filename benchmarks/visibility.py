#!/usr/bin/env python
"""Every crossing, crossing counts and inside/outside against Open3D, on the same queries,
timed in alternation in one run; trimesh, libigl and VTK on a sample.

    python benchmarks/visibility.py [--rays 200000] [--pairs 7] [--out benchmarks/results]

Scenes: bumpy spheres of 20 k and 330 k triangles and the frog contour (open: no
inside/outside). ``intersect_all`` against
Open3D's ``list_intersections``, ``count_intersections`` against its
``count_intersections``, ``contains`` against its ``compute_occupancy`` (one ray per point,
``nsamples=1``); agreement: the same count or the same answer. Writes ``visibility.md``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import open3d as o3d
import pyvista as pv

import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere

sys.path.insert(0, str(Path(__file__).parent))
import scenes
from timing import alternated_ratio, machine_description

SCENES = {
    "bumpy sphere (20 k triangles)": lambda: bumpy_sphere(5),
    "bumpy sphere (330 k triangles)": lambda: bumpy_sphere(7),
    "frog contour (1.5 M triangles, open)": scenes.frog,
}


def cases(scene: vrc.Scene, origins: np.ndarray, directions: np.ndarray) -> list[tuple]:
    """(label, ours, Open3D's, agreement) of each query on ``scene``; inside/outside only
    for closed meshes."""
    peer = o3d.t.geometry.RaycastingScene()
    peer.add_triangles(
        o3d.core.Tensor(scene.prepared.points.astype(np.float32)),
        o3d.core.Tensor(scene.prepared.triangles.astype(np.uint32)),
    )
    rays = o3d.core.Tensor(np.hstack((origins, directions)).astype(np.float32))
    queries = o3d.core.Tensor(origins.astype(np.float32))

    def counts_agree() -> float:
        return float((scene.count_intersections(origins, directions) == peer.count_intersections(rays).numpy()).mean())

    def inside_agree() -> float:
        theirs = peer.compute_occupancy(queries, nsamples=1).numpy().astype(bool)
        return float((scene.contains(origins) == theirs).mean())

    found = [
        ("intersect_all / list_intersections", lambda: scene.intersect_all(origins, directions),
         lambda: peer.list_intersections(rays), None),
        ("count_intersections", lambda: scene.count_intersections(origins, directions),
         lambda: peer.count_intersections(rays), counts_agree),
    ]  # fmt: skip
    try:
        scene.contains(origins[:1])
    except ValueError:  # an open mesh
        return found
    found.append(("contains / compute_occupancy", lambda: scene.contains(origins),
                  lambda: peer.compute_occupancy(queries, nsamples=1), inside_agree))  # fmt: skip
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=200_000)
    parser.add_argument("--pairs", type=int, default=7)
    parser.add_argument("--sample", type=int, default=2000, help="queries for trimesh and libigl")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    rows, singles = [], []
    for name, make in SCENES.items():
        scene = vrc.Scene(make())
        points = scene.prepared.points
        low, high = points.min(axis=0), points.max(axis=0)
        origins = rng.uniform(low, high, (args.rays, 3))
        directions = rng.normal(size=(args.rays, 3))
        for label, ours, theirs, agree in cases(scene, origins, directions):
            ratio, q1, q3 = alternated_ratio(ours, theirs, args.pairs)
            seconds = min(_time(ours) for _ in range(3))
            rows.append((name, label, args.rays / seconds / 1e6, ratio, q1, q3, agree() if agree else None))
            print(rows[-1], flush=True)
        if "open" not in name:
            singles += _single_thread_peers(name, scene, origins[: args.sample])
    _write(args, rows, singles)


def _time(f) -> float:
    start = time.perf_counter()
    f()
    return time.perf_counter() - start


def _single_thread_peers(name, scene, origins) -> list[tuple]:
    import igl
    import trimesh

    mesh = trimesh.Trimesh(scene.prepared.points, scene.prepared.triangles, process=False)
    n = len(origins)
    found = []
    ours = _time(lambda: scene.contains(origins))
    found.append((name, "vtkraycast contains", n / ours / 1e6, 1.0))
    inside = scene.contains(origins)
    for label, f in (
        ("trimesh contains", lambda: mesh.contains(origins)),
        ("libigl winding number > 0.5", lambda: np.abs(igl.winding_number(mesh.vertices, mesh.faces, origins)) > 0.5),
        ("VTK vtkSelectEnclosedPoints", lambda: _vtk_enclosed(scene.prepared, origins)),
    ):
        result = f()
        found.append((name, label, n / _time(f) / 1e6, float((np.asarray(result) == inside).mean())))
    return found


def _vtk_enclosed(mesh, points) -> np.ndarray:
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkFiltersModeling import vtkSelectEnclosedPoints

    select = vtkSelectEnclosedPoints()
    select.SetInputData(pv.PolyData(points))
    select.SetSurfaceData(pv.PolyData.from_regular_faces(mesh.points, mesh.triangles))
    select.Update()
    return vtk_to_numpy(select.GetOutput().GetPointData().GetArray("SelectedPoints")).astype(bool)


def _write(args, rows, singles) -> None:
    machine = machine_description()
    lines = [
        f"`python benchmarks/visibility.py --rays {args.rays} --pairs {args.pairs}` on {machine}. "
        f"{args.rays:,} random rays (origins in the box, random directions) or points per scene; Open3D's "
        f"time over vtkraycast's, median of {args.pairs} calls timed in alternation (quartiles in brackets); "
        "agreement with Open3D (float32 rays and points).",
        "",
        "| scene | query | vtkraycast M/s | vs Open3D | agree |",
        "|---|---|---:|---:|---:|",
    ]
    for name, label, rate, ratio, q1, q3, agree in rows:
        share = "" if agree is None else f"{100 * agree:.3f}%"
        lines.append(f"| {name} | {label} | {rate:.2f} | {ratio:.2f}x ({q1:.2f} to {q3:.2f}) | {share} |")
    lines += ["", f"Single-thread peers, {args.sample:,} points (separate timings):", "",
              "| scene | method | M/s | same answer as vtkraycast |", "|---|---|---:|---:|"]  # fmt: skip
    lines += [f"| {n} | {label} | {rate:.3f} | {100 * agree:.2f}% |" for n, label, rate, agree in singles]
    lines += ["", "Targets (issue 29): intersect_all and contains at least as fast as Open3D's "
              "list_intersections and compute_occupancy."]  # fmt: skip
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "visibility.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
