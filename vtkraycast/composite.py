"""Composite inputs (vtkMultiBlockDataSet, vtkPartitionedDataSet(Collection),
pyvista.MultiBlock): every leaf dataset prepared on its own, then merged into one mesh
that remembers each triangle's leaf (VTK's flat index, the hardware selector's
``CompositeIndex``) and its cell within the leaf."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
from vtkmodules.vtkCommonCore import vtkPoints
from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkCompositeDataSet, vtkDataSet, vtkPolyData

__all__ = ["leaves", "merge_leaves"]


def leaves(composite: vtkCompositeDataSet) -> Iterator[tuple[int, vtkDataSet]]:
    """(flat index, dataset) of every non-empty leaf, depth first, as VTK numbers them."""
    iterator = composite.NewIterator()
    iterator.SkipEmptyNodesOn()
    iterator.InitTraversal()
    while not iterator.IsDoneWithTraversal():
        leaf = iterator.GetCurrentDataObject()
        index = iterator.GetCurrentFlatIndex()
        if not isinstance(leaf, vtkDataSet):
            raise TypeError(f"composite leaf {index} is a {type(leaf).__name__}, not a dataset")
        yield index, leaf
        iterator.GoToNextItem()


def _missing(dtype: np.dtype) -> float | int:
    return np.nan if dtype.kind == "f" else 0


def _merged_arrays(per_leaf: list[dict[str, np.ndarray]], rows: list[int]) -> dict[str, np.ndarray]:
    """Arrays of the leaves stacked, rows of a leaf without the array NaN (floating) or 0;
    a name whose leaves disagree in components is dropped (no one meaning to stack)."""
    merged = {}
    for name in dict.fromkeys(n for arrays in per_leaf for n in arrays):
        present = [arrays[name] for arrays in per_leaf if name in arrays]
        if len({a.shape[1:] for a in present}) != 1:
            continue
        dtype = np.result_type(*present)
        row = present[0].shape[1:]
        parts = [
            arrays[name].astype(dtype, copy=False) if name in arrays else np.full((n, *row), _missing(dtype), dtype)
            for arrays, n in zip(per_leaf, rows)
        ]
        merged[name] = np.concatenate(parts)
    return merged


def merge_leaves(composite: vtkCompositeDataSet, prepare: Callable, numeric_arrays: Callable) -> tuple:
    """The leaves' meshes (``prepare(leaf)``, mesh.prepare_mesh) merged: (points, triangles,
    cell ids local to their leaf, flat index per triangle, a vtkPolyData holding the merged
    points with one triangle cell per triangle and the leaves' arrays, ``numeric_arrays``)."""
    prepared, indices = [], []
    for index, leaf in leaves(composite):
        prepared.append(prepare(leaf))
        indices.append(index)
    n_points = [m.points.shape[0] for m in prepared]
    n_tris = [m.n_triangles for m in prepared]
    offsets = np.concatenate(([0], np.cumsum(n_points)[:-1])).astype(np.int64)
    points = np.concatenate([m.points for m in prepared]) if prepared else np.zeros((0, 3))
    triangles = (
        np.concatenate([m.triangles.astype(np.int64) + o for m, o in zip(prepared, offsets)])
        if prepared
        else np.zeros((0, 3), np.int64)
    )
    if triangles.size and triangles.max() >= 2**32:
        raise ValueError(f"composite inputs of at most 2**32 - 1 points are supported, got {points.shape[0]}")
    cell_ids = np.concatenate([m.cell_ids for m in prepared]) if prepared else np.zeros(0, np.int64)
    leaf_ids = np.repeat(np.asarray(indices, np.int64), n_tris)

    point_arrays, cell_arrays = [], []
    for m in prepared:
        points_of_leaf, cells_of_leaf = numeric_arrays(m.surface)
        point_arrays.append(points_of_leaf)
        cell_arrays.append({name: values[m.surface_cell_ids] for name, values in cells_of_leaf.items()})
    surface = vtkPolyData()
    vtk_points = vtkPoints()
    vtk_points.SetData(numpy_to_vtk(points, deep=True))
    surface.SetPoints(vtk_points)
    cells = vtkCellArray()
    cells.SetData(
        numpy_to_vtkIdTypeArray(np.arange(0, 3 * len(triangles) + 1, 3, dtype=np.int64), deep=True),
        numpy_to_vtkIdTypeArray(np.ascontiguousarray(triangles.reshape(-1)), deep=True),
    )
    surface.SetPolys(cells)
    for data, arrays, rows in (
        (surface.GetPointData(), point_arrays, n_points),
        (surface.GetCellData(), cell_arrays, n_tris),
    ):
        for name, values in _merged_arrays(arrays, rows).items():
            array = numpy_to_vtk(np.ascontiguousarray(values), deep=True)
            array.SetName(name)
            data.AddArray(array)
    return points, triangles.astype(np.uint32), cell_ids, leaf_ids, surface
