"""Output arrays of a cast: which exist, and the arrays the native core writes them into.

Only the arrays asked for are allocated, and the core's workers write every one of them,
hits and misses, in one pass. Point arrays of the mesh are interpolated with the
barycentric weights (integer ones take the value of the point of largest weight); cell
arrays take the value of the hit cell. Misses are NaN for floating-point arrays and 0 for
integer ones.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from . import _core
from .mesh import PreparedMesh, numeric_arrays

__all__ = [
    "DEFAULT_ARRAYS",
    "GEOMETRY_ARRAYS",
    "MeshArrays",
    "allocate",
    "mesh_arrays",
    "output_bytes",
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
    flags excluded): VTK's integer and floating types, any number of components."""
    point, cell = numeric_arrays(mesh.surface)
    excluded = (*GEOMETRY_ARRAYS, "vtkGhostType")
    return MeshArrays(
        *({n: v for n, v in found.items() if n not in excluded} for found in (point, cell)),
        composite=mesh.composite_ids is not None,
    )


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


def row_layout(found: MeshArrays, name: str, real: type) -> tuple[np.dtype, tuple[int, ...]]:
    """Element type and row shape of output array ``name``."""
    if name in _GEOMETRY:
        ids = name.endswith("Id") or name == "CompositeIndex"
        dtype = np.uint8 if name == "vtkValidPointMask" else (np.int64 if ids else real)
        return np.dtype(dtype), _GEOMETRY[name][1]
    values = found.point.get(name)
    values = found.cell[name] if values is None else values
    return values.dtype, values.shape[1:]


def output_bytes(found: MeshArrays, names: list[str], real: type) -> int:
    """Bytes per ray of the output arrays ``names``."""
    return sum(dtype.itemsize * math.prod(shape) for dtype, shape in (row_layout(found, name, real) for name in names))


def allocate(found: MeshArrays, names: list[str], n: int, real: type) -> dict[str, np.ndarray]:
    """Uninitialised output arrays for ``n`` rays, in the order of ``names`` (the core
    writes every element)."""
    rows = {name: row_layout(found, name, real) for name in names}
    return {name: np.empty((n, *shape), dtype) for name, (dtype, shape) in rows.items()}


def request_outputs(
    request: _core.Request, mesh: PreparedMesh, found: MeshArrays, buffers: dict[str, np.ndarray]
) -> None:
    """Points ``request`` at the output arrays ``buffers`` and the mesh data they need."""
    rows = {"point": mesh.surface.GetNumberOfPoints(), "cell": mesh.surface.GetNumberOfCells()}
    for name, out in buffers.items():
        if name in _GEOMETRY:
            setattr(request, _GEOMETRY[name][0], out)
            continue
        kind = "point" if name in found.point else "cell"
        values = getattr(found, kind)[name]
        if values.shape[0] != rows[kind]:  # (VTK lets an array's length disagree with its mesh)
            raise ValueError(f"{kind} array {name!r} has {values.shape[0]} tuples for {rows[kind]} {kind}s")
        request.add_field(values, out, kind == "point")
    if found.point.keys() & buffers.keys():
        request.mesh_triangles = mesh.triangles
    if "CellId" in buffers:
        request.cell_ids = mesh.cell_ids
    if "CompositeIndex" in buffers:
        request.composite_ids = mesh.composite_ids
    if found.cell.keys() & buffers.keys():
        request.surface_cell_ids = mesh.surface_cell_ids
