"""The peer ray casters the benchmarks compare against, behind one interface: build
(untimed in the tables), prepare the rays, run (timed), collect a Result."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class Result:
    ids: np.ndarray  # int64, -1 on a miss
    t: np.ndarray  # float64 ray parameter (units of the direction), NaN on a miss
    bary: np.ndarray  # (n, 3) weights of the triangle's points, NaN on a miss


class Peer:
    """A peer ray caster: ``build`` (untimed), ``prepare`` rays (untimed), ``run`` (timed),
    ``collect`` the raw output into a Result (untimed)."""

    name = ""
    threads = 1
    note = ""
    precision = "float32"

    def build(self, points: np.ndarray, triangles: np.ndarray) -> None:
        raise NotImplementedError

    def prepare(self, origins: np.ndarray, dirs: np.ndarray) -> Any:
        raise NotImplementedError

    def run(self, rays: Any) -> Any:
        raise NotImplementedError

    def collect(self, out: Any) -> Result:
        raise NotImplementedError


class Open3DPeer(Peer):
    name = "open3d RaycastingScene f32"
    precision = "float32"
    threads = os.cpu_count() or 1
    note = "float32 vertices and rays (Embree inside)"

    def build(self, points, triangles):
        import open3d as o3d

        self.o3d = o3d
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor(points.astype(np.float32)), o3d.core.Tensor(triangles.astype(np.uint32))
        )
        self.scene.cast_rays(o3d.core.Tensor(np.array([[0, 0, 0, 0, 0, 1]], np.float32)))  # commit

    def prepare(self, origins, dirs):
        return self.o3d.core.Tensor(np.hstack((origins, dirs)).astype(np.float32))

    def run(self, rays):
        return self.scene.cast_rays(rays)

    def collect(self, out):
        ids = out["primitive_ids"].numpy().astype(np.int64)
        ids[ids == np.iinfo(np.uint32).max] = -1
        t = out["t_hit"].numpy().astype(np.float64)
        uv = out["primitive_uvs"].numpy().astype(np.float64)
        return Result(*_peer_result(ids, t, uv))


class EmbreexPeer(Peer):
    threads = 1
    precision = "float32"
    note = "float32 vertices and rays; the binding loops over rays on one thread"

    def __init__(self, robust: bool = False) -> None:
        self.robust = robust
        self.name = "embreex f32" + (" robust" if robust else "")

    def build(self, points, triangles):
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        self.scene = rtcs.EmbreeScene(robust=self.robust) if self.robust else rtcs.EmbreeScene()
        self.mesh = TriangleMesh(self.scene, points.astype(np.float32)[triangles])
        self.scene.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32))  # commit

    def prepare(self, origins, dirs):
        return (np.ascontiguousarray(origins, np.float32), np.ascontiguousarray(dirs, np.float32))

    def run(self, rays):
        return self.scene.run(rays[0], rays[1], output=1)

    def collect(self, out):
        ids = out["primID"].astype(np.int64)
        ids[(ids < 0) | (out["geomID"] < 0)] = -1
        t = out["tfar"].astype(np.float64)
        uv = np.stack((out["u"], out["v"]), axis=1).astype(np.float64)
        return Result(*_peer_result(ids, t, uv))


class LibiglPeer(Peer):
    name = "libigl AABB"
    precision = "float64"
    threads = 1
    note = "float64 in, t and (u, v) returned rounded to float32; one thread"

    def build(self, points, triangles):
        import igl

        self.V = np.ascontiguousarray(points, np.float64)
        self.F = np.ascontiguousarray(triangles, np.int64)
        self.tree = igl.AABB()
        self.tree.init(self.V, self.F)

    def prepare(self, origins, dirs):
        return (np.ascontiguousarray(origins, np.float64), np.ascontiguousarray(dirs, np.float64))

    def run(self, rays):
        return self.tree.intersect_ray_first(self.V, self.F, rays[0], rays[1])

    def collect(self, out):
        ids, t, uv = out
        return Result(
            *_peer_result(
                np.asarray(ids, np.int64).copy(), np.asarray(t, np.float64).copy(), np.asarray(uv, np.float64).copy()
            )
        )


def _peer_result(ids: np.ndarray, t: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    miss = ids < 0
    t[miss | ~np.isfinite(t)] = np.nan
    bary = np.column_stack((1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]))
    bary[miss] = np.nan
    return ids, t, bary


def make_peers() -> list[Peer]:
    peers: list[Peer] = []
    for factory in (Open3DPeer, EmbreexPeer, lambda: EmbreexPeer(robust=True), LibiglPeer):
        peer = factory()
        try:
            peer.build(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]), np.array([[0, 1, 2]]))
        except Exception as exc:  # a missing peer is reported, not fatal
            print(f"peer {peer.name} unavailable: {exc!r}", flush=True)
            continue
        peers.append(peer)
    return peers


class TrimeshPeer(Peer):
    name = "trimesh ray (pyembree backend)"
    threads = 1
    note = "trimesh.Trimesh.ray.intersects_first; embreex underneath when installed"

    def build(self, points, triangles):
        import trimesh

        self.mesh = trimesh.Trimesh(points, triangles.astype(np.int64), process=False)
        self.mesh.ray.intersects_first(np.zeros((1, 3)), np.array([[0, 0, 1.0]]))

    def prepare(self, origins, dirs):
        return origins, dirs

    def run(self, rays):
        return self.mesh.ray.intersects_first(rays[0], rays[1])

    def collect(self, out):
        ids = np.asarray(out, np.int64)
        return Result(ids, np.full(ids.shape, np.nan), np.full((ids.size, 3), np.nan))


class PyvistaMultiRayTracePeer(Peer):
    name = "pyvista multi_ray_trace"
    threads = 1
    note = "PolyData.multi_ray_trace(first_point=True), trimesh underneath"
    sampled = True

    def build(self, points, triangles):
        import pyvista as pv

        self.mesh = pv.PolyData(points, faces=np.c_[np.full(len(triangles), 3), triangles].ravel())

    def prepare(self, origins, dirs):
        return origins, dirs

    def run(self, rays):
        _, hit_rays, cells = self.mesh.multi_ray_trace(rays[0], rays[1], first_point=True)
        ids = np.full(len(rays[0]), -1, np.int64)
        ids[np.asarray(hit_rays, np.int64)] = np.asarray(cells, np.int64)
        return ids

    def collect(self, out):
        return Result(out, np.full(out.shape, np.nan), np.full((out.size, 3), np.nan))


class VtkLocatorPeer(Peer):
    """VTK's own locators through IntersectWithLine, one Python call per ray (sampled)."""

    threads = 1
    sampled = True

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.name = f"VTK {kind}.IntersectWithLine (Python loop)"

    def build(self, points, triangles):
        import pyvista as pv
        from vtkmodules.vtkCommonDataModel import vtkStaticCellLocator
        from vtkmodules.vtkFiltersGeneral import vtkOBBTree

        self.mesh = pv.PolyData(points, faces=np.c_[np.full(len(triangles), 3), triangles].ravel())
        self.locator = vtkOBBTree() if self.kind == "vtkOBBTree" else vtkStaticCellLocator()
        self.locator.SetDataSet(self.mesh)
        self.locator.BuildLocator()
        self.reach = 10.0 * float(np.linalg.norm(np.ptp(points, axis=0)))

    def prepare(self, origins, dirs):
        return origins, dirs

    def run(self, rays):
        from vtkmodules.vtkCommonCore import reference, vtkIdList, vtkPoints

        ids = np.full(len(rays[0]), -1, np.int64)
        t, x, pc, sub, cell = reference(0.0), [0.0] * 3, [0.0] * 3, reference(0), reference(0)
        for k, (o, d) in enumerate(zip(rays[0], rays[1])):
            end = o + d / np.linalg.norm(d) * self.reach
            if self.kind == "vtkOBBTree":
                points, cells = vtkPoints(), vtkIdList()
                if self.locator.IntersectWithLine(o, end, points, cells) and cells.GetNumberOfIds():
                    ids[k] = cells.GetId(0)
            elif self.locator.IntersectWithLine(o, end, 0.0, t, x, pc, sub, cell):
                ids[k] = cell.get()
        return ids

    def collect(self, out):
        return Result(out, np.full(out.shape, np.nan), np.full((out.size, 3), np.nan))


def more_peers() -> list[Peer]:
    """The casters users reach for that are too slow or too coarse for the accuracy tables."""
    return [
        TrimeshPeer(),
        PyvistaMultiRayTracePeer(),
        VtkLocatorPeer("vtkStaticCellLocator"),
        VtkLocatorPeer("vtkOBBTree"),
    ]
