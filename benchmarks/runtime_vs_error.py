#!/usr/bin/env python
"""Run time against error: every vtkraycast strategy x precision, and its peers, on the same rays.

Command line (from the repository root)::

    python benchmarks/runtime_vs_error.py            # full run: 3.5 min on an idle 2-core EPYC, 15 loaded
    python benchmarks/runtime_vs_error.py --quick    # smoke test, small sizes, under a minute
    python benchmarks/runtime_vs_error.py --out DIR  # write the outputs somewhere else

The machine (``platform.platform()``, ``os.cpu_count()``, the CPU model) and the exact
command line are printed first and written at the top of ``runtime_vs_error.md``.

What is measured, per scene and method:

- Mrays/s: median over ``--repeats`` (>= 5) timed runs of the full cast on every core
  (``Scene.cast`` for camera scenes, ``Scene.intersect`` for ray sets; one untimed warm-up
  run first). Building the scene (triangulation, BVH; the peers' own structures) and making
  the ray arrays are not timed. Peers are timed on their own Python call with the same rays
  (Open3D ``RaycastingScene.cast_rays`` on all cores; embreex's ``EmbreeScene.run`` and
  libigl's ``AABB.intersect_ray_first`` loop over the rays on one thread in their bindings).
- Errors against the exact reference (``vtkraycast.validate.exact_first_hits``, exact
  integer arithmetic) on a seeded sample of the same rays: wrong triangle (both hit, not one
  of the exactly tied first triangles), leak (the ray hits, the method misses), false hit,
  ``t`` relative error over the rays hit correctly (median, 99.9th percentile, max), and the
  largest barycentric error where the method hit the reference's (lowest tied) triangle.
  In scenes where every ray must hit (an eye inside a closed mesh, rays aimed at interior
  points of a plane) leaks are counted on *all* rays, not just the sample.
- The exact reference is made affordable on large meshes by binning: all rays of a scene
  share one origin, so a triangle is a candidate for a ray only if its central projection on
  the cube face of the ray's dominant axis overlaps the ray's cell (conservative bounds
  with rounding margins; triangles straddling the face's plane are always candidates).

Peers see the rays as their APIs take them: Open3D and embreex in float32 (origins,
directions and vertices rounded to float32), libigl in float64 (it returns ``t`` and
``(u, v)`` rounded to float32). Their ``(u, v)`` are the weights of the 2nd and 3rd point.

Outputs in ``--out`` (default ``benchmarks/results``): ``runtime_vs_error.csv`` (one row
per scene x method), ``runtime_vs_error.md`` (tables aggregated per method and per stress
scene) and ``runtime_vs_error.png`` (Mrays/s against error, Pareto fronts drawn).
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import platform
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
from peer_casters import Peer, Result, make_peers
from timing import cpu_model

SEED = 20240611
FLOOR = 1e-7  # error-rate floor on the chart's log axis (a zero is drawn at the floor)


# ----------------------------------------------------------------------------------------
# machine and command line
# ----------------------------------------------------------------------------------------


def machine_lines() -> list[str]:
    from importlib import metadata

    import vtkraycast

    versions = [f"vtkraycast {vtkraycast.__version__}"]
    for name, module in (
        ("numpy", "numpy"),
        ("vtk", "vtk"),
        ("pyvista", "pyvista"),
        ("open3d", "open3d"),
        ("embreex", "embreex"),
        ("libigl", "igl"),
    ):
        try:
            versions.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            try:
                versions.append(f"{name} {__import__(module).__version__}")
            except (ImportError, AttributeError):
                versions.append(f"{name} ?")
    return [
        f"platform: {platform.platform()}",
        f"cpu: {cpu_model()}; os.cpu_count() = {os.cpu_count()}",
        f"python: {sys.version.split()[0]}; " + ", ".join(versions),
        "command: " + " ".join(shlex.quote(a) for a in [Path(sys.executable).name, *sys.argv]),
        source_line(),
        "load average at start (1, 5, 15 min): " + ", ".join(f"{x:.2f}" for x in os.getloadavg()),
    ]


def source_line() -> str:
    """The repository commit, whether the package sources differ from it, and when the
    installed native core was built (the package is imported from the installed copy)."""
    from vtkraycast import _core

    repo = Path(__file__).resolve().parents[1]

    def git(*cmd: str) -> str:
        try:
            return subprocess.run(
                ["git", "-C", str(repo), *cmd], capture_output=True, text=True, timeout=10
            ).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    head = git("log", "-1", "--format=%h (%ad) %s", "--date=iso") or "unknown"
    dirty = git("status", "--porcelain", "--", "src", "vtkraycast", "CMakeLists.txt", "pyproject.toml")
    built = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(os.path.getmtime(_core._module.__file__)))
    return (
        f"source: commit {head}{'; package sources modified since' if dirty else ''}; "
        f"installed native core built {built}"
    )


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


# ----------------------------------------------------------------------------------------
# rays
# ----------------------------------------------------------------------------------------


def camera_rays(cam: Any) -> tuple[np.ndarray, np.ndarray]:
    """Origins and directions of every pixel ray of a perspective camera, in output order
    (pixel (i, r), row r = 0 at the bottom, index i + r nx), computed with the same float64
    operations in the same order as the native core, so the rays are bit-identical."""
    assert not cam.parallel
    n = cam.nx * cam.ny
    k = np.arange(n)
    i, r = k % cam.nx, k // cam.nx
    j = cam.ny - 1 - r
    x = -cam.w * 0.5 + cam.w / cam.nx * (i + 0.5)
    y = cam.h * 0.5 - cam.h / cam.ny * (j + 0.5)
    right, up, backward = cam.right, cam.up, cam.backward
    d = x[:, None] * right + y[:, None] * up - cam.d * backward
    return np.broadcast_to(cam.eye, d.shape).copy(), np.ascontiguousarray(d)


def rays_hitting_box(origins: np.ndarray, dirs: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Mask of rays whose line meets the box ``bounds`` (enlarged by 1e-6 of its size) at t >= 0."""
    lo, hi = bounds[0::2].astype(float), bounds[1::2].astype(float)
    pad = 1e-6 * (hi - lo).max() + 1e-300
    lo, hi = lo - pad, hi + pad
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / dirs
        t1, t2 = (lo - origins) * inv, (hi - origins) * inv
    tn = np.nanmax(np.where(np.isnan(t1), -np.inf, np.minimum(t1, t2)), axis=1)
    tf = np.nanmin(np.where(np.isnan(t2), np.inf, np.maximum(t1, t2)), axis=1)
    return (tn <= tf * (1 + 1e-9)) & (tf >= 0)


# ----------------------------------------------------------------------------------------
# exact reference, binned
# ----------------------------------------------------------------------------------------


def exact_reference(
    points: np.ndarray,
    triangles: np.ndarray,
    eye: np.ndarray,
    dirs: np.ndarray,
    *,
    tmin: float = 0.0,
    tmax: float = math.inf,
) -> Any:
    """``exact_first_hits`` for rays sharing the origin ``eye``, each ray tested only against
    the triangles whose projection may cover it (see the module docstring)."""
    from vtkraycast.validate import ExactHits, exact_first_hits

    points = np.asarray(points, np.float64)
    triangles = np.asarray(triangles, np.int64)
    eye = np.asarray(eye, np.float64)
    n = dirs.shape[0]
    accepted: list[frozenset[int]] = [frozenset()] * n
    t_out = np.full(n, np.nan)
    bary_out = np.full((n, 3), np.nan)
    on_edge = np.zeros(n, bool)
    if n == 0 or triangles.shape[0] == 0:
        return ExactHits(accepted, t_out, bary_out, on_edge)
    eps = np.finfo(np.float64).eps
    rel = points - eye  # rounded differences
    err = 2 * eps * (np.abs(points) + np.abs(eye))  # bound on their rounding error
    axis = np.argmax(np.abs(dirs), axis=1)
    sign = np.sign(dirs[np.arange(n), axis])
    for k in range(3):
        a, b = (k + 1) % 3, (k + 2) % 3
        for s in (1.0, -1.0):
            rays = np.flatnonzero((axis == k) & (sign == s))
            if rays.size == 0:
                continue
            du = dirs[rays, a] / dirs[rays, k]
            dv = dirs[rays, b] / dirs[rays, k]
            # triangle vertices along the face's axis
            zk = s * rel[:, k]
            ek = err[:, k]
            zt = zk[triangles]
            et = ek[triangles]
            front = (zt > 2 * et).all(axis=1)
            behind = (zt < -2 * et).all(axis=1)
            straddle = np.flatnonzero(~front & ~behind)
            tri_f = np.flatnonzero(front)
            # projected bounding boxes of the front triangles, with rounding margins
            vt = triangles[tri_f]
            z = zk[vt]
            ez = ek[vt]
            pu = rel[vt, a] * s / z
            pv_ = rel[vt, b] * s / z
            mu = 2 * (err[vt, a] + np.abs(pu) * ez) / (z - ez) + 8 * eps * (1 + np.abs(pu))
            mv = 2 * (err[vt, b] + np.abs(pv_) * ez) / (z - ez) + 8 * eps * (1 + np.abs(pv_))
            u0, u1 = (pu - mu).min(axis=1), (pu + mu).max(axis=1)
            v0, v1 = (pv_ - mv).min(axis=1), (pv_ + mv).max(axis=1)
            # grid over the rays' range
            ru0, ru1, rv0, rv1 = du.min(), du.max(), dv.min(), dv.max()
            keep = (u1 >= ru0) & (u0 <= ru1) & (v1 >= rv0) & (v0 <= rv1)
            tri_f, u0, u1, v0, v1 = tri_f[keep], u0[keep], u1[keep], v0[keep], v1[keep]
            g = int(np.clip(math.sqrt(rays.size / 2.0), 1, 96))
            su = (ru1 - ru0) / g if ru1 > ru0 else 1.0
            sv = (rv1 - rv0) / g if rv1 > rv0 else 1.0
            ci = np.clip(((du - ru0) / su).astype(np.int64), 0, g - 1)
            cj = np.clip(((dv - rv0) / sv).astype(np.int64), 0, g - 1)
            ray_cell = ci * g + cj
            i0 = np.clip(np.floor((u0 - ru0) / su).astype(np.int64) - 1, 0, g - 1)
            i1 = np.clip(np.floor((u1 - ru0) / su).astype(np.int64) + 1, 0, g - 1)
            j0 = np.clip(np.floor((v0 - rv0) / sv).astype(np.int64) - 1, 0, g - 1)
            j1 = np.clip(np.floor((v1 - rv0) / sv).astype(np.int64) + 1, 0, g - 1)
            nu, nv = i1 - i0 + 1, j1 - j0 + 1
            count = nu * nv
            owner = np.repeat(np.arange(tri_f.size), count)
            local = np.arange(owner.size) - np.repeat(np.cumsum(count) - count, count)
            cells = (i0[owner] + local // nv[owner]) * g + (j0[owner] + local % nv[owner])
            order = np.argsort(cells, kind="stable")
            cells, tris_in = cells[order], tri_f[owner[order]]
            occupied = np.unique(ray_cell)
            starts = np.searchsorted(cells, occupied, side="left")
            ends = np.searchsorted(cells, occupied, side="right")
            for cell, lo_, hi_ in zip(occupied.tolist(), starts.tolist(), ends.tolist()):
                subset = np.union1d(tris_in[lo_:hi_], straddle)
                which = rays[ray_cell == cell]
                if subset.size == 0:
                    continue
                hits = exact_first_hits(
                    points, triangles[subset], np.broadcast_to(eye, (which.size, 3)), dirs[which], tmin=tmin, tmax=tmax
                )
                for q, w in enumerate(which.tolist()):
                    if hits.accepted[q]:
                        accepted[w] = frozenset(int(subset[x]) for x in hits.accepted[q])
                t_out[which] = hits.t
                bary_out[which] = hits.barycentric
                on_edge[which] = hits.on_edge
    return ExactHits(accepted, t_out, bary_out, on_edge)


# ----------------------------------------------------------------------------------------
# methods
# ----------------------------------------------------------------------------------------


def vrc_name(strategy: str, precision: str, accel: str) -> str:
    return f"vtkraycast {strategy} {precision}" + ("" if accel == "bvh" else " accel=none")


# ----------------------------------------------------------------------------------------
# timing and scoring
# ----------------------------------------------------------------------------------------


def timed(fn: Callable[[], Any], repeats: int, budget: float) -> tuple[list[float], Any]:
    """One warm-up call, then ``repeats`` timed calls (at least 3; fewer than ``repeats``
    only when one call takes longer than ``budget / repeats`` seconds)."""
    t0 = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t0
    n = repeats if first * repeats <= budget else max(3, int(budget / max(first, 1e-9)))
    n = min(n, repeats)
    times = []
    for _ in range(n):
        out = None
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return times, out


@dataclass
class Row:
    scene: str
    kind: str  # "camera" or "rays"
    stress: bool
    n_triangles: int
    method: str
    family: str  # "vtkraycast" or "peer"
    strategy: str = ""
    precision: str = ""
    accel: str = ""
    threads: int = 0
    prep_s: float = math.nan
    n_rays_timed: int = 0
    repeats: int = 0
    time_median_s: float = math.nan
    time_min_s: float = math.nan
    mrays_s: float = math.nan
    hit_fraction: float = math.nan
    n_ref: int = 0
    ref_hits: int = 0
    leak_rays: int = 0
    leaks: int = 0
    leak_rate: float = math.nan
    wrong: int = 0
    wrong_rate: float = math.nan
    wrong_side: int = 0  # the returned triangle is not met by the exact ray at all
    wrong_depth: int = 0  # it is met, but farther than the exact first hit (depth order)
    wrong_depth_beyond_tie: int = 0  # ... by more than 32 eps of the method's precision
    wrong_depth_max_gap: float = math.nan  # largest relative t gap of those depth errors
    false_hits: int = 0
    false_hit_rate: float = math.nan
    t_rel_median: float = math.nan
    t_rel_p999: float = math.nan
    t_rel_max: float = math.nan
    bary_max_err: float = math.nan
    note: str = ""
    # per-ray errors for pooling (not written to the CSV)
    t_errors: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    examples: list = field(default_factory=list, repr=False)

    def record_times(self, times: list[float]) -> None:
        """The timing columns, from the times of casting ``n_rays_timed`` rays."""
        self.repeats = len(times)
        self.time_median_s = float(np.median(times))
        self.time_min_s = float(np.min(times))
        self.mrays_s = self.n_rays_timed / self.time_median_s / 1e6


CSV_FIELDS = [f for f in Row.__dataclass_fields__ if f not in ("t_errors", "examples")]


def score(
    row: Row,
    ref: Any,
    sample: np.ndarray,
    res: Result,
    must_hit: bool,
    origins: np.ndarray,
    dirs: np.ndarray,
    all_ids: np.ndarray | None,
    geometry: tuple[np.ndarray, np.ndarray],
    tie: float,
) -> None:
    """Fills the error columns of ``row``: ``res`` holds the method's answers on the sampled
    rays; ``all_ids`` its ids on every ray (for must-hit scenes), or None. A wrong triangle
    is checked exactly: "side" when the ray does not meet it at all (an inside test decided
    wrongly), "depth" when the ray meets it farther than the first hit; ``tie`` is the
    relative t difference below which vtkraycast calls two hits a tie (32 eps of the
    precision) and gives the lowest triangle id, so a depth error within it is by design."""
    from vtkraycast.validate import classify, exact_first_hits

    ids = res.ids
    masks = classify(ref, ids)
    hit_ref = np.array([bool(a) for a in ref.accepted])
    row.n_ref = int(sample.size)
    row.ref_hits = int(hit_ref.sum())
    row.wrong = int(masks["wrong"].sum())
    row.wrong_rate = row.wrong / max(row.ref_hits, 1)
    points, triangles = geometry
    wrong_kind = {}
    for q in np.flatnonzero(masks["wrong"]).tolist():
        k = int(sample[q])
        one = exact_first_hits(points, triangles[[int(ids[q])]], origins[k : k + 1], dirs[k : k + 1])
        if one.accepted[0]:
            gap = (float(one.t[0]) - float(ref.t[q])) / abs(float(ref.t[q]))
            wrong_kind[q] = (
                f"wrong-depth (its exact t is {gap:.1e} relative beyond the first hit; tie tolerance {tie:.1e})"
            )
            row.wrong_depth += 1
            row.wrong_depth_beyond_tie += int(gap > tie)
            row.wrong_depth_max_gap = gap if math.isnan(row.wrong_depth_max_gap) else max(row.wrong_depth_max_gap, gap)
        else:
            wrong_kind[q] = "wrong-side (the exact ray does not meet the returned triangle)"
            row.wrong_side += 1
    row.false_hits = int(masks["false_hit"].sum())
    row.false_hit_rate = row.false_hits / max(int((~hit_ref).sum()), 1)
    if must_hit and all_ids is not None:
        row.leak_rays = int(all_ids.size)
        leak_mask_all = all_ids < 0
        row.leaks = int(leak_mask_all.sum())
        leak_idx = np.flatnonzero(leak_mask_all)
    else:
        row.leak_rays = row.ref_hits
        row.leaks = int(masks["leak"].sum())
        leak_idx = sample[masks["leak"]]
    row.leak_rate = row.leaks / max(row.leak_rays, 1)
    good = masks["correct"] & hit_ref
    if good.any():
        terr = np.abs(res.t[good] - ref.t[good]) / np.abs(ref.t[good])
        row.t_errors = terr
        row.t_rel_median = float(np.median(terr))
        row.t_rel_p999 = float(np.quantile(terr, 0.999))
        row.t_rel_max = float(terr.max())
    lowest = np.array([min(a) if a else -2 for a in ref.accepted])
    same = good & (ids == lowest)
    if same.any():
        row.bary_max_err = float(np.nanmax(np.abs(res.bary[same] - ref.barycentric[same])))
    # a few reproducers: (kind, ray index, origin, direction, method's id, accepted ids)
    side = [q for q, v in wrong_kind.items() if v.startswith("wrong-side")]
    depth = [q for q, v in wrong_kind.items() if v.startswith("wrong-depth")]
    for kind, idx in (("leak", leak_idx[:3]), ("wrong", sample[side[:3] + depth[:2]])):
        for k in np.asarray(idx, dtype=np.int64).tolist():
            pos = np.flatnonzero(sample == k)
            acc = sorted(ref.accepted[pos[0]]) if pos.size else "(must hit: no exact reference run)"
            got = int(ids[pos[0]]) if pos.size else -1
            label = wrong_kind.get(int(pos[0]), kind) if kind == "wrong" else "leak"
            row.examples.append((label, int(k), origins[k].tolist(), dirs[k].tolist(), got, acc))


# ----------------------------------------------------------------------------------------
# scenes
# ----------------------------------------------------------------------------------------


@dataclass
class SceneSpec:
    name: str
    mesh: Callable[[], Any]
    camera: Callable[[Any], Any] | None = None  # mesh -> vrc.Camera
    rays: Callable[[Any, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None
    must_hit: bool = False
    stress: bool = False
    n_ref: int = 2000
    max_rays: int | None = None  # a seeded random subset of a ray set, to bound the run time


def rotation(ax: float, ay: float, az: float) -> np.ndarray:
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def build_scenes(quick: bool) -> list[SceneSpec]:
    import pyvista as pv
    from pyvista import examples

    import vtkraycast as vrc
    from vtkraycast.testing import bumpy_sphere, rays_at_vertices_and_edges

    px = 96 if quick else 512
    n_ref = 150 if quick else 2000
    n_ref_stress = 200 if quick else 3000
    sub = 3 if quick else 6
    scenes: list[SceneSpec] = []

    def framing(mesh: Any) -> Any:
        return vrc.Camera.framing(mesh.bounds, view="iso", nx=px, ny=px)

    for name in ("airplane", "ant", "nut", "sphere"):
        scenes.append(SceneSpec(name, getattr(examples, f"load_{name}"), camera=framing, n_ref=n_ref))
    if not quick:
        scenes.append(
            SceneSpec(
                "frog contour",
                lambda: examples.load_frog_tissues().contour_labels(),
                camera=lambda m: vrc.Camera.framing(m.bounds, view="iso", nx=1024, ny=1024),
                n_ref=n_ref,
            )
        )

    combos = [(0.0, 1.0), (0.0, 1e-4), (0.0, 1e-6), (1e3, 1.0), (1e3, 1e-4), (1e6, 1.0), (1e6, 1e-6)]
    if quick:
        combos = [(0.0, 1.0), (1e6, 1e-6)]

    def sphere(subdivisions: int, offset: float, scale: float) -> Callable[[], Any]:
        return lambda: bumpy_sphere(subdivisions, offset=offset, scale=scale)

    def rays_from(eye: np.ndarray) -> Callable[[Any, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        return lambda mesh, points, triangles: rays_at_vertices_and_edges(points, triangles, eye)

    def label(offset: float, scale: float) -> str:
        return f"off {offset:g} scale {scale:g}"

    # Ray subsets sized for about 0.6 s a call of the slowest kernel on the 2-core machine the
    # results come from. Where the sphere is tiny against its offset vtkraycast's float32 BVH
    # boxes collapse onto a few float32 cells and every ray visits every triangle, so those
    # scenes get few rays.
    cap = 1000 if quick else 50_000
    degenerate_cap = {(1e3, 1e-4): 100 if quick else 800, (1e6, 1e-6): 100 if quick else 150}

    # closed bumpy spheres seen from their centre (strictly inside): rays at every vertex
    # and edge midpoint
    for offset, scale in combos:
        scenes.append(
            SceneSpec(
                f"inside bumpy s{sub} {label(offset, scale)}",
                sphere(sub, offset, scale),
                rays=rays_from(np.full(3, offset)),
                must_hit=True,
                stress=True,
                n_ref=n_ref_stress,
                max_rays=degenerate_cap.get((offset, scale), cap),
            )
        )
    # a small closed sphere, every ray referenced, accel="none" too
    for offset, scale in [(0.0, 1.0), (1e6, 1e-6)] if not quick else []:
        scenes.append(
            SceneSpec(
                f"inside bumpy s3 {label(offset, scale)}",
                sphere(3, offset, scale),
                rays=rays_from(np.full(3, offset)),
                must_hit=True,
                stress=True,
                n_ref=10**9,
            )
        )

    # a perspective camera inside a closed bumpy sphere: every pixel must hit
    def inside_camera(offset: float, scale: float) -> Callable[[Any], Any]:
        eye = offset + scale * np.array([0.21, -0.13, 0.07])
        look = eye + scale * np.array([1.0, 0.3, -0.2])
        side = 20 if (offset, scale) in degenerate_cap else px  # degenerate BVH: ~1.5 ms a ray
        return lambda mesh: vrc.Camera(eye, look, (0, 0, 1), view_angle=90, nx=side, ny=side)

    for offset, scale in [(0.0, 1.0), (1e6, 1e-6)] if not quick else [(0.0, 1.0)]:
        scenes.append(
            SceneSpec(
                f"camera inside bumpy s{sub} {label(offset, scale)}",
                sphere(sub, offset, scale),
                camera=inside_camera(offset, scale),
                must_hit=True,
                stress=True,
                n_ref=n_ref_stress,
            )
        )

    # grazing: a camera just above a tilted plane, looking along it
    rot = rotation(0.3, -0.2, 0.5)
    res = 40 if quick else 150

    def tilted_plane() -> Any:
        plane = pv.Plane(
            center=(0, 0, 0), direction=(0, 0, 1), i_size=2, j_size=2, i_resolution=res, j_resolution=res
        ).triangulate()
        p = np.array(plane.points, dtype=np.float64)
        p[:, 2] = 0.0
        plane.points = p @ rot.T
        return plane

    def grazing_camera(mesh: Any) -> Any:
        # rays meet the plane's z = 0 between x = -1 and 1 when they dip 0.05 to 0.38 degrees:
        # a 0.5 degree view centred on the plane's middle sees mostly such grazing hits
        eye = rot @ np.array([-1.3, 0.05, 2e-3])
        side = 64 if quick else 192  # grazing rays cross many BVH nodes: ~25 us a ray here
        return vrc.Camera(
            eye, rot @ np.array([0.0, 0.0, 0.0]), rot @ np.array([0.0, 0.0, 1.0]), view_angle=0.5, nx=side, ny=side
        )

    scenes.append(
        SceneSpec(
            "grazing camera over tilted plane", tilted_plane, camera=grazing_camera, stress=True, n_ref=n_ref_stress
        )
    )

    # grazing at vertices and edges: an eye 1e-9 above the plane z = 0, rays aimed at its
    # interior vertices and edge midpoints (every ray must hit, at t = 1)
    def flat_plane() -> Any:
        plane = pv.Plane(
            center=(0, 0, 0), direction=(0, 0, 1), i_size=2, j_size=2, i_resolution=res, j_resolution=res
        ).triangulate()
        p = np.array(plane.points, dtype=np.float64)
        p[:, 2] = 0.0
        plane.points = p
        return plane

    def plane_rays(mesh: Any, points: np.ndarray, triangles: np.ndarray):
        eye = np.array([-1.5, 0.1, 1e-9])
        o, d = rays_at_vertices_and_edges(points, triangles, eye)
        target = o + d
        inner = (np.abs(target[:, :2]) < 0.999).all(axis=1)
        return o[inner], d[inner]

    scenes.append(
        SceneSpec(
            "grazing rays at plane vertices/edges",
            flat_plane,
            rays=plane_rays,
            must_hit=True,
            stress=True,
            n_ref=n_ref_stress,
            max_rays=cap,
        )
    )

    # rays tangent to a bumpy sphere: from outside, at the vertices and edge midpoints on
    # the silhouette
    def tangent_rays(mesh: Any, points: np.ndarray, triangles: np.ndarray):
        eye = np.array([3.0, 1.2, 0.7])
        o, d = rays_at_vertices_and_edges(points, triangles, eye)
        target = o + d
        normal = target / np.linalg.norm(target, axis=1, keepdims=True)
        cos = np.abs(np.einsum("ij,ij->i", normal, d)) / np.linalg.norm(d, axis=1)
        keep = cos < 0.05
        return o[keep], d[keep]

    scenes.append(
        SceneSpec(
            f"tangent rays bumpy s{sub}", sphere(sub, 0.0, 1.0), rays=tangent_rays, stress=True, n_ref=n_ref_stress
        )
    )
    return scenes


# ----------------------------------------------------------------------------------------
# the run
# ----------------------------------------------------------------------------------------


def log_row(row: Row) -> None:
    log(
        f"  {row.method:45s} {row.mrays_s:7.2f} Mrays/s  leaks {row.leaks}/{row.leak_rays}  "
        f"wrong {row.wrong}/{row.ref_hits} (side {row.wrong_side}, depth {row.wrong_depth})  "
        f"false {row.false_hits}  t 99.9% {row.t_rel_p999:.1e}"
    )


def _cost_per_ray(call: Callable[[int], Any], n_small: int, n_large: int, n_full: int, budget: float) -> float:
    """Seconds per ray of ``call(n)`` (n rays), from a pilot of ``n_small`` rays, refined on
    ``n_large`` rays when the small pilot (whose fixed overhead inflates the cost per ray)
    predicts more than ``budget`` for ``n_full`` rays and the larger pilot is affordable."""
    worst = 0.0
    for n in (n_small, n_large):
        call(n)  # warm-up
        t0 = time.perf_counter()
        call(n)
        worst = (time.perf_counter() - t0) / n
        if worst * n_full <= budget or n == n_large or worst * n_large > 2.0:
            break
    return worst


def fit_camera(scene: Any, cam: Any, args: argparse.Namespace) -> tuple[Any, str]:
    """The camera, its pixel grid made coarser (to about ``args.call_budget`` seconds a cast)
    when one cast of the slowest vtkraycast kernel would take longer than
    ``args.camera_budget`` (a pilot cast measures the cost per ray)."""
    worst = 0.0
    n_full = cam.nx * cam.ny
    for strategy in ("watertight", "plane"):

        def call(n: int, strategy: str = strategy) -> Any:
            side = int(math.sqrt(n))
            return scene.buffers(cam.replace(nx=side, ny=side), arrays=["TriangleId"], strategy=strategy)

        worst = max(worst, _cost_per_ray(call, 32 * 32, 128 * 128, n_full, args.camera_budget))
    if worst * n_full <= args.camera_budget:
        return cam, ""
    f = math.sqrt(args.call_budget / (worst * cam.nx * cam.ny))
    small = cam.replace(nx=max(8, int(cam.nx * f)), ny=max(8, int(cam.ny * f)))
    return small, (
        f"camera reduced from {cam.nx}x{cam.ny} to {small.nx}x{small.ny}: {worst * 1e6:.1f} us per ray in a pilot cast"
    )


def fit_rays(
    scene: Any, origins: np.ndarray, dirs: np.ndarray, args: argparse.Namespace, rng: np.random.Generator
) -> tuple[np.ndarray | None, str]:
    """A guard for slower machines: a seeded random subset of the rays (about
    ``args.call_budget`` seconds a call) when one ``intersect`` of them all with the slowest
    vtkraycast kernel would take longer than ``args.guard_budget``, else None."""
    n = origins.shape[0]
    order = rng.permutation(n)
    worst = 0.0
    for strategy in ("watertight", "plane"):

        def call(m: int, strategy: str = strategy) -> Any:
            return scene.intersect(origins[order[:m]], dirs[order[:m]], strategy=strategy)

        worst = max(worst, _cost_per_ray(call, min(n, 1000), min(n, 10000), n, args.guard_budget))
    if worst * n <= args.guard_budget:
        return None, ""
    keep = np.sort(rng.choice(n, size=min(n, max(200, int(args.call_budget / worst))), replace=False))
    return keep, f"rays subsampled from {n} to {keep.size}: {worst * 1e6:.1f} us per ray in a pilot"


def run_scene(spec: SceneSpec, peers: list[Peer], args: argparse.Namespace, rng: np.random.Generator) -> list[Row]:
    import vtkraycast as vrc

    log(f"scene {spec.name}: loading")
    mesh = spec.mesh()
    t0 = time.perf_counter()
    scene = vrc.Scene(mesh)
    prep = time.perf_counter() - t0
    points, triangles = scene.prepared.points, scene.prepared.triangles
    m = int(triangles.shape[0])
    cam = spec.camera(mesh) if spec.camera else None
    scene_note = ""
    if cam is not None:
        kind = "camera"
        cam, scene_note = fit_camera(scene, cam, args)
        origins, dirs = camera_rays(cam)
    else:
        kind = "rays"
        origins, dirs = spec.rays(mesh, points, triangles)
        origins, dirs = np.ascontiguousarray(origins, np.float64), np.ascontiguousarray(dirs, np.float64)
        if spec.max_rays is not None and origins.shape[0] > spec.max_rays:
            scene_note = f"a random {spec.max_rays} of the {origins.shape[0]} rays"
            keep = np.sort(rng.choice(origins.shape[0], size=spec.max_rays, replace=False))
            origins, dirs = origins[keep], dirs[keep]
        keep, guard_note = fit_rays(scene, origins, dirs, args, rng)
        scene_note = "; ".join(x for x in (scene_note, guard_note) if x)
        if keep is not None:
            origins, dirs = origins[keep], dirs[keep]
    if scene_note:
        log(f"  {scene_note}")
    n = origins.shape[0]
    eye = origins[0]
    assert (origins == eye).all(), "the reference binning needs one common ray origin"
    # the sample for the exact reference: rays that may meet the mesh's box
    pool = np.flatnonzero(rays_hitting_box(origins, dirs, np.array(mesh.bounds)))
    sample = np.sort(rng.choice(pool, size=min(spec.n_ref, pool.size), replace=False)) if pool.size else pool
    log(f"  {m} triangles, {n} rays ({kind}), BVH {prep:.2f} s; exact reference on {sample.size} rays ...")
    t0 = time.perf_counter()
    ref = exact_reference(points, triangles, eye, dirs[sample])
    hit_ref = np.array([bool(a) for a in ref.accepted])
    log(
        f"  reference {time.perf_counter() - t0:.1f} s: {hit_ref.sum()} hits, "
        f"{int(ref.on_edge.sum())} through an edge or vertex"
    )
    if spec.must_hit and not hit_ref.all():
        log(f"  WARNING: {int((~hit_ref).sum())} sampled rays miss in a must-hit scene")
    rows: list[Row] = []
    base = dict(scene=spec.name, kind=kind, stress=spec.stress, n_triangles=m)
    geometry = (points, triangles)
    small = m < args.brute_force_below
    arrays = ["TriangleId", "Depth", "Barycentric"]

    def score_row(row: Row, res: Result, all_ids: np.ndarray, precision: Any) -> None:
        """Scores a method's row against this scene's exact reference, with ties to 32 eps."""
        tie = 32 * float(np.finfo(precision).eps)
        score(row, ref, sample, res, spec.must_hit, origins, dirs, all_ids, geometry, tie)

    for accel in ("bvh", "none"):
        if accel == "none" and not small:
            continue
        for strategy in vrc.STRATEGIES:
            for precision in ("float64", "float32"):
                row = Row(
                    **base,
                    method=vrc_name(strategy, precision, accel),
                    family="vtkraycast",
                    strategy=strategy,
                    precision=precision,
                    accel=accel,
                    threads=os.cpu_count() or 1,
                    prep_s=prep,
                )
                opts = dict(strategy=strategy, precision=precision, accel=accel)
                all_ids = None
                if cam is not None:
                    tcam = cam
                    if accel == "none":  # brute force: timed on a coarser grid of the same view
                        f = args.brute_force_downsample
                        tcam = cam.replace(nx=max(1, cam.nx // f), ny=max(1, cam.ny // f))
                        row.note = f"timed at {tcam.nx}x{tcam.ny}; errors from intersect on the sampled rays"
                    times, img = timed(
                        lambda c=tcam, o=opts: scene.cast(c, arrays=arrays, **o), args.repeats, args.budget
                    )
                    row.n_rays_timed = tcam.nx * tcam.ny
                    ids_full = np.asarray(img["TriangleId"])
                    row.hit_fraction = float((ids_full >= 0).mean())
                    if accel == "bvh":
                        res = Result(
                            ids_full[sample].astype(np.int64),
                            np.asarray(img["Depth"], np.float64)[sample] / cam.d,
                            np.asarray(img["Barycentric"], np.float64)[sample],
                        )
                        all_ids = ids_full
                        # the camera rays made here must be the core's own rays
                        check = scene.intersect(origins[sample], dirs[sample], **opts)
                        mismatch = int((check["triangle_id"] != res.ids).sum())
                        if mismatch:
                            row.note = f"{mismatch} sampled rays differ between cast and intersect"
                            log(f"  WARNING {row.method}: {row.note}")
                    else:
                        h = scene.intersect(origins[sample], dirs[sample], **opts)
                        res = Result(h["triangle_id"], h["t"].astype(np.float64), h["barycentric"].astype(np.float64))
                else:
                    times, h = timed(lambda o=opts: scene.intersect(origins, dirs, **o), args.repeats, args.budget)
                    row.n_rays_timed = n
                    all_ids = h["triangle_id"]
                    row.hit_fraction = float((all_ids >= 0).mean())
                    res = Result(
                        all_ids[sample], h["t"].astype(np.float64)[sample], h["barycentric"].astype(np.float64)[sample]
                    )
                    h = None
                row.record_times(times)
                score_row(row, res, all_ids, precision)
                row.note = "; ".join(x for x in (scene_note, row.note) if x)
                img = None
                rows.append(row)
                log_row(row)

    for peer in peers:
        row = Row(**base, method=peer.name, family="peer", threads=peer.threads, note=peer.note)
        try:
            t0 = time.perf_counter()
            peer.build(points, triangles)
            row.prep_s = time.perf_counter() - t0
            rays = peer.prepare(origins, dirs)
            times, out = timed(lambda p=peer, r=rays: p.run(r), args.repeats, args.budget)
            res_all = peer.collect(out)
            out = rays = None
        except Exception as exc:
            log(f"  {peer.name} failed: {exc!r}")
            row.note = f"failed: {exc!r}"
            rows.append(row)
            continue
        row.n_rays_timed = n
        row.record_times(times)
        row.hit_fraction = float((res_all.ids >= 0).mean())
        res = Result(res_all.ids[sample], res_all.t[sample], res_all.bary[sample])
        score_row(row, res, res_all.ids, peer.precision)
        row.note = "; ".join(x for x in (scene_note, row.note) if x)
        rows.append(row)
        log_row(row)
        peer.scene = peer.tree = peer.mesh = None  # free the peer's structures
    return rows


# ----------------------------------------------------------------------------------------
# reports
# ----------------------------------------------------------------------------------------


def fmt(x: float, kind: str = "e") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if kind == "e":
        return "0" if x == 0 else f"{x:.1e}"
    if kind == "f":
        return f"{x:.2f}" if x >= 0.1 else f"{x:.2g}"
    return str(x)


def aggregate(rows: list[Row]) -> list[dict[str, Any]]:
    methods: dict[str, list[Row]] = {}
    for r in rows:
        methods.setdefault(r.method, []).append(r)
    out = []
    for name, rs in methods.items():
        ok = [r for r in rs if not r.note.startswith("failed")]
        cam = [r.mrays_s for r in ok if r.kind == "camera" and not math.isnan(r.mrays_s)]
        cam_best = [r.n_rays_timed / r.time_min_s / 1e6 for r in ok if r.kind == "camera" and r.time_min_s > 0]
        frog = [r.mrays_s for r in ok if r.scene == "frog contour"]
        frog_best = [r.n_rays_timed / r.time_min_s / 1e6 for r in ok if r.scene == "frog contour"]
        stress = [r for r in ok if r.stress]
        terr = np.concatenate([r.t_errors for r in ok]) if ok else np.zeros(0)
        leaks, leak_rays = sum(r.leaks for r in ok), sum(r.leak_rays for r in ok)
        wrong, ref_hits = sum(r.wrong for r in ok), sum(r.ref_hits for r in ok)
        s_leaks, s_leak_rays = sum(r.leaks for r in stress), sum(r.leak_rays for r in stress)
        s_wrong, s_hits = sum(r.wrong for r in stress), sum(r.ref_hits for r in stress)
        bary = [r.bary_max_err for r in ok if not math.isnan(r.bary_max_err)]
        out.append(
            dict(
                method=name,
                family=rs[0].family,
                threads=rs[0].threads,
                scenes=len(ok),
                mrays_camera=float(np.median(cam)) if cam else math.nan,
                mrays_frog=frog[0] if frog else math.nan,
                mrays_camera_best=float(np.median(cam_best)) if cam_best else math.nan,
                mrays_frog_best=frog_best[0] if frog_best else math.nan,
                leaks=leaks,
                leak_rays=leak_rays,
                leak_rate=leaks / max(leak_rays, 1),
                wrong=wrong,
                ref_hits=ref_hits,
                wrong_rate=wrong / max(ref_hits, 1),
                wrong_side=sum(r.wrong_side for r in ok),
                wrong_depth=sum(r.wrong_depth for r in ok),
                wrong_depth_beyond=sum(r.wrong_depth_beyond_tie for r in ok),
                depth_gap=max(
                    [r.wrong_depth_max_gap for r in ok if not math.isnan(r.wrong_depth_max_gap)], default=math.nan
                ),
                false_hits=sum(r.false_hits for r in ok),
                stress_error=s_leaks / max(s_leak_rays, 1) + s_wrong / max(s_hits, 1),
                t_med=float(np.median(terr)) if terr.size else math.nan,
                t_p999=float(np.quantile(terr, 0.999)) if terr.size else math.nan,
                t_max=float(terr.max()) if terr.size else math.nan,
                bary_max=max(bary) if bary else math.nan,
            )
        )
    return out


def write_csv(rows: list[Row], path: Path) -> None:
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: getattr(r, k) for k in CSV_FIELDS})


def write_markdown(
    rows: list[Row], agg: list[dict[str, Any]], path: Path, header: list[str], wall: float, args: argparse.Namespace
) -> str:
    lines = ["# vtkraycast: run time against error", ""]
    lines += [f"- {h}" for h in header]
    lines += [
        f"- wall time: {wall:.0f} s; repeats: median of {args.repeats} timed runs after a warm-up; "
        "load average at the end: " + ", ".join(f"{x:.2f}" for x in os.getloadavg()),
        "",
    ]
    lines += [
        "Per method over all scenes. Mrays/s: median over the camera-ray scenes (perspective "
        "cameras, every pixel; vtkraycast's `Scene.cast` with TriangleId, Depth and Barycentric), and on "
        "the frog contour alone; each from the median run, in parentheses from the fastest run (a "
        "guide when the machine is shared). Leaks: rays that hit a surface but were missed (all rays of the "
        "must-hit scenes, the exact-reference sample elsewhere) / rays checked. Wrong: hit a triangle that "
        "is not among the exact first hits, over the sampled rays that hit; *side*: the exact ray does not "
        "meet the returned triangle at all (an inside test decided wrongly, typically the neighbour across an "
        "edge), *depth*: it meets it, but beyond the first hit (depth order); vtkraycast calls hits "
        "within 32 eps (relative, of the kernel's precision) ties and gives the lowest triangle id, so "
        "depth errors *beyond tie* are those with a larger gap (max gap: the largest relative t gap). "
        "t error: relative, over the rays hit correctly; bary: largest weight error where the method hit "
        "the reference's triangle.",
        "",
        "| method | threads | Mrays/s camera (median) | Mrays/s frog | leaks / rays checked | wrong rate | "
        "wrong: side / depth | false hits | t rel err median | t rel err 99.9% | t rel err max | bary max err |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for a in agg:
        lines.append(
            f"| {a['method']} | {a['threads']} | {fmt(a['mrays_camera'], 'f')} ({fmt(a['mrays_camera_best'], 'f')}) | "
            f"{fmt(a['mrays_frog'], 'f')} ({fmt(a['mrays_frog_best'], 'f')}) | "
            f"{a['leaks']} / {a['leak_rays']} ({fmt(a['leak_rate'])}) | "
            f"{fmt(a['wrong_rate'])} ({a['wrong']}/{a['ref_hits']}) | "
            f"{a['wrong_side']} / {a['wrong_depth']} ({a['wrong_depth_beyond']} beyond tie; "
            f"max gap {fmt(a['depth_gap'])}) | "
            f"{a['false_hits']} | {fmt(a['t_med'])} | {fmt(a['t_p999'])} | {fmt(a['t_max'])} | {fmt(a['bary_max'])} |"
        )
    stress_scenes = list(dict.fromkeys(r.scene for r in rows if r.stress))
    if stress_scenes:
        lines += [
            "",
            "## Stress scenes: leaks / wrong triangles",
            "",
            "Each cell is `leaks/wrong`; the header gives the rays checked for leaks and the "
            "reference sample that hit (the denominator of wrong). `.` means not run.",
            "",
        ]
        info = {}
        for s in stress_scenes:
            r = next(r for r in rows if r.scene == s and r.family == "vtkraycast")
            info[s] = f"{s} ({r.n_triangles} tris; {r.leak_rays} / {r.ref_hits})"
        lines.append("| method | " + " | ".join(info[s] for s in stress_scenes) + " |")
        lines.append("|---|" + "---:|" * len(stress_scenes))
        for a in agg:
            cells = []
            for s in stress_scenes:
                r = next((r for r in rows if r.scene == s and r.method == a["method"]), None)
                cells.append("." if r is None or r.note.startswith("failed") else f"{r.leaks}/{r.wrong}")
            if any(c != "." for c in cells):
                lines.append(f"| {a['method']} | " + " | ".join(cells) + " |")
    scenes = list(dict.fromkeys(r.scene for r in rows))
    lines += [
        "",
        "## Mrays/s per scene",
        "",
        "| method | " + " | ".join(scenes) + " |",
        "|---|" + "---:|" * len(scenes),
    ]
    for a in agg:
        cells = []
        for s in scenes:
            r = next((r for r in rows if r.scene == s and r.method == a["method"]), None)
            cells.append("." if r is None else fmt(r.mrays_s, "f"))
        lines.append(f"| {a['method']} | " + " | ".join(cells) + " |")
    ex = [(r, e) for r in rows for e in r.examples if r.family == "vtkraycast" and r.strategy in ("auto", "watertight")]
    if ex:
        lines += [
            "",
            "## Reproducers: errors of the strategies claimed exact (watertight, auto)",
            "",
            "`Scene(mesh).intersect(origin, direction, strategy=..., precision=...)` on the scene's mesh "
            "(see `build_scenes`); triangle ids index `scene.prepared.triangles`.",
            "",
            "```",
        ]
        seen = set()
        for r, (kind, k, o, d, got, acc) in ex:
            key = (r.scene, r.precision, r.accel, k)
            if key in seen or len(seen) >= 24:
                continue
            seen.add(key)
            lines.append(
                f"{r.scene} | {r.method} | ray {k}: origin={o!r} direction={d!r} -> got {got}, exact {acc}: {kind}"
            )
        lines += ["```"]
    text = "\n".join(lines) + "\n"
    path.write_text(text)
    return text


def pareto(xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Indices of the points no other point beats on both speed (higher) and error (lower)."""
    order = np.lexsort((ys, -xs))
    front, best = [], math.inf
    for i in order:
        if ys[i] < best:
            front.append(i)
            best = ys[i]
    return np.array(front, dtype=int)


def plot(agg: list[dict[str, Any]], path: Path, header: list[str]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = [a for a in agg if "accel=none" not in a["method"]]
    use_frog = all(not math.isnan(a["mrays_frog"]) for a in pts)
    xkey, xlabel = (
        ("mrays_frog", "Mrays/s, frog contour 1024x1024 (1.5M triangles)")
        if use_frog
        else ("mrays_camera", "Mrays/s, median over camera scenes")
    )
    pts = [a for a in pts if not math.isnan(a[xkey])]
    fig, axes = plt.subplots(1, 2, figsize=(15, 6.5))
    panels = [
        ("stress_error", "leak rate + wrong-triangle rate on the stress scenes (+ floor)", FLOOR),
        ("t_p999", "t relative error, 99.9th percentile over all scenes", 1e-18),
    ]
    for ax, (ykey, ylabel, floor) in zip(axes, panels):
        xs = np.array([a[xkey] for a in pts])
        ys = np.array([max(a[ykey], 0.0) + floor if not math.isnan(a[ykey]) else math.nan for a in pts])
        ok = ~np.isnan(ys)
        placed: list[tuple[float, float]] = []
        lx = (xs - np.nanmin(xs)) / max(np.nanmax(xs) - np.nanmin(xs), 1e-12)
        ly = np.log10(np.where(np.isnan(ys), 1.0, ys))
        ly = (ly - ly.min()) / max(ly.max() - ly.min(), 1e-12)
        for a, x, y, px_, py_ in sorted(zip(pts, xs, ys, lx, ly), key=lambda p: (-p[4], p[3])):
            if math.isnan(y):
                continue
            peer = a["family"] == "peer"
            zero = a[ykey] == 0
            marker = "s" if peer else ("o" if "float64" in a["method"] else "^")
            color = "tab:red" if peer else "tab:blue"
            ax.scatter([x], [y], marker=marker, s=60, facecolors="none" if zero else color, edgecolors=color, zorder=3)
            label = a["method"].replace("vtkraycast ", "").replace("float", "f")
            shift = 0  # stack labels of points that sit together
            while any(abs(px_ - qx) < 0.12 and abs(py_ - shift * 0.035 - qy) < 0.03 for qx, qy in placed):
                shift += 1
            placed.append((px_, py_ - shift * 0.035))
            ax.annotate(
                label,
                (x, y),
                textcoords="offset points",
                xytext=(6, 3 - 11 * shift),
                fontsize=7.5,
                arrowprops=dict(arrowstyle="-", color="0.6", lw=0.5) if shift else None,
            )
        if ok.sum():
            front = pareto(xs[ok], ys[ok])
            fx, fy = xs[ok][front], ys[ok][front]
            order = np.argsort(fx)
            ax.step(
                fx[order],
                fy[order],
                where="pre",
                color="gray",
                lw=1.2,
                ls="--",
                zorder=2,
                label="Pareto front (faster and more accurate is down-right)",
            )
        ax.set_yscale("log")
        if ok.sum():
            lo, hi = np.nanmin(ys), np.nanmax(ys)
            pad = 10 ** (0.12 * max(math.log10(hi / lo), 1))
            ax.set_ylim(lo / pad, hi * pad)
            ax.set_xlim(0, np.nanmax(xs) * 1.35)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
    axes[0].set_title(f"errors (hollow: zero, drawn at the floor {FLOOR:g})", fontsize=10)
    axes[1].set_title("blue: vtkraycast (o float64, ^ float32); red squares: peers", fontsize=10)
    fig.suptitle("vtkraycast run time vs error  |  " + header[1], fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


# ----------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="small sizes: a smoke test in under a minute")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path(__file__).resolve().parent / "results",
        help="output directory (default: benchmarks/results)",
    )
    parser.add_argument(
        "--repeats", type=int, default=None, help="timed runs per measurement (default 5; 3 with --quick)"
    )
    parser.add_argument("--only", default=None, help="run only scenes whose name contains this text")
    args = parser.parse_args(argv)
    if args.repeats is None:
        args.repeats = 3 if args.quick else 5
    args.budget = 20.0 if not args.quick else 3.0  # seconds per timing; a slower method gets >= 3 repeats
    args.brute_force_below = 1000 if args.quick else 5000
    # Guards for slower machines, checked by a pilot call of the slowest vtkraycast kernels:
    # when one call would take longer than guard_budget (ray sets) or camera_budget (cameras),
    # the rays are subsampled, or the camera made coarser, to about call_budget seconds a call.
    args.call_budget = 0.1 if args.quick else 0.6
    args.guard_budget = 1.0 if args.quick else 6.0
    args.camera_budget = 1.0 if args.quick else 6.0
    args.brute_force_downsample = 8
    header = machine_lines()
    for line in header:
        print(line, flush=True)
    start = time.perf_counter()
    rng = np.random.default_rng(SEED)
    peers = make_peers()
    log("peers: " + ", ".join(p.name for p in peers))
    rows: list[Row] = []
    for spec in build_scenes(args.quick):
        if args.only and args.only not in spec.name:
            continue
        rows += run_scene(spec, peers, args, np.random.default_rng(rng.integers(2**32)))
    wall = time.perf_counter() - start
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(rows, args.out / "runtime_vs_error.csv")
    agg = aggregate(rows)
    text = write_markdown(rows, agg, args.out / "runtime_vs_error.md", header, wall, args)
    plot(agg, args.out / "runtime_vs_error.png", header)
    print()
    print(text)
    log(f"wrote {args.out / 'runtime_vs_error.csv'}, .md and .png in {wall:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
