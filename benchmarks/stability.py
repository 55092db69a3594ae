#!/usr/bin/env python
"""Numerical stability, scenario by scenario: leaks, wrong triangles and the worst ``t``
error of every vtkraycast strategy and precision, and of Open3D, embreex and libigl on the
same rays, against the exact reference (``vtkraycast.validate``).

    python benchmarks/stability.py [--out benchmarks/results]

Writes ``stability.md`` and ``stability.csv``. The scenarios are those of ``tests/stress``
(built by ``vtkraycast.testing``), small enough for the exact reference to judge every ray.
"""

from __future__ import annotations

import argparse
import csv
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyvista as pv

import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere, camera_rays, integer_grid, rays_at_vertices_and_edges, star_mesh
from vtkraycast.validate import classify, exact_first_hits

sys.path.insert(0, str(Path(__file__).parent))
from peer_casters import make_peers
from timing import machine_description

Scenario = tuple[pv.PolyData, np.ndarray, np.ndarray]


def inside(offset: float, scale: float, subdivisions: int = 3) -> Callable[[], Scenario]:
    def make() -> Scenario:
        mesh = bumpy_sphere(subdivisions, offset=offset, scale=scale)
        scene = vrc.Scene(mesh)
        eye = np.full(3, offset) + scale * np.array([0.11, -0.07, 0.05])
        return mesh, *rays_at_vertices_and_edges(scene.prepared.points, scene.prepared.triangles, eye)

    return make


def outside(offset: float) -> Scenario:
    mesh = bumpy_sphere(3, offset=offset)
    centre = np.full(3, offset)
    cam = vrc.Camera(centre + [2.0, 1.5, 1.0], centre, (0, 0, 1), view_angle=50, nx=48, ny=36)
    return mesh, *camera_rays(cam)


def grid_parallel() -> Scenario:
    cam = vrc.Camera((4, 4, 10), (4, 4, 0), (0, 1, 0), w=8.5, h=8.5, nx=17, ny=17, parallel=True)
    return integer_grid(8), *camera_rays(cam)


def star(offset: float) -> Callable[[], Scenario]:
    def make() -> Scenario:
        eye = np.full(3, offset) + [0.25, -0.5, 0.125]
        cam = vrc.Camera(eye, eye + [0, 0, -1], (0, 1, 0), w=33 / 16, h=25 / 16, nx=33, ny=25)
        return star_mesh(cam), *camera_rays(cam)

    return make


def slivers(aspect: float) -> Callable[[], Scenario]:
    def make() -> Scenario:
        n = 200
        ys = np.linspace(0, n * aspect, n + 1)
        points = np.array([[0, 0, 0]] + [[1, y, 0] for y in ys], float)
        faces = np.array([[3, 0, k + 1, k + 2] for k in range(n)]).ravel()
        heights = np.linspace(0, n * aspect, 22)[1:-1]
        origins = np.array([[x, x * y, 1.0] for x in np.linspace(0.1, 0.9, 20) for y in heights])
        return pv.PolyData(points, faces=faces), origins, np.broadcast_to([0.0, 0.0, -1.0], origins.shape).copy()

    return make


def grazing() -> Scenario:
    mesh = pv.Plane(i_resolution=20, j_resolution=20).triangulate()
    rng = np.random.default_rng(5)
    n = 2000
    origins = np.c_[np.full(n, -0.6), rng.uniform(-0.5, 0.5, n), np.full(n, 1e-9)]
    directions = np.c_[np.ones(n), rng.uniform(-0.1, 0.1, n), -1e-9 * rng.uniform(0.5, 3, n)]
    return mesh, origins, directions


def flipped() -> Scenario:
    mesh = bumpy_sphere(3)
    faces = mesh.faces.reshape(-1, 4).copy()
    flip = np.random.default_rng(2).random(len(faces)) < 0.5
    faces[flip, 1:] = faces[flip, 1:][:, ::-1]
    mesh = pv.PolyData(mesh.points, faces=faces.ravel())
    return mesh, *rays_at_vertices_and_edges(mesh.points, faces[:, 1:], [0.1, 0.05, -0.02])


SCENARIOS: dict[str, Callable[[], Scenario]] = {
    "inside, offset 1e3": inside(1e3, 1.0),
    "inside, offset 1e6": inside(1e6, 1.0),
    "inside, offset 1e8": inside(1e8, 1.0),
    "inside, scale 1e-8": inside(0.0, 1e-8),
    "inside, scale 1e-4": inside(0.0, 1e-4),
    "inside, scale 1e8": inside(0.0, 1e8),
    "inside, offset 1e6, scale 1e-6": inside(1e6, 1e-6),
    "outside camera, offset 1e6": lambda: outside(1e6),
    "integer grid, pixel centres on vertices/edges": grid_parallel,
    "star mesh, vertices on pixel rays": star(0.0),
    "star mesh at offset 1e5": star(1e5),
    "slivers, aspect 1e-8": slivers(1e-8),
    "grazing rays, 1e-9 rad": grazing,
    "inconsistent orientation, inside": flipped,
}


def vtkraycast_methods() -> list[tuple[str, Callable[[vrc.Scene, np.ndarray, np.ndarray], np.ndarray]]]:
    methods = []
    for strategy in vrc.STRATEGIES:
        for precision in ("float64", "float32"):

            def run(scene, o, d, strategy=strategy, precision=precision):
                hits = scene.intersect(o, d, strategy=strategy, precision=precision)
                return hits["triangle_id"], hits["t"]

            methods.append((f"{strategy} {precision[-2:]}", run))
    return methods


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args()
    machine = f"{machine_description()}, Python {platform.python_version()}"
    print(machine)
    peers = make_peers()
    rows = []
    start = time.perf_counter()
    for name, make in SCENARIOS.items():
        mesh, origins, directions = make()
        scene = vrc.Scene(mesh)
        points, triangles = scene.prepared.points, scene.prepared.triangles
        ref = exact_first_hits(points, triangles, origins, directions)
        results = [(label, run(scene, origins, directions)) for label, run in vtkraycast_methods()]
        for peer in peers:
            peer.build(points, triangles)
            out = peer.collect(peer.run(peer.prepare(origins, directions)))
            results.append((peer.name, (out.ids, out.t)))
        for label, (ids, t) in results:
            masks = classify(ref, ids)
            good = masks["correct"] & (ids >= 0)
            err = np.abs(t[good] - ref.t[good]) / np.maximum(np.abs(ref.t[good]), 1e-300)
            rows.append(
                dict(
                    scenario=name,
                    rays=len(origins),
                    method=label,
                    leaks=int(masks["leak"].sum()),
                    wrong=int(masks["wrong"].sum()),
                    false_hits=int(masks["false_hit"].sum()),
                    t_error=float(err.max()) if err.size else 0.0,
                )
            )
        print(f"{name}: {len(origins)} rays, {scene.n_triangles} triangles", flush=True)
    wall = time.perf_counter() - start

    methods = list(dict.fromkeys(r["method"] for r in rows))
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "stability.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    cell = {(r["scenario"], r["method"]): r for r in rows}

    def table(fmt: Callable[[dict], str]) -> list[str]:
        lines = ["| scenario (rays) | " + " | ".join(methods) + " |", "|---|" + "---:|" * len(methods)]
        for name in SCENARIOS:
            n = cell[(name, methods[0])]["rays"]
            lines.append(f"| {name} ({n}) | " + " | ".join(fmt(cell[(name, m)]) for m in methods) + " |")
        return lines

    text = [
        "# Stability: leaks / wrong triangles, and the worst t error",
        "",
        f"`python benchmarks/stability.py` on {machine}; {wall:.0f} s.",
        "Every ray is judged by the exact reference. A cell `L/W` counts leaks (the ray hits a",
        "surface, the method misses) and wrong triangles (both hit, the method's triangle is not",
        "the exact first one; on an edge or vertex every triangle sharing it is right).",
        "Open3D and embreex take float32 rays and vertices; libigl returns float32 t.",
        "",
        *table(lambda r: f"{r['leaks']}/{r['wrong']}" + (f" +{r['false_hits']}F" if r["false_hits"] else "")),
        "",
        "Worst relative t error over the rays hit correctly:",
        "",
        *table(lambda r: f"{r['t_error']:.0e}"),
    ]
    (args.out / "stability.md").write_text("\n".join(text) + "\n")
    print("\n".join(text))


if __name__ == "__main__":
    main()
