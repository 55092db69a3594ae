#!/usr/bin/env python
"""vtkraycast against Open3D's ``RaycastingScene.cast_rays`` (Embree inside) on what users
call: three scenes, three views each from mostly empty to full frame, the same camera rays,
each of our casts timed in alternation with Open3D's in one run.

    python benchmarks/peers.py [--pixels 1024] [--pairs 15] [--out benchmarks/results]

Rows per view: the defaults (``Scene.cast(camera)``: TriangleId, CellId, Barycentric, Depth,
the valid mask and the mesh's arrays), the default geometry (``interpolate=False``: the mesh's
arrays left out) and TriangleId alone. Open3D returns t, ids, uvs and normals in every cast.
Also: the first image (one-shot ``vrc.cast`` against Open3D's build and first cast), bytes per
triangle, and every other peer on the frog's framed view. Writes ``peers.md`` and ``peers.png``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

import vtkraycast as vrc
from vtkraycast.testing import camera_rays

sys.path.insert(0, str(Path(__file__).parent))
import scenes
from peer_casters import Open3DPeer, make_peers, more_peers
from timing import alternated_ratio, machine_description, median_seconds

ROWS = {  # label -> Scene.cast options
    "default arrays, mesh's arrays included": {},
    "default geometry (interpolate=False)": {"interpolate": False},
    "TriangleId alone": {"arrays": ["TriangleId"]},
}
TARGETS = {"default arrays, mesh's arrays included": 3.0, "TriangleId alone": 4.0}


def geometric_mean(values) -> float:
    return float(np.exp(np.mean(np.log(values))))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pixels", type=int, default=1024)
    parser.add_argument("--pairs", type=int, default=15, help="alternated casts per row and view")
    parser.add_argument("--sample", type=int, default=2000, help="rays for the per-ray Python peers")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args()
    machine = machine_description()
    print(machine, flush=True)
    n = args.pixels
    ratios: dict[tuple[str, str, str], tuple[float, float, float]] = {}
    coverage, first, memory, sizes = {}, {}, {}, {}
    for name, make in scenes.SCENES.items():
        mesh = make()
        scene = vrc.Scene(mesh)
        peer = Open3DPeer()
        peer.build(scene.prepared.points, scene.prepared.triangles)
        sizes[name] = scene.n_triangles
        for view in scenes.VIEWS:
            camera = scenes.view(mesh, view, n, scene=name)
            rays = peer.prepare(*camera_rays(camera))
            ids = np.asarray(scene.cast(camera, arrays=["TriangleId"])["TriangleId"])
            coverage[name, view] = float(np.mean(ids >= 0))
            agree = float(np.mean(peer.collect(peer.run(rays)).ids == ids))
            for label, options in ROWS.items():
                ratios[name, view, label] = alternated_ratio(
                    partial(scene.cast, camera, **options), partial(peer.run, rays), args.pairs
                )
                print(name, view, label, f"{ratios[name, view, label][0]:.2f}x", f"ids agree {agree:.4%}", flush=True)
        camera = scenes.view(mesh, "close", n)
        rays = peer.prepare(*camera_rays(camera))
        first[name] = alternated_ratio(partial(vrc.cast, mesh, camera), partial(build_and_cast, peer, scene, rays), 5)
        memory[name] = scene.memory_bytes / scene.n_triangles  # after casts: with the memory they keep
        print(name, "first image", f"{1 / first[name][0]:.3f}x", f"{memory[name]:.1f} bytes/triangle", flush=True)

    lines = [
        f"`python benchmarks/peers.py --pixels {n} --pairs {args.pairs}` on {machine}. "
        f"{n}x{n} camera rays; each cell is Open3D's cast time over vtkraycast's (its throughput "
        f"ratio), the median of {args.pairs} casts timed in alternation with Open3D's (quartiles in brackets).",
        "",
        "| scene, view (frame covered) | " + " | ".join(ROWS) + " |",
        "|---|" + "---:|" * len(ROWS),
    ]
    for name, view in coverage:
        cells = [f"{m:.2f}x ({q1:.2f} to {q3:.2f})" for m, q1, q3 in (ratios[name, view, label] for label in ROWS)]
        lines.append(
            f"| {name} ({sizes[name] / 1e6:.1f} M triangles), {view} ({coverage[name, view]:.0%}) | "
            + " | ".join(cells)
            + " |"
        )
    means = {label: geometric_mean([ratios[key + (label,)][0] for key in coverage]) for label in ROWS}
    lines.append("| **geometric mean** | " + " | ".join(f"**{means[label]:.2f}x**" for label in ROWS) + " |")
    first_mean = geometric_mean([1 / first[name][0] for name in first])
    lines += [
        "",
        "Targets (issue 25): "
        + "; ".join(f"{label} {means[label]:.2f}x (target >= {target:g}x)" for label, target in TARGETS.items())
        + f"; first image (one-shot `vrc.cast`, default arrays, close view) {first_mean:.3f}x "
        "Open3D's build and first cast "
        f"(target <= 0.25x; per scene "
        + ", ".join(f"{name} {1 / first[name][0]:.3f}x" for name in first)
        + "); bytes per triangle "
        + ", ".join(f"{name} {memory[name]:.1f}" for name in memory)
        + " (target <= 80).",
    ]
    lines += [""] + all_peers(n, args.sample)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "peers.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    plot(ratios, coverage, machine, args.out / "peers.png")


def build_and_cast(peer: Open3DPeer, scene: vrc.Scene, rays) -> None:
    """Open3D's first image: its scene built, then one cast."""
    peer.build(scene.prepared.points, scene.prepared.triangles)
    peer.run(rays)


def all_peers(n: int, sample: int) -> list[str]:
    """Every peer on the frog's framed view, TriangleId: build, first image, cast, agreement
    (separate medians of 5; per-ray Python peers on a sample of rays, scaled)."""
    mesh = scenes.frog()
    camera = scenes.view(mesh, "framed", n)
    scene = vrc.Scene(mesh)
    median_of = partial(median_seconds, repeats=5)
    ids = np.asarray(scene.cast(camera, arrays=["TriangleId"])["TriangleId"])
    rows = [
        ("vtkraycast Scene (BVH)", os.cpu_count(), median_of(lambda: vrc.Scene(mesh)),
         median_of(lambda: vrc.Scene(mesh).cast(camera, arrays=["TriangleId"])),
         median_of(lambda: scene.cast(camera, arrays=["TriangleId"])), 1.0),
        ("vtkraycast vrc.cast (one shot, no BVH)", os.cpu_count(), float("nan"),
         median_of(lambda: vrc.cast(mesh, camera, arrays=["TriangleId"])), float("nan"), 1.0),
    ]  # fmt: skip
    origins, directions = camera_rays(camera)
    points, triangles = scene.prepared.points, scene.prepared.triangles
    chosen_sample = np.sort(np.random.default_rng(1).choice(ids.size, size=min(ids.size, sample), replace=False))
    for peer in make_peers() + more_peers():
        chosen = chosen_sample if getattr(peer, "sampled", False) else np.arange(ids.size)
        start = time.perf_counter()
        peer.build(points, triangles)
        build = time.perf_counter() - start
        prepared = peer.prepare(origins[chosen], directions[chosen])
        start = time.perf_counter()
        out = peer.run(prepared)
        once = time.perf_counter() - start
        cast = median_of(partial(peer.run, prepared)) if once < 20 else once
        scale = ids.size / len(chosen)
        label = peer.name + ("" if len(chosen) == ids.size else f" [{len(chosen)} rays sampled]")
        rows.append(
            (
                label,
                peer.threads,
                build,
                build + once * scale,
                cast * scale,
                float(np.mean(peer.collect(out).ids == ids[chosen])),
            )
        )
        print(rows[-1], flush=True)
    lines = [
        f"Every peer, frog contour ({scene.n_triangles:,} triangles), framed view, TriangleId, "
        "separate medians of 5 (not alternated):",
        "",
        "| caster | threads | build s | first image s | cast s | Mrays/s | TriangleId agreement |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, threads, build, first, cast, agree in rows:
        text = [("-" if np.isnan(v) else f"{v:.3f}") for v in (build, first, cast)]
        rate = "-" if np.isnan(cast) else f"{ids.size / cast / 1e6:.2f}"
        lines.append(f"| {name} | {threads} | {' | '.join(text)} | {rate} | {agree:.4%} |")
    return lines


def plot(ratios, coverage, machine: str, path: Path) -> None:
    """One group of bars per scene and view, one bar per row, the targets as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = list(coverage)
    fig, ax = plt.subplots(figsize=(11, 4))
    x = np.arange(len(keys))
    width = 0.8 / len(ROWS)
    for i, label in enumerate(ROWS):
        ax.bar(x + i * width, [ratios[key + (label,)][0] for key in keys], width, label=label)
    for target in TARGETS.values():
        ax.axhline(target, ls="--", lw=0.8, color="gray")
    ax.axhline(1.0, lw=0.8, color="black")
    ax.set_xticks(x + width, [f"{name}\n{view} ({coverage[name, view]:.0%})" for name, view in keys], fontsize=8)
    ax.set_ylabel("Open3D's cast time / vtkraycast's")
    ax.legend(fontsize=8)
    ax.set_title(f"alternated casts, 1024x1024; {machine}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
