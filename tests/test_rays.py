"""Scene.intersect's ray API (batch shapes, arrays, position and normal) and Scene.occluded,
against independent references: numpy's geometry of the hit triangles and Open3D's
RaycastingScene (cast_rays, test_occlusions)."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv

import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere


@pytest.fixture(scope="module")
def sphere():
    return vrc.Scene(bumpy_sphere(4))


def random_rays(n: int, seed: int = 0):
    """Origins around the unit sphere's box, aimed at random points of it (some miss)."""
    rng = np.random.default_rng(seed)
    origins = rng.uniform(-2.5, 2.5, (n, 3))
    targets = rng.uniform(-1.2, 1.2, (n, 3))
    return origins, targets - origins


def test_batch_shapes_broadcast(sphere):
    origins = np.zeros((4, 5, 3)) + [0, 0, 3]
    directions = np.array([0.01, 0.02, -1.0])
    hits = sphere.intersect(origins, directions)
    assert set(hits) == {"triangle_id", "cell_id", "t", "barycentric"}
    assert hits["triangle_id"].shape == (4, 5) and hits["barycentric"].shape == (4, 5, 3)
    flat = sphere.intersect(origins.reshape(-1, 3), np.tile(directions, (20, 1)))
    np.testing.assert_array_equal(hits["triangle_id"].ravel(), flat["triangle_id"])
    one = sphere.intersect([0, 0, 3], directions, arrays="t")
    assert one["t"].shape == () and one["t"] == flat["t"][0]
    with pytest.raises(ValueError, match="do not broadcast"):
        sphere.intersect(np.zeros((4, 3)), np.ones((5, 3)))
    for bad in ((np.zeros((4, 2)), np.ones((4, 2))), (np.zeros(3), np.ones((4, 2)))):
        with pytest.raises(ValueError, match=r"shape \(\.\.\., 3\)"):
            sphere.intersect(*bad)
    with pytest.raises(ValueError, match="unknown ray array 'depth'"):
        sphere.intersect(origins, directions, arrays=["depth"])


def test_position_and_normal_are_the_hit_triangles(sphere):
    origins, directions = random_rays(4000)
    hits = sphere.intersect(origins, directions, arrays=["triangle_id", "t", "barycentric", "position", "normal"])
    assert list(hits) == ["triangle_id", "t", "barycentric", "position", "normal"]
    hit = hits["triangle_id"] >= 0
    assert 0.3 < hit.mean() < 0.9
    points, triangles = sphere.prepared.points, sphere.prepared.triangles
    corners = points[triangles[hits["triangle_id"][hit]]]  # (h, 3, 3)
    np.testing.assert_allclose(
        hits["position"][hit], origins[hit] + hits["t"][hit, None] * directions[hit], rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(
        hits["position"][hit], np.einsum("hk,hkc->hc", hits["barycentric"][hit], corners), rtol=0, atol=1e-12
    )
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    np.testing.assert_allclose(hits["normal"][hit], normal / np.linalg.norm(normal, axis=1)[:, None], atol=1e-12)
    assert np.isnan(hits["position"][~hit]).all() and np.isnan(hits["normal"][~hit]).all()


def test_against_open3d_cast_rays(sphere):
    o3d = pytest.importorskip("open3d")
    origins, directions = random_rays(20000, seed=1)
    peer = o3d.t.geometry.RaycastingScene()
    peer.add_triangles(
        o3d.core.Tensor(sphere.prepared.points.astype(np.float32)),
        o3d.core.Tensor(sphere.prepared.triangles.astype(np.uint32)),
    )
    rays = o3d.core.Tensor(np.hstack((origins, directions)).astype(np.float32))
    theirs = peer.cast_rays(rays)
    ours = sphere.intersect(origins, directions, arrays=["triangle_id", "t", "normal"])
    ids = theirs["primitive_ids"].numpy().astype(np.int64)
    ids[ids == np.iinfo(np.uint32).max] = -1
    assert np.mean(ours["triangle_id"] == ids) > 0.999  # float32 rays: a few edge rays differ
    both = (ours["triangle_id"] == ids) & (ids >= 0)
    # (Open3D's float32 origins and directions: t off by their rounding, 1e-6 absolute here)
    np.testing.assert_allclose(ours["t"][both], theirs["t_hit"].numpy()[both], rtol=1e-5, atol=2e-6)
    np.testing.assert_allclose(ours["normal"][both], theirs["primitive_normals"].numpy()[both], atol=1e-5)
    occluded = peer.test_occlusions(rays, tnear=0.0, tfar=0.6).numpy()
    assert np.mean(sphere.occluded(origins, directions, tmax=0.6) == occluded) > 0.999


def test_a_large_batch_answers_as_small_ones_and_open3d(sphere):
    # 200 k rays with every array are 19 MB of outputs: past 16 MB they are written by
    # streaming stores, small batches through the cache.
    o3d = pytest.importorskip("open3d")
    origins, directions = random_rays(200_000, seed=3)
    names = ["triangle_id", "cell_id", "t", "barycentric", "position", "normal"]
    large = sphere.intersect(origins, directions, arrays=names)
    for first in range(0, 200_000, 40_000):
        part = slice(first, first + 40_000)
        small = sphere.intersect(origins[part], directions[part], arrays=names)
        for name in names:
            np.testing.assert_array_equal(large[name][part], small[name], err_msg=name)
    peer = o3d.t.geometry.RaycastingScene()
    peer.add_triangles(
        o3d.core.Tensor(sphere.prepared.points.astype(np.float32)),
        o3d.core.Tensor(sphere.prepared.triangles.astype(np.uint32)),
    )
    theirs = peer.cast_rays(o3d.core.Tensor(np.hstack((origins, directions)).astype(np.float32)))
    ids = theirs["primitive_ids"].numpy().astype(np.int64)
    ids[ids == np.iinfo(np.uint32).max] = -1
    assert np.mean(large["triangle_id"] == ids) > 0.999
    hit = large["triangle_id"] >= 0
    np.testing.assert_allclose(
        large["position"][hit], origins[hit] + large["t"][hit, None] * directions[hit], rtol=0, atol=1e-12
    )
    assert (large["cell_id"][~hit] == -1).all() and np.isnan(large["barycentric"][~hit]).all()


def test_the_usual_call_answers_as_the_general_way():
    """Calls with float64 arrays (n, 3) or (3,) go the core's quick way (_core.quick_rays:
    it makes the outputs itself); their answers equal those of the general way (taken by
    naming the strategy "auto" stands for), and a hit's cell id is the input cell (quads of
    two triangles each) whose rectangle holds the hit point."""
    mesh = pv.Plane(i_size=1, j_size=1, i_resolution=7, j_resolution=5)
    scene = vrc.Scene(mesh)
    rng = np.random.default_rng(8)
    origins = rng.uniform(-0.7, 0.7, (400, 3)) + [0, 0, 1]
    directions = rng.uniform(-0.5, 0.5, (400, 3)) - [0, 0, 1]
    directions[::3] *= -1  # some rays leave the plane behind, some meet its back
    every = ["normal", "t", "triangle_id", "position", "cell_id", "barycentric"]
    for tmin, tmax, culling, arrays in (
        (0.0, np.inf, False, None),
        (0.5, 1.2, False, every),
        (0, np.inf, True, ["position"]),
    ):
        assert scene._quick_rays(origins, directions, tmin, tmax, None, culling, arrays or ["t"]) is not None
        options = dict(tmin=tmin, tmax=tmax, backface_culling=culling, arrays=arrays)
        quick = scene.intersect(origins, directions, **options)
        general = scene.intersect(origins, directions, **options, strategy="watertight")
        assert list(quick) == (arrays or ["triangle_id", "cell_id", "t", "barycentric"])
        for name in quick:
            assert quick[name].dtype == general[name].dtype
            np.testing.assert_array_equal(quick[name], general[name], err_msg=name)
        np.testing.assert_array_equal(
            scene.occluded(origins, directions, tmin=tmin, tmax=tmax, backface_culling=culling),
            scene.occluded(origins, directions, tmin=tmin, tmax=tmax, backface_culling=culling, strategy="watertight"),
        )
    hits = scene.intersect(origins, directions)
    hit = hits["triangle_id"] >= 0
    assert 0.2 < hit.mean() < 0.8
    points = origins[hit] + hits["t"][hit, None] * directions[hit]
    centres = mesh.cell_centers().points[hits["cell_id"][hit]]
    assert (np.abs(points - centres)[:, :2] <= [1 / 14 + 1e-12, 1 / 10 + 1e-12]).all()
    for o, d in ((origins[5], directions[5]), (origins[5].tolist(), tuple(directions[5]))):
        one = scene.intersect(o, d)
        assert one["triangle_id"].shape == () and one["barycentric"].shape == (3,)
        for name in one:
            np.testing.assert_array_equal(one[name], hits[name][5], err_msg=name)
        assert scene.occluded(o, d).shape == ()
    for o, d in ((origins[7], directions), (origins, directions[7])):  # one origin or direction for all
        assert scene._quick_rays(o, d, 0.0, np.inf, None, False, every) is not None  # (one origin: read as one row)
        broadcast = scene.intersect(o, d, arrays=every)
        copied = np.broadcast_to(o, (400, 3)).copy(), np.broadcast_to(d, (400, 3)).copy()
        general = scene.intersect(*copied, arrays=every, strategy="watertight")
        assert 0.2 < (broadcast["triangle_id"] >= 0).mean() < 0.8
        for name in every:
            np.testing.assert_array_equal(broadcast[name], general[name], err_msg=name)
        np.testing.assert_array_equal(scene.occluded(o, d), scene.occluded(*copied, strategy="watertight"))
    big = vrc.Scene(mesh.scale(8, inplace=False))
    whole = np.round(origins * 8).astype(int), np.round(directions * 8).astype(int)  # the same rays as floats
    ints, floats = big.intersect(*whole), big.intersect(*(a.astype(float) for a in whole))
    assert (ints["triangle_id"] >= 0).mean() > 0.2
    for name in ints:
        np.testing.assert_array_equal(ints[name], floats[name], err_msg=name)


def test_unusual_calls_go_the_general_way(sphere):
    """Rays the quick way cannot take as they are (directions shifted in the core, origins
    beyond its bound, bad values) are left to the general way, which casts them or raises."""
    origins, directions = random_rays(500, seed=9)
    hits = sphere.intersect(origins, directions)
    short = directions * 2.0**-40
    assert sphere._quick_rays(origins, short, 0.0, np.inf, None, False, ["t"]) is None
    np.testing.assert_array_equal(sphere.intersect(origins, short)["t"], hits["t"] * 2.0**40)
    as_float = sphere.intersect(origins.astype(np.float32), directions.astype(np.float32))
    assert (as_float["triangle_id"] == hits["triangle_id"]).mean() > 0.99
    far = origins.copy()
    far[7] = [1e95, 0, 0]
    assert sphere._quick_rays(far, directions, 0.0, np.inf, None, False, ["t"]) is None
    with pytest.raises(ValueError, match=r"a ray origin lies .* from the scene's centre"):
        sphere.intersect(far, directions)
    bad = origins.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="origins must be finite; row 3"):
        sphere.intersect(bad, directions)
    zero = directions.copy()
    zero[4] = 0
    with pytest.raises(ValueError, match="directions must be non-zero"):
        sphere.occluded(origins, zero)
    with pytest.raises(ValueError, match="tmin must be >= 0"):
        sphere.intersect(origins, directions, tmin=-1.0)
    with pytest.raises(TypeError, match="origins must be numeric"):
        sphere.intersect(origins > 0, directions)
    with pytest.raises(ValueError, match="inhomogeneous"):
        sphere.occluded([[0, 0, 3], [0, 0]], [0, 0, -1])


@pytest.mark.parametrize("accel", ["bvh", "none"])
@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_occluded_is_intersect_finding_a_hit_in_range(sphere, accel, precision):
    origins, directions = random_rays(3000, seed=2)
    for tmin, tmax in ((0.0, np.inf), (0.0, 0.5), (0.4, 0.8), (0.7, 0.7)):
        found = sphere.intersect(origins, directions, tmin=tmin, tmax=tmax, accel=accel, precision=precision)
        occluded = sphere.occluded(origins, directions, tmin=tmin, tmax=tmax, accel=accel, precision=precision)
        assert occluded.dtype == bool and occluded.shape == (3000,)
        np.testing.assert_array_equal(occluded, found["triangle_id"] >= 0)


def test_occluded_from_inside_a_closed_mesh_is_always_true():
    scene = vrc.Scene(pv.Sphere(theta_resolution=40, phi_resolution=40))
    directions = np.random.default_rng(3).normal(size=(5000, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    assert scene.occluded(np.zeros(3), directions).all()
    assert not scene.occluded(np.zeros(3), directions, tmax=0.4).any()  # radius 0.5


def test_occluded_just_inside_and_just_outside_its_range():
    """occluded takes a hit the leaf filter finds certain without the exact test
    (traverse_wide.hpp): never one a hair beyond tmin or tmax, nor a back face culled."""
    scene = vrc.Scene(pv.Plane(i_size=2, j_size=2, i_resolution=30, j_resolution=30))
    rng = np.random.default_rng(5)
    origins = np.column_stack([rng.uniform(-0.9, 0.9, (2000, 2)), rng.uniform(0.2, 3, 2000)])
    directions = rng.uniform(-0.3, 0.3, (2000, 3)) - [0, 0, 1]
    t = scene.intersect(origins, directions)["t"]
    origins, directions = origins[t < np.inf], directions[t < np.inf] * t[t < np.inf, None]  # every hit now at t = 1
    assert len(origins) > 1000
    assert np.abs(scene.intersect(origins, directions)["t"] - 1).max() < 1e-14
    for tmin, tmax, hit in (
        (0.0, 1 - 1e-9, False),
        (0.0, 1 + 1e-9, True),
        (1 - 1e-9, 5.0, True),
        (1 + 1e-9, 5.0, False),
    ):
        np.testing.assert_array_equal(scene.occluded(origins, directions, tmin=tmin, tmax=tmax), hit)
    assert scene.occluded(origins, directions, backface_culling=True).all()  # (the plane faces +z)
    assert not scene.occluded(origins * [1, 1, -1], directions * [1, 1, -1], backface_culling=True).any()
    assert scene.occluded(origins * [1, 1, -1], directions * [1, 1, -1]).all()


def test_rays_through_a_scene_beyond_the_caches_match_every_triangle_tested():
    """Scenes this large trace several rays at a time, steps interleaved (render.hpp,
    trace_rays_interleaved); the answers are still the closest hits the kernel finds when
    it meets every triangle (accel="none"), bit for bit, for closest and any hit."""
    scene = vrc.Scene(bumpy_sphere(6))
    assert scene.n_triangles == 81920 and scene.memory_bytes > 4 << 20  # past the 2 MiB of render.hpp
    origins, directions = random_rays(400, seed=4)
    origins[:5] = [[1e19, 0, 0]] * 5  # beyond float's reach of the boxes: traced alone, in double
    directions[:5] = [[-1, 1e-20, 0], [-1, 0, 0], [-1, 0.1, 0.1], [-1, -0.2, 0.3], [1, 0, 0]]
    for tmin, tmax in ((0.0, np.inf), (0.5, 2.5)):
        bvh = scene.intersect(origins, directions, tmin=tmin, tmax=tmax, threads=2)
        every = scene.intersect(origins, directions, tmin=tmin, tmax=tmax, accel="none", threads=2)
        assert 0.2 < np.mean(bvh["triangle_id"] >= 0) < 0.95
        for name in bvh:
            np.testing.assert_array_equal(bvh[name], every[name], err_msg=name)
        np.testing.assert_array_equal(
            scene.occluded(origins, directions, tmin=tmin, tmax=tmax), every["triangle_id"] >= 0
        )


def test_rays_from_the_box_middle_through_tiny_triangles_around_it():
    """A lidar or camera in the middle of a scene's box sits at the core's origin, where
    node bounds can be tiny or subnormal; they are moved outward off such magnitudes
    (src/wide_bvh.hpp, kTinyBound: subnormal numbers cost Intel cores a hundred cycles per
    instruction). Rays from that middle, and from points 1e-30 off it, to triangles within
    1e-21 and 1e-40 of it and to a cube around it find the hits of every triangle tested
    (accel="none"), bit for bit."""
    rng = np.random.default_rng(5)
    cube = pv.Cube(x_length=2, y_length=2, z_length=2).triangulate()  # (its box's middle: 0)
    corners = np.concatenate([rng.normal(scale=1e-21, size=(150, 3, 3)), rng.normal(scale=1e-40, size=(50, 3, 3))])
    points = np.concatenate([cube.points, corners.reshape(-1, 3)])
    tiny = len(cube.points) + np.arange(3 * len(corners)).reshape(-1, 3)
    triangles = np.concatenate([cube.regular_faces, tiny])
    scene = vrc.Scene(pv.PolyData(points, np.column_stack([np.full(len(triangles), 3), triangles]).ravel()))
    n = 4000
    origins = np.zeros((n, 3))
    origins[n // 2 :] = rng.normal(scale=1e-30, size=(n - n // 2, 3))
    targets = corners[rng.integers(0, len(corners), n)].mean(axis=1)
    directions = np.where(rng.uniform(size=(n, 1)) < 0.8, targets - origins, rng.normal(size=(n, 3)))
    bvh = scene.intersect(origins, directions, arrays=["triangle_id", "t"])
    every = scene.intersect(origins, directions, arrays=["triangle_id", "t"], accel="none")
    assert np.mean(bvh["triangle_id"] >= len(cube.regular_faces)) > 0.3  # (many hit the tiny ones)
    for name in bvh:
        np.testing.assert_array_equal(bvh[name], every[name], err_msg=name)


@pytest.mark.parametrize("directions", ["fisheye", "unrelated", "vertices", "vertices at 1e5"])
def test_one_origin_and_a_grid_of_directions_equal_ray_by_ray(directions):
    """One origin with (rows, columns, 3) directions goes in bundles (as a lidar does): the
    same answers as the same rays with the origin repeated (ray by ray), whether the grid
    is coherent (an equidistant fisheye camera; rays aimed at every vertex of a height
    field, within rounding of it, where the bundles' culling by projection meets edge
    functions near zero) or not (random directions: each tile then goes ray by ray)."""
    scene = vrc.Scene(bumpy_sphere(5))
    eye = np.array([0.4, -2.6, 0.9])
    if directions.startswith("vertices"):
        offset = 1e5 if directions.endswith("1e5") else 0.0
        x, y = np.meshgrid(np.linspace(-1, 1, 160), np.linspace(-1, 1, 120))
        z = 0.1 * np.sin(3.1 * x) * np.cos(2.3 * y) + 0.05 * np.random.default_rng(5).random(x.shape)
        field = (
            pv.StructuredGrid(x + offset, y + offset, z + offset)
            .extract_surface(algorithm="dataset_surface")
            .triangulate()
        )
        scene = vrc.Scene(field)
        eye = np.array([0.13, -0.41, 1.7]) + offset
        grid = np.stack([x, y, z], axis=-1) + offset - eye
    elif directions == "fisheye":
        forward = -eye / np.linalg.norm(eye)
        right = np.cross(forward, [0, 0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        u, v = np.meshgrid(np.linspace(-1, 1, 160), np.linspace(-1, 1, 120))
        theta, phi = np.hypot(u, v) * np.radians(60), np.arctan2(v, u)  # 120-degree field
        across = np.cos(phi)[..., None] * right + np.sin(phi)[..., None] * up
        grid = np.cos(theta)[..., None] * forward + np.sin(theta)[..., None] * across
    else:
        grid = np.random.default_rng(3).normal(size=(120, 160, 3))
    arrays = ["triangle_id", "t", "barycentric", "position", "normal"]
    bundled = scene.intersect(eye, grid, arrays=arrays)
    one_by_one = scene.intersect(np.broadcast_to(eye, grid.shape), grid, arrays=arrays)
    if directions.startswith("vertices"):  # (rays at the field's border pass it by)
        assert np.mean(one_by_one["triangle_id"] >= 0) > 0.9
    else:
        assert 0.01 < np.mean(one_by_one["triangle_id"] >= 0) < 0.95
    for name in arrays:
        np.testing.assert_array_equal(bundled[name], one_by_one[name])


@pytest.mark.parametrize("offset", [0.0, 1e5])
def test_rays_leaving_every_vertex_of_a_convex_mesh(offset):
    # Each ray starts exactly on a vertex: the edges through it meet the ray at its origin
    # (zero edge functions, settled exactly). Through the centre it next meets the antipodal
    # vertex (an icosphere is centrally symmetric) at t = 2; outwards, nothing; with tmin = 0
    # both meet a triangle of the vertex at t = 0.
    mesh = pv.Icosphere(radius=1.0, nsub=3).translate((offset, offset, offset))
    scene = vrc.Scene(mesh)
    points = np.asarray(mesh.points)
    centre = np.full(3, offset)
    out = points - centre
    faces = mesh.faces.reshape(-1, 4)[:, 1:]
    through = scene.intersect(points, -out, tmin=1e-9)
    np.testing.assert_allclose(through["t"], 2.0, atol=1e-9)
    antipode = np.argmin(np.linalg.norm(points[:, None] + points[None] - 2 * centre, axis=2), axis=1)
    assert (faces[through["triangle_id"]] == antipode[:, None]).any(axis=1).all()
    assert scene.occluded(points, -out, tmin=1e-9).all()
    assert not scene.occluded(points, out, tmin=1e-9).any()
    assert (scene.intersect(points, out, tmin=1e-9)["triangle_id"] == -1).all()
    for direction in (out, -out):
        at_origin = scene.intersect(points, direction)
        assert (at_origin["t"] == 0).all()
        assert (faces[at_origin["triangle_id"]] == np.arange(len(points))[:, None]).any(axis=1).all()
