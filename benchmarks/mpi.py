#!/usr/bin/env python
"""Casting under MPI: what compositing costs beside the cast, measured on local ranks.

    mpiexec -n 2 python benchmarks/mpi.py [--pixels 1024] [--repeats 7] [--bands rows|columns]

The frog contour is split among the ranks by cell order (global cell ids attached); each
rank casts its piece at full resolution with the default arrays, then the nearest hit per
pixel is composited (vtkraycast/parallel.py): to rank 0 through the ranks' shared memory
(the default when the ranks run on one node), to rank 0 by direct send (as across
nodes), and in ParaView's layout, to each rank's band of rows. Prints, on rank 0, the
median of each phase over the repeats (barriers between phases), the compositing time
per pixel, the bytes direct send moved and the time MPI takes to move as many bytes in
one exchange (the floor of direct send). On this machine (2 cores) the ranks share the
cores, so the cast itself does not scale.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pyvista as pv
from mpi4py import MPI

import vtkraycast as vrc

sys.path.insert(0, str(Path(__file__).parent))
import scenes

GEOMETRY = ["TriangleId", "CellId", "Barycentric", "Depth", "vtkValidPointMask"]


def piece_of(mesh: pv.PolyData, rank: int, size: int) -> pv.PolyData:
    faces = mesh.faces.reshape(-1, 4)
    cells = np.array_split(np.arange(mesh.n_cells), size)[rank]
    piece = pv.PolyData(mesh.points, faces=faces[cells].ravel())
    piece.cell_data["GlobalIds"] = cells.astype(np.int64)
    piece.GetCellData().SetGlobalIds(piece.GetCellData().GetArray("GlobalIds"))
    return piece


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pixels", type=int, default=1024)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument(
        "--bands", choices=("rows", "columns"), default="rows", help="how ParaView's layout splits the image"
    )
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    mesh = scenes.frog()
    camera = scenes.view(mesh, "framed", args.pixels)
    scene = vrc.Scene(piece_of(mesh, comm.rank, comm.size), comm=comm)
    adapter = scene._comm
    counting = _Counting(adapter)  # (not an mpi4py adapter: casts through it send directly)
    cuts = np.linspace(0, args.pixels, comm.size + 1).astype(int)  # (ParaView's layout: a band each)
    bands = [(0, args.pixels - 1, int(cuts[r]), int(cuts[r + 1]) - 1) for r in range(comm.size)]
    if args.bands == "columns":  # (as VTK splits an image wider than high)
        bands = [(y0, y1, x0, x1) for x0, x1, y0, y1 in bands]

    def phases(through, **where) -> tuple[float, float]:
        """The local cast's and the compositing's times, barriers around each."""
        scene._comm = through
        comm.Barrier()
        start = time.perf_counter()
        _, finish = scene._cast_local(camera, arrays=GEOMETRY, **where)
        comm.Barrier()
        middle = time.perf_counter()
        finish()
        comm.Barrier()
        scene._comm = adapter
        return middle - start, time.perf_counter() - middle

    scene.cast(camera, arrays=GEOMETRY)  # (the scene's keys and global cell ids, the shared window, once)
    phases(counting, root=0)
    times: dict[str, list] = {"node": [], "direct": [], "bands": [], "floor": [], "total": []}
    for _ in range(args.repeats):
        times["node"].append(phases(adapter, root=0))
        counting.bytes = 0
        times["direct"].append(phases(counting, root=0))
        moved = comm.allreduce(counting.bytes, op=MPI.MAX)
        times["bands"].append(phases(adapter, root=None, extent=bands[comm.rank]))
        # the floor: MPI moving as many bytes in one all-to-all exchange
        message = np.zeros(moved, np.uint8)
        counts = np.zeros(comm.size, np.int64)
        counts[(comm.rank + 1) % comm.size] = moved
        comm.Barrier()
        floor_start = time.perf_counter()
        adapter.alltoallv(message, counts)
        comm.Barrier()
        times["floor"].append(time.perf_counter() - floor_start)
        start_full = time.perf_counter()
        scene.cast(camera, arrays=GEOMETRY)
        comm.Barrier()
        times["total"].append(time.perf_counter() - start_full)
    if comm.rank == 0:
        cast, comp = np.median(times["node"], axis=0)
        direct_cast, direct = np.median(times["direct"], axis=0)
        band_cast, band = np.median(times["bands"], axis=0)
        floor, total = float(np.median(times["floor"])), float(np.median(times["total"]))
        pixels = args.pixels**2
        print(
            f"{comm.size} ranks, frog contour framed, {args.pixels}x{args.pixels}, default geometry arrays, "
            f"{scene._threads} threads per rank, median of {args.repeats}:"
        )
        print(
            f"  the whole image on rank 0, the ranks' frames in shared memory (the default on one node): "
            f"local cast {1e3 * cast:.1f} ms, compositing {1e3 * comp:.1f} ms "
            f"({1e9 * comp / pixels:.1f} ns per pixel, {comp / cast:.0%} of the cast); "
            f"Scene.cast end to end {1e3 * total:.1f} ms"
        )
        print(
            f"  the whole image on rank 0 by direct send (across nodes): local cast {1e3 * direct_cast:.1f} ms, "
            f"compositing {1e3 * direct:.1f} ms ({direct / direct_cast:.0%} of the cast); it moved at most "
            f"{moved / 2**20:.1f} MiB from one rank, which MPI alone moves in {1e3 * floor:.1f} ms "
            f"({floor / direct_cast:.0%} of the cast)"
        )
        print(
            f"  ParaView's layout (each rank receives its band of {args.bands}, direct send): local cast "
            f"{1e3 * band_cast:.1f} ms, compositing {1e3 * band:.1f} ms ({band / band_cast:.0%} of the cast)"
        )


class _Counting:
    """The adapter, counting the bytes this rank sends to others."""

    def __init__(self, adapter):
        self._adapter, self.bytes = adapter, 0
        self.rank, self.size = adapter.rank, adapter.size

    def gather_object(self, value, root=None):
        return self._adapter.gather_object(value, root)

    def alltoallv(self, send, counts, room):
        self.bytes += int(counts.sum() - counts[self.rank])
        return self._adapter.alltoallv(send, counts, room)


if __name__ == "__main__":
    main()
