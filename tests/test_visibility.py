"""Every crossing along a ray, crossing counts and inside/outside (Scene.intersect_all,
count_intersections, contains): exact on rays through every vertex and edge of closed
meshes, against geometry (a convex mesh is crossed twice by any line through its
interior), libigl's winding number, VTK's vtkSelectEnclosedPoints and Open3D."""

from __future__ import annotations

import igl
import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc
import vtkraycast.scene as scene_module
from vtkraycast.testing import bumpy_sphere


def _icosphere(offset: float = 0.0, scale: float = 1.0) -> pv.PolyData:
    mesh = pv.Icosphere(radius=scale, nsub=2)
    mesh.points += offset
    return mesh


@pytest.mark.parametrize(("offset", "scale"), [(0.0, 1.0), (1e6, 1.0), (0.0, 1e-6), (1e3, 1e4)])
def test_lines_through_every_vertex_and_edge_cross_a_convex_mesh_twice(offset, scale):
    mesh = _icosphere(offset, scale)
    scene = vrc.Scene(mesh)
    points = mesh.points.astype(np.float64)
    edges = mesh.extract_all_edges().lines.reshape(-1, 3)[:, 1:]
    targets = np.concatenate((points, (points[edges[:, 0]] + points[edges[:, 1]]) / 2))
    centre = np.full(3, offset)
    origins = centre + 3 * (targets - centre)  # outside, aimed through the target at the centre
    counts = scene.count_intersections(origins, targets - origins)
    assert (counts == 2).all(), np.unique(counts, return_counts=True)
    hits = scene.intersect_all(origins, targets - origins)
    t = hits["t"]
    first = hits["ray_splits"][:-1]
    # the first crossing is at the target (t = 1, the vertex or edge point itself)
    np.testing.assert_allclose(t[first], 1.0, rtol=1e-9)
    assert (np.diff(t)[np.diff(hits["ray_ids"]) == 0] >= 0).all()  # sorted by t within a ray


def test_crossings_carry_their_triangle_cell_and_weights():
    mesh = bumpy_sphere(3)
    scene = vrc.Scene(mesh)
    rng = np.random.default_rng(3)
    origins = rng.uniform(-2, 2, (500, 3))
    directions = rng.normal(size=(500, 3))
    hits = scene.intersect_all(origins, directions)
    tri = scene.prepared.triangles[hits["triangle_id"]]
    corners = scene.prepared.points[tri]
    from_weights = np.einsum("nk,nkc->nc", hits["barycentric"], corners)
    along_ray = origins[hits["ray_ids"]] + hits["t"][:, None] * directions[hits["ray_ids"]]
    np.testing.assert_allclose(from_weights, along_ray, atol=1e-9)
    np.testing.assert_array_equal(hits["cell_id"], scene.prepared.cell_ids[hits["triangle_id"]])
    # the first crossing is intersect's closest hit
    closest = scene.intersect(origins, directions)
    has = np.diff(hits["ray_splits"]) > 0
    np.testing.assert_array_equal(closest["triangle_id"] >= 0, has)
    np.testing.assert_array_equal(hits["t"][hits["ray_splits"][:-1][has]], closest["t"][has])
    # rays from the inside of a closed surface cross it an odd number of times
    inside = scene.contains(origins)
    np.testing.assert_array_equal(scene.count_intersections(origins, directions) % 2 == 1, inside)


def test_crossings_do_not_depend_on_other_calls_or_threads():
    """The listing's working memory is kept from call to call and shared by concurrent
    calls in turn: a call after a larger one, and calls from several Python threads at
    once, list what a lone call lists."""
    from concurrent.futures import ThreadPoolExecutor

    scene = vrc.Scene(bumpy_sphere(3))
    rng = np.random.default_rng(5)
    batches = [(rng.uniform(-2, 2, (n, 3)), rng.normal(size=(n, 3))) for n in (30_000, 9_000, 12_000, 5_000)]
    alone = [scene.intersect_all(o, d, threads=1) for o, d in batches]

    def same(found, expected):
        assert found.keys() == expected.keys()
        for name in expected:
            np.testing.assert_array_equal(found[name], expected[name])

    for (o, d), expected in zip(batches[::-1], alone[::-1]):  # (the largest first, then smaller)
        same(scene.intersect_all(o, d, threads=2), expected)
    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(lambda batch: scene.intersect_all(*batch, threads=2), batches * 3))
    for found, expected in zip(results, alone * 3):
        same(found, expected)
    assert sum(len(found["t"]) for found in alone) > 10_000


@pytest.mark.parametrize("level", [4, 6])  # 6: beyond the caches, rays traced eight at a time
def test_counts_agree_with_open3d(level):
    o3d = pytest.importorskip("open3d")
    mesh = bumpy_sphere(level)
    scene = vrc.Scene(mesh)
    rng = np.random.default_rng(5)
    origins = rng.uniform(-2, 2, (20000, 3))
    directions = rng.normal(size=(20000, 3))
    ours = scene.count_intersections(origins, directions)
    peer = o3d.t.geometry.RaycastingScene()
    peer.add_triangles(o3d.core.Tensor(scene.prepared.points.astype(np.float32)),
                       o3d.core.Tensor(scene.prepared.triangles.astype(np.uint32)))  # fmt: skip
    theirs = peer.count_intersections(o3d.core.Tensor(np.hstack((origins, directions)).astype(np.float32))).numpy()
    assert (ours == theirs).mean() > 0.999  # (Open3D rounds rays and points to float32)
    # every crossing listed, ray by ray and by t; the first is the closest hit that testing
    # every triangle finds
    crossings = scene.intersect_all(origins, directions)
    np.testing.assert_array_equal(np.diff(crossings["ray_splits"]), ours)
    assert (np.diff(crossings["ray_ids"]) >= 0).all()
    same_ray = np.diff(crossings["ray_ids"]) == 0
    assert (np.diff(crossings["t"])[same_ray] >= 0).all()
    first = crossings["ray_splits"][:-1][ours > 0]
    closest = scene.intersect(origins[ours > 0][:300], directions[ours > 0][:300], accel="none", arrays="t")["t"]
    np.testing.assert_array_equal(crossings["t"][first[:300]], closest)


@pytest.fixture(params=["grid", "rays"])
def contains_by(request, monkeypatch):
    """contains answers large batches with a grid of cells and small ones with a ray per
    point: the tests that take this run both ways."""
    monkeypatch.setattr(scene_module, "_GRID_POINTS", 0 if request.param == "grid" else 2**62)
    return request.param


@pytest.mark.parametrize("flip", [False, True])
def test_contains_equals_libigl_winding_number(flip, contains_by):
    mesh = bumpy_sphere(3)
    if flip:
        mesh = mesh.copy()
        mesh.flip_faces(inplace=True)
    scene = vrc.Scene(mesh)
    points, triangles = scene.prepared.points, scene.prepared.triangles.astype(np.int64)
    rng = np.random.default_rng(8)
    queries = np.concatenate((
        rng.uniform(-1.5, 1.5, (3000, 3)),
        points * 0.999, points * 1.001,  # beside every vertex, inside and out
        points + np.array([0.0, 0.0, 0.01]),  # aligned with vertices along the axes
        points[triangles].mean(axis=1) * 1.0001,
    ))  # fmt: skip
    winding = igl.winding_number(points, triangles, queries)
    expected = np.abs(winding) > 0.5
    np.testing.assert_array_equal(scene.contains(queries), expected)


def test_contains_agrees_with_vtk_select_enclosed_points(contains_by):
    """VTK's vtkSelectEnclosedPoints votes over rays cast with a tolerance, so it is asked
    only about points clear of the surface (beyond 1 % of the mesh's size, by VTK's own
    implicit distance): there the answers must be the same."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkFiltersModeling import vtkSelectEnclosedPoints

    mesh = bumpy_sphere(4)
    rng = np.random.default_rng(11)
    points = pv.PolyData(rng.uniform(-1.2, 1.2, (3000, 3)))
    clear = np.abs(points.compute_implicit_distance(mesh)["implicit_distance"]) > 0.03
    select = vtkSelectEnclosedPoints()
    select.SetInputData(points)
    select.SetSurfaceData(mesh)
    select.SetTolerance(1e-6)
    select.Update()
    theirs = vtk_to_numpy(select.GetOutput().GetPointData().GetArray("SelectedPoints")).astype(bool)
    ours = vrc.Scene(mesh).contains(points.points)
    assert clear.sum() > 2500 and 0.2 < theirs[clear].mean() < 0.8
    np.testing.assert_array_equal(ours[clear], theirs[clear])


def test_contains_on_a_grid_aligned_with_the_mesh(contains_by):
    # a cube of unit grid squares: query points on the same grid lines as its vertices,
    # so every ray from them is aligned with the vertices in two of three coordinates
    box = pv.Box(bounds=(0, 4, 0, 4, 0, 4), level=3).triangulate().clean()
    scene = vrc.Scene(box)
    grid = np.stack(np.meshgrid(*[np.arange(-1, 5.5, 0.5)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = scene.contains(grid)
    expected = ((grid >= 0) & (grid <= 4)).all(axis=1)  # on the surface counts as inside
    np.testing.assert_array_equal(inside, expected)
    assert inside.shape == (len(grid),)


def _shells() -> pv.PolyData:
    """A bumpy shell around a cavity (an inner sphere facing inwards) and a separate small
    sphere: three regions of empty cells at least, answers that differ between them."""
    outer = bumpy_sphere(4)
    cavity = pv.Icosphere(radius=0.45, nsub=3).flip_faces()
    apart = pv.Icosphere(radius=0.3, center=(2.2, 0.3, -0.1), nsub=2)
    return outer + cavity + apart


@pytest.mark.parametrize(
    ("offset", "scale", "grid"), [(0.0, 1.0, True), (0.0, 1e-6, True), (1e6, 1.0, True), (1e6, 1e-3, False)]
)
def test_contains_over_every_cell_of_the_grid_equals_the_winding_number(offset, scale, grid):
    # Queries on a lattice four times finer than contains' cells (on their bounds, within
    # roundings) and beside every vertex, with half the triangles flipped (parity does
    # not care; the winding number is taken on the mesh as made). Far from the origin
    # for its size the grid cannot place points safely in its cells: rays answer.
    mesh = _shells()
    points, triangles = mesh.points.astype(np.float64), mesh.regular_faces.astype(np.int64)
    rng = np.random.default_rng(11)
    flipped = triangles.copy()
    turn = rng.random(len(triangles)) < 0.5
    flipped[turn] = flipped[turn][:, ::-1]
    scene = vrc.Scene(pv.PolyData.from_regular_faces(points * scale + offset, flipped))
    low, high = points.min(axis=0), points.max(axis=0)
    steps = 4 * round(np.cbrt(scene_module._GRID_CELLS_PER_TRIANGLE * len(triangles)))
    lattice = low + rng.integers(0, steps + 1, (20_000, 3)) / steps * (high - low).max()
    queries = np.concatenate((lattice, points * 0.998, points * 1.002, points + 0.001))
    expected = np.abs(igl.winding_number(points, triangles, queries)) > 0.5
    np.testing.assert_array_equal(scene.contains(queries * scale + offset), expected)
    assert bool(scene._grid) == grid
    assert scene.contains(points * scale + offset).all()  # on the surface: inside


def test_contains_refuses_open_meshes_and_keeps_shapes():
    with pytest.raises(ValueError, match="closed surface"):
        vrc.Scene(pv.Plane()).contains([[0, 0, 0]])
    scene = vrc.Scene(pv.Sphere())
    assert scene.contains(np.zeros((2, 3, 3))).shape == (2, 3)
    assert scene.count_intersections(np.zeros((4, 1, 3)), [[1, 0, 0], [0, 1, 0]]).shape == (4, 2)


CAMERA = vrc.Camera((0.2, -3.0, 0.5), (0, 0, 0), (0, 0, 1), nx=64, ny=48, view_angle=40)


def test_layers_hold_the_crossings_in_order():
    scene = vrc.Scene(bumpy_sphere(3))
    layered = scene.cast(CAMERA, layers=3)
    assert layered.dimensions == (64, 48, 3)
    n = CAMERA.nx * CAMERA.ny
    first = scene.cast(CAMERA)  # the core's ordinary cast: layer 0
    for name in ("TriangleId", "CellId", "Depth", "Barycentric", "vtkValidPointMask"):
        np.testing.assert_array_equal(layered[name][:n], first[name], err_msg=name)
    origins, directions, tmin, tmax = CAMERA.rays()
    hits = scene.intersect_all(origins, directions, tmin=tmin, tmax=tmax)
    counts = np.diff(hits["ray_splits"])
    for layer in (1, 2):
        has = counts > layer
        rows = hits["ray_splits"][:-1][has] + layer
        ids = layered["TriangleId"][layer * n : (layer + 1) * n]
        np.testing.assert_array_equal(ids[has], hits["triangle_id"][rows])
        assert (ids[~has] == -1).all()
        depth = layered["Depth"][layer * n : (layer + 1) * n]
        np.testing.assert_array_equal(depth[has], hits["t"][rows] * CAMERA.d)
    assert (layered["TriangleId"][n : 2 * n] >= 0).sum() > 1000  # the back of the sphere
    with pytest.raises(ValueError, match="layers must be an integer"):
        scene.cast(CAMERA, layers=0)


def test_hit_count_and_thickness_of_a_box_and_a_bumpy_sphere():
    box = pv.Box(bounds=(-0.5, 0.5, -0.5, 0.5, -0.5, 0.5), level=2).triangulate().clean()
    camera = vrc.Camera((0.1, 0.05, 3.0), (0.1, 0.05, 0.0), (0, 1, 0), nx=40, ny=30, h=1.6, parallel=True)
    image = vrc.Scene(box).cast(camera, arrays=["HitCount", "Thickness", "Depth"])
    hit = np.isfinite(image["Depth"])
    assert hit.mean() > 0.2 and image.array_names == ["Depth", "HitCount", "Thickness"]
    np.testing.assert_array_equal(image["HitCount"], np.where(hit, 2, 0))
    np.testing.assert_allclose(image["Thickness"][hit], 1.0, rtol=1e-12)  # the box is 1 deep
    assert (image["Thickness"][~hit] == 0).all()
    scene = vrc.Scene(bumpy_sphere(3))
    image = scene.cast(CAMERA, arrays=["HitCount", "Thickness"])
    origins, directions, tmin, tmax = CAMERA.rays()
    counts = scene.count_intersections(origins, directions, tmin=tmin, tmax=tmax)
    np.testing.assert_array_equal(image["HitCount"], counts)
    inside_eye = vrc.Camera((0, 0, 0), (1, 0, 0), (0, 0, 1), nx=16, ny=16, view_angle=60)
    from_inside = scene.cast(inside_eye, arrays=["HitCount", "Thickness"])  # the eye inside: odd counts
    assert (from_inside["HitCount"] % 2 == 1).all() and (from_inside["Thickness"] > 0.5).all()


def test_visible_cells_and_points_of_a_convex_mesh_face_the_eye():
    mesh = pv.Icosphere(radius=1.0, nsub=3)
    scene = vrc.Scene(mesh)
    camera = vrc.Camera((0.3, -4.0, 1.0), (0, 0, 0), (0, 0, 1), nx=400, ny=400, view_angle=35)
    points, faces = mesh.points.astype(np.float64), mesh.faces.reshape(-1, 4)[:, 1:]
    corners = points[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    facing = np.einsum("ij,ij->i", normals, camera.eye - corners[:, 0]) > 0
    cells = scene.visible_cells(camera)
    assert np.isin(cells, np.flatnonzero(facing)).all()
    assert len(cells) > 0.97 * facing.sum()  # (all but slivers at the silhouette)
    seen = scene.visible_points(camera)
    touching = np.zeros(len(points), bool)  # a vertex of some front-facing face
    touching[faces[facing].ravel()] = True
    surrounded = np.ones(len(points), bool)  # every face around it faces the eye
    np.logical_and.at(surrounded, faces.ravel(), np.repeat(facing, 3))
    assert np.isin(seen, np.flatnonzero(touching)).all()
    assert np.isin(np.flatnonzero(surrounded), seen).all()
    part = scene.extract_visible(camera)
    assert part.n_cells == len(cells)
    np.testing.assert_array_equal(np.sort(part["vtkOriginalCellIds"]), cells)


def test_one_shot_cast_takes_layers_crossing_arrays_and_panoramas():
    mesh = bumpy_sphere(3)
    scene = vrc.Scene(mesh)
    for options in ({"layers": 2}, {"arrays": ["HitCount", "Depth"]}):
        once, built = vrc.cast(mesh, CAMERA, **options), scene.cast(CAMERA, **options)
        for name in built.array_names:
            np.testing.assert_array_equal(once[name], built[name], err_msg=name)
    panorama = vrc.Panorama((0.0, 0.0, 0.0), 32, 16)
    np.testing.assert_array_equal(vrc.cast(mesh, panorama)["Depth"], scene.cast(panorama)["Depth"])
