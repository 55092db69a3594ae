"""Camera casts go through the BVH a packet of pixels at a time, culling nodes against the
packet's pixels and depths (with each node's image rectangle, src/projected_scene.hpp) and
testing each triangle only on the pixels its projection can cover (src/traverse_tile.hpp);
without a BVH (``bvh=False``, the one-shot ``vrc.cast``) the triangles are binned to the
tiles their projection touches (src/bin_triangles.hpp). ``Scene.intersect`` on the same
rays traverses the BVH ray by ray. All call the same ray-triangle test, so every pixel must
agree exactly: any pixel a tile path wrongly culled would show here as a miss or a farther
triangle. (Culling by depth trusts the test's t to within rounding: the exact test's always
is; the inexact ones' is on these scenes, not on every grazing ray.)"""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv
from pyvista import examples

import vtkraycast as vrc
from vtkraycast.testing import bumpy_sphere, camera_rays, integer_grid, star_mesh


def assert_same_as_ray_by_ray(scene: vrc.Scene, cam: vrc.Camera, **options) -> int:
    """Checks the BVH scene's packets and a flat scene's bins against ray-by-ray casts."""
    hits = compare(scene, scene, cam, **options)
    assert compare(vrc.Scene(scene.prepared.surface, bvh=False), scene, cam, **options) == hits
    return hits


def compare(scene: vrc.Scene, reference: vrc.Scene, cam: vrc.Camera, **options) -> int:
    image = scene.cast(cam, arrays=["TriangleId", "Depth", "Barycentric"], **options)
    origins, directions = camera_rays(cam)
    scale = 1.0 if cam.parallel else cam.d
    ref = reference.intersect(
        origins,
        directions,
        tmin=cam.near / scale,
        tmax=cam.far / scale,
        **{k: v for k, v in options.items() if k in ("strategy", "precision", "backface_culling")},
    )
    ids = np.asarray(image["TriangleId"])
    np.testing.assert_array_equal(ids, ref["triangle_id"])
    # Asked for ids alone, a tile settles most pixels without their rays' depths (sure hits,
    # traverse_tile.hpp): the same triangles.
    ids_only = scene.cast(cam, arrays=["TriangleId"], **options)["TriangleId"]
    np.testing.assert_array_equal(ids_only, ref["triangle_id"])
    hit = ids >= 0
    depth = np.asarray(image["Depth"])[hit]
    if depth.dtype == np.float64:
        np.testing.assert_array_equal(depth, ref["t"][hit] * scale)
    else:  # float32 t, then scaled: one more rounding than the core's float32(t d)
        np.testing.assert_allclose(depth, ref["t"][hit] * np.float64(scale), rtol=2**-23)
    np.testing.assert_array_equal(np.asarray(image["Barycentric"])[hit], ref["barycentric"][hit])
    return int(hit.sum())


def around(mesh, *, view="iso", nx=61, ny=47, **kw) -> vrc.Camera:
    return vrc.Camera.framing(mesh.bounds, view=view, nx=nx, ny=ny, **kw)


@pytest.mark.parametrize("name", ["airplane", "ant", "nut"])
@pytest.mark.parametrize("view", ["iso", "xy", "-z"])
def test_shipped_meshes(name, view):
    mesh = getattr(examples, f"load_{name}")()
    scene = vrc.Scene(mesh)
    assert assert_same_as_ray_by_ray(scene, around(mesh, view=view)) > 100
    assert assert_same_as_ray_by_ray(scene, around(mesh, view=view, parallel=True, nx=33, ny=70)) > 20


@pytest.mark.parametrize(("offset", "scale"), [(0.0, 1.0), (1e6, 1e-6), (1e8, 1.0), (-3e4, 1e4)])
@pytest.mark.parametrize("parallel", [False, True])
def test_offsets_and_scales(offset, scale, parallel):
    mesh = bumpy_sphere(4, offset=offset, scale=scale)
    scene = vrc.Scene(mesh)
    cam = around(mesh, parallel=parallel, nx=64, ny=48)
    assert assert_same_as_ray_by_ray(scene, cam) > 500


def test_strategies_precisions_and_culling():
    mesh = bumpy_sphere(3)
    scene = vrc.Scene(mesh)
    cam = around(mesh, nx=40, ny=40)
    for strategy in vrc.STRATEGIES:
        for precision in ("float64", "float32"):
            for culling in (False, True):
                options = {"strategy": strategy, "precision": precision, "backface_culling": culling}
                assert assert_same_as_ray_by_ray(scene, cam, **options) > 300


@pytest.mark.parametrize("view", ["+x", "-x", "+y", "-y", "+z", "-z", "iso"])
def test_views_along_each_axis(view):
    """The sure hits' depths and weights are completed four pixels at a time, with the
    shear's axes chosen per lane, or by index when the four rays share them (views along an
    axis): each way, with and without back-face culling (which the axes' order decides),
    the rays cast one by one."""
    mesh = bumpy_sphere(4)
    scene = vrc.Scene(mesh)
    for culling in (False, True):
        assert assert_same_as_ray_by_ray(scene, around(mesh, view=view, nx=80, ny=64), backface_culling=culling) > 900


@pytest.mark.parametrize("offset", [0.0, 1e5])
def test_eye_inside_a_closed_mesh(offset):
    # Triangles all around the eye, some reaching behind its plane (no usable projection),
    # vertices exactly on pixel rays (the stability benchmark's star scenes).
    eye = np.full(3, offset) + [0.3, 0.2, 0.1]
    cam = vrc.Camera(eye, eye + [1, 2, 3], (0, 0, 1), view_angle=120, nx=50, ny=30)
    scene = vrc.Scene(star_mesh(cam, step=3))
    assert assert_same_as_ray_by_ray(scene, cam) == 50 * 30
    cam = vrc.Camera(eye, eye + [0, 0, -1], (0, 1, 0), w=33 / 16, h=25 / 16, nx=33, ny=25)
    assert assert_same_as_ray_by_ray(vrc.Scene(star_mesh(cam)), cam) == 33 * 25


@pytest.mark.parametrize("offset", [0.0, 1e5])
@pytest.mark.parametrize("view_angle", [60, 120, 170])
def test_eye_inside_a_large_mesh(offset, view_angle):
    # Large enough that the camera path prepares the scene: the triangles crossing the eye's
    # plane get the rectangles of their cones over the image (ProjectedScene::cone_rect), and
    # so do the leaves and nodes holding them (a flat scene bins them to those rectangles); a
    # wrong rectangle would show as a miss or a farther triangle. The eye near the surface
    # puts such triangles in the frame, nearby.
    mesh = bumpy_sphere(5, offset=offset)  # 20 k triangles
    scene = vrc.Scene(mesh)
    built = scene.memory_bytes
    centre = np.full(3, offset)
    # a triangle's centre less a fraction of its size along its normal: inside, next to it
    cell = 1234
    normal = mesh.cell_normals[cell]
    near_surface = mesh.cell_centers().points[cell] - centre - 0.005 * normal
    tangent = np.cross(normal, [0, 0, 1])
    views = [
        ([0.0, 0.0, 0.0], [1, 2, 3]),
        (near_surface, tangent + 0.3 * normal),
        (near_surface, tangent - 0.5 * normal),
    ]
    for eye, towards in views:
        cam = vrc.Camera(centre + eye, centre + eye + towards, (0, 0, 1), view_angle=view_angle, nx=128, ny=96)
        assert assert_same_as_ray_by_ray(scene, cam) == 128 * 96
    assert scene.memory_bytes > built  # (prepared, not ray by ray)
    # against Open3D's Embree (float32: a few pixels along edges may differ)
    import open3d as o3d

    peer = o3d.t.geometry.RaycastingScene()
    prepared = scene.prepared
    peer.add_triangles(o3d.core.Tensor((prepared.points - centre).astype(np.float32)),
                       o3d.core.Tensor(prepared.triangles.astype(np.uint32)))  # fmt: skip
    origins, directions = camera_rays(cam)
    ray_rows = np.hstack((origins - centre, directions)).astype(np.float32)
    theirs = peer.cast_rays(o3d.core.Tensor(ray_rows))["primitive_ids"].numpy().astype(np.int64)
    ours = np.asarray(scene.cast(cam, arrays=["TriangleId"])["TriangleId"])
    assert np.mean(theirs == ours) > 0.995


def test_eye_in_the_plane_of_a_terrain():
    # Every triangle of a flat grid reaches behind the eye's plane and the eye lies in their
    # plane (the cones degenerate): beyond `near` no pixel's ray meets the grid; from 0 every
    # ray hits the triangle holding the eye, at the eye, and none from an eye off the grid.
    # Then the eye a little above it.
    grid = pv.Plane(i_size=4, j_size=4, i_resolution=100, j_resolution=100).triangulate()
    scene = vrc.Scene(grid)
    for eye, near, hits in (((0.013, 0.007, 0), 1e-3, 0), ((0.013, 0.007, 0), 0.0, 128 * 96), ((-2.5, 0.1, 0), 0.0, 0)):
        cam = vrc.Camera(eye, np.add(eye, (1, 0.3, 0)), (0, 0, 1), view_angle=90, nx=128, ny=96, near=near)
        assert assert_same_as_ray_by_ray(scene, cam) == hits
    for height in (1e-9, 0.05):
        cam = vrc.Camera((0, 0, height), (1, 0.3, -0.2), (0, 0, 1), view_angle=90, nx=128, ny=96)
        assert assert_same_as_ray_by_ray(scene, cam) > 128 * 40


def shuffled_layers(depths, tilt: float, seed: int = 3) -> pv.PolyData:
    """Square grids of large triangles stacked along z (each tilted by ``tilt`` along x),
    their triangles in a random order: the BVH's leaves mix the layers, so a pixel's
    first candidate is often a layer behind another."""
    rng = np.random.default_rng(seed)
    layers = []
    for z in depths:
        grid = pv.Plane(center=(0, 0, z), i_size=2, j_size=2, i_resolution=4, j_resolution=4).triangulate()
        grid.points[:, 2] += tilt * grid.points[:, 0]
        layers.append(grid)
    merged = pv.merge(layers, merge_points=False)
    faces = merged.faces.reshape(-1, 4)[rng.permutation(merged.n_cells)]
    return pv.PolyData(merged.points, faces.ravel())


@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize(
    ("depths", "tilt"),
    [((0.0, 0.3, 0.6, 0.9), 0.0), ((0.0, 0.3, 0.6, 0.9), 0.4), ((0.0, 0.05, 0.1), 0.5), ((0.0, 1e-9, 0.5), 0.0)],
    ids=["apart", "tilted", "depths overlapping", "coincident"],
)
def test_sure_hits_of_layers_in_any_order(depths, tilt, parallel):
    # A candidate surely hit and surely in front of a pixel's sure hit takes its place
    # (traverse_tile.hpp, test_pixel); one whose depths may overlap it makes the ray.
    mesh = shuffled_layers(depths, tilt)
    cam = vrc.Camera((0.1, 0.2, 2.6), (0.1, 0.2, 0.0), (0, 1, 0), view_angle=45.0, nx=96, ny=80, parallel=parallel)
    if parallel:
        cam = cam.replace(h=2.5, w=3.0)
    hits = assert_same_as_ray_by_ray(vrc.Scene(mesh), cam)
    assert hits > 0.5 * cam.nx * cam.ny


@pytest.mark.parametrize(("centre", "pixel", "n"), [(4.0, 0.25, 32), (4.5, 2.0**-25, 30), (4.0, 1.0, 8), (4.0, 2.0, 4)])
def test_rays_through_vertices_and_edges(centre, pixel, n):
    # Cameras whose pixel centres land on the grid's vertices and edges (at 1 and 2 units
    # a pixel, its triangles are smaller than a pixel: each is binned pixel by pixel on a
    # flat scene). Zoomed in, the
    # centres still lie exactly on a diagonal edge, whose points project 2^24 pixels away,
    # to columns and rows that single precision rounds by half a pixel, both the same way
    # (the footprint that keeps a triangle's pixels must allow for that rounding).
    mesh = integer_grid(8)
    eye, target = (centre, centre, 10), (centre, centre, 0)
    cam = vrc.Camera(eye, target, (0, 1, 0), parallel=True, w=n * pixel, h=n * pixel, nx=n, ny=n)
    assert assert_same_as_ray_by_ray(vrc.Scene(mesh), cam) == n * n
    cam = vrc.Camera(eye, target, (0, 1, 0), d=10, w=n * pixel, h=n * pixel, nx=n, ny=n)
    assert assert_same_as_ray_by_ray(vrc.Scene(mesh), cam) == n * n


def triangles_just_missing_pixel_centres(
    cam: vrc.Camera, gap: float, rng: np.random.Generator, spacing: int = 10
) -> pv.PolyData:
    """Lone triangles, one by every spacing-th pixel centre, each with an edge passing `gap`
    pixels outside that centre at a random angle; their points lie at random depths on the
    rays of non-integer pixel positions, which single precision rounds by far more than the
    gap."""
    points = []
    for row in range(spacing // 2, cam.ny - spacing // 2, spacing):
        for col in range(spacing // 2, cam.nx - spacing // 2, spacing):
            theta = rng.uniform(0, 2 * np.pi)
            u, n = np.array([np.cos(theta), np.sin(theta)]), np.array([-np.sin(theta), np.cos(theta)])
            centre = np.array([col, row], float) + gap * n
            a, b, c, h = rng.uniform(1.3, 3.7, 4)
            for i, r in (centre + a * u, centre - b * u, centre + 0.3 * c * u + h * n):
                # column i, row r (from the bottom) on the image plane, then at depth t
                x, y, z = cam.pixel_center(i, cam.ny - 1 - r)
                t = rng.uniform(2, 4)
                if cam.parallel:
                    points.append(cam.eye + x * cam.right + y * cam.up - t * cam.backward)
                else:
                    points.append(cam.eye + t * (x * cam.right + y * cam.up + z * cam.backward))
    faces = np.c_[np.full(len(points) // 3, 3), np.arange(len(points)).reshape(-1, 3)]
    return pv.PolyData(np.array(points), faces=faces.ravel())


@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize("offset", [0.0, 1234.567])
def test_pixel_centres_just_outside_edges(parallel, offset):
    # A tile settles a pixel without its ray when its centre lies inside a triangle's
    # projection by more than every rounding (sure hits): here the exact rays pass a
    # billionth of a pixel outside, within the single-precision rounding of the projected
    # points, so a bound short of that rounding would claim hits the kernel does not find.
    rng = np.random.default_rng(5)
    eye, target = np.array([0.3, -0.2, 10.0]) + offset, np.full(3, offset)
    cam = vrc.Camera(eye, target, (0.1, 1, 0), view_angle=40, nx=300, ny=260, parallel=parallel)
    scene = vrc.Scene(triangles_just_missing_pixel_centres(cam, 1e-9, rng))
    assert compare(scene, scene, cam) > 3000


@pytest.mark.parametrize("culling", [False, True])
@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize(
    ("subdivisions", "nx", "ny", "least_hits"),
    [
        # 330 k triangles, front and back, a few per pixel: a flat scene bins them pixel by
        # pixel, and each pixel first tests the nearest triangle that seems to cover it.
        (7, 96, 80, 1000),
        # 10 k triangles facing the eye over 33 k pixels: their rectangles hold one to a
        # dozen pixel centres (a leaf's triangles on up to four are tested eight at a time,
        # the rest pixel row by pixel row), many across the 64-pixel tiles' borders.
        (5, 400, 376, 25000),
    ],
    ids=["smaller than pixels", "on a few pixels"],
)
def test_triangles_near_pixel_size(subdivisions, nx, ny, least_hits, culling, parallel):
    mesh = bumpy_sphere(subdivisions)
    cam = around(mesh, parallel=parallel, nx=nx, ny=ny)
    assert assert_same_as_ray_by_ray(vrc.Scene(mesh), cam, backface_culling=culling) > least_hits


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_grazing_rays(precision):
    """A camera just above a tilted plane, looking along it: its rays dip 0.05 to 0.4
    degrees, so t is ill-conditioned, yet the exact test's t stays within the rounding that
    depth culling allows. (The inexact float32 tests do not: on such rays their packets may
    end on another triangle than ray by ray, within their own error; see docs/exactness.md.)"""
    a, b, c = 0.3, -0.2, 0.5
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    rot = rz @ ry @ rx
    plane = pv.Plane(i_size=2, j_size=2, i_resolution=80, j_resolution=80).triangulate()
    points = np.array(plane.points)
    points[:, 2] = 0
    plane.points = points @ rot.T
    eye = rot @ np.array([-1.3, 0.05, 2e-3])
    cam = vrc.Camera(eye, (0, 0, 0), rot @ np.array([0.0, 0.0, 1.0]), view_angle=0.5, nx=96, ny=96)
    assert assert_same_as_ray_by_ray(vrc.Scene(plane), cam, precision=precision) > 96 * 96 // 2  # mostly grazing hits


def test_near_far_and_view_angles():
    mesh = bumpy_sphere(4)
    scene = vrc.Scene(mesh)
    for kw in ({"near": 2.9, "far": 3.3}, {"view_angle": 170}, {"view_angle": 1e-3}):
        cam = vrc.Camera((2.2, 1.6, 1.2), (0, 0, 0), (0, 0, 1), nx=53, ny=31, **kw)
        assert_same_as_ray_by_ray(scene, cam)
    assert assert_same_as_ray_by_ray(scene, vrc.Camera((0.5, 0.1, 0), (1, 0, 0), (0, 0, 1), nx=53, ny=31)) == 53 * 31


def test_small_images_of_large_scenes_go_ray_by_ray():
    """Preparing a camera costs every point and node: a few pixels of a large scene are
    cheaper ray by ray, so such a cast keeps no preparation memory; more pixels do. Both
    give the ray-by-ray images."""
    mesh = bumpy_sphere(6)  # 82 k triangles
    scene = vrc.Scene(mesh)
    built = scene.memory_bytes
    assert compare(scene, scene, around(mesh, nx=16, ny=16)) > 40
    assert scene.memory_bytes == built
    assert compare(scene, scene, around(mesh, nx=256, ny=256)) > 10_000
    assert scene.memory_bytes > built


def test_large_images_stream_their_outputs():
    """A cast whose outputs reach 16 MiB writes them with streaming stores, tile row by tile
    row (src/outputs.hpp, src/render.hpp): the same values as the rays cast one by one, and
    as each array cast alone (below that size, stored through the cache): point and cell
    arrays of four- and eight-byte types, one and three components, and the others."""
    mesh = bumpy_sphere(4)
    mesh.point_data["height"] = mesh.points[:, 2].astype(np.float32)
    mesh.point_data["xyz"] = mesh.points.astype(np.float64)
    mesh.point_data["label"] = np.arange(mesh.n_points, dtype=np.int32)
    mesh.cell_data["area"] = mesh.compute_cell_sizes()["Area"].astype(np.float64)
    mesh.cell_data["index"] = np.arange(mesh.n_cells, dtype=np.int64)
    scene = vrc.Scene(mesh)
    cam = around(mesh, nx=800, ny=700)  # 560 k pixels: 22 MB of TriangleId, Depth and Barycentric
    assert compare(scene, scene, cam) > 100_000
    image = scene.cast(cam)
    names = ["height", "xyz", "label", "area", "index", "CellId", "vtkValidPointMask", "TriangleId"]
    for name in names:  # (the largest alone, xyz, is 13 MB)
        np.testing.assert_array_equal(image[name], scene.cast(cam, arrays=[name])[name], err_msg=name)
    assert np.isnan(image["xyz"][image["TriangleId"] < 0]).all()


def test_one_triangle_in_a_large_frame():
    mesh = bumpy_sphere(0, scale=1e-3)
    cam = vrc.Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), view_angle=30, nx=301, ny=203)
    assert 0 < assert_same_as_ray_by_ray(vrc.Scene(mesh), cam) < 100


def test_flat_scene_is_the_one_shot_cast():
    mesh = bumpy_sphere(3)
    cam = around(mesh)
    flat = vrc.Scene(mesh, bvh=False)
    assert not flat.has_bvh and vrc.Scene(mesh).has_bvh
    assert flat.memory_bytes < vrc.Scene(mesh).memory_bytes
    one_shot = vrc.cast(mesh, cam, arrays=["TriangleId"])
    np.testing.assert_array_equal(one_shot["TriangleId"], flat.cast(cam, arrays=["TriangleId"])["TriangleId"])
    with pytest.raises(ValueError, match="bvh=False"):
        flat.intersect([[0, 0, 5]], [[0, 0, -1]])
    hits = flat.intersect([[0, 0, 5]], [[0, 0, -1]], accel="none")
    assert hits["triangle_id"][0] >= 0
    with pytest.raises(TypeError, match="bvh"):
        vrc.Scene(mesh, bvh="no")


def test_images_wider_than_tiles_index():
    """Image rectangles hold 16-bit pixel indices: a wider image goes ray by ray through
    the BVH, a scene without one refuses it, and the one-shot cast builds a BVH for it."""
    mesh = bumpy_sphere(2)
    cam = vrc.Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), d=1.0, w=1.2, h=1.2 / 70_000, nx=70_000, ny=1)
    scene = vrc.Scene(mesh)
    assert compare(scene, scene, cam) > 1000
    with pytest.raises(ValueError, match="65535 x 65535"):
        vrc.Scene(mesh, bvh=False).cast(cam)
    one_shot = vrc.cast(mesh, cam, arrays=["TriangleId"])["TriangleId"]
    np.testing.assert_array_equal(one_shot, scene.cast(cam, arrays=["TriangleId"])["TriangleId"])


def test_unused_points_are_dropped():
    """The core keeps only the points triangles use, renumbered in the order they are
    first used: points far from the mesh change neither the image nor the memory."""
    mesh = bumpy_sphere(3)
    far = np.vstack([mesh.points, np.random.default_rng(0).uniform(-1e6, 1e6, (500, 3))])
    padded = type(mesh)(far, mesh.faces)
    cam = around(mesh, nx=80, ny=60)
    for bvh in (True, False):
        a, b = vrc.Scene(mesh, bvh=bvh), vrc.Scene(padded, bvh=bvh)
        assert a.memory_bytes == b.memory_bytes
        assert compare(b, vrc.Scene(mesh), cam) > 500
        np.testing.assert_array_equal(a.cast(cam)["Barycentric"], b.cast(cam)["Barycentric"])


def test_casts_keep_their_working_memory():
    """A camera cast's projected points and camera-tree nodes (16 bytes each) stay with the
    scene for the next cast rather than being allocated afresh."""
    mesh = bumpy_sphere(3)
    scene = vrc.Scene(mesh)
    before = scene.memory_bytes
    scene.cast(around(mesh))
    after = scene.memory_bytes
    assert after - before == 16 * (mesh.n_points + scene._core.n_camera_nodes)
    scene.cast(around(mesh, view="xy", nx=120, ny=90))
    assert scene.memory_bytes == after


@pytest.mark.parametrize("parallel", [False, True])
def test_model_outside_the_depth_range(parallel):
    """A model behind the eye, nearer than the near plane or beyond the far plane leaves
    no tile to trace (nothing is projected): every pixel a miss, as ray by ray."""
    mesh = bumpy_sphere(3)
    scene = vrc.Scene(mesh)
    base = vrc.Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), nx=40, ny=30, parallel=parallel, h=3.0)
    for cam in (base.replace(look_at=(0, 0, 6)), base.replace(near=4.5), base.replace(far=1.5)):
        assert assert_same_as_ray_by_ray(scene, cam) == 0
    assert assert_same_as_ray_by_ray(scene, base.replace(near=2.5, far=3.5)) > 10


def test_concurrent_casts_on_one_scene():
    """Casts release the GIL, so Python threads may cast one scene at once: each borrows
    its own working memory from the scene, and every image equals the same cast run alone."""
    from concurrent.futures import ThreadPoolExecutor

    mesh = bumpy_sphere(4)
    scene = vrc.Scene(mesh)
    cams = [around(mesh, view=v, nx=150, ny=110) for v in ("iso", "xy", "xz", "yz", "-z", "+x")]
    alone = [scene.cast(c, arrays=["TriangleId", "Depth"], threads=1) for c in cams]
    with ThreadPoolExecutor(4) as pool:
        together = list(pool.map(lambda c: scene.cast(c, arrays=["TriangleId", "Depth"], threads=1), cams * 3))
    for k, image in enumerate(together):
        np.testing.assert_array_equal(image["TriangleId"], alone[k % len(cams)]["TriangleId"])
        np.testing.assert_array_equal(image["Depth"], alone[k % len(cams)]["Depth"])
    kept = 16 * (mesh.n_points + scene._core.n_camera_nodes)
    assert scene.memory_bytes - vrc.Scene(mesh).memory_bytes in range(kept, 4 * kept + 1, kept)


@pytest.mark.parametrize("build_threads", [1, 2])
def test_node_rectangles_framed_by_many_workers(build_threads):
    """Workers frame the node rectangles a subtree at a time (the camera tree keeps the
    builder's layout, each subtree in one block): any node framed before its children, or
    left unframed, would cull pixels. Two builders (one thread, or subtrees built apart and
    then laid out), a root that is a leaf, and more workers than subtrees to go round."""
    mesh = bumpy_sphere(5)
    scene = vrc.Scene(mesh, threads=build_threads)
    assert scene._core.n_camera_nodes > 500  # many subtrees
    for threads in (1, 2, 5):
        assert assert_same_as_ray_by_ray(scene, around(mesh, nx=160, ny=120), threads=threads) > 3000
    two = pv.Plane(i_resolution=1, j_resolution=1).triangulate()
    assert vrc.Scene(two)._core.n_camera_nodes == 1
    for threads in (1, 3):
        assert compare(vrc.Scene(two), vrc.Scene(two), around(two), threads=threads) > 0


@pytest.mark.parametrize("parallel", [False, True])
def test_views_of_part_of_a_mesh(parallel):
    """A camera frames only the camera tree's subtrees whose boxes it may see, and of the
    others' points projects those that seen subtrees share (ProjectedScene::
    project_and_frame): views of parts of a mesh, cast after a view of the whole (whose
    projections the working memory keeps) and on a scene of their own, equal the rays cast
    one by one."""
    mesh = bumpy_sphere(5)
    scene = vrc.Scene(mesh)
    whole = around(mesh, nx=96, ny=80, parallel=parallel)
    parts = [(0.6, 1.2, -0.3, 0.3, -0.3, 0.3), (-0.2, 0.2, 0.7, 1.2, 0.3, 0.8), (-1.2, -0.5, -1.2, -0.5, -0.2, 0.2)]
    for bounds in parts:
        for view in ("iso", "-z"):
            part = vrc.Camera.framing(bounds, view=view, nx=96, ny=80, parallel=parallel)
            assert assert_same_as_ray_by_ray(scene, whole) > 1000
            assert compare(scene, scene, part) > 1000
            assert compare(vrc.Scene(mesh), scene, part) > 1000


def test_camera_tree_leaves_hold_up_to_63_triangles():
    """Camera casts go through the BVH with every subtree of at most 63 triangles collapsed
    into one leaf (the BVH's own leaves hold at most 8): 63 triangles make one leaf, 64 a
    root over two; casts through either equal the rays cast one by one through the BVH."""
    grid = pv.Plane(i_resolution=8, j_resolution=4).triangulate()
    assert grid.n_cells == 64
    for n, camera_nodes in ((63, 1), (64, 3)):
        mesh = pv.PolyData(grid.points, grid.faces[: 4 * n])
        scene = vrc.Scene(mesh)
        assert scene._core.n_nodes > camera_nodes
        assert scene._core.n_camera_nodes == camera_nodes
        assert compare(scene, scene, around(mesh, view="xy", nx=64, ny=64)) > 1000
