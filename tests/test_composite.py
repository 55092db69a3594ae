"""Composite inputs (pyvista.MultiBlock, vtkMultiBlockDataSet, vtkPartitionedDataSet(Collection))
cast as one scene: against the same blocks appended by VTK (vtkAppendPolyData) into one mesh,
with each pixel's block and local cell found from the appended mesh's triangle."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv
from vtkmodules.vtkCommonDataModel import (
    vtkMultiBlockDataSet,
    vtkPartitionedDataSet,
    vtkPartitionedDataSetCollection,
    vtkTable,
)
from vtkmodules.vtkFiltersCore import vtkAppendPolyData

import vtkraycast as vrc

CAMERA = vrc.Camera((0.8, -3.0, 1.5), (0.8, 0.6, 0.1), (0, 0, 1), nx=96, ny=64, view_angle=35)


def _blocks() -> list[pv.PolyData]:
    sphere = pv.Sphere(radius=0.7, theta_resolution=24, phi_resolution=16)
    sphere.point_data.clear()
    sphere.point_data["Heat"] = sphere.points[:, 2].copy()
    cube = pv.Cube(center=(1.6, 0.2, 0.0)).triangulate()
    cube.point_data.clear()
    cube.cell_data.clear()
    cube.cell_data["Face"] = np.arange(cube.n_cells, dtype=np.int32) + 10
    cone = pv.Cone(center=(0.4, 1.4, 0.3), resolution=12)  # a polygon cap: triangulated
    cone.point_data.clear()
    cone.cell_data.clear()
    cone.point_data["Heat"] = np.full(cone.n_points, 7.0)
    return [sphere, cube, cone]


def _appended(blocks: list[pv.PolyData]) -> tuple[pv.PolyData, np.ndarray, np.ndarray]:
    """The blocks in one mesh (VTK's append), and for each of its cells the block number
    and the cell's id within its block."""
    append = vtkAppendPolyData()
    for block in blocks:
        append.AddInputData(block)
    append.Update()
    block_of = np.repeat(np.arange(len(blocks)), [b.n_cells for b in blocks])
    local = np.concatenate([np.arange(b.n_cells) for b in blocks])
    return pv.wrap(append.GetOutput()), block_of, local


def _nested(blocks: list[pv.PolyData]) -> tuple[pv.MultiBlock, list[int]]:
    """Nested, with empty blocks; the flat index VTK gives each of ``blocks``."""
    inner = pv.MultiBlock([blocks[1], pv.PolyData(), blocks[2]])
    # flat indices: root 0, sphere 1, None 2, inner 3 -> cube 4, empty 5, cone 6
    return pv.MultiBlock([blocks[0], None, inner]), [1, 4, 6]


def _check(image, blocks, flat_indices) -> None:
    merged, block_of, local = _appended(blocks)
    reference = vrc.cast(merged, CAMERA, arrays=["CellId", "Depth"])
    hit = reference["CellId"] >= 0
    assert hit.mean() > 0.2
    np.testing.assert_array_equal(image["Depth"], reference["Depth"])
    cells = reference["CellId"][hit]
    expected_leaf = np.full(hit.shape, -1)
    expected_leaf[hit] = np.asarray(flat_indices)[block_of[cells]]
    np.testing.assert_array_equal(image["CompositeIndex"], expected_leaf)
    expected_cell = np.full(hit.shape, -1)
    expected_cell[hit] = local[cells]
    np.testing.assert_array_equal(image["CellId"], expected_cell)
    assert set(np.unique(image["CompositeIndex"])) == {-1, *flat_indices}


def test_nested_multiblock_with_empty_blocks_is_one_scene():
    blocks = _blocks()
    multiblock, flat = _nested(blocks)
    before = [b.copy(deep=True) for b in blocks]
    image = vrc.cast(multiblock, CAMERA)
    _check(image, blocks, flat)
    assert {"CompositeIndex", "Heat", "Face"} <= set(image.array_names)
    for block, copy in zip(blocks, before):  # inputs never modified
        assert block == copy


def test_arrays_of_the_hit_block_and_nan_or_zero_where_it_lacks_them():
    blocks = _blocks()
    multiblock, _ = _nested(blocks)
    image = vrc.cast(multiblock, CAMERA)
    leaf, heat, face = image["CompositeIndex"], image["Heat"], image["Face"]
    assert np.isnan(heat[leaf == 4]).all()
    np.testing.assert_allclose(heat[leaf == 6], 7.0, rtol=1e-14)
    assert (face[leaf == 1] == 0).all() and (face[leaf == 6] == 0).all() and (face[leaf == 4] >= 10).all()
    np.testing.assert_array_equal(face[leaf == 4], image["CellId"][leaf == 4] + 10)
    assert face.dtype == np.int32 and heat.dtype == np.float64


def test_interpolated_array_of_a_block_is_its_own_field():
    blocks = _blocks()
    multiblock, _ = _nested(blocks)
    image = vrc.cast(multiblock, CAMERA, arrays=["CompositeIndex", "Heat", "Position"])
    sphere = image["CompositeIndex"] == 1
    # Heat is the sphere's z: interpolated linearly, it is the hit point's z.
    np.testing.assert_allclose(image["Heat"][sphere], image["Position"][sphere, 2], atol=1e-12)


@pytest.mark.parametrize("kind", ["multiblock", "partitioned", "collection"])
def test_vtk_composite_types(kind):
    blocks = _blocks()
    if kind == "multiblock":
        data = vtkMultiBlockDataSet()
        for k, block in enumerate(blocks):
            data.SetBlock(k, block)
    elif kind == "partitioned":
        data = vtkPartitionedDataSet()
        for k, block in enumerate(blocks):
            data.SetPartition(k, block)
    else:
        data = vtkPartitionedDataSetCollection()
        for k, block in enumerate(blocks):
            part = vtkPartitionedDataSet()
            part.SetPartition(0, block)
            data.SetPartitionedDataSet(k, part)
    iterator = data.NewIterator()
    iterator.InitTraversal()
    flat = []
    while not iterator.IsDoneWithTraversal():
        flat.append(iterator.GetCurrentFlatIndex())
        iterator.GoToNextItem()
    _check(vrc.cast(data, CAMERA), blocks, flat)


def test_filter_and_scene_take_composites():
    blocks = _blocks()
    multiblock, flat = _nested(blocks)
    caster = vrc.RayCastFilter()
    caster.SetInputData(multiblock)
    caster.SetResolution(CAMERA.nx, CAMERA.ny)
    caster.Update()  # no camera: one framing the whole input
    image = pv.wrap(caster.GetOutput())
    assert set(np.unique(image["CompositeIndex"])) == {-1, *flat}
    scene = vrc.Scene(multiblock)
    hits = scene.intersect([[0.0, -5.0, 0.0], [1.6, -5.0, 0.2], [5.0, 5.0, 5.0]], [0.0, 1.0, 0.0])
    assert hits["composite_index"].tolist() == [1, 4, -1]
    assert hits["cell_id"][2] == -1 and 0 <= hits["cell_id"][1] < blocks[1].n_cells
    assert set(hits) == {"triangle_id", "cell_id", "t", "barycentric", "composite_index"}


def test_composite_names_refused_for_plain_meshes_and_bad_leaves():
    with pytest.raises(ValueError, match="CompositeIndex exists for composite inputs"):
        vrc.cast(pv.Sphere(), CAMERA, arrays=["CompositeIndex"])
    with pytest.raises(ValueError, match="composite_index exists"):
        vrc.Scene(pv.Sphere()).intersect([0, 0, 2], [0, 0, -1], arrays=["composite_index"])
    data = vtkMultiBlockDataSet()
    data.SetBlock(0, pv.Sphere())
    data.SetBlock(1, vtkTable())
    with pytest.raises(TypeError, match="composite leaf 2 is a vtkTable"):
        vrc.Scene(data)


def test_empty_composite_gives_an_all_miss_image():
    image = vrc.cast(pv.MultiBlock([None, pv.MultiBlock()]), CAMERA)
    assert (image["CompositeIndex"] == -1).all() and (image["TriangleId"] == -1).all()
