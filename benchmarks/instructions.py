#!/usr/bin/env python
"""Instructions per ray, counted by valgrind's callgrind: unlike timings, the count repeats
exactly on a shared, noisy machine, so it measures small changes to the core.

    python benchmarks/instructions.py [--pixels 1024] [--arrays TriangleId] [--scene bvh|flat] [--functions 5]
    python benchmarks/instructions.py --rays 50000 [--functions 5]

The frog contour (1.5 M triangles) is written once to a temporary file; a child process
under callgrind loads it, builds the scene (not counted; ``--scene flat`` builds no BVH, as
``vrc.cast`` does) and casts once from the iso camera of benchmarks/peers.py on one thread.
Only the cast's worker threads are counted (they run ``vrc::render``; the core keeps its
symbols for this), which includes the per-camera projection and binning. Prints
instructions per ray, and with ``--functions N`` the N functions that executed the most
(callgrind_annotate's self counts: where the instructions go). With ``--rays N``, N of
benchmarks/rays.py's random rays from outside through its 20 k-triangle bumpy sphere go
through ``Scene.intersect`` (its default arrays) on one thread instead.

valgrind 3.19 cannot run AVX-512 code: on such a machine, count a build made without it
(``pip install --no-build-isolation --no-deps . --target /tmp/cg
-Ccmake.define.CMAKE_CXX_FLAGS=-mno-avx512f``, then ``PYTHONPATH=/tmp/cg python ...``).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = """
import sys
import pyvista as pv
import vtkraycast as vrc
mesh = pv.read(sys.argv[1])
n = int(sys.argv[2])
camera = vrc.Camera.framing(mesh.bounds, view="iso", nx=n, ny=n)
scene = vrc.Scene(mesh, threads=1, bvh=sys.argv[4] == "bvh")
scene.cast(camera, arrays=sys.argv[3].split(","), threads=1)
"""

CHILD_RAYS = """
import sys
import numpy as np
import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere
scene = vrc.Scene(bumpy_sphere(5), threads=1)
points = scene.prepared.points
low, high = points.min(axis=0), points.max(axis=0)
rng = np.random.default_rng(7)
n = int(sys.argv[1])
origins = (low + high) / 2 + rng.uniform(-1.5, 1.5, (n, 3)) * float((high - low).max())
scene.intersect(origins, rng.uniform(low, high, (n, 3)) - origins, threads=1)
"""


def count(child: str, arguments: list[str], workdir: Path, functions: int) -> int:
    """Instructions of the cast's worker threads when `child` runs with `arguments`."""
    out = workdir / "callgrind.out"
    command = [
        "valgrind",
        "--tool=callgrind",
        "--collect-atstart=no",
        "--toggle-collect=std::thread::_State_impl*vrc::render*",  # the cast's worker threads
        f"--callgrind-out-file={out}",
        sys.executable,
        "-c",
        child,
        *arguments,
    ]
    # run from the temporary directory, not the checkout: the installed package is measured
    run = subprocess.run(command, capture_output=True, text=True, cwd=workdir)
    if run.returncode != 0:
        sys.exit(run.stderr[-3000:])
    totals = re.search(r"^(?:summary|totals): (\d+)", out.read_text(), re.MULTILINE)
    if functions:
        annotated = subprocess.run(["callgrind_annotate", str(out)], capture_output=True, text=True).stdout
        rows = [line for line in annotated.splitlines() if re.match(r"^\s*[\d,]+ \(", line)]
        print("\n".join(row[:160] for row in rows[1 : functions + 1]))  # rows[0]: the total
    return int(totals.group(1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pixels", type=int, default=1024)
    parser.add_argument("--arrays", default="TriangleId", help="comma-separated output arrays")
    parser.add_argument(
        "--scene",
        choices=["bvh", "flat"],
        default="bvh",
        help="cast through the BVH (Scene) or bin to tiles without one (vrc.cast)",
    )
    parser.add_argument("--functions", type=int, default=0, help="also list the N costliest functions")
    parser.add_argument("--rays", type=int, default=0, help="count Scene.intersect of this many random rays instead")
    args = parser.parse_args()
    from pyvista import examples

    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        if args.rays:
            instructions = count(CHILD_RAYS, [str(args.rays)], workdir, args.functions)
            print(f"bumpy sphere (20 k triangles), {args.rays} random rays from outside, Scene.intersect: "
                  f"{instructions} instructions, {instructions / args.rays:.0f} per ray")  # fmt: skip
            return
        mesh_file = workdir / "frog.vtp"
        examples.load_frog_tissues().contour_labels().save(mesh_file)
        instructions = count(
            CHILD, [str(mesh_file), str(args.pixels), args.arrays, args.scene], workdir, args.functions
        )
    rays = args.pixels**2
    print(
        f"frog contour, {args.scene} scene, {args.pixels}x{args.pixels}, {args.arrays}: {instructions} instructions, "
        f"{instructions / rays:.0f} per ray"
    )


if __name__ == "__main__":
    main()
