"""Images kept from a scene's casts and handed back, refilled, once nothing can observe them.

Making a pyvista image, wrapping its arrays for VTK and destroying the image again is a
few percent of a 1024x1024 cast when the caches are cold after other work (as between a
user's casts). A scene keeps
the images of its last two casts (two, as the buffer pool keeps arrays: a loop holding its
last image finds the one before it free) and hands one back when the new cast asks for
arrays of the same names, types and sizes, and nothing else can observe it:

- no Python reference or weak reference to it, and no VTK object holding it (a pipeline, a
  plotter's mapper);
- no reference to its point data, and each of its arrays held by nothing else (no numpy
  view or pyvista array of it, no other dataset sharing it after a shallow copy);
- nothing changed through VTK since the cast (its modification time: geometry, arrays
  added, removed or renamed, cell or field data) and each array still its own cast's
  memory, tuples and components (VTK changes those without a modification time).

Its arrays are then marked modified after the cast (VTK keeps their ranges until then).
The image of the last cast is not handed back at once, even when free: two images take
turns, as the buffer pool's arrays do. Written again right after its cast, an image's
arrays are still partly in the last-level cache, dirty, and the next cast's streaming
stores to them are slower than to arrays written a cast earlier.
"""

from __future__ import annotations

import sys
import threading
import weakref
from collections import deque
from typing import Any

import numpy as np

from .buffers import BufferPool
from .camera import Camera
from .image import fill_image, place_image

__all__ = ["ImagePool"]


class _Kept:
    """A kept image, its arrays (numpy and VTK) and what it was left with."""

    __slots__ = ("arrays", "buffers", "image", "layouts", "mtime", "place", "pointers")


def _counts() -> tuple[int, int, int]:
    """sys.getrefcount of an object held once by a _Kept attribute, by a list (its item
    taken into a local variable) and by a local variable alone, asked for as _observed
    asks (the counts include the call's own references in some Python versions and not in
    others)."""
    kept = _Kept()
    kept.image = object()
    listed = [object()]
    item = listed[0]
    local = object()
    return sys.getrefcount(kept.image), sys.getrefcount(item), sys.getrefcount(local)


_HELD, _LISTED, _LOCAL = _counts()


class ImagePool:
    """pyvista images of the last ``generations`` casts, handed back when unobserved."""

    def __init__(self, buffers: BufferPool, generations: int = 2) -> None:
        self._buffers = buffers
        self._kept: deque[_Kept] = deque(maxlen=generations)
        self._lock = threading.Lock()  # (concurrent casts on one scene)

    def image(
        self, layouts: dict[str, tuple[np.dtype, tuple[int, ...]]], camera: Camera, world_space: bool
    ) -> tuple[Any, dict[str, np.ndarray]]:
        """An image of ``camera``'s pixel grid and its arrays (uninitialised, of the given
        dtypes and shapes, by name) set as its point data: a kept one nothing observes,
        else a new one. Call :meth:`written` once the arrays are written."""
        import pyvista as pv

        place = None if world_space else (camera.nx, camera.ny)  # (None: placed at every cast)
        with self._lock:
            for kept in list(self._kept):
                # (the last image matching is left for the next cast: two take turns)
                if (kept.layouts == layouts and kept is self._kept[-1]) or _observed(kept):
                    continue
                self._kept.remove(kept)
                if kept.layouts != layouts:
                    continue  # (dropped: its arrays go back to the buffer pool)
                if place is None or kept.place != place:
                    place_image(kept.image, camera, world_space=world_space)
                    kept.place = place
                self._kept.append(kept)
                return kept.image, kept.buffers
            kept = _Kept()
            kept.layouts, kept.place = layouts, place
            kept.buffers = self._buffers.allocate(layouts)
            kept.image = fill_image(pv.ImageData(), camera, kept.buffers, world_space=world_space)
            point_data = kept.image.GetPointData()
            kept.arrays = [point_data.GetAbstractArray(name) for name in kept.buffers]
            kept.pointers = [array.GetVoidPointer(0) for array in kept.arrays]
            kept.mtime = None
            self._kept.append(kept)
            return kept.image, kept.buffers

    def written(self, image: Any) -> None:
        """Marks ``image``'s arrays modified after a cast wrote them, and notes its state."""
        with self._lock:
            for kept in self._kept:
                if kept.image is image:
                    for array in kept.arrays:
                        array.Modified()
                    kept.mtime = image.GetMTime()

    @property
    def unused_bytes(self) -> int:
        """Bytes of the kept images' arrays that nothing observes."""
        with self._lock:
            return sum(a.nbytes for kept in self._kept if not _observed(kept) for a in kept.buffers.values())


def _observed(kept: _Kept) -> bool:
    """Whether anything but the pool can see ``kept``'s image or its arrays, or the image
    has changed since its cast (see the module's docstring)."""
    if (
        sys.getrefcount(kept.image) != _HELD
        or weakref.getweakrefcount(kept.image)
        or kept.image.GetReferenceCount() != 1
    ):
        return True
    if kept.mtime is None or kept.image.GetMTime() != kept.mtime:
        return True
    point_data = kept.image.GetPointData()
    if sys.getrefcount(point_data) != _LOCAL:
        return True
    for i, values in enumerate(kept.buffers.values()):
        array = kept.arrays[i]
        if sys.getrefcount(array) != _LISTED or array.GetReferenceCount() != 2:  # (its point data and this wrapper)
            return True
        components = values.shape[1] if values.ndim > 1 else 1
        if (
            array.GetVoidPointer(0) != kept.pointers[i]
            or array.GetNumberOfTuples() != values.shape[0]
            or array.GetNumberOfComponents() != components
        ):
            return True
    return False
