#!/usr/bin/env python
"""Arbitrary rays: ``Scene.intersect`` and ``Scene.occluded`` against Open3D's
``cast_rays`` and ``test_occlusions`` (Embree, float32), on the same rays, timed in
alternation in one run; embreex, libigl and trimesh on a sample.

    python benchmarks/rays.py [--rays 1000000] [--pairs 11] [--out benchmarks/results]

Scenes: pyvista's ant (912 triangles), a 20 k-triangle bumpy sphere and the frog contour
(1.5 M). Ray sets: from outside (origins around the box, aimed at random points of it),
from inside the box in random directions, and from random points of the surface in random
directions with a small tmin (the occlusion queries of ambient occlusion or shadows).
Writes ``rays.md``.
"""

from __future__ import annotations

import argparse
import itertools
import os
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from pyvista import examples

import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere

sys.path.insert(0, str(Path(__file__).parent))
import scenes
from peer_casters import EmbreexPeer, LibiglPeer, Open3DPeer, TrimeshPeer
from timing import alternated_ratio, machine_description, median_seconds

SCENES = {
    "ant (912 triangles)": examples.load_ant,
    "bumpy sphere (20 k triangles)": lambda: bumpy_sphere(5),
    "frog contour (1.5 M triangles)": scenes.frog,
}


def ray_sets(scene: vrc.Scene, n: int, rng: np.random.Generator) -> dict[str, tuple[np.ndarray, np.ndarray, float]]:
    """(origins, directions, tmin) of each ray set."""
    points, triangles = scene.prepared.points, scene.prepared.triangles
    low, high = points.min(axis=0), points.max(axis=0)
    centre, size = (low + high) / 2, float((high - low).max())
    outside = centre + rng.uniform(-1.5, 1.5, (n, 3)) * size
    targets = rng.uniform(low, high, (n, 3))
    inside = rng.uniform(low, high, (n, 3))
    random_directions = rng.normal(size=(n, 3))
    corners = points[triangles[rng.integers(0, len(triangles), n)]]
    weights = rng.dirichlet((1, 1, 1), n)
    surface = np.einsum("nk,nkc->nc", weights, corners)
    return {
        "from outside": (outside, targets - outside, 0.0),
        "from inside": (inside, random_directions, 0.0),
        "from the surface, tmin 1e-6": (surface, rng.normal(size=(n, 3)), 1e-6 * size),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--pairs", type=int, default=11, help="alternated calls per row")
    parser.add_argument("--sample", type=int, default=100_000, help="rays for the single-thread peers")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args()
    machine = machine_description()
    print(machine, flush=True)
    rng = np.random.default_rng(7)
    rows, others = [], []
    for label, make in SCENES.items():
        scene = vrc.Scene(make())
        points, triangles = scene.prepared.points, scene.prepared.triangles
        peer = Open3DPeer()
        peer.build(points, triangles)
        for kind, (origins, directions, tmin) in ray_sets(scene, args.rays, rng).items():
            rays = peer.prepare(origins, directions)
            # cast_rays takes no tmin: its users move the origins instead.
            moved = peer.prepare(origins + tmin * directions, directions) if tmin else rays
            ours = scene.intersect(origins, directions, tmin=tmin)
            ids = peer.collect(peer.run(moved)).ids
            agree = float(np.mean(ours["triangle_id"] == ids))
            hit_rate = float(np.mean(ours["triangle_id"] >= 0))
            cast = alternated_ratio(
                partial(scene.intersect, origins, directions, tmin=tmin), partial(peer.run, moved), args.pairs
            )
            occluded = scene.occluded(origins, directions, tmin=tmin)
            their_occlusion = peer.scene.test_occlusions(rays, tnear=tmin).numpy()
            agree_occluded = float(np.mean(occluded == their_occlusion))
            occlusion = alternated_ratio(
                partial(scene.occluded, origins, directions, tmin=tmin),
                partial(peer.scene.test_occlusions, rays, tnear=tmin),
                args.pairs,
            )
            ours_rate = args.rays / median_seconds(partial(scene.intersect, origins, directions, tmin=tmin), 5) / 1e6
            rows.append((label, kind, hit_rate, ours_rate, cast, agree, occlusion, agree_occluded))
            print(rows[-1], flush=True)
        if label.startswith("bumpy"):
            others = single_thread_peers(scene, *ray_sets(scene, args.sample, rng)["from outside"][:2])
            small = small_batches(scene, peer, rng)
    lines = [
        f"`python benchmarks/rays.py --rays {args.rays} --pairs {args.pairs}` on {machine}. "
        f"{args.rays:,} rays per set; Open3D's time over vtkraycast's, median of {args.pairs} calls timed in "
        "alternation (quartiles in brackets); agreement: the same triangle id (intersect) or the same answer "
        "(occluded) as Open3D, which rounds rays and points to float32.",
        "",
        "| scene | rays | hit | vtkraycast intersect Mrays/s | intersect vs Open3D cast_rays | ids agree "
        "| occluded vs Open3D test_occlusions | agree |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for label, kind, hit_rate, rate, cast, agree, occlusion, agree_occluded in rows:
        lines.append(
            f"| {label} | {kind} | {hit_rate:.0%} | {rate:.1f} | {cast[0]:.2f}x ({cast[1]:.2f} to {cast[2]:.2f}) "
            f"| {agree:.3%} | {occlusion[0]:.2f}x ({occlusion[1]:.2f} to {occlusion[2]:.2f}) | {agree_occluded:.3%} |"
        )
    means = [float(np.exp(np.mean(np.log([row[i][0] for row in rows])))) for i in (4, 6)]
    lines += [
        f"| **geometric mean** | | | | **{means[0]:.2f}x** | | **{means[1]:.2f}x** | |",
        "",
        "Targets (issue 27): intersect >= 1.5x Open3D's cast_rays, occluded >= 1.5x its test_occlusions.",
        "",
        f"Single-thread peers, bumpy sphere, {args.sample:,} rays from outside (separate medians of 3):",
        "",
        "| caster | threads | Mrays/s | ids agree with vtkraycast |",
        "|---|---:|---:|---:|",
    ] + [f"| {name} | {threads} | {rate:.2f} | {agree:.3%} |" for name, threads, rate, agree in others]
    lines += [
        "",
        "Small batches, bumpy sphere, rays from outside, new rays at every call: the time of one call (median of "
        f"{SMALL_PAIRS} alternated pairs; Open3D's excludes turning numpy arrays into its tensors, as above):",
        "",
        "| rays per call | vtkraycast intersect µs | Open3D cast_rays µs | Open3D's time over vtkraycast's |",
        "|---:|---:|---:|---:|",
    ] + [f"| {n:,} | {ours:.0f} | {theirs:.0f} | {ratio[0]:.2f}x ({ratio[1]:.2f} to {ratio[2]:.2f}) |"
         for n, ours, theirs, ratio in small]  # fmt: skip
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "rays.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


SMALL_PAIRS = 101


def small_batches(scene: vrc.Scene, peer: Open3DPeer, rng: np.random.Generator) -> list[tuple]:
    """(rays, our µs, Open3D's µs, alternated ratio) per call of 1 to 10,000 rays: what a
    user pays per call (picking, a few points' visibility) besides the rays themselves.
    Every call gets rays of its own, as a user's would (the same rays called again ran
    faster, on both sides: the branch predictor learns them); each caster goes through the
    same batches in the same order."""
    rows = []
    for n in (1, 100, 10_000):
        batches = [ray_sets(scene, n, rng)["from outside"][:2] for _ in range(SMALL_PAIRS)]
        ours = cycling(scene.intersect, batches)
        theirs = cycling(peer.run, [(peer.prepare(origins, directions),) for origins, directions in batches])
        ratio = alternated_ratio(ours, theirs, SMALL_PAIRS)
        rows.append((n, median_seconds(ours, SMALL_PAIRS) * 1e6, median_seconds(theirs, SMALL_PAIRS) * 1e6, ratio))
        print(rows[-1], flush=True)
    return rows


def cycling(call: Callable, batches: list[tuple]) -> Callable[[], Any]:
    """A function that calls ``call`` on the next of ``batches`` each time, round and round."""
    turns = itertools.cycle(batches)
    return lambda: call(*next(turns))


def single_thread_peers(scene: vrc.Scene, origins: np.ndarray, directions: np.ndarray) -> list[tuple]:
    ours = scene.intersect(origins, directions)["triangle_id"]
    rows = [("vtkraycast Scene.intersect", os.cpu_count(), len(origins) / median_seconds(
        partial(scene.intersect, origins, directions), 3) / 1e6, 1.0)]  # fmt: skip
    for peer in (EmbreexPeer(), LibiglPeer(), TrimeshPeer()):
        try:
            peer.build(scene.prepared.points, scene.prepared.triangles)
        except Exception as exc:  # a missing peer is reported, not fatal
            print(f"peer {peer.name} unavailable: {exc!r}", flush=True)
            continue
        prepared = peer.prepare(origins, directions)
        start = time.perf_counter()
        out = peer.run(prepared)
        seconds = median_seconds(partial(peer.run, prepared), 3) if time.perf_counter() - start < 10 else 1e9
        rows.append(
            (peer.name, peer.threads, len(origins) / seconds / 1e6, float(np.mean(peer.collect(out).ids == ours)))
        )
        print(rows[-1], flush=True)
    return rows


if __name__ == "__main__":
    main()
