"""Mesh preparation: any VTK dataset to float64 points and uint32 triangles, with a map
from every triangle back to the input cell it came from."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from vtkmodules.util.numpy_support import numpy_to_vtkIdTypeArray, vtk_to_numpy
from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkCompositeDataSet, vtkDataSet, vtkPolyData
from vtkmodules.vtkFiltersCore import vtkTriangleFilter
from vtkmodules.vtkFiltersGeometry import vtkDataSetSurfaceFilter

from .composite import merge_leaves

__all__ = ["PreparedMesh", "numeric_arrays", "prepare_mesh"]

#: vtkDataSetAttributes' DUPLICATECELL | HIDDENCELL.
_SKIPPED_GHOSTS = 1 | 32


@dataclass(frozen=True)
class PreparedMesh:
    """Triangles ready for the native core, and what the fields need to find the input data.

    Attributes
    ----------
    points : numpy.ndarray
        ``(n_points, 3)`` float64 coordinates (a copy when the input's were not float64).
    triangles : numpy.ndarray
        ``(n_triangles, 3)`` uint32 point indices, ordered by input cell.
    cell_ids : numpy.ndarray
        ``(n_triangles,)`` int64 id of the input cell each triangle came from.
    surface_cell_ids : numpy.ndarray
        ``(n_triangles,)`` int64 id of the cell of ``surface`` each triangle came from
        (the same array as ``cell_ids`` for polygonal input).
    surface : vtkPolyData
        The polygonal data whose point and cell arrays are interpolated (the input itself
        for polygonal input; its extracted surface otherwise; for a composite input, the
        leaves' triangles and arrays merged). Never modified.
    composite_ids : numpy.ndarray or None
        ``(n_triangles,)`` int64 flat index of the leaf each triangle came from, for a
        composite input (``cell_ids`` are then local to the leaf); None otherwise.
    global_cell_ids : numpy.ndarray or None
        The input's global cell ids (``GetCellData().GetGlobalIds()``), indexed by input
        cell id, when it has them: what orders triangles across MPI ranks.
    """

    points: np.ndarray
    triangles: np.ndarray
    cell_ids: np.ndarray
    surface_cell_ids: np.ndarray
    surface: vtkPolyData
    composite_ids: np.ndarray | None = None
    global_cell_ids: np.ndarray | None = None

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])

    @cached_property
    def cells_are_triangles(self) -> bool:
        """Whether triangle i came from cell i of the input and of ``surface`` for every i
        (an all-triangle mesh): the core then writes CellId and gathers cell arrays
        without looking the cell up."""
        own = np.arange(self.n_triangles, dtype=np.int64)
        return bool(np.array_equal(self.cell_ids, own) and np.array_equal(self.surface_cell_ids, own))


def _cells(cell_array: vtkCellArray) -> tuple[np.ndarray, np.ndarray]:
    """Offsets and connectivity of a vtkCellArray as int64 numpy arrays (views when possible),
    checked: a malformed array (say, a legacy cell list with negative counts) is refused."""
    offsets = vtk_to_numpy(cell_array.GetOffsetsArray()).astype(np.int64, copy=False)
    connectivity = vtk_to_numpy(cell_array.GetConnectivityArray()).astype(np.int64, copy=False)
    if offsets.size and (offsets[0] != 0 or offsets[-1] != connectivity.size or (np.diff(offsets) < 0).any()):
        raise ValueError("the mesh's cell array is malformed (its offsets do not describe its connectivity)")
    return offsets, connectivity


def _triangles_of_polys(poly: vtkPolyData, first_id: int) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of the polygon cells: triangles as they are, larger polygons through
    vtkTriangleFilter (ear cutting handles concave ones), fewer than 3 points dropped."""
    offsets, conn = _cells(poly.GetPolys())
    sizes = np.diff(offsets)
    if conn.size == 3 * sizes.size and (sizes == 3).all():  # all triangles: the connectivity as is
        return conn.reshape(-1, 3), np.arange(first_id, first_id + sizes.size)
    tri_cells = np.flatnonzero(sizes == 3)
    tris = conn[offsets[tri_cells][:, None] + np.arange(3)]
    ids = tri_cells
    big = np.flatnonzero(sizes > 3)
    if big.size:
        big_tris, big_ids = _triangulate_polygons(poly, offsets, conn, big)
        tris = np.concatenate((tris, big_tris))
        ids = np.concatenate((ids, big_ids))
        order = np.argsort(ids, kind="stable")
        tris, ids = tris[order], ids[order]
    return tris, ids + first_id


def _triangulate_polygons(
    poly: vtkPolyData, offsets: np.ndarray, conn: np.ndarray, cells: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    # Only polygons go into vtkTriangleFilter: with lines or vertices beside them VTK 9.7
    # was seen to mis-size the cell data, so the cell map rides along on a polygon-only copy.
    sizes = np.diff(offsets)[cells]
    new_offsets = np.concatenate(([0], np.cumsum(sizes)))
    gather = np.repeat(offsets[cells] - new_offsets[:-1], sizes) + np.arange(new_offsets[-1])
    polys = vtkCellArray()
    polys.SetData(numpy_to_vtkIdTypeArray(new_offsets, deep=True), numpy_to_vtkIdTypeArray(conn[gather], deep=True))
    only = vtkPolyData()
    only.SetPoints(poly.GetPoints())
    only.SetPolys(polys)
    source_cell = numpy_to_vtkIdTypeArray(cells.astype(np.int64), deep=True)
    source_cell.SetName("vtkraycast_source_cell")
    only.GetCellData().AddArray(source_cell)
    triangulate = vtkTriangleFilter()
    triangulate.SetInputData(only)
    triangulate.PassVertsOff()
    triangulate.PassLinesOff()
    triangulate.Update()
    out = triangulate.GetOutput()
    out_offsets, out_conn = _cells(out.GetPolys())
    if out_conn.size != 3 * (out_offsets.size - 1):
        raise RuntimeError("vtkTriangleFilter returned non-triangle cells")
    ids = vtk_to_numpy(out.GetCellData().GetArray("vtkraycast_source_cell")).astype(np.int64)
    return out_conn.reshape(-1, 3), ids


def _triangles_of_strips(poly: vtkPolyData, first_id: int) -> tuple[np.ndarray, np.ndarray]:
    """Strip (p0, p1, p2, p3, ...) gives (p0, p1, p2), (p2, p1, p3), ...: every other
    triangle swaps its first two points to keep one orientation, as vtkTriangleStrip does."""
    offsets, conn = _cells(poly.GetStrips())
    counts = np.maximum(np.diff(offsets) - 2, 0)
    strip = np.repeat(np.arange(counts.size), counts)
    k = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    base = offsets[strip] + k
    odd = (k % 2).astype(bool)
    first = np.where(odd, base + 1, base)
    second = np.where(odd, base, base + 1)
    tris = np.stack((conn[first], conn[second], conn[base + 2]), axis=1)
    return tris, strip + first_id


def as_polydata(mesh: Any) -> tuple[vtkPolyData, np.ndarray | None]:
    """The input as vtkPolyData, and the map from its cells to the input's cells (None when
    the input already is polygonal). Other datasets contribute their outer surface."""
    if isinstance(mesh, vtkPolyData):
        return mesh, None
    if isinstance(mesh, vtkDataSet):
        surface = vtkDataSetSurfaceFilter()
        surface.SetInputData(mesh)
        surface.PassThroughCellIdsOn()
        surface.SetOriginalCellIdsName("vtkraycast_source_cell")
        surface.Update()
        out = vtkPolyData()
        out.ShallowCopy(surface.GetOutput())
        ids = out.GetCellData().GetArray("vtkraycast_source_cell")
        cell_map = vtk_to_numpy(ids).astype(np.int64) if ids is not None else np.zeros(0, np.int64)
        out.GetCellData().RemoveArray("vtkraycast_source_cell")
        return out, cell_map
    raise TypeError(
        "expected a vtkPolyData, pyvista.PolyData, another vtkDataSet or a composite dataset "
        f"(vtkMultiBlockDataSet, pyvista.MultiBlock, vtkPartitionedDataSet), got {type(mesh).__name__}"
    )


def numeric_arrays(data: vtkDataSet) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The named numeric point and cell arrays of ``data`` (VTK's integer and floating
    types, any number of components; bit and string arrays skipped), as numpy views."""
    found: list[dict[str, np.ndarray]] = []
    for attributes in (data.GetPointData(), data.GetCellData()):
        arrays = {}
        for k in range(attributes.GetNumberOfArrays()):
            array = attributes.GetArray(k)  # None for string and other non-numeric arrays
            name = array.GetName() if array is not None else None
            if name and not array.IsA("vtkBitArray"):
                values = np.ascontiguousarray(vtk_to_numpy(array))
                if values.dtype.kind in "iuf":
                    arrays[name] = values
        found.append(arrays)
    return found[0], found[1]


def prepare_mesh(mesh: Any) -> PreparedMesh:
    """Triangulates ``mesh`` for the native core without modifying it.

    Polygons and triangle strips become triangles; vertex and line cells are ignored;
    polygons with fewer than three points are dropped. Raises ``ValueError`` for
    non-finite coordinates of any point a triangle uses.

    Examples
    --------
    >>> import pyvista as pv
    >>> from vtkraycast.mesh import prepare_mesh
    >>> quad = pv.PolyData([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]], faces=[4, 0, 1, 2, 3])
    >>> prepared = prepare_mesh(quad)
    >>> prepared.n_triangles, prepared.cell_ids.tolist()
    (2, [0, 0])
    """
    if isinstance(mesh, vtkCompositeDataSet):
        points, triangles, cell_ids, leaf_ids, surface = merge_leaves(mesh, prepare_mesh, numeric_arrays)
        return PreparedMesh(points, triangles, cell_ids, np.arange(len(triangles), dtype=np.int64), surface, leaf_ids)
    poly, cell_map = as_polydata(mesh)
    n_points = poly.GetNumberOfPoints()
    if n_points >= 2**32:
        raise ValueError(f"meshes of at most 2**32 - 1 points are supported, got {n_points}")
    vtk_points = poly.GetPoints()
    if vtk_points is None or n_points == 0:
        points = np.zeros((0, 3), np.float64)
    else:
        points = np.ascontiguousarray(vtk_to_numpy(vtk_points.GetData()), dtype=np.float64)
    n_verts, n_lines, n_polys = poly.GetNumberOfVerts(), poly.GetNumberOfLines(), poly.GetNumberOfPolys()
    parts = [_triangles_of_polys(poly, n_verts + n_lines)] if n_polys else []
    if poly.GetNumberOfStrips():
        parts.append(_triangles_of_strips(poly, n_verts + n_lines + n_polys))
    if parts:
        tris = np.concatenate([p[0] for p in parts])
        ids = np.concatenate([p[1] for p in parts])
    else:
        tris, ids = np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    if tris.size and (tris.min() < 0 or tris.max() >= n_points):
        raise ValueError("the mesh has cells that refer to points it does not have")
    finite = np.isfinite(points).all(axis=1)
    if not finite.all() and not finite[tris].all():
        bad = int(np.flatnonzero(~finite)[0])
        raise ValueError(f"the mesh has non-finite point coordinates (point {bad}: {points[bad].tolist()})")
    ids = ids.astype(np.int64)
    input_ids = ids if cell_map is None else cell_map[ids]
    cell_data = mesh.GetCellData()
    ghosts = cell_data.GetArray("vtkGhostType")
    for name, array in (("vtkGhostType", ghosts), ("global cell ids", cell_data.GetGlobalIds())):
        if array is not None and array.GetNumberOfTuples() != mesh.GetNumberOfCells():
            raise ValueError(
                f"the mesh's {name} array has {array.GetNumberOfTuples()} values for {mesh.GetNumberOfCells()} cells"
            )
    if ghosts is not None and len(input_ids):
        # Cells another piece owns (duplicate) or that are not to be shown (hidden), as
        # VTK's renderers skip them.
        flags = vtk_to_numpy(ghosts)[input_ids].astype(np.int64)
        keep = (flags & _SKIPPED_GHOSTS) == 0
        tris, ids, input_ids = tris[keep], ids[keep], input_ids[keep]
    global_ids = cell_data.GetGlobalIds()
    global_ids = vtk_to_numpy(global_ids).astype(np.int64) if global_ids is not None else None
    return PreparedMesh(
        points, np.ascontiguousarray(tris, dtype=np.uint32), input_ids, ids, poly, global_cell_ids=global_ids
    )
