#!/usr/bin/env python
"""Two or more builds of the core timed cast after cast in alternation: each round sees
the same state of a shared, noisy machine, so a change of a few percent shows in the
ratios where separate runs minutes apart cannot resolve it.

    pip install --no-build-isolation --no-deps . --target /tmp/before -Cbuild-dir=/tmp/build-before
    (change the core)
    pip install --no-build-isolation --no-deps . --target /tmp/after -Cbuild-dir=/tmp/build-after
    python benchmarks/compare_builds.py /tmp/before /tmp/after [--rounds 60] [--threads 2]
        [--scene frog|channels|terrain|bumpy|small|sphere|ant] [--view framed|close|full|lidar|rays|occluded|crossings]
        [--rays-from outside|inside|surface]
        [--flat] [--pixels 1024]
        [--arrays ids|geometry|default] [--cold]

Each directory holds an installed ``vtkraycast``. Each build runs in its own process (two
builds' extensions cannot share one: their types would clash) and builds its own scene,
so builds may lay out their scenes differently; the processes cast one at a time, in turn,
at this script's signal. Every build's image must equal the first's. Prints each build's
median and minimum time and the median and quartiles of its time over the first build's,
round by round. The frog, channels and terrain scenes and their views are benchmarks/scenes.py's
(peers.py's); the bumpy scene is a 330 k-triangle sphere filling the frame; the small one an
82 k-triangle sphere covering 1 % of it (benchmarks/skipping.py). What is timed is the whole
``Scene.cast`` a user calls, with ``--arrays``: TriangleId alone (``ids``, the default), the
default geometry (``geometry``: interpolate=False), the defaults with the mesh's arrays
(``default``), or the arrays named (``Depth,Elevation``). Builds are compared by the first
array cast. ``--view lidar`` times ``Scene.scan`` of benchmarks/sensors.py's 64 x 2048
lidar instead, comparing range images; ``--view rays`` times ``Scene.intersect`` (its
default arrays) of benchmarks/rays.py's rays from outside (500,000; ``--rays``; from inside or
from the surface with ``--rays-from``), comparing
triangle ids, ``--view occluded`` ``Scene.occluded`` of the same rays; ``--view crossings``
times ``Scene.intersect_all`` of visibility.py's random rays (origins in the mesh's box,
random directions; ``--rays``), comparing the crossings' t.
The sphere scene is rays.py's 20 k-triangle bumpy sphere, the ant pyvista's.
``--cold`` writes over 64 MB before each cast, as another caster run in between would
(peers.py's alternated pairs), so the cast finds its scene out of cache.
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np

ARRAYS = {"ids": {"arrays": ["TriangleId"]}, "geometry": {"interpolate": False}, "default": {}}
RAY_SETS = {"outside": "from outside", "inside": "from inside", "surface": "from the surface, tmin 1e-6"}


def caster(build: str, args: argparse.Namespace, pipe) -> None:
    """In a child process: builds the scene with `build`'s core, then casts once per
    message, answering with the time taken (and the image, for the first cast)."""
    sys.path.insert(0, build)
    sys.path.insert(1, str(Path(__file__).parent))
    import scenes

    import vtkraycast as vrc
    from vtkraycast.testing import bumpy_sphere

    n = args.pixels
    if args.scene in ("sphere", "ant"):
        from pyvista import examples

        mesh = bumpy_sphere(5) if args.scene == "sphere" else examples.load_ant()
    elif args.scene == "bumpy":
        mesh = bumpy_sphere(7)
        camera = vrc.Camera((2.2, 1.6, 1.2), (0, 0, 0), (0, 0, 1), view_angle=40, nx=n, ny=n)
    elif args.scene == "small":  # benchmarks/skipping.py's sphere covering 1 % of the frame
        mesh = bumpy_sphere(6)
        camera = vrc.Camera((0, 0, 2.0), (0, 0, 0), (0, 1, 0), view_angle=158.3, nx=n, ny=n)
    else:
        mesh = scenes.SCENES[args.scene]()
    scene = vrc.Scene(mesh, threads=args.threads, bvh=not args.flat)
    if args.view in ("rays", "occluded"):
        import rays

        origins, directions, tmin = rays.ray_sets(scene, args.rays, np.random.default_rng(7))[RAY_SETS[args.rays_from]]
    elif args.view == "crossings":
        rng = np.random.default_rng(0)
        points = scene.prepared.points
        origins = rng.uniform(points.min(axis=0), points.max(axis=0), (args.rays, 3))
        directions = rng.normal(size=(args.rays, 3))
    elif args.view == "lidar":
        import sensors

        camera = sensors.scene_lidar(mesh, args.scene)
    elif args.scene not in ("bumpy", "small"):
        camera = scenes.view(mesh, args.view, n, scene=args.scene)
    options = ARRAYS[args.arrays] if args.arrays in ARRAYS else {"arrays": args.arrays.split(",")}
    compared = options.get("arrays", ["TriangleId"])[0]

    def cast() -> np.ndarray:
        if args.view == "rays":
            return scene.intersect(origins, directions, tmin=tmin, threads=args.threads)["triangle_id"]
        if args.view == "occluded":
            return scene.occluded(origins, directions, tmin=tmin, threads=args.threads)
        if args.view == "crossings":
            return scene.intersect_all(origins, directions, threads=args.threads)["t"]
        if args.view == "lidar":
            return scene.scan(camera, range_image=True, threads=args.threads)[1]
        return np.asarray(scene.cast(camera, threads=args.threads, **options)[compared])

    cold = args.cold
    other = np.zeros(8 << 20) if cold else None  # 64 MB, beyond the last-level cache
    pipe.send(None)  # ready
    while pipe.recv():
        if cold:
            other += 1
        start = time.perf_counter()
        image = cast()
        pipe.send((time.perf_counter() - start, image))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("builds", nargs="+", type=Path, help="directories of `pip install --target` builds")
    parser.add_argument("--rounds", type=int, default=60)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument(
        "--scene", choices=["frog", "channels", "terrain", "bumpy", "small", "sphere", "ant"], default="frog"
    )
    parser.add_argument(
        "--view",
        choices=["framed", "close", "full", "inside", "lidar", "rays", "occluded", "crossings"],
        default="framed",
    )
    parser.add_argument("--rays", type=int, default=500_000, help="rays of --view rays, occluded and crossings")
    parser.add_argument(
        "--rays-from", choices=list(RAY_SETS), default="outside", help="rays.py's set of --view rays, occluded"
    )
    parser.add_argument("--flat", action="store_true", help="cast without a BVH, as vrc.cast does")
    parser.add_argument("--pixels", type=int, default=1024)
    parser.add_argument(
        "--arrays",
        default="ids",
        help=f"what the timed Scene.cast asks for: {', '.join(ARRAYS)} or array names, comma-separated",
    )
    parser.add_argument("--cold", action="store_true", help="write over 64 MB before each cast")
    args = parser.parse_args()
    context = multiprocessing.get_context("spawn")
    pipes, children = [], []

    def receive(k: int):
        try:
            return pipes[k].recv()
        except EOFError:
            children[k].join(5)
            for child in children:
                child.kill()
            raise SystemExit(
                f"the process of {args.builds[k]} ended (exit code {children[k].exitcode}): see above"
            ) from None

    for build in args.builds:
        ours, theirs = context.Pipe()
        child = context.Process(
            target=caster,
            args=(str(build.resolve()), args, theirs),
        )
        child.start()
        theirs.close()  # (the child's end held here too, a child that died would never be noticed)
        pipes.append(ours)
        children.append(child)
        receive(len(pipes) - 1)  # one build at a time: the scenes are not built while another casts

    def cast(k: int) -> tuple[float, np.ndarray]:
        pipes[k].send(True)
        return receive(k)

    first = [cast(k)[1] for k in range(len(pipes))]
    for k in range(len(pipes)):
        if not np.array_equal(first[k], first[0], equal_nan=True):
            sys.exit(f"{args.builds[k]} casts a different image from {args.builds[0]}")
    times = np.array([[cast(k)[0] for k in range(len(pipes))] for _ in range(args.rounds)])
    for pipe, child in zip(pipes, children):
        pipe.send(False)
        child.join()
    n = args.pixels
    what = {
        "lidar": "64 x 2048 beams, scan's arrays",
        "rays": f"{args.rays:,} rays from outside, intersect's arrays",
        "crossings": f"{args.rays:,} random rays, intersect_all",
    }.get(args.view, f"{n}x{n}, arrays: {args.arrays}")
    print(
        f"{args.scene} ({args.view}){' (flat)' if args.flat else ''}, {what}, {args.threads} threads, "
        f"{args.rounds} rounds" + (", 64 MB written over before each cast" if args.cold else "")
    )
    for k, build in enumerate(args.builds):
        ratio = times[:, k] / times[:, 0]
        q1, median, q3 = np.percentile(ratio, [25, 50, 75])
        print(
            f"{build!s:40s} median {np.median(times[:, k]) * 1e3:6.1f} ms, min {times[:, k].min() * 1e3:6.1f} ms; "
            f"time over the first's: median {median:.3f} (quartiles {q1:.3f} to {q3:.3f})"
        )


if __name__ == "__main__":
    main()
