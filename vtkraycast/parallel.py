"""Casting a mesh distributed over MPI ranks: each rank casts its own piece at full
resolution, then the nearest hit of every pixel is chosen across ranks and its arrays
reach the rank(s) that receive the image.

The choice is the serial cast's rule made global: the least depth, and among hits within
the tie tolerance of it (the same point reached through two triangles) the lowest global
triangle key. With the input's global cell ids (``vtkCellData::GetGlobalIds``, as
ParaView's RedistributeDataSet makes them) the key orders triangles as the serial mesh
does, so an N-rank image equals the serial one. Ranks without triangles still take part in
every collective call.

Communicators are mpi4py's (``MPI.Comm``); :class:`VtkController` adapts VTK's
``vtkMultiProcessController`` (ParaView's pvbatch and pvserver) to the same few calls.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

__all__ = ["Mpi4pyComm", "VtkController", "communicator", "composite", "default_threads", "triangle_keys"]

#: Key of a miss: above every triangle's.
NO_HIT = np.iinfo(np.int64).max
#: Triangles of one cell get consecutive keys below this many (a polygon of 2**16 points is
#: beyond any mesh seen; checked).
_PER_CELL = 2**16


class VtkController:
    """The calls :func:`composite` makes, on a vtkMultiProcessController."""

    def __init__(self, controller: Any) -> None:
        from vtkmodules.vtkParallelCore import vtkCommunicator

        self._controller = controller
        self._ops = {"min": vtkCommunicator.MIN_OP, "sum": vtkCommunicator.SUM_OP}

    @property
    def rank(self) -> int:
        return self._controller.GetLocalProcessId()

    @property
    def size(self) -> int:
        return self._controller.GetNumberOfProcesses()

    def reduce(self, values: np.ndarray, op: str, root: int | None) -> np.ndarray | None:
        from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy

        flat = np.ascontiguousarray(values.reshape(len(values), -1))
        send = numpy_to_vtk(flat, deep=True, array_type=None)
        receive = send.NewInstance()
        if root is None:
            self._controller.AllReduce(send, receive, self._ops[op])
        else:
            self._controller.Reduce(send, receive, self._ops[op], root)
            if self.rank != root:
                return None
        return vtk_to_numpy(receive).reshape(values.shape).astype(values.dtype, copy=False)

    def gather_object(self, value: Any) -> list[Any]:
        """Every rank's ``value`` (small: names, dtypes), in rank order, on every rank."""
        import pickle

        data = np.frombuffer(pickle.dumps(value), np.int8)
        sizes = self.reduce(np.eye(self.size, dtype=np.int64)[self.rank] * len(data), "sum", None)
        buffer = np.zeros(int(sizes.sum()), np.int8)
        start = int(sizes[: self.rank].sum())
        buffer[start : start + len(data)] = data
        total = self.reduce(buffer, "sum", None)
        bounds = np.concatenate(([0], np.cumsum(sizes)))
        return [pickle.loads(total[bounds[r] : bounds[r + 1]].tobytes()) for r in range(self.size)]


class Mpi4pyComm:
    """The calls :func:`composite` makes, on an mpi4py communicator."""

    def __init__(self, comm: Any) -> None:
        from mpi4py import MPI

        self._comm, self._mpi = comm, MPI

    @property
    def rank(self) -> int:
        return self._comm.Get_rank()

    @property
    def size(self) -> int:
        return self._comm.Get_size()

    def reduce(self, values: np.ndarray, op: str, root: int | None) -> np.ndarray | None:
        mpi_op = {"min": self._mpi.MIN, "sum": self._mpi.SUM}[op]
        send = np.ascontiguousarray(values)
        if root is None:
            out = np.empty_like(send)
            self._comm.Allreduce(send, out, op=mpi_op)
            return out
        out = np.empty_like(send) if self.rank == root else None
        self._comm.Reduce(send, out, op=mpi_op, root=root)
        return out

    def gather_object(self, value: Any) -> list[Any]:
        return self._comm.allgather(value)


def communicator(comm: Any) -> VtkController | Mpi4pyComm:
    """The adapter for an mpi4py communicator or a vtkMultiProcessController."""
    if hasattr(comm, "GetNumberOfProcesses"):
        return VtkController(comm)
    if hasattr(comm, "Allreduce") and hasattr(comm, "Get_rank"):
        return Mpi4pyComm(comm)
    raise TypeError(f"comm must be an mpi4py communicator or a vtkMultiProcessController, got {type(comm).__name__}")


def default_threads(comm: Any) -> int:
    """Cores of this node divided among the ranks on it (mpi4py), so ranks do not
    oversubscribe a node; all cores for a VTK controller (ranks per node unknown)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    if hasattr(comm, "Split_type"):
        from mpi4py import MPI

        local = comm.Split_type(MPI.COMM_TYPE_SHARED)
        ranks_here = local.Get_size()
        local.Free()
        return max(1, cores // ranks_here)
    return cores


def triangle_keys(cell_ids: np.ndarray, global_ids: np.ndarray | None, rank: int) -> np.ndarray:
    """Each triangle's global key: from the global id of its cell (and its place among the
    cell's triangles) when the input has global cell ids, else from the rank and its index."""
    n = len(cell_ids)
    if global_ids is None:
        return (np.int64(rank) << np.int64(40)) + np.arange(n, dtype=np.int64)
    starts = np.flatnonzero(np.r_[True, np.diff(cell_ids) != 0])
    within = np.arange(n) - np.repeat(starts, np.diff(np.r_[starts, n]))
    if n and within.max() >= _PER_CELL:
        raise ValueError(f"a cell of more than {_PER_CELL} triangles: global triangle keys overflow")
    return global_ids[cell_ids].astype(np.int64) * _PER_CELL + within


def composite(
    comm: VtkController | Mpi4pyComm,
    buffers: dict[str, np.ndarray],
    hit_keys: np.ndarray,
    layout: dict[str, tuple[np.dtype, tuple[int, ...]]],
    root: int | None,
    tie: float,
) -> dict[str, np.ndarray] | None:
    """The image of every rank's hits: ``buffers`` (this rank's arrays, Depth among them;
    an array a rank lacks counts as missing there), ``hit_keys`` (this rank's key of each
    pixel's hit, NO_HIT on a miss), ``layout`` (dtype and row shape of every array, agreed
    by all ranks). Returns the arrays on ``root`` (every rank when None), None elsewhere."""
    depth = np.where(hit_keys != NO_HIT, buffers["Depth"].astype(np.float64), np.inf)
    nearest = comm.reduce(depth, "min", None)
    candidate = (hit_keys != NO_HIT) & (depth <= nearest + tie * np.abs(nearest))
    winner = comm.reduce(np.where(candidate, hit_keys, NO_HIT), "min", None)
    mine = candidate & (hit_keys == winner)
    hit = winner != NO_HIT
    out = {}
    for name, (dtype, row) in layout.items():
        contribution = np.zeros((len(hit_keys), *row), dtype)
        if name in buffers:
            contribution[mine] = buffers[name][mine]
        total = comm.reduce(contribution, "sum", root)
        if total is None:
            continue
        if name in ("TriangleId", "CellId", "CompositeIndex"):
            total[~hit] = -1
        elif dtype.kind == "f":
            total[~hit] = np.nan
        out[name] = total
    return out if (root is None or comm.rank == root) else None
