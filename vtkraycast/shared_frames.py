"""Full-frame images in memory the ranks of one node share (an MPI-3 shared window), for the
whole image on one rank: each other rank casts straight into its own segment of the window
and the receiving rank reads their hits where they lie, so nothing is gathered, sent or
received; only the winners' rows are copied, once (parallel.cast_on_node).

A communicator whose ranks span several nodes, or a VTK controller, keeps direct send
(parallel.py), as does a node whose shared-memory file system (``/dev/shm``, where MPI
keeps the window: a container's is often 64 MiB) has not room for the frames: writing
beyond it would kill the process. Set ``ENABLED = False`` to use direct send everywhere.
"""

from __future__ import annotations

import math
import os
import weakref
from typing import Any

import numpy as np

__all__ = ["ENABLED", "NodeFrames", "free_shared_bytes", "segment_bytes"]

#: Whether casts to one rank read the other ranks' images in shared memory where they can.
ENABLED = True

_ALIGN = 64  # (each array's first row on a cache line of its own)
_KEY = np.dtype(np.int64)

#: Room left on the shared-memory file system beside the frames (MPI's own segments,
#: other programs).
HEADROOM = 2**27

#: A communicator's frames, by its MPI handle: made once (a collective call) and kept, as
#: freeing a window is collective too and may only happen inside a collective cast.
_BY_COMM: dict[int, NodeFrames | None] = {}

Layout = dict[str, tuple[np.dtype, tuple[int, ...]]]


def _round_up(n: int) -> int:
    return -(-n // _ALIGN) * _ALIGN


def segment_bytes(layout: Layout, pixels: int, triangles: int) -> int:
    """Bytes of one rank's segment: its triangles' keys, then a full frame of each array."""
    total = _round_up(triangles * _KEY.itemsize)
    for dtype, row in layout.values():
        total += _round_up(pixels * dtype.itemsize * math.prod(row))
    return total


def free_shared_bytes() -> int:
    """Bytes free on this node's shared-memory file system (0 when there is none)."""
    try:
        stat = os.statvfs("/dev/shm")
    except OSError:
        return 0
    return stat.f_bavail * stat.f_frsize


class NodeFrames:
    """The shared window of a communicator whose ranks all run on one node, its segments
    grown as casts need (collectively, inside a cast, where every rank computes the same
    sizes)."""

    def __init__(self, comm: Any) -> None:
        from mpi4py import MPI

        self._comm, self._mpi = comm, MPI
        self._window: Any = None
        self._sizes: list[int] = []
        self._keys: weakref.ref | None = None  # (whose keys this rank's segment holds, not kept alive)

    @property
    def comm(self) -> Any:
        return self._comm

    @staticmethod
    def of(comm: Any) -> NodeFrames | None:
        """The frames of mpi4py communicator ``comm`` (collective on first use), None when
        its ranks span nodes or shared frames are off."""
        if not ENABLED:
            return None
        from mpi4py import MPI

        handle = comm.py2f()
        if handle not in _BY_COMM:
            local = comm.Split_type(MPI.COMM_TYPE_SHARED)
            one_node = local.Get_size() == comm.Get_size()
            local.Free()
            _BY_COMM[handle] = NodeFrames(comm) if one_node else None
        return _BY_COMM[handle]

    def fits(self, sizes: list[int], free: int) -> bool:
        """Whether segments of ``sizes[r]`` bytes for each rank r fit beside ``free`` bytes
        free (the least any rank saw: every rank decides alike)."""
        return self._holds(sizes) or sum(self._grown(sizes)) <= free + sum(self._sizes) - HEADROOM

    def reserve(self, sizes: list[int]) -> None:
        """Segments of at least ``sizes[r]`` bytes for each rank r (collective)."""
        if self._holds(sizes):
            return
        MPI = self._mpi
        if self._window is not None:
            self._window.Unlock_all()
            self._window.Free()
        grown = self._grown(sizes)
        info = MPI.Info.Create()
        info.Set("alloc_shared_noncontig", "true")  # (each rank's segment in pages of its own)
        self._window = MPI.Win.Allocate_shared(grown[self._comm.Get_rank()], 1, info, comm=self._comm)
        info.Free()
        self._window.Lock_all(MPI.MODE_NOCHECK)
        self._sizes, self._keys = grown, None

    def _holds(self, sizes: list[int]) -> bool:
        return self._window is not None and all(need <= have for need, have in zip(sizes, self._sizes))

    def _grown(self, sizes: list[int]) -> list[int]:
        """Sizes to allocate for ``sizes``: a quarter more, so that slightly larger casts
        fit, and never less than now."""
        return [max(need, have) + need // 4 for need, have in zip(sizes, self._sizes or [0] * len(sizes))]

    def arrays(
        self, rank: int, layout: Layout, pixels: int, triangles: int
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Rank ``rank``'s keys and full-frame arrays in its segment (views)."""
        memory, _ = self._window.Shared_query(rank)
        segment = np.frombuffer(memory, np.uint8)
        keys = segment[: triangles * _KEY.itemsize].view(_KEY)
        at, out = _round_up(triangles * _KEY.itemsize), {}
        for name, (dtype, row) in layout.items():
            size = pixels * dtype.itemsize * math.prod(row)
            out[name] = segment[at : at + size].view(dtype).reshape(pixels, *row)
            at += _round_up(size)
        return keys, out

    def hold_keys(self, keys: np.ndarray, segment: np.ndarray) -> None:
        """Puts this rank's triangle keys in its segment, unless they are there already."""
        if self._keys is None or self._keys() is not keys:
            segment[...] = keys
            self._keys = weakref.ref(keys)

    def written(self) -> None:
        """Every rank's writes to its segment are seen by the others (collective)."""
        self._window.Sync()
        self._comm.Barrier()
        self._window.Sync()

    def read(self) -> None:
        """The receiving rank is done reading (collective): segments may be written again."""
        self._comm.Barrier()
