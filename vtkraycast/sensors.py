"""Sensors beyond the pinhole: a 360-degree equirectangular panorama and a spinning lidar.
Both are grids of rays from one point (rows of equal elevation), which the core traces in
bundles, with the answers of :meth:`Scene.intersect` on the same rays; their directions
have unit length, so t is the distance."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Lidar", "Panorama"]


def _frame(forward: Any, up: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit forward, left and up axes (up made orthogonal to forward)."""
    f = np.asarray(forward, dtype=np.float64).reshape(3)
    u = np.asarray(up, dtype=np.float64).reshape(3)
    if not (np.isfinite(f).all() and np.isfinite(u).all()) or not np.linalg.norm(f) > 0:
        raise ValueError("forward must be a finite non-zero vector, up a finite vector")
    f = f / np.linalg.norm(f)
    left = np.cross(u, f)
    if not np.linalg.norm(left) > 1e-12:
        raise ValueError("up is parallel to forward (or zero): the sensor's orientation is undefined")
    left /= np.linalg.norm(left)
    return f, left, np.cross(f, left)


def _directions(f, left, up, azimuths: np.ndarray, elevations: np.ndarray) -> np.ndarray:
    """Unit directions ``(len(elevations) * len(azimuths), 3)``, row after row of equal
    elevation, at ``azimuths`` (radians, counter-clockwise from forward seen from above,
    towards left) and ``elevations`` (radians above the horizontal plane): trigonometry on
    the two axes alone, the grid by broadcasting."""
    horizontal = np.cos(azimuths)[:, None] * f + np.sin(azimuths)[:, None] * left
    grid = np.cos(elevations)[:, None, None] * horizontal + (np.sin(elevations)[:, None] * up)[:, None, :]
    return grid.reshape(-1, 3)


def _point(value: Any, name: str) -> np.ndarray:
    p = _frozen(value)
    if p.shape != (3,) or not np.isfinite(p).all():
        raise ValueError(f"{name} must be three finite numbers, got {value!r}")
    return p


def _kept_rays(sensor: Any, make: Callable[[], tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    """The sensor's rays, made by ``make`` at the first call, read-only, and kept on it."""
    kept = sensor.__dict__.get("_rays")
    if kept is None:
        kept = make()
        for a in kept:
            a.flags.writeable = False  # (a no-op on the broadcast origins: read-only already)
        object.__setattr__(sensor, "_rays", kept)  # (not a field of the frozen dataclass)
    return kept


def _frozen(value: Any) -> np.ndarray:
    """A read-only float64 copy, flat: a sensor keeps what it was made with."""
    a = np.array(value, dtype=np.float64).reshape(-1)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class Panorama:
    """An equirectangular 360 x 180 degree camera at ``eye``: pixel column ``i`` looks at
    azimuth ``360 (i + 0.5) / nx - 180`` degrees (0 straight ``forward``, positive to the
    left), row ``r`` (0 at the bottom, VTK image order) at elevation ``180 (r + 0.5) / ny -
    90``. :meth:`Scene.cast` takes it; Depth is the distance from the eye along the ray.

    Examples
    --------
    >>> import pyvista as pv
    >>> import vtkraycast as vrc
    >>> image = vrc.Scene(pv.Sphere(radius=2.0)).cast(vrc.Panorama((0, 0, 0), 64, 32))
    >>> image.dimensions, bool(abs(float(image["Depth"].max()) - 2.0) < 0.01)
    ((64, 32, 1), True)
    """

    eye: Any
    nx: int
    ny: int
    forward: Any = (1.0, 0.0, 0.0)
    up: Any = (0.0, 0.0, 1.0)
    near: float = 0.0
    far: float = math.inf
    _axes: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "eye", _point(self.eye, "eye"))
        for name in ("nx", "ny"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        if not 0 <= self.near < self.far:
            raise ValueError(f"need 0 <= near < far, got near={self.near}, far={self.far}")
        object.__setattr__(self, "_axes", _frame(self.forward, self.up))

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Origins and unit directions ``(nx * ny, 3)``, pixel ``(i, r)`` at ``i + r * nx``.
        Read-only arrays, made at the first call and kept."""

        def make() -> tuple[np.ndarray, np.ndarray]:
            azimuths = 2 * np.pi * (np.arange(self.nx) + 0.5) / self.nx - np.pi
            elevations = np.pi * (np.arange(self.ny) + 0.5) / self.ny - np.pi / 2
            directions = _directions(*self._axes, azimuths, elevations)
            return np.broadcast_to(self.eye, directions.shape), directions

        return _kept_rays(self, make)


@dataclass(frozen=True)
class Lidar:
    """A spinning lidar at ``position``: one ring per angle of ``elevations`` (degrees above
    the plane normal to ``up``), each with ``azimuth_steps`` beams evenly over 360 degrees
    from ``forward`` (towards the left: counter-clockwise seen from above). Returns closer
    than ``min_range`` or farther than ``max_range`` are not reported. :meth:`Scene.scan`
    casts it.

    Examples
    --------
    >>> import pyvista as pv
    >>> import vtkraycast as vrc
    >>> lidar = vrc.Lidar((0, 0, 0), elevations=[-10, 0, 10], azimuth_steps=90)
    >>> cloud = vrc.Scene(pv.Sphere(radius=3.0, theta_resolution=60, phi_resolution=60)).scan(lidar)
    >>> cloud.n_points, bool(abs(float(cloud["Range"].mean()) - 3.0) < 0.01)
    (270, True)
    """

    position: Any
    elevations: Any
    azimuth_steps: int
    forward: Any = (1.0, 0.0, 0.0)
    up: Any = (0.0, 0.0, 1.0)
    min_range: float = 0.0
    max_range: float = math.inf
    _axes: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _point(self.position, "position"))
        elevations = _frozen(self.elevations)
        if elevations.size == 0 or not np.isfinite(elevations).all() or (np.abs(elevations) > 90).any():
            raise ValueError("elevations must be one or more angles in degrees within [-90, 90]")
        object.__setattr__(self, "elevations", elevations)
        steps = self.azimuth_steps
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
            raise ValueError(f"azimuth_steps must be an integer >= 1, got {steps!r}")
        if not 0 <= self.min_range < self.max_range:
            raise ValueError(f"need 0 <= min_range < max_range, got {self.min_range}, {self.max_range}")
        object.__setattr__(self, "_axes", _frame(self.forward, self.up))

    def rays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Origins, unit directions ``(rings * steps, 3)`` (beam ``a`` of ring ``e`` at
        ``a + e * steps``), and each beam's ring and azimuth (degrees). Read-only arrays,
        made at the first call and kept: every scan of the lidar casts the same beams."""

        def make() -> tuple[np.ndarray, ...]:
            azimuths = np.arange(self.azimuth_steps) * (360.0 / self.azimuth_steps)
            directions = _directions(*self._axes, np.radians(azimuths), np.radians(self.elevations))
            ring = np.repeat(np.arange(len(self.elevations)), self.azimuth_steps)
            azimuth = np.tile(azimuths, len(self.elevations))
            return np.broadcast_to(self.position, directions.shape), directions, ring, azimuth

        return _kept_rays(self, make)
