#!/usr/bin/env python
"""vtkraycast against the ray casters users would otherwise pick, on the same camera rays,
in one run: build (preparation) and cast timed separately, medians of repeats, Mrays/s, the
ratio to vtkraycast, agreement of triangle ids, memory per triangle (resident growth over
the build).

    python benchmarks/peers.py [--pixels 1024] [--repeats 5] [--out benchmarks/results]

The scene is the frog contour (pyvista's frog_tissues.vti, contour_labels(), 1.5 M
triangles) from a perspective camera that frames it. Writes ``peers.md``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from pyvista import examples

import vtkraycast as vrc
from vtkraycast.testing import camera_rays

sys.path.insert(0, str(Path(__file__).parent))
from peer_casters import make_peers, more_peers


def resident() -> int:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pixels", type=int, default=1024)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--sample", type=int, default=2000, help="rays for the per-ray Python loops")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args()
    machine = f"{platform.platform()}, {os.cpu_count()} cores"
    print(machine, flush=True)
    mesh = examples.load_frog_tissues().contour_labels()
    n = args.pixels
    cam = vrc.Camera.framing(mesh.bounds, view="iso", nx=n, ny=n)
    rays = n * n

    before = resident()
    start = time.perf_counter()
    scene = vrc.Scene(mesh)
    build = time.perf_counter() - start
    first_start = time.perf_counter()
    image = scene.cast(cam, arrays=["TriangleId"])
    first = time.perf_counter() - first_start
    grown = resident() - before
    times = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        image = scene.cast(cam, arrays=["TriangleId"])
        times.append(time.perf_counter() - start)
    ours = float(np.median(times))
    ids = np.asarray(image["TriangleId"])
    rows = [
        (
            "vtkraycast (auto, float64)",
            os.cpu_count(),
            build,
            build + first,
            ours,
            1.0,
            1.0,
            scene.memory_bytes / scene.n_triangles,
            grown / scene.n_triangles,
        )
    ]
    print(rows[-1], flush=True)

    origins, directions = camera_rays(cam)
    points, triangles = scene.prepared.points, scene.prepared.triangles
    rng = np.random.default_rng(1)
    sample = np.sort(rng.choice(rays, size=min(rays, args.sample), replace=False))
    for peer in make_peers() + more_peers():
        chosen = sample if getattr(peer, "sampled", False) else np.arange(rays)
        before = resident()
        start = time.perf_counter()
        peer.build(points, triangles)
        peer_build = time.perf_counter() - start
        grown = resident() - before
        prepared = peer.prepare(origins[chosen], directions[chosen])
        start = time.perf_counter()
        out = peer.run(prepared)
        peer_first = time.perf_counter() - start
        repeats = args.repeats if peer_first < 20 else 1
        times = [peer_first]
        for _ in range(repeats - 1):
            start = time.perf_counter()
            out = peer.run(prepared)
            times.append(time.perf_counter() - start)
        theirs = float(np.median(times))
        agree = float(np.mean(peer.collect(out).ids == ids[chosen]))
        scale = rays / len(chosen)  # a sampled peer's times, scaled to the whole image
        label = peer.name + ("" if len(chosen) == rays else f" [{len(chosen)} rays sampled]")
        cast = theirs * scale
        rows.append(
            (
                label,
                peer.threads,
                peer_build,
                peer_build + peer_first * scale,
                cast,
                ours / cast,
                agree,
                float("nan"),
                grown / scene.n_triangles,
            )
        )
        print(rows[-1], flush=True)

    lines = [
        f"`python benchmarks/peers.py --pixels {n}` on {machine}: frog contour "
        f"({scene.n_triangles:,} triangles), {n}x{n} camera rays, medians of {args.repeats}.",
        "",
        "| caster | threads | build s | first image s | cast s | Mrays/s | cast time vs vtkraycast "
        "| TriangleId agreement | structure bytes/triangle | resident growth bytes/triangle |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, threads, b, f, c, ratio, agree, mem, grown in rows:
        mem_text = "-" if np.isnan(mem) else f"{mem:.1f}"
        lines.append(
            f"| {name} | {threads} | {b:.3f} | {f:.3f} | {c:.4f} | {rays / c / 1e6:.2f} | {1 / ratio:.2f}x "
            f"| {agree:.4%} | {mem_text} | {grown:.0f} |"
        )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "peers.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
