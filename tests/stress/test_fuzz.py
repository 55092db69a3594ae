"""Fuzzing the Python entry points with hypothesis: any input gives a result or a clear
ValueError / TypeError (MemoryError for absurd image sizes), never a crash, a hang or another
exception. The number of inputs tried is printed (run with -s)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import pyvista as pv
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import vtkraycast as vrc

ALLOWED = (ValueError, TypeError, MemoryError)
TRIED = {"camera": 0, "cast": 0, "intersect": 0, "mesh": 0}
# Derandomized: CI sees the same inputs every run (explore more with --hypothesis-seed).
FUZZ = settings(max_examples=400, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)

weird_float = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-320, 1e308, -1e308, 1.0, 30.0, 179.999]),
)
weird_number = st.one_of(weird_float, st.integers(-(2**40), 2**40), st.booleans(), st.none(), st.text(max_size=3))
weird_vector = st.one_of(
    st.tuples(weird_float, weird_float, weird_float),
    st.lists(weird_float, max_size=5),
    st.just("abc"),
    st.none(),
)


@pytest.fixture(scope="module")
def scene():
    return vrc.Scene(pv.Sphere(theta_resolution=12, phi_resolution=12))


@pytest.fixture(scope="module", autouse=True)
def report():
    yield
    print("\nfuzzed inputs:", TRIED, "total", sum(TRIED.values()))


@FUZZ
@given(
    eye=weird_vector,
    look_at=weird_vector,
    up=weird_vector,
    kwargs=st.dictionaries(
        st.sampled_from(["d", "w", "h", "nx", "ny", "view_angle", "parallel", "near", "far"]), weird_number, max_size=5
    ),
)
def test_camera(eye, look_at, up, kwargs):
    TRIED["camera"] += 1
    try:
        cam = vrc.Camera(eye, look_at, up, **kwargs)
    except ALLOWED:
        return
    assert cam.nx >= 1 and cam.ny >= 1 and cam.w > 0 and cam.h > 0 and cam.d > 0
    assert np.isfinite(cam.frame).all()


@FUZZ
@given(
    nx=st.integers(-3, 40),
    ny=st.integers(-3, 40),
    options=st.dictionaries(
        st.sampled_from(["arrays", "strategy", "precision", "accel", "threads", "backface_culling", "interpolate"]),
        st.one_of(
            weird_number,
            st.sampled_from(["auto", "plane", "float32", "none", "bvh", "Depth", "Normals"]),
            st.lists(st.sampled_from(["Depth", "TriangleId", "Normals", "nope", 3]), max_size=3),
        ),
        max_size=4,
    ),
)
def test_cast(scene, nx, ny, options):
    TRIED["cast"] += 1
    try:
        cam = vrc.Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), nx=nx, ny=ny)
        image = scene.cast(cam, **options)
    except ALLOWED:
        return
    assert image.dimensions == (nx, ny, 1)


@FUZZ
@given(
    origins=st.one_of(
        st.lists(st.lists(weird_float, min_size=3, max_size=3), max_size=4),
        st.lists(weird_float, max_size=4),
        st.just([[0, 0, 3]]),
        st.just(np.zeros((2, 3), np.float32)),
        st.just(np.array([["a", "b", "c"]])),
    ),
    directions=st.one_of(
        st.lists(st.lists(weird_float, min_size=3, max_size=3), max_size=4),
        st.just([[0, 0, -1]]),
        st.just(np.zeros((1, 3))),
    ),
    tmin=weird_float,
    tmax=weird_float,
)
def test_intersect(scene, origins, directions, tmin, tmax):
    TRIED["intersect"] += 1
    try:
        hits = scene.intersect(origins, directions, tmin=tmin, tmax=tmax)
    except ALLOWED:
        return
    hit = hits["triangle_id"] >= 0
    assert np.isfinite(hits["t"][hit]).all() and (hits["t"][hit] >= tmin).all()
    assert math.isnan(tmax) is False


@FUZZ
@given(
    points=st.lists(st.tuples(weird_float, weird_float, weird_float), min_size=0, max_size=6),
    faces=st.lists(st.integers(-2, 8), max_size=12),
)
def test_meshes(points, faces):
    TRIED["mesh"] += 1
    try:
        mesh = pv.PolyData(np.array(points, float).reshape(-1, 3))
        if faces:
            mesh.faces = np.array(faces)
    except Exception:
        return
    try:
        image = vrc.cast(mesh, vrc.Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), nx=8, ny=8))
    except ALLOWED:
        return
    assert image.n_points == 64
