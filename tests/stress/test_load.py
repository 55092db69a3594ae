"""Load and faults: many Python threads casting through one Scene, aborted casts, and
memory that stays flat over hundreds of casts."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc


@pytest.fixture(scope="module")
def scene():
    return vrc.Scene(pv.examples.load_nut())


def cameras(n: int) -> list[vrc.Camera]:
    mesh_bounds = pv.examples.load_nut().bounds
    views = ["iso", "+x", "-x", "+y", "-y", "+z", "-z", "xz"]
    return [vrc.Camera.framing(mesh_bounds, view=views[k % len(views)], nx=96 + k, ny=64) for k in range(n)]


def test_casts_from_many_threads_on_one_scene_are_identical(scene):
    cams = cameras(12)
    expected = [scene.cast(c, arrays=["TriangleId", "Depth"], threads=1) for c in cams]
    with ThreadPoolExecutor(max_workers=8) as pool:
        for _ in range(3):
            results = list(pool.map(lambda c: scene.cast(c, arrays=["TriangleId", "Depth"]), cams))
            for got, want in zip(results, expected):
                np.testing.assert_array_equal(got["TriangleId"], want["TriangleId"])
                np.testing.assert_array_equal(got["Depth"], want["Depth"])


def test_an_aborted_cast_leaves_the_scene_usable(scene):
    cam = cameras(1)[0].replace(nx=1500, ny=1500)
    with pytest.raises(InterruptedError):
        scene.cast(cam, arrays=["TriangleId"], progress=lambda done, total: False, threads=1)
    small = cam.replace(nx=96, ny=64)
    np.testing.assert_array_equal(
        scene.cast(small, arrays=["TriangleId"])["TriangleId"], vrc.cast(pv.examples.load_nut(), small)["TriangleId"]
    )


def resident_bytes() -> int:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.skipif(not os.path.exists("/proc/self/statm"), reason="needs Linux /proc")
def test_memory_stays_flat_over_hundreds_of_casts(scene):
    """300 casts (and 60 scene builds) after a warm-up: resident memory grows by less than
    one cast's worth of output, so nothing leaks per cast or per build."""
    cam = cameras(1)[0].replace(nx=256, ny=256)
    mesh = pv.examples.load_nut()
    for _ in range(20):
        scene.cast(cam)
        vrc.Scene(mesh)
    before = resident_bytes()
    samples = []
    for k in range(300):
        scene.cast(cam)
        if k % 5 == 0:
            vrc.Scene(mesh)
        if k % 50 == 0:
            samples.append(resident_bytes())
    growth = resident_bytes() - before
    print("resident MB every 50 casts:", [round(s / 2**20, 1) for s in samples], "growth", growth / 2**20)
    assert growth < 8 * 2**20


def test_a_mesh_modified_during_casts_changes_nothing_already_built():
    """The Scene owns a copy of the mesh: another thread rewriting the mesh's points while
    casts run cannot change their results (nor crash them); a new Scene sees the change."""
    import threading

    mesh = pv.Sphere(theta_resolution=60, phi_resolution=60)
    scene = vrc.Scene(mesh)
    cam = vrc.Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), nx=120, ny=90)
    expected = scene.cast(cam, arrays=["TriangleId", "Depth"])
    stop = threading.Event()

    def scribble():
        rng = np.random.default_rng(0)
        while not stop.is_set():
            mesh.points[:] = rng.normal(size=mesh.points.shape)

    writer = threading.Thread(target=scribble)
    writer.start()
    try:
        for _ in range(20):
            got = scene.cast(cam, arrays=["TriangleId", "Depth"])
            np.testing.assert_array_equal(got["TriangleId"], expected["TriangleId"])
            np.testing.assert_array_equal(got["Depth"], expected["Depth"])
        vrc.Scene(mesh)  # building from a mesh being rewritten: some snapshot, no crash
    finally:
        stop.set()
        writer.join()
