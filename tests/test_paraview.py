"""The ParaView plugin (filters/vtkraycast_paraview.py) inside real ParaView.

vtkraycast is installed for ParaView's Python the way docs/paraview.md
says (``pip install --no-deps --target DIR .``, ``usercustomize.py`` beside it,
``PYTHONPATH=DIR``); ``pvbatch`` then runs tests/paraview/raycast_pvbatch.py, which loads
the plugin with ``LoadPlugin(path, ns=globals())`` and applies ``RayCast`` to a ParaView
source and to files this test wrote. Here, in the project's own environment, the same
meshes are cast by ``vrc.cast`` with the same camera and options, and the arrays compared:
integer arrays exactly, floating ones to their precision.

Skipped when ParaView's ``pvbatch`` is not installed (``.ci/run`` installs Debian's
``paraview``). The install for ParaView's Python is cached in pytest's cache directory,
keyed by the package's sources, so only the first run after a change compiles the core.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc

ROOT = Path(__file__).resolve().parent.parent
PLUGIN = ROOT / "filters" / "vtkraycast_paraview.py"
STARTUP_HOOK = ROOT / "filters" / "paraview_usercustomize.py"
SCRIPT = Path(__file__).resolve().parent / "paraview" / "raycast_pvbatch.py"
PVBATCH = shutil.which("pvbatch")

pytestmark = pytest.mark.skipif(
    PVBATCH is None, reason="ParaView's pvbatch is not installed (apt-get install paraview; .ci/run does)"
)


def _clean_env() -> dict[str, str]:
    """The environment without what would point ParaView's Python at this project's venv."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONHOME", "PYTHONPATH", "PYTHONNOUSERSITE")}
    env.pop("VIRTUAL_ENV", None)
    return env


def _paraview_python_version() -> tuple[int, int]:
    probe = "import sys; print('%d.%d' % sys.version_info[:2])"
    done = subprocess.run(
        [PVBATCH, "-c", probe], capture_output=True, text=True, timeout=120, env=_clean_env(), check=False
    )
    for line in done.stdout.splitlines():
        if line.count(".") == 1 and line.replace(".", "").isdigit():
            major, minor = line.split(".")
            return int(major), int(minor)
    raise AssertionError(f"could not read ParaView's Python version:\n{done.stdout}\n{done.stderr}")


def _sources_digest(python: str) -> str:
    digest = hashlib.sha256(python.encode())
    files = [ROOT / "pyproject.toml", ROOT / "CMakeLists.txt"]
    files += sorted(p for d in ("src", "vtkraycast") for p in (ROOT / d).rglob("*") if p.is_file())
    for path in files:
        if "__pycache__" in path.parts:
            continue
        digest.update(str(path.relative_to(ROOT)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


@pytest.fixture(scope="module")
def paraview_path(request, tmp_path_factory) -> Path:
    """A directory holding vtkraycast built for ParaView's Python, as the README installs it."""
    version = _paraview_python_version()
    if sys.version_info[:2] == version:
        python = sys.executable
    else:
        python = shutil.which(f"python{version[0]}.{version[1]}")
        assert python, f"ParaView uses Python {version}: a python{version[0]}.{version[1]} is needed to build for it"
    cache_provider = getattr(request.config, "cache", None)  # None with -p no:cacheprovider
    if cache_provider is None:
        cache = tmp_path_factory.mktemp("vtkraycast-paraview")
    else:
        cache = Path(cache_provider.mkdir("vtkraycast-paraview"))
    target = cache / _sources_digest(python)
    if not (target / "vtkraycast").is_dir():
        partial = cache / f"partial-{os.getpid()}"
        shutil.rmtree(partial, ignore_errors=True)
        command = [python, "-m", "pip", "install", "--no-deps", "--target", str(partial / "site"), str(ROOT)]
        # The README's command; without build isolation when the build back end is at hand
        # (faster, offline), and never in the checkout's build/ (other builds use it).
        if python == sys.executable and all(importlib.util.find_spec(m) for m in ("scikit_build_core", "nanobind")):
            command.append("--no-build-isolation")
        command += ["--config-settings", f"build-dir={partial / 'build'}"]
        done = subprocess.run(command, capture_output=True, text=True, timeout=1200, check=False)
        assert done.returncode == 0, f"{' '.join(command)}\n{done.stdout}\n{done.stderr}"
        try:
            (partial / "site").rename(target)
        except OSError:  # a concurrent run installed the same sources first
            pass
        shutil.rmtree(partial, ignore_errors=True)
        # Keep the newest few installs: a concurrent run may be using one of them.
        installs = sorted(
            (p for p in cache.iterdir() if not p.name.startswith("partial-")), key=lambda p: p.stat().st_mtime
        )
        for old in installs[:-3]:
            shutil.rmtree(old, ignore_errors=True)
    shutil.copy(STARTUP_HOOK, target / "usercustomize.py")  # the README's second step
    return target


# -- the plan: inputs, camera and options; the pvbatch script and the references share it --

SPHERE_CAMERA = {
    "CameraPosition": [0.9, 1.3, 2.6],
    "CameraFocalPoint": [0.05, -0.1, 0.0],
    "CameraViewUp": [0.0, 1.0, 0.0],
    "CameraViewAngle": 35.0,
    "Resolution": [96, 72],
}
MOVED = {"CameraPosition": [-1.4, 0.6, 2.2], "CameraViewUp": [0.1, 1.0, 0.0], "CameraViewAngle": 28.0}
TORUS_CAMERA = {
    "CameraPosition": [0.7, -2.9, 2.1],
    "CameraFocalPoint": [0.02, 0.03, -0.01],
    "CameraViewUp": [0.0, 0.0, 1.0],
    "CameraViewAngle": 40.0,
    "Resolution": [80, 60],
}


def _torus(path: Path) -> None:
    """Triangles, half of them facing inwards, with float, integer and vector point arrays
    and integer and float cell arrays."""
    mesh = pv.ParametricTorus(ringradius=1.0, crosssectionradius=0.35, u_res=40, v_res=20).triangulate().clean()
    faces = mesh.faces.reshape(-1, 4).copy()
    faces[1::2, 1:3] = faces[1::2, 2:0:-1]  # every other triangle turned over: culling shows
    mesh.faces = faces.ravel()
    points = mesh.points
    mesh.point_data.clear()
    mesh.cell_data.clear()
    mesh.point_data["Temperature"] = np.hypot(points[:, 0], points[:, 1]) + points[:, 2] ** 2
    mesh.point_data["Velocity"] = np.column_stack((-points[:, 1], points[:, 0], points[:, 2])).astype(np.float32)
    mesh.point_data["Label"] = (np.arange(mesh.n_points) % 7).astype(np.int32)
    mesh.cell_data["Material"] = (np.arange(mesh.n_cells) // 50).astype(np.int32)
    mesh.cell_data["Pressure"] = np.linspace(-1.0, 1.0, mesh.n_cells)
    mesh.save(path)


def _block(path: Path) -> None:
    """An unstructured grid of hexahedra (not polygonal: the caster uses its surface)."""
    grid = pv.ImageData(dimensions=(5, 4, 3), spacing=(0.5, 0.6, 0.7), origin=(-1.0, -1.1, -0.7))
    grid = grid.cast_to_unstructured_grid()
    grid.point_data["Height"] = grid.points[:, 2].copy()
    grid.cell_data["Block"] = np.arange(grid.n_cells, dtype=np.int32)
    grid.save(path)


def _ball(path: Path) -> None:
    """A sphere inside the torus's hole, sharing the torus's Temperature, with a cell
    array of its own: the composite case's second block."""
    mesh = pv.Sphere(radius=0.45, center=(0.1, 0.0, 0.05), theta_resolution=20, phi_resolution=14)
    mesh.point_data.clear()
    mesh.point_data["Temperature"] = mesh.points[:, 2] * 3.0
    mesh.cell_data["Patch"] = (np.arange(mesh.n_cells) % 5).astype(np.int32)
    mesh.save(path)


def _plan(tmp: Path) -> dict:
    _torus(tmp / "torus.vtp")
    _ball(tmp / "ball.vtp")
    _block(tmp / "block.vtu")
    torus = str(tmp / "torus.vtp")
    return {
        "plugin": str(PLUGIN),
        "out": str(tmp),
        "sphere": {
            "source": {"Center": [0.1, -0.2, 0.05], "Radius": 0.8, "ThetaResolution": 24, "PhiResolution": 18},
            "cast": SPHERE_CAMERA,
            "moved": MOVED,
        },
        "files": {
            "torus_default": {"path": torus, "cast": TORUS_CAMERA},
            "torus_options": {
                "path": torus,
                "cast": {
                    **TORUS_CAMERA,
                    "Strategy": "moller-trumbore",
                    "Precision": "float32",
                    "BackfaceCulling": 1,
                    "Arrays": ["Depth", "TriangleId", "Barycentric", "Position", "Normal", "Label", "Pressure"],
                },
            },
            "torus_parallel": {
                "path": torus,
                "cast": {
                    **TORUS_CAMERA,
                    "ParallelProjection": 1,
                    "ParallelScale": 1.2,
                    "Strategy": "cramer",
                    "Interpolate": 0,
                    "WorldSpace": 1,
                },
            },
            "block": {"path": str(tmp / "block.vtu"), "cast": {**TORUS_CAMERA, "Strategy": "plane"}},
        },
        "composite": {"paths": [torus, str(tmp / "ball.vtp")], "cast": TORUS_CAMERA},
        "errors": {
            "path": torus,
            "cast": {**TORUS_CAMERA, "Resolution": [16, 12]},
            "bad": [
                ["Resolution", [0, 12]],
                ["Strategy", "bogus"],
                ["Precision", "float16"],
                ["Arrays", ["Nope"]],
                ["CameraFocalPoint", TORUS_CAMERA["CameraPosition"]],
                ["CameraViewAngle", 180.0],
            ],
        },
    }


def _reference(mesh, properties: dict):
    """vrc.cast of ``mesh`` with the camera and options the plugin's properties describe."""
    nx, ny = properties["Resolution"]
    eye, focal = properties["CameraPosition"], properties["CameraFocalPoint"]
    up = properties["CameraViewUp"]
    d = math.dist(eye, focal)
    if properties.get("ParallelProjection", 0):
        camera = vrc.Camera(eye, focal, up, d=d, h=2.0 * properties["ParallelScale"], nx=nx, ny=ny, parallel=True)
    else:
        camera = vrc.Camera(eye, focal, up, d=d, view_angle=properties.get("CameraViewAngle", 30.0), nx=nx, ny=ny)
    return vrc.cast(
        mesh,
        camera,
        arrays=properties.get("Arrays") or None,
        strategy=properties.get("Strategy", "auto"),
        precision=properties.get("Precision", "float64"),
        interpolate=bool(properties.get("Interpolate", 1)),
        backface_culling=bool(properties.get("BackfaceCulling", 0)),
        world_space=bool(properties.get("WorldSpace", 0)),
    )


def _assert_same_image(got, expected, placement: dict, case: str, *, surface: bool = False) -> None:
    """Same arrays as ``expected``. ``surface``: a non-polygonal input, whose surface VTK 9.2
    (ParaView 5.11) and the project's VTK extract with the same triangles but faces starting
    at different points, so Barycentric matches as the set of the three weights."""
    assert got.dimensions == expected.dimensions, case
    assert list(got.point_data.keys()) == list(expected.point_data.keys()), case
    np.testing.assert_array_equal(placement["origin"], expected.origin, err_msg=case)
    np.testing.assert_array_equal(placement["spacing"], expected.spacing, err_msg=case)
    np.testing.assert_array_equal(placement["direction"], np.asarray(expected.direction_matrix).ravel(), err_msg=case)
    for key in ("origin", "spacing", "direction"):  # announced in RequestInformation, before the data
        np.testing.assert_array_equal(placement["information"][key], placement[key], err_msg=f"{case}: {key}")
    if "TriangleId" in expected.point_data:  # the view is not empty
        assert (expected["TriangleId"] >= 0).mean() > 0.1, case
    for name in expected.point_data.keys():
        a, b = got.point_data[name], expected.point_data[name]
        assert a.dtype == b.dtype, f"{case}: {name} is {a.dtype}, vrc.cast gives {b.dtype}"
        if surface and name == "Barycentric":
            a, b = np.sort(a, axis=1), np.sort(b, axis=1)
        if np.issubdtype(b.dtype, np.integer):
            np.testing.assert_array_equal(a, b, err_msg=f"{case}: {name}")
        else:
            tol = 1e-12 if b.dtype == np.float64 else 1e-6
            np.testing.assert_allclose(a, b, rtol=tol, atol=tol, equal_nan=True, err_msg=f"{case}: {name}")


@pytest.fixture(scope="module")
def pvbatch_run(paraview_path, tmp_path_factory):
    """Runs the pvbatch script once; returns its report, output directory, plan and stderr."""
    tmp = tmp_path_factory.mktemp("paraview")
    plan = _plan(tmp)
    (tmp / "plan.json").write_text(json.dumps(plan))
    env = dict(_clean_env(), PYTHONPATH=str(paraview_path))
    start = time.perf_counter()
    done = subprocess.run(
        [PVBATCH, str(SCRIPT), str(tmp / "plan.json")],
        cwd=tmp, env=env, capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    seconds = time.perf_counter() - start
    assert done.returncode == 0, f"pvbatch failed ({done.returncode}):\n{done.stdout}\n{done.stderr}"
    report = json.loads((tmp / "report.json").read_text())
    print(f"pvbatch ran in {seconds:.1f} s: ParaView {report['paraview']}, VTK {report['vtk']}")
    return report, tmp, plan, done.stderr


def test_plugin_loads_in_paraview_without_pyvista_or_pip_vtk(pvbatch_run, paraview_path):
    report, *_ = pvbatch_run
    assert report["completed"]
    assert report["paraview"].startswith("paraview version 5.")
    assert report["vtk"].startswith("9.")
    assert [m for m in report["modules"] if not m.startswith("vtkraycast")] == []
    assert Path(report["vtkraycast_file"]).resolve().is_relative_to(paraview_path.resolve())


def test_arrays_equal_vrc_cast_on_a_paraview_source(pvbatch_run):
    report, tmp, _, _ = pvbatch_run
    mesh = pv.read(tmp / "sphere_input.vtp")
    assert mesh.n_cells == 2 * 24 * (18 - 2)  # ParaView's sphere: ThetaResolution x PhiResolution
    for case, properties in [("sphere", SPHERE_CAMERA), ("sphere_moved", {**SPHERE_CAMERA, **MOVED})]:
        got = pv.read(tmp / f"{case}.vti")
        expected = _reference(mesh, properties)
        assert set(got.point_data.keys()) >= {"TriangleId", "CellId", "Barycentric", "Depth", "Normals"}
        _assert_same_image(got, expected, report["casts"][case], case)
    # The two cameras saw different things.
    first, moved = pv.read(tmp / "sphere.vti"), pv.read(tmp / "sphere_moved.vti")
    assert not np.array_equal(first["TriangleId"], moved["TriangleId"])


def test_arrays_equal_vrc_cast_on_files(pvbatch_run):
    report, tmp, plan, _ = pvbatch_run
    for case, spec in plan["files"].items():
        got = pv.read(tmp / f"{case}.vti")
        expected = _reference(pv.read(spec["path"]), spec["cast"])
        _assert_same_image(got, expected, report["casts"][case], case, surface=spec["path"].endswith(".vtu"))
    default = pv.read(tmp / "torus_default.vti")
    assert list(default.point_data.keys()) == [
        "TriangleId", "CellId", "Barycentric", "Depth", "vtkValidPointMask",
        "Temperature", "Velocity", "Label", "Material", "Pressure",
    ]  # fmt: skip
    options = pv.read(tmp / "torus_options.vti")
    assert (options["TriangleId"] != default["TriangleId"]).mean() > 0.05  # back-face culling took effect
    assert options["Depth"].dtype == np.float32 and options["Position"].shape == (80 * 60, 3)
    assert list(pv.read(tmp / "torus_parallel.vti").point_data.keys())[-1] == "vtkValidPointMask"
    assert report["casts"]["torus_parallel"]["spacing"][0] == pytest.approx(2.4 / 60)  # world space


def test_composite_input_is_one_scene_as_vrc_cast_of_a_multiblock(pvbatch_run):
    report, tmp, plan, _ = pvbatch_run
    spec = plan["composite"]
    got = pv.read(tmp / "composite.vti")
    expected = _reference(pv.MultiBlock([pv.read(path) for path in spec["paths"]]), spec["cast"])
    _assert_same_image(got, expected, report["casts"]["composite"], "composite")
    # Both blocks are seen (flat indices 1 and 2); each keeps its own cell ids and arrays.
    assert set(np.unique(got["CompositeIndex"])) == {-1, 1, 2}
    ball = got["CompositeIndex"] == 2
    assert (got["Patch"][~ball] == 0).all() and np.isnan(got["Pressure"][ball]).all()


def test_camera_change_recasts_without_rebuilding(pvbatch_run):
    report, *_ = pvbatch_run
    assert report["builds_first"] == [1, 1]
    assert report["builds_after_camera_change"] == [1, 1]
    assert report["builds_after_mesh_change"] == [2, 2]


def test_bad_property_values_are_paraview_errors_not_crashes(pvbatch_run):
    report, _, plan, stderr = pvbatch_run
    errors = report["errors"]
    assert errors["good"] == 16 * 12
    for name, _ in plan["errors"]["bad"]:
        assert errors[name] == [0, 16 * 12], name  # empty while bad, back once fixed
    assert "ERROR: In RayCast (vtkraycast): Resolution: nx must be at least 1 pixel, got 0" in stderr
    assert "ERROR: In RayCast (vtkraycast): Strategy: unknown strategy 'bogus'" in stderr
    assert "ERROR: In RayCast (vtkraycast): Precision: unknown precision 'float16'" in stderr
    assert "unknown array 'Nope'" in stderr
    assert "CameraPosition and CameraFocalPoint coincide" in stderr
    assert "view_angle must be strictly between 0 and 180 degrees, got 180.0" in stderr
    assert "Traceback" not in stderr
    assert "leaked" not in stderr  # the native scenes are released before Python shuts down


# -- under MPI: mpirun -np N pvbatch, the filter on every rank ---------------------------

MPI_SCRIPT = Path(__file__).resolve().parent / "paraview" / "raycast_mpi_pvbatch.py"
MPI_CASES = ("pieces", "unique", "duplicated")


@pytest.fixture(scope="module")
def pvbatch_mpi_runs(paraview_path, tmp_path_factory):
    """The MPI script on 1 (the serial reference), 2 and 3 ranks (ParaView's OpenMPI)."""
    mpirun = Path(PVBATCH).parent / "mpirun"
    if not mpirun.exists():
        pytest.skip("ParaView's mpirun is not installed")
    tmp = tmp_path_factory.mktemp("paraview-mpi")
    env = dict(_clean_env(), PYTHONPATH=str(paraview_path))
    reports = {}
    for n in (1, 2, 3):
        plan = {
            "plugin": str(PLUGIN),
            "out": str(tmp),
            "tag": f"np{n}",
            "sphere": {"ThetaResolution": 40, "PhiResolution": 30, "Radius": 0.8, "Center": [0.05, -0.1, 0.0]},
            "cast": SPHERE_CAMERA,
        }
        (tmp / f"plan{n}.json").write_text(json.dumps(plan))
        command = [str(mpirun), "--allow-run-as-root", "--oversubscribe", "--bind-to", "none", "-np", str(n)]
        done = subprocess.run(
            [*command, PVBATCH, str(MPI_SCRIPT), str(tmp / f"plan{n}.json")],
            cwd=tmp, env=env, capture_output=True, text=True, timeout=180, check=False,
        )  # fmt: skip
        assert done.returncode == 0, f"mpirun -np {n} pvbatch failed:\n{done.stdout}\n{done.stderr}"
        assert "leaked" not in done.stderr, done.stderr  # exits cleanly
        reports[n] = json.loads((tmp / f"np{n}-report.json").read_text())
    return tmp, reports


@pytest.mark.parametrize("ranks", [2, 3])
def test_ranks_assemble_one_image_equal_to_the_serial_one(pvbatch_mpi_runs, ranks):
    tmp, reports = pvbatch_mpi_runs
    nx, ny = SPHERE_CAMERA["Resolution"]
    assert reports[ranks]["ranks"] == ranks and reports[1]["ranks"] == 1
    for case in MPI_CASES:
        serial, got = pv.read(tmp / f"np1-{case}.pvti"), pv.read(tmp / f"np{ranks}-{case}.pvti")
        assert got.dimensions == serial.dimensions == (nx, ny, 1), case
        # Each rank holds its block of the extent: ParaView counts the image once (blocks
        # share their boundary column of points), not once per rank.
        assert nx * ny <= reports[ranks]["points"][case] < nx * ny + ranks * ny, case
        hit = serial["vtkValidPointMask"] == 1
        assert 0.2 < hit.mean() < 0.9
        np.testing.assert_array_equal(got["vtkValidPointMask"], serial["vtkValidPointMask"], err_msg=case)
        # Pieces without global cell ids: ties on shared edges may go to the other
        # triangle of the edge, whose depth differs in its last bits.
        np.testing.assert_allclose(got["Depth"], serial["Depth"], rtol=1e-13, equal_nan=True, err_msg=case)
        np.testing.assert_allclose(got["Normals"], serial["Normals"], rtol=1e-12, atol=1e-12, equal_nan=True)
        assert (got["TriangleId"] >= 0).sum() == hit.sum()
