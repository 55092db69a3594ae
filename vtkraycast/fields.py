"""Output arrays of a cast: which exist, and the arrays the native core writes them into.

Only the arrays asked for are allocated, and the core's workers write every one of them,
hits and misses, in one pass. Point arrays of the mesh are interpolated with the
barycentric weights (integer ones take the value of the point of largest weight); cell
arrays take the value of the hit cell. Misses are NaN for floating-point arrays and 0 for
integer ones.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from . import _core
from .buffers import BufferPool
from .mesh import PreparedMesh, numeric_arrays

__all__ = [
    "DEFAULT_ARRAYS",
    "GEOMETRY_ARRAYS",
    "MeshArrays",
    "allocate",
    "gather_at_hits",
    "mesh_arrays",
    "mesh_arrays_for",
    "miss_value",
    "output_layouts",
    "request_outputs",
    "row_layout",
    "select_arrays",
]

#: Arrays the caster itself produces, in output order.
GEOMETRY_ARRAYS = (
    "TriangleId",
    "CellId",
    "Barycentric",
    "Depth",
    "Position",
    "Normal",
    "vtkValidPointMask",
    "CompositeIndex",
)
#: What ``arrays=None`` gives (Position and Normal only when asked for).
DEFAULT_ARRAYS = ("TriangleId", "CellId", "Barycentric", "Depth", "vtkValidPointMask")
#: The request's attribute each geometry array is written through, and its row shape.
_GEOMETRY = {
    "TriangleId": ("triangle_id", ()),
    "CellId": ("cell_id", ()),
    "CompositeIndex": ("composite_index", ()),
    "vtkValidPointMask": ("valid", ()),
    "Depth": ("depth", ()),
    "Barycentric": ("barycentric", (3,)),
    "Position": ("position", (3,)),
    "Normal": ("normal", (3,)),
}


class MeshArrays(NamedTuple):
    """The mesh's numeric point and cell arrays by name, as numpy views."""

    point: dict[str, np.ndarray]
    cell: dict[str, np.ndarray]
    composite: bool = False  #: whether the mesh came from a composite dataset (CompositeIndex exists)


def mesh_arrays(mesh: PreparedMesh) -> MeshArrays:
    """Numeric point and cell arrays of the mesh (names of geometry arrays and VTK's ghost
    flags excluded): VTK's integer and floating types, any number of components.

    Kept on the mesh until its surface changes (its modification time, which an added,
    removed or modified array advances): looking them up in VTK took longer than a small
    batch of rays."""
    stamp = mesh.surface.GetMTime()
    kept = mesh.__dict__.get("_arrays")
    if kept is not None and kept[0] == stamp:
        return kept[1]
    point, cell = numeric_arrays(mesh.surface)
    excluded = (*GEOMETRY_ARRAYS, "vtkGhostType")
    found = MeshArrays(
        *({n: v for n, v in found.items() if n not in excluded} for found in (point, cell)),
        composite=mesh.composite_ids is not None,
    )
    object.__setattr__(mesh, "_arrays", (stamp, found))  # (not a field of the frozen dataclass)
    return found


#: No mesh arrays (what output arrays of the caster's own need).
NO_MESH_ARRAYS = MeshArrays({}, {})


def mesh_arrays_for(mesh: PreparedMesh, names: Iterable[str]) -> MeshArrays:
    """The mesh's arrays, when output arrays ``names`` include any of them (asking VTK
    whether they changed cost a call of a few rays a tenth of its time)."""
    return NO_MESH_ARRAYS if _GEOMETRY.keys() >= set(names) else mesh_arrays(mesh)


def select_arrays(found: MeshArrays, arrays: Iterable[str] | str | None, interpolate: bool) -> list[str]:
    """Names of the output arrays: ``arrays`` checked against what exists, or the defaults
    (plus CompositeIndex for a composite input, and the mesh's own arrays when
    ``interpolate``)."""
    if arrays is None:
        names = list(DEFAULT_ARRAYS) + (["CompositeIndex"] if found.composite else [])
        if interpolate:
            names += [n for n in (*found.point, *found.cell) if n not in names]
        return names
    if isinstance(arrays, str):
        arrays = [arrays]
    names = []
    for name in arrays:
        if not isinstance(name, str):
            raise TypeError(f"array names must be strings, got {name!r}")
        if name not in GEOMETRY_ARRAYS and name not in found.point and name not in found.cell:
            known = ", ".join([*GEOMETRY_ARRAYS, *found.point, *found.cell])
            raise ValueError(f"unknown array {name!r}; available: {known}")
        if name == "CompositeIndex" and not found.composite:
            raise ValueError("CompositeIndex exists for composite inputs (pyvista.MultiBlock, ...) only")
        if name not in names:
            names.append(name)
    return names


def _geometry_layout(name: str, real: type) -> tuple[np.dtype, tuple[int, ...]]:
    ids = name.endswith("Id") or name == "CompositeIndex"
    dtype = np.uint8 if name == "vtkValidPointMask" else (np.int64 if ids else real)
    return np.dtype(dtype), _GEOMETRY[name][1]


#: The geometry arrays' layouts by (name, precision), made once: a batch of a few rays
#: otherwise spent a tenth of its call making them again.
_GEOMETRY_LAYOUTS = {
    (name, real): _geometry_layout(name, real) for name in _GEOMETRY for real in (np.float32, np.float64)
}


def row_layout(found: MeshArrays, name: str, real: type) -> tuple[np.dtype, tuple[int, ...]]:
    """Element type and row shape of output array ``name`` (``real``: a PRECISIONS type)."""
    layout = _GEOMETRY_LAYOUTS.get((name, real))
    if layout is not None:
        return layout
    values = found.point.get(name)
    values = found.cell[name] if values is None else values
    return values.dtype, values.shape[1:]


def output_layouts(
    found: MeshArrays, names: list[str], n: int, real: type
) -> dict[str, tuple[np.dtype, tuple[int, ...]]]:
    """The dtype and shape of each output array ``names`` for ``n`` rays, by name."""
    layouts = {}
    for name in names:
        dtype, shape = _GEOMETRY_LAYOUTS.get((name, real)) or row_layout(found, name, real)
        layouts[name] = (dtype, (n, *shape))
    return layouts


def allocate(
    found: MeshArrays, names: list[str], n: int, real: type, pool: BufferPool | None = None
) -> dict[str, np.ndarray]:
    """Uninitialised output arrays for ``n`` rays, in the order of ``names`` (the core
    writes every element), from ``pool`` when given."""
    layouts = output_layouts(found, names, n, real)
    if pool is not None:
        return pool.allocate(layouts)
    return {name: np.empty(shape, dtype) for name, (dtype, shape) in layouts.items()}


def request_outputs(
    request: _core.Request, mesh: PreparedMesh, found: MeshArrays, buffers: dict[str, np.ndarray]
) -> None:
    """Points ``request`` at the output arrays ``buffers`` and the mesh data they need."""
    for name, out in buffers.items():
        if name in _GEOMETRY:
            setattr(request, _GEOMETRY[name][0], out)
            continue
        kind = "point" if name in found.point else "cell"
        values = getattr(found, kind)[name]
        rows = mesh.surface.GetNumberOfPoints() if kind == "point" else mesh.surface.GetNumberOfCells()
        if values.shape[0] != rows:  # (VTK lets an array's length disagree with its mesh)
            raise ValueError(f"{kind} array {name!r} has {values.shape[0]} tuples for {rows} {kind}s")
        request.add_field(values, out, kind == "point")
    request.cells_are_triangles = mesh.cells_are_triangles
    if "CellId" in buffers and not mesh.cells_are_triangles:
        request.cell_ids = mesh.cell_ids
    if "CompositeIndex" in buffers:
        request.composite_ids = mesh.composite_ids
    if found.cell.keys() & buffers.keys() and not mesh.cells_are_triangles:
        request.surface_cell_ids = mesh.surface_cell_ids


def gather_at_hits(mesh, names: list[str], triangle_id: np.ndarray, barycentric: np.ndarray) -> dict[str, np.ndarray]:
    """The output arrays ``names`` for hits ``triangle_id`` (-1 = miss) with weights
    ``barycentric``, computed in numpy from a :class:`~vtkraycast.mesh.PreparedMesh` (Depth
    and Barycentric excepted, which come from the ray-triangle test itself): for depth
    layers, whose hits come from every crossing rather than from the core's cast."""
    found = mesh_arrays(mesh)
    point_arrays, cell_arrays = found.point, found.cell
    real = barycentric.dtype
    hit = triangle_id >= 0
    hit_ids = triangle_id[hit]
    corners = mesh.triangles[hit_ids].astype(np.int64)
    weights = barycentric[hit].astype(np.float64)

    def scatter(values: np.ndarray) -> np.ndarray:
        missing = np.nan if np.issubdtype(values.dtype, np.inexact) else 0
        full = np.full((triangle_id.shape[0],) + values.shape[1:], missing, dtype=values.dtype)
        full[hit] = values
        return full

    def interpolate(values: np.ndarray) -> np.ndarray:
        if np.issubdtype(values.dtype, np.floating):  # integer arrays cannot be averaged
            shape = (-1,) + (1,) * (values.ndim - 1)
            acc = sum(weights[:, c].reshape(shape) * values[corners[:, c]].astype(np.float64) for c in range(3))
            return acc.astype(values.dtype, copy=False)
        return values[corners[np.arange(corners.shape[0]), np.argmax(weights, axis=1)]]

    out: dict[str, np.ndarray] = {}
    for name in names:
        if name == "TriangleId":
            out[name] = triangle_id
        elif name == "CellId":
            out[name] = np.where(hit, mesh.cell_ids[np.maximum(triangle_id, 0)] if mesh.n_triangles else -1, -1)
        elif name == "CompositeIndex":
            out[name] = np.where(hit, mesh.composite_ids[np.maximum(triangle_id, 0)] if mesh.n_triangles else -1, -1)
        elif name == "vtkValidPointMask":
            out[name] = hit.astype(np.uint8)
        elif name == "Position":
            out[name] = scatter(np.einsum("nc,ncd->nd", weights, mesh.points[corners]).astype(real))
        elif name == "Normal":
            p = mesh.points[corners]
            n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
            out[name] = scatter((n / np.linalg.norm(n, axis=1, keepdims=True)).astype(real))
        elif name in point_arrays:
            out[name] = scatter(interpolate(point_arrays[name]))
        elif name in cell_arrays:
            out[name] = scatter(cell_arrays[name][mesh.surface_cell_ids[hit_ids]])
    return out


def miss_value(name: str, dtype: np.dtype) -> float | int:
    """What output array ``name`` of type ``dtype`` holds on a miss: -1 for ids, NaN for
    floating types, 0 for other integers."""
    if name in ("TriangleId", "CellId", "CompositeIndex"):
        return -1
    return np.nan if np.dtype(dtype).kind == "f" else 0
