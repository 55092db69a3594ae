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
from collections.abc import Callable
from typing import Any

import numpy as np

from . import _core
from .fields import miss_value
from .shared_frames import NodeFrames

#: The largest message an exchange sends in one piece (a C int counts MPI's bytes).
MESSAGE_PIECE = 2**30
#: Where received bytes go: a uint8 array of the given length.
Room = Callable[[int], np.ndarray]

__all__ = [
    "Mpi4pyComm",
    "VtkController",
    "Workspace",
    "communicator",
    "composite",
    "default_threads",
    "node_frames",
    "triangle_keys",
]

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

    def alltoallv(
        self, send: np.ndarray, counts: np.ndarray, room: Room | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bytes ``send[segment r]`` (segments of ``counts`` bytes, in rank order) to each
        rank r; returns what every rank sent here (in ``room(bytes)``), in rank order, and
        the sizes. VTK's controllers have no all-to-all: blocking sends and receives, one
        pair at a time in the same order on every rank (so none waits on a rank waiting on
        it)."""
        from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
        from vtkmodules.vtkCommonCore import vtkUnsignedCharArray

        size, rank = self.size, self.rank
        matrix = np.zeros((size, size), dtype=np.int64)  # (bytes from row rank to column rank)
        matrix[rank] = counts
        matrix = self.allreduce(matrix, "sum")
        sends, receives = _offsets(counts), _offsets(matrix[:, rank])
        out = (room or _bytes)(int(receives[-1]))
        out[receives[rank] : receives[rank + 1]] = send[sends[rank] : sends[rank + 1]]
        for source in range(size):
            for target in range(size):
                if source == target or matrix[source, target] == 0 or rank not in (source, target):
                    continue
                if rank == source:
                    self._controller.Send(numpy_to_vtk(send[sends[target] : sends[target + 1]]), target, _TAG)
                else:
                    message = vtkUnsignedCharArray()
                    self._controller.Receive(message, source, _TAG)
                    out[receives[source] : receives[source + 1]] = vtk_to_numpy(message)
        return out, matrix[:, rank].copy()


_TAG = 827  # (the tag of compositing's point-to-point messages)


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
    def comm(self) -> Any:
        return self._comm

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

    def alltoallv(
        self, send: np.ndarray, counts: np.ndarray, room: Room | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bytes ``send[segment r]`` (segments of ``counts`` bytes, in rank order) to each
        rank r; returns what every rank sent here (in ``room(bytes)``), in rank order, and
        the sizes."""
        MPI = self._mpi
        received = np.empty(self.size, dtype=np.int64)
        self._comm.Alltoall(np.ascontiguousarray(counts, dtype=np.int64), received)
        sends, receives = _offsets(counts), _offsets(received)
        out = (room or _bytes)(int(receives[-1]))
        # MPI's counts and displacements are C ints: beyond that, messages in pieces (in
        # order: MPI keeps the order of messages between two ranks with one tag).
        piece = MESSAGE_PIECE
        if self._comm.allreduce(max(int(sends[-1]), int(receives[-1])), op=MPI.MAX) <= piece:
            self._comm.Alltoallv([send, (counts, sends[:-1]), MPI.BYTE], [out, (received, receives[:-1]), MPI.BYTE])
            return out, received
        requests = []
        for other in range(self.size):
            incoming = out[receives[other] : receives[other + 1]]
            outgoing = send[sends[other] : sends[other + 1]]
            requests += [
                self._comm.Irecv([incoming[a : a + piece], MPI.BYTE], other, _TAG)
                for a in range(0, len(incoming), piece)
            ]
            requests += [
                self._comm.Isend([outgoing[a : a + piece], MPI.BYTE], other, _TAG)
                for a in range(0, len(outgoing), piece)
            ]
        MPI.Request.Waitall(requests)
        return out, received


def _bytes(n: int) -> np.ndarray:
    return np.empty(n, np.uint8)


def _offsets(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def communicator(comm: Any) -> VtkController | Mpi4pyComm:
    """The adapter for an mpi4py communicator or a vtkMultiProcessController."""
    if hasattr(comm, "GetNumberOfProcesses"):
        return VtkController(comm)
    if hasattr(comm, "Allreduce") and hasattr(comm, "Get_rank"):
        return Mpi4pyComm(comm)
    raise TypeError(f"comm must be an mpi4py communicator or a vtkMultiProcessController, got {type(comm).__name__}")


def node_frames(comm: VtkController | Mpi4pyComm) -> NodeFrames | None:
    """The shared frames of the adapter's communicator when its ranks run on one node
    (collective on first use; shared_frames.py), else None (direct send)."""
    return NodeFrames.of(comm.comm) if isinstance(comm, Mpi4pyComm) else None


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


class Workspace:
    """Byte buffers a scene's collective casts use again and again, by role, grown as
    needed: a fresh buffer costs a page fault per 4 KiB on its first write, as much as the
    compositing passes themselves. Collective casts on one scene run one at a time (MPI
    orders a communicator's collective calls), so the roles never overlap."""

    def __init__(self) -> None:
        self._buffers: dict[str, np.ndarray] = {}

    def room(self, role: str) -> Room:
        """``room(bytes)``: the role's buffer, ``bytes`` long."""

        def take(nbytes: int) -> np.ndarray:
            kept = self._buffers.get(role)
            if kept is None or len(kept) < nbytes:
                kept = self._buffers[role] = np.empty(max(nbytes, 1) + nbytes // 4, np.uint8)
            return kept[:nbytes]

        return take


def frame_regions(regions: list[tuple[int, int, int, int] | None]) -> np.ndarray:
    """Rows (x0, x1, y0, y1) for :func:`composite`, an empty one (x0 > x1) where a rank
    receives nothing."""
    return np.array([(0, -1, 0, -1) if r is None else r for r in regions], dtype=np.int64).reshape(-1, 4)


def composite(
    comm: VtkController | Mpi4pyComm,
    buffers: dict[str, np.ndarray],
    keys: np.ndarray,
    layout: dict[str, tuple[np.dtype, tuple[int, ...]]],
    shape: tuple[int, int],
    regions: list[tuple[int, int, int, int] | None],
    tie: float,
    work: Workspace,
) -> dict[str, np.ndarray] | None:
    """This rank's region of the image of every rank's hits.

    ``buffers``: this rank's full-frame arrays (TriangleId, Depth and vtkValidPointMask
    among them; an array a rank lacks counts as missing there); ``keys``: the global key of
    each of its triangles; ``layout``: dtype and row shape of every output array, agreed by
    all ranks; ``shape``: the frame (ny, nx); ``regions``: per rank the columns and rows
    (x0, x1, y0, y1, inclusive) it receives, None for nothing; ``work``: the scene's
    buffers. Returns this rank's region's arrays (None when it receives nothing).

    Direct send: each rank sends every hit (depth, key, rows) to the ranks whose regions
    hold its pixel, in one exchange; each keeps, per pixel, the hit the serial cast keeps.
    A rank's region starts as its own arrays' values there (views when it is whole rows of
    the frame: the whole frame, ParaView's bands), where its own hits already are."""
    ny, nx = shape
    pixels, rank = nx * ny, comm.rank
    for region in regions:
        if region is not None and region[0] <= region[1] and region[2] <= region[3]:
            if region[0] < 0 or region[1] >= nx or region[2] < 0 or region[3] >= ny:
                raise ValueError(f"the region {region} reaches beyond the {nx}x{ny} image")
    hits = (buffers["vtkValidPointMask"].view(np.uint8), buffers["TriangleId"], buffers["Depth"], keys)
    mine = regions[rank]
    frames = {name: _full_frame(buffers, name, dtype, row, pixels) for name, (dtype, row) in layout.items()}
    # Depth and the mask travel in the records (every hit sent is a hit).
    rows = [name for name in layout if name not in ("Depth", "vtkValidPointMask")]
    sent = [_row_bytes(frames[name]) for name in rows]
    # A rank's own hits in its region stay in its own arrays (no message to itself).
    targets = frame_regions([None if r == rank else other for r, other in enumerate(regions)])
    hit_bytes = 20 + sum(values.shape[1] for values in sent)  # (record: place, depth, key; compositing.hpp)
    room = int(np.count_nonzero(targets[:, 0] <= targets[:, 1])) * int(np.count_nonzero(hits[0])) * hit_bytes
    messages = work.room("sent")(room)
    sizes = _core.composite_send(*hits, nx, targets, sent, messages)
    received, received_sizes = comm.alltoallv(messages[: int(sizes.sum())], sizes, work.room("received"))
    if mine is None:
        return None
    x0, x1, y0, y1 = mine
    n = max(0, x1 - x0 + 1) * max(0, y1 - y0 + 1)

    def region(values: np.ndarray) -> np.ndarray:
        """The region's rows of a full-frame array: a slice (a view) when they are whole
        rows of the frame (the whole frame, ParaView's bands), else a copy."""
        if x0 == 0 and x1 == nx - 1:
            return values[y0 * nx : (y1 + 1) * nx]
        block = values.reshape(ny, nx, *values.shape[1:])[y0 : y1 + 1, x0 : x1 + 1]
        return np.ascontiguousarray(block).reshape(n, *values.shape[1:])

    own = (*(region(values) for values in hits[:3]), keys)
    out = {name: region(values) for name, values in frames.items()}
    depth = out.get("Depth")
    mask = out.get("vtkValidPointMask")
    _core.composite_receive(
        received,
        received_sizes,
        *own,
        tie,
        [_row_bytes(out[name]) for name in rows],
        depth,
        None if mask is None else mask.view(np.uint8),
        n,
    )
    return out


def cast_on_node(
    frames: NodeFrames,
    cast: Callable[[dict[str, np.ndarray] | None], dict[str, np.ndarray]],
    keys: np.ndarray,
    full: dict[str, tuple[np.dtype, tuple[int, ...]]],
    layout: dict[str, tuple[np.dtype, tuple[int, ...]]],
    needed: list[str],
    root: int,
    sizes: list[int],
    triangles: list[int],
    pixels: int,
    tie: float,
) -> Callable[[], dict[str, np.ndarray] | None]:
    """A collective cast to ``root`` through the shared memory of one node: every rank but
    the root casts (``cast(out)``: the ``needed`` arrays into ``out``, new ones for None)
    straight into its segment of ``frames``, laid out as ``full`` (every array of the cast)
    after its triangles' ``keys``; the root casts into arrays of its own. Returns the
    compositing still to do (collective): on the root the image's arrays of ``layout``
    (its own, the other ranks' winning hits written in), None elsewhere. ``triangles``:
    each rank's count; ``sizes``: each rank's segment's (segment_bytes, 0 for the root);
    ``pixels``: the frame's."""
    rank, size = frames.comm.Get_rank(), frames.comm.Get_size()
    frames.reserve(sizes)
    if rank != root:
        held, arrays = frames.arrays(rank, full, pixels, triangles[rank])
        frames.hold_keys(keys, held)
        for name, values in arrays.items():
            if name not in needed:  # (an array this rank lacks: missing at its hits)
                values[...] = miss_value(name, values.dtype)
        cast({name: arrays[name] for name in needed})

        def send() -> None:
            frames.written()
            frames.read()

        return send
    buffers = cast(None)
    rows = [name for name in layout if name not in ("Depth", "vtkValidPointMask")]

    def receive() -> dict[str, np.ndarray]:
        frames.written()
        try:
            out = {name: _full_frame(buffers, name, dtype, row, pixels) for name, (dtype, row) in layout.items()}
            others = [frames.arrays(r, full, pixels, triangles[r]) for r in range(size) if r != root]
            _core.composite_merge(
                buffers["vtkValidPointMask"].view(np.uint8),
                buffers["TriangleId"],
                buffers["Depth"],
                keys,
                [arrays["vtkValidPointMask"].view(np.uint8) for _, arrays in others],
                [arrays["TriangleId"] for _, arrays in others],
                [arrays["Depth"] for _, arrays in others],
                [held for held, _ in others],
                [[_row_bytes(arrays[name]) for name in rows] for _, arrays in others],
                tie,
                [_row_bytes(out[name]) for name in rows],
                buffers["vtkValidPointMask"].view(np.uint8),
            )
        finally:
            frames.read()  # (also when the merge failed: the other ranks wait here)
        return out

    return receive


def _full_frame(
    buffers: dict[str, np.ndarray], name: str, dtype: np.dtype, row: tuple[int, ...], pixels: int
) -> np.ndarray:
    values = buffers.get(name)
    if values is None:
        return np.full((pixels, *row), miss_value(name, dtype), dtype)
    return np.ascontiguousarray(values, dtype=dtype)


def _row_bytes(values: np.ndarray) -> np.ndarray:
    """An array's rows as bytes (a view): shape (rows, bytes per row)."""
    return values.reshape(len(values), -1).view(np.uint8)
