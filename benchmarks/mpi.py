#!/usr/bin/env python
"""Casting under MPI: what compositing costs beside the cast, measured on local ranks.

    mpiexec -n 2 python benchmarks/mpi.py [--pixels 1024] [--repeats 7] [--bands rows|columns]

The frog contour is split among the ranks by cell order (global cell ids attached); each
rank casts its piece at full resolution with the default arrays, then the nearest hit per
pixel is composited to rank 0 (vtkraycast/parallel.py), and, in ParaView's layout, to each
rank's band of rows. Prints, on rank 0, the median of
each phase over the repeats (barriers between phases), the compositing time per pixel,
the bytes it moved and the time MPI takes to move as many bytes in one exchange (the
floor of this design). On this machine (2 cores) the ranks share the cores, so the cast
itself does not scale.
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
from vtkraycast.parallel import communicator, composite

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
    adapter = communicator(comm)
    scene.cast(camera, arrays=GEOMETRY)  # (the scene's keys and global cell ids, once)
    whole = (0, args.pixels - 1, 0, args.pixels - 1)
    regions = [whole] + [None] * (comm.size - 1)
    cuts = np.linspace(0, args.pixels, comm.size + 1).astype(int)  # (ParaView's layout: a band each)
    bands = [(0, args.pixels - 1, int(cuts[r]), int(cuts[r + 1]) - 1) for r in range(comm.size)]
    if args.bands == "columns":  # (as VTK splits an image wider than high)
        bands = [(y0, y1, x0, x1) for x0, x1, y0, y1 in bands]
    casts, composites, totals, floors, banded = [], [], [], [], []
    moved = 0
    for _ in range(args.repeats):
        comm.Barrier()
        start = time.perf_counter()
        _, buffers = scene._cast_into(None, camera, arrays=GEOMETRY, threads=scene._threads, mesh=scene._global_mesh)
        comm.Barrier()
        middle = time.perf_counter()
        layout = {name: (values.dtype, values.shape[1:]) for name, values in buffers.items()}
        sent = _Counting(adapter)
        composite(sent, buffers, scene._keys, layout, (args.pixels, args.pixels), regions, 1e-14, scene._work)
        comm.Barrier()
        end = time.perf_counter()
        moved = comm.allreduce(sent.bytes, op=MPI.MAX)
        # (rank 0's arrays now hold the image: cast again)
        _, buffers = scene._cast_into(None, camera, arrays=GEOMETRY, threads=scene._threads, mesh=scene._global_mesh)
        comm.Barrier()
        band_start = time.perf_counter()
        composite(adapter, buffers, scene._keys, layout, (args.pixels, args.pixels), bands, 1e-14, scene._work)
        comm.Barrier()
        banded.append(time.perf_counter() - band_start)
        # the floor: MPI moving as many bytes in one all-to-all exchange
        message = np.zeros(moved, np.uint8)
        counts = np.zeros(comm.size, np.int64)
        counts[(comm.rank + 1) % comm.size] = moved
        comm.Barrier()
        floor_start = time.perf_counter()
        adapter.alltoallv(message, counts)
        comm.Barrier()
        floors.append(time.perf_counter() - floor_start)
        start_full = time.perf_counter()
        scene.cast(camera, arrays=GEOMETRY)
        comm.Barrier()
        totals.append(time.perf_counter() - start_full)
        casts.append(middle - start)
        composites.append(end - middle)
    if comm.rank == 0:
        cast, comp, total, floor, band = (float(np.median(x)) for x in (casts, composites, totals, floors, banded))
        pixels = args.pixels**2
        print(
            f"{comm.size} ranks, frog contour framed, {args.pixels}x{args.pixels}, default geometry arrays, "
            f"{scene._threads} threads per rank, median of {args.repeats}:"
        )
        print(
            f"  local cast {1e3 * cast:.1f} ms, compositing {1e3 * comp:.1f} ms "
            f"({1e9 * comp / pixels:.1f} ns per pixel, {comp / cast:.0%} of the cast); "
            f"Scene.cast end to end {1e3 * total:.1f} ms; compositing moved at most {moved / 2**20:.1f} MiB "
            f"from one rank, which MPI alone moves in {1e3 * floor:.1f} ms ({floor / cast:.0%} of the cast)"
        )
        print(
            f"  ParaView's layout (each rank receives its band of {args.bands}): compositing {1e3 * band:.1f} ms "
            f"({band / cast:.0%} of the cast)"
        )


class _Counting:
    """The adapter, counting the bytes this rank sends to others."""

    def __init__(self, adapter):
        self._adapter, self.bytes = adapter, 0
        self.rank, self.size = adapter.rank, adapter.size

    def alltoallv(self, send, counts, room):
        self.bytes += int(counts.sum() - counts[self.rank])
        return self._adapter.alltoallv(send, counts, room)


if __name__ == "__main__":
    main()
