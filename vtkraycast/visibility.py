"""What a camera sees beyond the first hit: depth layers, crossings and thickness along
each pixel ray, and the cells and points in view. Built on Scene.intersect_all and
Scene.occluded (exact), a numpy pass over the hits."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .fields import gather_at_hits, mesh_arrays, select_arrays

if TYPE_CHECKING:
    from .camera import Camera
    from .scene import Scene

__all__ = ["crossing_arrays", "ids_present", "layered_arrays", "visible_points"]


def ids_present(ids: np.ndarray) -> np.ndarray:
    """The distinct non-negative values of ``ids`` (negative ones ignored), sorted, as
    int64: a mark per possible id, not np.unique's sort or hash (a frame's or a mesh's
    millions of ids against a mesh's points or cells)."""
    ids = ids[ids >= 0]
    marked = np.zeros(int(ids.max()) + 1 if ids.size else 0, dtype=bool)
    marked[ids] = True
    return np.flatnonzero(marked)


#: Arrays computed from every crossing along the pixel ray, asked for by name.
CROSSING_ARRAYS = ("HitCount", "Thickness")


def _pixel_crossings(scene: Scene, camera: Camera, threads: int | None) -> tuple[dict, np.ndarray, float]:
    origins, directions, tmin, tmax = camera.rays()
    hits = scene.intersect_all(origins, directions, tmin=tmin, tmax=tmax, threads=threads)
    depth_per_t = 1.0 if camera.parallel else camera.d
    return hits, directions, depth_per_t


def crossing_arrays(scene: Scene, camera: Camera, names: list[str], threads: int | None) -> dict[str, np.ndarray]:
    """``HitCount`` (surface crossings along each pixel ray within near and far, int32) and
    ``Thickness`` (length along it inside closed surfaces, from the parity of the crossings;
    the mesh must be closed)."""
    hits, directions, _ = _pixel_crossings(scene, camera, threads)
    counts = np.diff(hits["ray_splits"])
    out = {}
    if "HitCount" in names:
        out["HitCount"] = counts.astype(np.int32)
    if "Thickness" in names:
        origins, _, tmin, tmax = camera.rays()
        if tmin == 0 and not camera.parallel:  # every ray starts at the eye
            inside = np.broadcast_to(scene.contains(camera.eye[None]), counts.shape)
        else:
            inside = scene.contains(origins + tmin * directions)
        # Crossing k of a ray leaves the inside when the ray starts inside and k is even,
        # or starts outside and k is odd: inside lengths are sums of +t (leaving) and -t
        # (entering), from tmin when it starts inside, to tmax when it ends inside.
        k = np.arange(len(hits["t"])) - np.repeat(hits["ray_splits"][:-1], counts)
        ray = hits["ray_ids"]
        leaving = (k % 2 == 0) == inside[ray]
        inner = np.bincount(ray, weights=np.where(leaving, hits["t"], -hits["t"]), minlength=len(counts))
        inner -= np.where(inside, tmin, 0.0)
        ends_inside = inside ^ (counts % 2 == 1)
        if np.isfinite(tmax):
            inner += np.where(ends_inside, tmax, 0.0)
        out["Thickness"] = inner * np.linalg.norm(directions, axis=1)
    return out


def layered_arrays(
    scene: Scene, camera: Camera, layers: int, arrays: Any, interpolate: bool, threads: int | None
) -> dict[str, np.ndarray]:
    """The arrays of a cast with ``layers`` depth layers: rows ``l * nx * ny + pixel`` hold
    the (l + 1)-th crossing along each pixel ray (misses where it has fewer)."""
    found = mesh_arrays(scene.prepared)
    names = [n for n in select_arrays(found, arrays, interpolate) if n not in CROSSING_ARRAYS]
    hits, _, depth_per_t = _pixel_crossings(scene, camera, threads)
    n = camera.nx * camera.ny
    counts = np.diff(hits["ray_splits"])
    k = np.arange(len(hits["t"])) - np.repeat(hits["ray_splits"][:-1], counts)
    shown = k < layers
    rows = k[shown] * n + hits["ray_ids"][shown]
    triangle = np.full(layers * n, -1, np.int64)
    triangle[rows] = hits["triangle_id"][shown]
    weights = np.full((layers * n, 3), np.nan)
    weights[rows] = hits["barycentric"][shown]
    out = gather_at_hits(scene.prepared, [m for m in names if m not in ("Depth", "Barycentric")], triangle, weights)
    out["Barycentric"] = weights
    if "Depth" in names:
        depth = np.full(layers * n, np.nan)
        depth[rows] = hits["t"][shown] * depth_per_t
        out["Depth"] = depth
    return {name: out[name] for name in names}


def visible_points(scene: Scene, camera: Camera, tolerance: float, threads: int | None) -> np.ndarray:
    """Ids of the mesh's points (those its triangles use) that the camera sees: inside the
    view, in [near, far], and nothing in front of them closer than ``1 - tolerance`` of the
    way from the eye."""
    points = scene.prepared.points
    used = ids_present(scene.prepared.triangles.ravel())
    p = points[used]
    offset = p - camera.eye
    along = offset @ -camera.backward  # depth in front of the eye
    x, y = offset @ camera.right, offset @ camera.up
    if not camera.parallel:  # on the image plane, at distance d
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = x / along * camera.d, y / along * camera.d
    in_view = (along > 0) & (np.abs(x) <= camera.w / 2) & (np.abs(y) <= camera.h / 2)
    in_view &= (along >= camera.near) & (along <= camera.far)
    # Rays from the eye (parallel: from the point's foot on the eye's plane) with t = 1 at the point.
    if camera.parallel:
        origins = p + along[:, None] * camera.backward
    else:
        origins = np.broadcast_to(camera.eye, p.shape)
    seen = np.flatnonzero(in_view)
    blocked = scene.occluded(origins[seen], (p - origins)[seen], tmax=1 - tolerance, threads=threads)
    return used[seen[~blocked]]
