"""Output arrays kept from a scene's casts and handed out again once nobody holds them.

A fresh output array costs a page fault per 4 KiB page on its first write: at 1024x1024
the defaults and a terrain's two point arrays are 77 MB, and faulting them in takes longer
than writing them. A scene keeps the arrays of its last
two casts (two, so that ``image = scene.cast(camera)`` in a loop, which holds the previous
image while the next cast runs, finds the one before it free) and reuses an array only
when the pool's is the last reference to it: no image, view, VTK array or pipeline output
made from it is alive, so nothing a user can reach ever changes under them.
"""

from __future__ import annotations

import math
import sys
import threading
from collections import deque

import numpy as np

__all__ = ["BufferPool"]


def _count_alone() -> int:
    """sys.getrefcount of an object only a list holds, asked for as _take asks (the count
    includes the call's own reference in some Python versions and not in others)."""
    kept = [object()]
    return sys.getrefcount(kept[0])


_ALONE = _count_alone()
SMALL = 1 << 16  #: bytes: malloc serves this little from its heap, already faulted in


class BufferPool:
    """Arrays of the last ``generations`` casts, reused when unreferenced elsewhere."""

    def __init__(self, generations: int = 2) -> None:
        self._generations: deque[list[np.ndarray]] = deque(maxlen=generations)
        self._lock = threading.Lock()  # (concurrent casts on one scene)

    def allocate(self, layouts: dict[str, tuple[np.dtype, tuple[int, ...]]]) -> dict[str, np.ndarray]:
        """Uninitialised arrays of the given dtypes and shapes, by name: kept ones that
        nobody else holds, else new ones. They join the pool as the latest generation.
        Small casts' arrays (under SMALL bytes in all) are new and not kept: looking for
        them cost a small batch of rays more than making them, and keeping them would push
        an image's arrays out of the pool."""
        if sum(dtype.itemsize * math.prod(shape) for dtype, shape in layouts.values()) < SMALL:
            return {name: np.empty(shape, dtype) for name, (dtype, shape) in layouts.items()}
        out = {}
        with self._lock:
            for name, (dtype, shape) in layouts.items():
                out[name] = self._take(dtype, shape)
            self._generations.append(list(out.values()))
        return out

    @property
    def unused_bytes(self) -> int:
        """Bytes of the kept arrays that only the pool holds."""
        with self._lock:
            return sum(a.nbytes for kept in self._generations for a in _unreferenced(kept))

    def _take(self, dtype: np.dtype, shape: tuple[int, ...]) -> np.ndarray:
        for kept in self._generations:
            for i in range(len(kept)):
                if kept[i].dtype == dtype and kept[i].shape == shape and sys.getrefcount(kept[i]) == _ALONE:
                    return kept.pop(i)
        return np.empty(shape, dtype)


def _unreferenced(kept: list[np.ndarray]) -> list[np.ndarray]:
    return [kept[i] for i in range(len(kept)) if sys.getrefcount(kept[i]) == _ALONE]
