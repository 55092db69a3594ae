"""vtkraycast against an independent ray caster: libigl's AABB tree (``igl.AABB``).

The same rays go through both: camera rays are rebuilt here in numpy from the documented
pixel model (DESIGN.md), so an error in the camera convention, the traversal or the
triangle test shows up as a disagreement. libigl intersects with Moeller-Trumbore in
double precision but hands back ``t`` and the barycentric ``(u, v)`` rounded to float32
(checked below), which sets the tolerances on depth and weights.

Where the two report different triangles, the disagreement must be *certified* as a ray
that grazes a triangle edge or vertex, with Shewchuk's exact ``igl.predicates.orient3d``:
see :func:`explain_disagreements`.
"""

from __future__ import annotations

from collections import Counter

import igl
import numpy as np
import pytest
import pyvista as pv
from igl.predicates import orient3d
from pyvista import examples

import vtkraycast as vrc

MESHES = {
    "airplane": examples.load_airplane,
    "ant": examples.load_ant,
    "nut": examples.load_nut,
    "sphere": examples.load_sphere,
}

#: libigl rounds t and (u, v) to float32: |fl32(x) - x| <= 2**-24 |x|.
F32_ROUND = 2.0**-24
#: Slack for the two double-precision kernels (Moeller-Trumbore vs watertight) differing.
F64_SLACK = 1e-9
#: A disagreement must be explained by a ray within DELTA_REL * (mesh radius) of an edge.
DELTA_REL = 1e-9


class Reference:
    """A shipped mesh, its vtkraycast scene and a libigl tree over the *same* triangles."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.seed = list(MESHES).index(name)
        self.mesh = MESHES[name]()
        if not self.mesh.is_all_triangles:  # vrc triangulates itself; libigl needs triangles
            self.mesh = self.mesh.triangulate()
        self.scene = vrc.Scene(self.mesh)
        self.V = self.scene.prepared.points
        self.F = self.scene.prepared.triangles.astype(np.int64)
        self.tree = igl.AABB()
        self.tree.init(self.V, self.F)
        self.center = 0.5 * (self.V.min(0) + self.V.max(0))
        self.radius = float(np.linalg.norm(self.V - self.center, axis=1).max())

    def igl(self, origins: np.ndarray, directions: np.ndarray):
        ids, t, uv = self.tree.intersect_ray_first(self.V, self.F, origins, directions)
        return ids, t, uv


@pytest.fixture(scope="module", params=list(MESHES))
def ref(request) -> Reference:
    return Reference(request.param)


def camera_rays(cam: vrc.Camera) -> tuple[np.ndarray, np.ndarray]:
    """Rays of every output pixel, rebuilt from the documented model: pixel (i, r), row r = 0
    at the bottom, is point i + r nx; its centre (x, y, -d) = pixel_center(i, ny - 1 - r);
    origin = eye, direction = x right + y up - d backward (so depth = t d)."""
    nx, ny = cam.nx, cam.ny
    i = np.tile(np.arange(nx), ny)
    j = ny - 1 - np.repeat(np.arange(ny), nx)
    x = -cam.w * 0.5 + cam.w / nx * (i + 0.5)
    y = cam.h * 0.5 - cam.h / ny * (j + 0.5)
    directions = x[:, None] * cam.right + y[:, None] * cam.up - cam.d * cam.backward
    origins = np.ascontiguousarray(np.broadcast_to(cam.eye, directions.shape))
    return origins, np.ascontiguousarray(directions)


def random_cameras(ref: Reference, seed: int, n: int = 3, nx: int = 160, ny: int = 120) -> list[vrc.Camera]:
    """Perspective cameras with the eye on a sphere of 1.5-3 mesh radii, looking near the centre."""
    rng = np.random.default_rng(seed)
    cams = []
    for _ in range(n):
        u = rng.normal(size=3)
        eye = ref.center + u / np.linalg.norm(u) * ref.radius * rng.uniform(1.5, 3.0)
        look = ref.center + rng.uniform(-0.1, 0.1, 3) * ref.radius
        cams.append(
            vrc.Camera(
                eye,
                look,
                rng.normal(size=3),
                d=rng.uniform(0.5, 2.0),
                view_angle=rng.uniform(25, 50),
                nx=nx,
                ny=ny,
            )
        )
    return cams


# --- exact certificates ------------------------------------------------------------------


def line_meets_triangle(o: np.ndarray, p: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Exactly: does the line through o and p meet the closed triangle P[k] = (a, b, c)?

    The line crosses the triangle iff the three tetrahedra (o, p, a, b), (o, p, b, c),
    (o, p, c, a) do not have opposite orientations (zero = on an edge counts as meeting)."""
    o, p = np.ascontiguousarray(o, dtype=np.float64), np.ascontiguousarray(p, dtype=np.float64)
    s = np.stack(
        [orient3d(o, p, np.ascontiguousarray(P[:, e]), np.ascontiguousarray(P[:, (e + 1) % 3])) for e in range(3)],
        -1,
    )
    return ~((s > 0).any(-1) & (s < 0).any(-1)) & (s != 0).any(-1)


def edge_certificates(o, d, t, P, delta):
    """Per ray (o, d) and triangle P at ray parameter ~t: ``(meets, near)``.

    The triangle is centrally projected from o onto the plane through q = o + t d
    perpendicular to d (the ray is the plane's origin). In that plane (floats, error ~1e-16
    of the mesh size, far below ``delta``) b is the point of the triangle's boundary
    nearest the ray and g its centroid; Y_in = b + eta (g - b) lies inside and
    Y_out = b - eta (g - b) outside (convexity), both within delta of the ray.

    - near: the boundary is within delta/2 of the ray AND, with exact predicates, the line
      o-Y_in meets the triangle and the line o-Y_out misses it. So two lines through the
      ray's origin, each passing within delta of the ray at the hit, disagree about the
      triangle: the ray is within delta of an edge (or vertex).
    - meets: the ray's own line meets the triangle exactly, or the Y_in line does (then
      the triangle is hit by a line within delta of the ray).
    """
    m = len(o)
    dn = d / np.linalg.norm(d, axis=1, keepdims=True)
    tau = t * np.linalg.norm(d, axis=1)
    q = o + dn * tau[:, None]
    helper = np.where(np.abs(dn[:, :1]) < 0.6, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    n1 = np.cross(dn, helper)
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    n2 = np.cross(dn, n1)
    rel = P - o[:, None]
    ahead = (rel * dn[:, None]).sum(-1)
    in_front = (ahead > 0).all(1)  # every vertex in front of the origin: projection is valid
    proj = rel * (tau[:, None] / np.where(ahead > 0, ahead, np.nan))[..., None]
    uv = np.stack([(proj * n1[:, None]).sum(-1), (proj * n2[:, None]).sum(-1)], -1)
    closest = []
    for e in range(3):
        a, b = uv[:, e], uv[:, (e + 1) % 3]
        ab = b - a
        s = np.clip(-(a * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-300), 0.0, 1.0)
        closest.append(a + s[:, None] * ab)
    closest = np.stack(closest, 1)
    dist = np.nan_to_num(np.linalg.norm(closest, axis=-1), nan=np.inf)
    k = np.argmin(dist, 1)
    b = closest[np.arange(m), k]
    rho = dist[np.arange(m), k]
    gb = uv.mean(1) - b
    eta = np.minimum(0.5, 0.25 * delta / np.maximum(np.linalg.norm(gb, axis=-1), 1e-300))

    def world(p2):
        return q + p2[:, :1] * n1 + p2[:, 1:] * n2

    y_in, y_out = world(b + eta[:, None] * gb), world(b - eta[:, None] * gb)
    close = in_front & (rho <= 0.5 * delta)
    cert_in = line_meets_triangle(o, y_in, P)
    near = close & cert_in & ~line_meets_triangle(o, y_out, P)
    meets = line_meets_triangle(o, q, P) | (close & cert_in)
    return meets, near


def plane_t(o, d, P):
    """Ray parameter of the triangle's plane, in double."""
    n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    return ((P[:, 0] - o) * n).sum(-1) / (d * n).sum(-1)


def explain_disagreements(ref: Reference, o, d, ours, theirs, delta):
    """Category of each ray on which vtkraycast (``ours``) and libigl (``theirs``) report
    different triangles, or ``None`` when the disagreement is not explained.

    A disagreement is explained when every reported triangle is met by the ray's line
    (or one within ``delta``), and either

    - "edge": the nearer reported triangle (by the plane depth in double) has an edge or
      vertex within ``delta`` of the ray, certified by exact predicates (see
      :func:`edge_certificates`). Such a ray is decided by rounding: either side of the
      edge is a correct answer, and the kernels round differently; or
    - "depth tie": both hit, at depths equal within libigl's float32 ``t`` (it cannot
      order them).

    ``delta`` = 1e-9 mesh radii is ~1e7 ulps of the coordinates: generous for rounding,
    yet a wrong triangle (a neighbour across an edge the ray is not near, or a miss of a
    triangle hit in its interior) is rejected, as ``test_certificate_rejects_wrong_answers``
    shows.
    """
    m = len(o)
    ids = np.stack([ours, theirs], 1)
    t = np.full((m, 2), np.inf)
    meets = np.ones((m, 2), bool)
    near = np.zeros((m, 2), bool)
    for side in range(2):
        h = np.flatnonzero(ids[:, side] >= 0)
        if h.size == 0:
            continue
        P = ref.V[ref.F[ids[h, side]]]
        t[h, side] = plane_t(o[h], d[h], P)
        meets[h, side], near[h, side] = edge_certificates(o[h], d[h], t[h, side], P, np.full(h.size, delta))
    nearer = np.argmin(t, 1)
    edge = near[np.arange(m), nearer]
    both = (ids >= 0).all(1)
    tie = both & (np.abs(t[:, 0] - t[:, 1]) <= 2 * F32_ROUND * t.min(1))
    out = []
    for k in range(m):
        if not meets[k].all():
            out.append(None)
        elif edge[k]:
            out.append("edge (silhouette)" if not both[k] else "edge (shared)" if tie[k] else "edge (occluding)")
        elif tie[k]:
            out.append("depth tie")
        else:
            out.append(None)
    return out


def compare_ids(ref, o, d, ours, theirs, label):
    """Agreement fractions; asserts every disagreement is explained; prints the figures."""
    n = len(ours)
    same = ours == theirs
    same_hit = (ours >= 0) == (theirs >= 0)
    bad = np.flatnonzero(~same)
    kinds = explain_disagreements(ref, o[bad], d[bad], ours[bad], theirs[bad], DELTA_REL * ref.radius)
    tally = Counter(k or "UNEXPLAINED" for k in kinds)
    print(
        f"\n[libigl {label} {ref.name}] {n} rays, hits {np.mean(ours >= 0):.3f}: "
        f"TriangleId agreement {same.mean():.5%} ({bad.size} differ: {dict(tally)}), "
        f"hit/miss agreement {same_hit.mean():.5%}"
    )
    unexplained = [int(i) for i, k in zip(bad, kinds) if k is None]
    assert not unexplained, f"rays {unexplained[:10]}: ours {ours[unexplained[:10]]}, libigl {theirs[unexplained[:10]]}"
    return same.mean(), same_hit.mean()


# --- the tests ---------------------------------------------------------------------------


def test_libigl_returns_float32_rounded_t_and_uv():
    """The tolerances below rest on this: libigl computes in double but returns t and (u, v)
    rounded to float32, and weights (1 - u - v, u, v) for the triangle's points in order."""
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    F = np.array([[0, 1, 2]], np.int64)
    tree = igl.AABB()
    tree.init(V, F)
    o = np.array([[0.1, 0.3, np.pi]])
    ids, t, uv = tree.intersect_ray_first(V, F, o, np.array([[0.0, 0, -1]]))
    assert ids.tolist() == [0]
    assert t[0] == np.float32(np.pi) and t[0] != np.pi
    assert uv[0].tolist() == [np.float32(0.1), np.float32(0.3)]
    ours = vrc.Scene(pv.PolyData(V, faces=[3, 0, 1, 2])).intersect(o, [[0.0, 0, -1]])
    np.testing.assert_allclose(ours["barycentric"][0], [0.6, 0.1, 0.3], rtol=0, atol=1e-15)
    assert ours["t"][0] == pytest.approx(np.pi, rel=1e-15)


def test_camera_rays_match_libigl(ref):
    """TriangleId per pixel agrees with libigl's first hit on >= 99.9% of pixels (hit/miss
    too), and every disagreement is a certified edge graze or depth tie."""
    for k, cam in enumerate(random_cameras(ref, seed=1000 + ref.seed)):
        image = ref.scene.cast(cam)
        o, d = camera_rays(cam)
        theirs, _, _ = ref.igl(o, d)
        same, same_hit = compare_ids(ref, o, d, image["TriangleId"], theirs, f"camera {k}")
        assert same >= 0.999
        assert same_hit >= 0.999
        assert (image["TriangleId"] >= 0).any()


def test_camera_depth_matches_libigl(ref):
    """Depth / d (our t) equals libigl's t up to libigl's float32 rounding (2**-24 relative):
    both solve the same ray-plane problem in double; measured max ~5.9e-8."""
    worst = 0.0
    for cam in random_cameras(ref, seed=2000 + ref.seed):
        image = ref.scene.cast(cam)
        o, d = camera_rays(cam)
        theirs, t, _ = ref.igl(o, d)
        both = (image["TriangleId"] == theirs) & (theirs >= 0)
        ours_t = image["Depth"][both] / cam.d
        err = np.abs(ours_t - t[both]) / ours_t
        worst = max(worst, float(err.max()))
        assert (err <= F32_ROUND + F64_SLACK).all(), err.max()
        assert np.isnan(image["Depth"][image["TriangleId"] < 0]).all()
    print(
        f"\n[libigl depth {ref.name}] max relative |Depth/d - t_igl| = {worst:.3e} (float32 half-ulp {F32_ROUND:.3e})"
    )


def test_barycentric_sums_to_one_and_reproduces_the_hit_point(ref):
    """Weights of the triangle's own points: sum 1 to float64 rounding, sum_c w_c P_c equals
    eye + (Depth/d) dir to ~1e-9 of the mesh size, and they equal libigl's (1-u-v, u, v)
    up to its float32 rounding of u and v (<= 2**-24 per weight)."""
    worst_point = worst_igl = 0.0
    for cam in random_cameras(ref, seed=3000 + ref.seed):
        image = ref.scene.cast(cam, arrays=["TriangleId", "Barycentric", "Depth", "Position"])
        o, d = camera_rays(cam)
        tri = image["TriangleId"]
        hit = tri >= 0
        w = image["Barycentric"][hit]
        assert np.isnan(image["Barycentric"][~hit]).all()
        np.testing.assert_allclose(w.sum(1), 1.0, rtol=0, atol=1e-12)
        assert (w >= -1e-12).all()
        corners = ref.V[ref.F[tri[hit]]]
        from_weights = np.einsum("nc,ncd->nd", w, corners)
        from_ray = o[hit] + (image["Depth"][hit] / cam.d)[:, None] * d[hit]
        err = np.linalg.norm(from_weights - from_ray, axis=1).max() / ref.radius
        worst_point = max(worst_point, err)
        assert err <= 1e-9
        np.testing.assert_allclose(image["Position"][hit], from_weights, rtol=0, atol=1e-12 * ref.radius)
        theirs, _, uv = ref.igl(o, d)
        same = theirs[hit] == tri[hit]
        igl_w = np.column_stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]])[hit][same]
        diff = np.abs(w[same] - igl_w).max()
        worst_igl = max(worst_igl, float(diff))
        assert diff <= F32_ROUND + F64_SLACK
    print(
        f"\n[libigl barycentric {ref.name}] |sum w P - hit| <= {worst_point:.2e} radii; "
        f"max |w - w_igl| = {worst_igl:.2e}"
    )


def test_intersect_random_rays_matches_libigl(ref):
    """Scene.intersect on rays from random points in and around the box in random
    directions (random lengths, t is in units of the direction): ids agree on >= 99.9%,
    disagreements are certified, t and weights agree to libigl's float32 rounding."""
    rng = np.random.default_rng(4000 + ref.seed)
    lo, hi = ref.V.min(0), ref.V.max(0)
    n = 40000
    o = rng.uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (n, 3))
    d = rng.normal(size=(n, 3)) * rng.uniform(0.1, 10.0, (n, 1))
    ours = ref.scene.intersect(o, d)
    theirs, t, uv = ref.igl(o, d)
    same, same_hit = compare_ids(ref, o, d, ours["triangle_id"], theirs, "random rays")
    assert same >= 0.999 and same_hit >= 0.999
    assert 0.02 < np.mean(theirs >= 0) < 0.98  # the rays are not trivially all hits or misses
    both = (ours["triangle_id"] == theirs) & (theirs >= 0)
    err = np.abs(ours["t"][both] - t[both]) / ours["t"][both]
    assert (err <= F32_ROUND + F64_SLACK).all(), err.max()
    igl_w = np.column_stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]])
    assert np.abs(ours["barycentric"][both] - igl_w[both]).max() <= F32_ROUND + F64_SLACK
    tid = ours["triangle_id"]
    np.testing.assert_array_equal(ours["cell_id"], np.where(tid >= 0, ref.scene.prepared.cell_ids[tid], -1))
    miss = ours["triangle_id"] < 0
    assert np.isnan(ours["t"][miss]).all() and np.isnan(ours["barycentric"][miss]).all()
    print(f"[libigl random rays {ref.name}] max relative |t - t_igl| = {err.max():.3e}")


def test_rays_through_vertices_and_edges(ref):
    """Rays aimed exactly at mesh vertices and at points on edges: the worst case for
    watertightness and for tie-breaking. Here the two casters legitimately disagree (which
    of the triangles sharing the vertex, or a graze past a silhouette vertex), so only the
    claim matters: every disagreement is a certified edge graze or depth tie.
    (Watertightness itself is checked exactly in the last test.)"""
    rng = np.random.default_rng(5000 + ref.seed)
    n = 20000
    u = rng.normal(size=(n, 3))
    o = ref.center + u / np.linalg.norm(u, axis=1, keepdims=True) * ref.radius * rng.uniform(1.5, 3.0, (n, 1))
    tri = rng.integers(0, len(ref.F), n)
    e = rng.integers(0, 3, n)
    a, b = ref.V[ref.F[tri, e]], ref.V[ref.F[tri, (e + 1) % 3]]
    target = np.where(rng.uniform(size=(n, 1)) < 0.5, a, a + rng.uniform(0, 1, (n, 1)) * (b - a))
    d = target - o
    ours = ref.scene.intersect(o, d)["triangle_id"]
    theirs, _, _ = ref.igl(o, d)
    compare_ids(ref, o, d, ours, theirs, "vertex/edge-aimed rays")


def test_certificate_rejects_wrong_answers(ref):
    """The criterion can fail. Rays through the centroids of visible triangles (far from any
    edge): claiming the neighbour across an edge, or a miss, is never certified. Rays
    through the midpoint of that shared edge: either of the two triangles is certified."""
    rng = np.random.default_rng(6000 + ref.seed)
    eye = random_cameras(ref, seed=7000 + ref.seed, n=1)[0].eye
    half = {}  # (a, b) -> triangles with edge a-b
    for k, f in enumerate(ref.F.tolist()):
        for e in range(3):
            half.setdefault(frozenset((f[e], f[(e + 1) % 3])), []).append(k)
    tri, other, mid = [], [], []
    for t in rng.permutation(len(ref.F))[:600].tolist():
        f = ref.F[t].tolist()
        for e in range(3):
            across = [k for k in half[frozenset((f[e], f[(e + 1) % 3]))] if k != t]
            if across:
                tri.append(t)
                other.append(across[0])
                mid.append(0.5 * (ref.V[f[e]] + ref.V[f[(e + 1) % 3]]))
                break
    tri, other, mid = np.array(tri), np.array(other), np.array(mid)
    o = np.ascontiguousarray(np.broadcast_to(eye, mid.shape))
    delta = DELTA_REL * ref.radius

    d = ref.V[ref.F[tri]].mean(1) - o
    visible = ref.igl(o, d)[0] == tri
    assert visible.sum() > 20
    o_v, d_v, tri_v, other_v = o[visible], d[visible], tri[visible], other[visible]
    assert all(k is None for k in explain_disagreements(ref, o_v, d_v, other_v, tri_v, delta))
    miss = np.full_like(tri_v, -1)
    assert all(k is None for k in explain_disagreements(ref, o_v, d_v, miss, tri_v, delta))
    assert all(k is None for k in explain_disagreements(ref, o_v, d_v, tri_v, miss, delta))

    d = mid - o
    first = ref.igl(o, d)[0]
    on_edge = (first == tri) | (first == other)
    assert on_edge.sum() > 20
    kinds = explain_disagreements(ref, o[on_edge], d[on_edge], tri[on_edge], other[on_edge], delta)
    assert all(k is not None and k.startswith("edge") for k in kinds), Counter(kinds)


def test_scene_cast_equals_cast(ref):
    """One scene, many cameras: Scene.cast gives exactly vrc.cast(mesh, cam), array for array."""
    for cam in random_cameras(ref, seed=8000 + ref.seed, n=2, nx=97, ny=61):
        a = ref.scene.cast(cam)
        b = vrc.cast(ref.mesh, cam)
        assert a.dimensions == b.dimensions == (cam.nx, cam.ny, 1)
        assert list(a.point_data.keys()) == list(b.point_data.keys())
        assert {"TriangleId", "CellId", "Barycentric", "Depth", "vtkValidPointMask"} <= set(a.point_data.keys())
        for name in a.point_data:
            assert a[name].dtype == b[name].dtype, name
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)
        assert (a["vtkValidPointMask"] == (a["TriangleId"] >= 0)).all()
        np.testing.assert_array_equal(
            a["CellId"],
            np.where(a["TriangleId"] >= 0, ref.scene.prepared.cell_ids[a["TriangleId"]], -1),
        )


def _c(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64)


def exact_difference(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a - b`` and, per row, whether it was exact (the error term of Knuth's TwoSum is 0)."""
    s = a - b
    bb = s - a
    err = (a - (s - bb)) + (-b - bb)
    return s, (err == 0).all(1)


def grid_eyes(ref: Reference, rng: np.random.Generator, n: int) -> np.ndarray:
    """Eyes at 1.5-3 radii, snapped to a power-of-two grid so that target - eye is exact
    for the float32-born mesh coordinates: the ray's line then passes exactly through the target."""
    u = rng.normal(size=(n, 3))
    grid = 2.0 ** np.floor(np.log2(ref.radius / 64))
    eyes = ref.center + u / np.linalg.norm(u, axis=1, keepdims=True) * ref.radius * rng.uniform(1.5, 3.0, (n, 1))
    return np.round(eyes / grid) * grid


def test_no_leaks_where_the_surface_closes_around_the_ray(ref):
    """Watertightness, decided with exact predicates rather than by comparison.

    Each ray's line passes *exactly* through an edge midpoint or a vertex (exact direction,
    checked). With orient3d we keep the rays around which the surface provably closes: for
    an edge, the two triangles' third points lie on opposite sides of the plane (eye, edge);
    for a vertex, its fan is closed, consistently oriented, and every fan triangle has the
    same orientation seen from the eye (the projected fan winds around the vertex). Such a
    ray must hit, at t <= 1 (t = 1 is the target; anything in front is fine). A miss or a
    hit behind is a leak. libigl's (non-watertight) count is printed for comparison."""
    rng = np.random.default_rng(9000 + ref.seed)
    V, F = ref.V, ref.F
    n = 6000
    # interior edges: exactly two triangles; half-edge rows (a, b, opposite point)
    half = np.concatenate([F[:, [0, 1, 2]], F[:, [1, 2, 0]], F[:, [2, 0, 1]]])
    key = np.minimum(half[:, 0], half[:, 1]) * len(V) + np.maximum(half[:, 0], half[:, 1])
    order = np.argsort(key, kind="stable")
    half, key = half[order], key[order]
    _, start, count = np.unique(key, return_index=True, return_counts=True)
    pair = start[count == 2]
    k = rng.integers(0, pair.size, n)
    a, b = V[half[pair[k], 0]], V[half[pair[k], 1]]
    o_edge = grid_eyes(ref, rng, n)
    d_edge, exact_edge = exact_difference((a + b) * 0.5, o_edge)  # (a + b) / 2 is exact for float32 inputs
    side1 = orient3d(_c(o_edge), _c(a), _c(b), _c(V[half[pair[k], 2]]))
    side2 = orient3d(_c(o_edge), _c(a), _c(b), _c(V[half[pair[k] + 1, 2]]))
    closes_edge = exact_edge & (side1 * side2 < 0)
    # vertices with a closed, consistently oriented fan; rows (v, x, y) in triangle order
    rot = np.concatenate([F[:, [0, 1, 2]], F[:, [1, 2, 0]], F[:, [2, 0, 1]]])
    rot = rot[np.argsort(rot[:, 0], kind="stable")]
    starts = np.searchsorted(rot[:, 0], np.arange(len(V) + 1))
    closed = np.zeros(len(V), bool)
    for v in range(len(V)):
        fan = rot[starts[v] : starts[v + 1]]
        xs, ys = np.sort(fan[:, 1]), np.sort(fan[:, 2])
        closed[v] = len(fan) >= 3 and np.array_equal(xs, ys) and np.unique(xs).size == xs.size
    vs = rng.choice(np.flatnonzero(closed), n)
    o_vert = grid_eyes(ref, rng, n)
    d_vert, exact_vert = exact_difference(V[vs], o_vert)
    size = starts[vs + 1] - starts[vs]
    ray = np.repeat(np.arange(n), size)
    fan = rot[np.concatenate([np.arange(starts[v], starts[v + 1]) for v in vs])]
    s = orient3d(_c(o_vert[ray]), _c(V[fan[:, 0]]), _c(V[fan[:, 1]]), _c(V[fan[:, 2]]))
    same_sign = (np.bincount(ray, s > 0, n) == size) | (np.bincount(ray, s < 0, n) == size)
    closes_vert = exact_vert & same_sign

    assert exact_edge.mean() > 0.99 and exact_vert.mean() > 0.99
    for label, o, d, closes in (
        ("edges", o_edge, d_edge, closes_edge),
        ("vertices", o_vert, d_vert, closes_vert),
    ):
        assert closes.sum() > n // 4, "too few rays where the surface provably closes: the test would be vacuous"
        o, d = o[closes], d[closes]
        hits = ref.scene.intersect(o, d)
        leak = (hits["triangle_id"] < 0) | ~(hits["t"] <= 1.0 + 1e-12)
        theirs, t_igl, _ = ref.igl(o, d)
        igl_leak = (theirs < 0) | ~(t_igl <= 1.0 + 1e-6)
        print(
            f"\n[exact watertightness {ref.name}] {closes.sum()} rays exactly through "
            f"closed {label}: "
            f"vtkraycast leaks {leak.sum()}, libigl leaks {igl_leak.sum()}"
        )
        assert not leak.any(), f"leaks through {label}: rays {np.flatnonzero(leak)[:10]}"
