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

from .fields import miss_value

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

    def allreduce(self, values: np.ndarray, op: str) -> np.ndarray:
        from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy

        send = numpy_to_vtk(np.ascontiguousarray(values.reshape(len(values), -1)), deep=True)
        receive = send.NewInstance()
        self._controller.AllReduce(send, receive, self._ops[op])
        return vtk_to_numpy(receive).reshape(values.shape).astype(values.dtype, copy=False)

    def gather_object(self, value: Any, root: int | None = None) -> list[Any] | None:
        """Every rank's ``value``, in rank order, on ``root`` (every rank when None)."""
        if root is None:
            return [self._broadcast_object(value if r == self.rank else None, r) for r in range(self.size)]
        if self.rank != root:
            self._controller.Send(_pickled(value), root, _TAG)
            return None
        values = []
        for r in range(self.size):
            if r == root:
                values.append(value)
                continue
            message = _pickled(None).NewInstance()  # (the sender's array type)
            self._controller.Receive(message, r, _TAG)
            values.append(_unpickled(message))
        return values

    def _broadcast_object(self, value: Any, root: int) -> Any:
        message = _pickled(value) if self.rank == root else _pickled(None).NewInstance()
        self._controller.Broadcast(message, root)
        return value if self.rank == root else _unpickled(message)

    def broadcast(self, values: np.ndarray, root: int) -> np.ndarray:
        from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy

        flat = np.ascontiguousarray(values.reshape(len(values), -1))
        message = numpy_to_vtk(flat, deep=True)
        if self.rank != root:
            message = message.NewInstance()
        self._controller.Broadcast(message, root)
        return vtk_to_numpy(message).reshape(values.shape).astype(values.dtype, copy=False)


_TAG = 827  # (message tag of the winners' arrays, on VTK's controller)


def _pickled(value: Any) -> Any:
    import pickle

    from vtkmodules.util.numpy_support import numpy_to_vtk

    return numpy_to_vtk(np.frombuffer(pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL), np.int8), deep=True)


def _unpickled(message: Any) -> Any:
    import pickle

    from vtkmodules.util.numpy_support import vtk_to_numpy

    return pickle.loads(vtk_to_numpy(message).tobytes())


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

    def allreduce(self, values: np.ndarray, op: str) -> np.ndarray:
        out = np.empty_like(values)
        self._comm.Allreduce(np.ascontiguousarray(values), out, op={"min": self._mpi.MIN, "sum": self._mpi.SUM}[op])
        return out

    def gather_object(self, value: Any, root: int | None = None) -> list[Any] | None:
        return self._comm.allgather(value) if root is None else self._comm.gather(value, root=root)

    def broadcast(self, values: np.ndarray, root: int) -> np.ndarray:
        values = np.ascontiguousarray(values)
        self._comm.Bcast(values, root=root)
        return values


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
    by all ranks). Returns the arrays on ``root`` (every rank when None), None elsewhere.

    Two reductions over the frame pick each pixel's winner (the least depth, then the
    lowest key within the tie tolerance); then only the winners' values travel, each rank
    sending its own to the root."""
    target = 0 if root is None else root
    hit = hit_keys != NO_HIT
    depth = np.where(hit, buffers["Depth"], np.inf).astype(np.float64, copy=False)
    nearest = comm.allreduce(depth, "min")
    candidate = hit & (depth <= nearest + tie * np.abs(nearest))
    winner = comm.allreduce(np.where(candidate, hit_keys, NO_HIT), "min")
    won = np.flatnonzero(candidate & (hit_keys == winner))
    sent = (won, {name: buffers[name][won] for name in layout if name in buffers})
    received = comm.gather_object(None if comm.rank == target else sent, target)
    out = None
    if comm.rank == target:
        # The root's own arrays already hold its hits and its misses; where another rank
        # won, that rank's values replace the root's.
        out = {}
        for name, (dtype, row) in layout.items():
            values = buffers.get(name)
            if values is None:
                values = np.full((len(hit_keys), *row), miss_value(name, dtype), dtype)
            values = values.astype(dtype, copy=False)
            for rank, message in enumerate(received):
                if rank != target:
                    indices, arrays = message
                    values[indices] = arrays[name] if name in arrays else miss_value(name, dtype)
            out[name] = values
    if root is None:
        out = {
            name: comm.broadcast(out[name] if comm.rank == target else np.empty((len(hit_keys), *row), dtype), target)
            for name, (dtype, row) in layout.items()
        }
    return out
