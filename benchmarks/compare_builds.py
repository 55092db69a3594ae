#!/usr/bin/env python
"""Two or more builds of the core timed in one process, cast after cast in alternation:
each round sees the same state of a shared, noisy machine, so a change of a few percent
shows in the ratios where separate runs minutes apart cannot resolve it.

    pip install --no-build-isolation --no-deps . --target /tmp/before -Cbuild-dir=/tmp/build-before
    (change the core)
    pip install --no-build-isolation --no-deps . --target /tmp/after -Cbuild-dir=/tmp/build-after
    python benchmarks/compare_builds.py /tmp/before /tmp/after [--rounds 60] [--threads 2]
        [--scene frog|bumpy] [--flat] [--pixels 1024]

Each directory holds an installed ``vtkraycast``. The first one is imported as usual; the
others' ``_core`` extensions are loaded beside it and cast the first one's scene (so the
scene's C++ layout must be the same in every build; nanobind warns that the type is
registered twice). Every build's image must equal the first's. Prints each build's median
and minimum time and the median and quartiles of its time over the first build's, round
by round. The frog scene is the contour of benchmarks/peers.py from its iso camera; the
bumpy scene is a 330 k-triangle sphere filling the frame; the small one an 82 k-triangle
sphere covering 1 % of it (benchmarks/skipping.py).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
import warnings
from pathlib import Path

import numpy as np


def load_core(directory: Path):
    """The ``_core`` extension installed under ``directory``, loaded as a separate module."""
    (path,) = (directory / "vtkraycast").glob("_core*.so")
    spec = importlib.util.spec_from_file_location("_core", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("builds", nargs="+", type=Path, help="directories of `pip install --target` builds")
    parser.add_argument("--rounds", type=int, default=60)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--scene", choices=["frog", "bumpy", "small"], default="frog")
    parser.add_argument("--flat", action="store_true", help="cast without a BVH, as vrc.cast does")
    parser.add_argument("--pixels", type=int, default=1024)
    args = parser.parse_args()
    first = args.builds[0].resolve()
    sys.path.insert(0, str(first))
    import vtkraycast as vrc  # the first build's
    from vtkraycast.mesh import prepare_mesh

    warnings.simplefilter("ignore", RuntimeWarning)  # nanobind: type registered twice
    cores = [vrc._core] + [load_core(b.resolve()) for b in args.builds[1:]]
    n = args.pixels
    if args.scene == "frog":
        from pyvista import examples

        mesh = examples.load_frog_tissues().contour_labels()
        camera = vrc.Camera.framing(mesh.bounds, view="iso", nx=n, ny=n)
    elif args.scene == "bumpy":
        from vtkraycast.testing import bumpy_sphere

        mesh = bumpy_sphere(7)
        camera = vrc.Camera((2.2, 1.6, 1.2), (0, 0, 0), (0, 0, 1), view_angle=40, nx=n, ny=n)
    else:  # benchmarks/skipping.py's sphere covering 1 % of the frame
        from vtkraycast.testing import bumpy_sphere

        mesh = bumpy_sphere(6)
        camera = vrc.Camera((0, 0, 2.0), (0, 0, 0), (0, 1, 0), view_angle=158.3, nx=n, ny=n)
    mesh = prepare_mesh(mesh)  # the triangulated points and triangles a Scene casts
    scene = cores[0].Scene(mesh.points, mesh.triangles, args.threads, not args.flat)
    images = [np.empty(n * n, np.int64) for _ in cores]

    def cast(k: int) -> float:
        start = time.perf_counter()
        c = camera
        cores[k].cast_camera(scene, c.frame, c.d, c.w, c.h, c.near, c.far, c.nx, c.ny, c.parallel, "auto", "bvh",
                             False, images[k], None, None, args.threads, None)  # fmt: skip
        return time.perf_counter() - start

    for k in range(len(cores)):
        cast(k)
        if not np.array_equal(images[k], images[0]):
            sys.exit(f"{args.builds[k]} casts a different image from {args.builds[0]}")
    times = np.array([[cast(k) for k in range(len(cores))] for _ in range(args.rounds)])
    print(f"{args.scene}{' (flat)' if args.flat else ''}, {n}x{n}, {args.threads} threads, {args.rounds} rounds")
    for k, build in enumerate(args.builds):
        ratio = times[:, k] / times[:, 0]
        q1, median, q3 = np.percentile(ratio, [25, 50, 75])
        print(
            f"{build!s:40s} median {np.median(times[:, k]) * 1e3:6.1f} ms, min {times[:, k].min() * 1e3:6.1f} ms; "
            f"time over the first's: median {median:.3f} (quartiles {q1:.3f} to {q3:.3f})"
        )


if __name__ == "__main__":
    main()
