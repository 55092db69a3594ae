"""The camera: the seed lecture's model (eye, window at distance ``d``, pixels), or VTK's."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["Camera"]


def _vector(value: Any, name: str) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    if v.shape != (3,):
        raise ValueError(f"{name} must be a 3-vector, got shape {np.shape(value)}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {v.tolist()}")
    return v


def _positive(value: float, name: str) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value}")
    return value


def _pixels(value: Any, name: str) -> int:
    if isinstance(value, bool) or not float(value).is_integer():
        raise ValueError(f"{name} must be a whole number of pixels, got {value!r}")
    value = int(value)
    if value < 1:
        raise ValueError(f"{name} must be at least 1 pixel, got {value}")
    return value


def _unit(v: np.ndarray) -> np.ndarray:
    """v / |v|, first scaled by a power of two so that squaring neither overflows nor
    underflows at any magnitude (0 stays 0)."""
    largest = float(np.abs(v).max())
    if largest == 0:
        return v
    v = np.ldexp(v, -math.frexp(largest)[1])
    return v / np.linalg.norm(v)


class Camera:
    """A pinhole (or parallel) camera and its pixel grid.

    The model of the seed lecture: the eye at the origin of camera space looks down
    ``-z``; the image window ``w x h`` lies at distance ``d``; pixel ``(i, j)``, ``j``
    counted from the top, has its centre at ``x = -w/2 + w/nx (i + 1/2)``,
    ``y = h/2 - h/ny (j + 1/2)``, ``z = -d``. The ray through it is ``P(t) = t P_ij``,
    so ``t = 1`` is the image plane. Output images follow VTK's order instead: row 0 is
    the bottom row (``j = ny - 1``).

    Parameters
    ----------
    eye, look_at, view_up : sequence of float
        Eye position, a point it looks at, and the up direction (orthogonalised against
        the view direction, as ``vtkCamera`` does).
    d : float, default: 1.0
        Distance from the eye to the image plane.
    w, h : float, optional
        Window size on the image plane. Give both, one (the other follows the pixel
        aspect ratio ``nx / ny``), or neither and a ``view_angle``.
    nx, ny : int, default: 640, 480
        Pixels across and down.
    view_angle : float, optional
        Vertical view angle in degrees (as ``vtkCamera``): ``h = 2 d tan(a/2)``,
        ``w = h nx / ny``. Defaults to VTK's 30 degrees when neither ``w`` nor ``h`` is given.
    parallel : bool, default: False
        Parallel projection: every ray has the view direction and starts on the plane
        through the eye; ``h`` is twice VTK's parallel scale.
    near, far : float, default: 0, inf
        Accepted hit depths along the view direction. ``near=d`` is the seed's rule that
        hits in front of the image plane are outside the frustum.
    shift : sequence of 2 float, default: (0, 0)
        The window's centre on the image plane, right and up of the view axis (same units
        as ``w`` and ``h``): an off-centre principal point (see :meth:`from_intrinsics`).

    Examples
    --------
    >>> from vtkraycast import Camera
    >>> cam = Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), d=1.0, w=2.0, h=1.0, nx=4, ny=2)
    >>> cam.pixel_center(0, 0)
    array([-0.75,  0.25, -1.  ])
    >>> cam.right, cam.up, cam.backward
    (array([1., 0., 0.]), array([0., 1., 0.]), array([0., 0., 1.]))
    >>> Camera((0, 0, 5), (0, 0, 0), (0, 0, 1))
    Traceback (most recent call last):
    ...
    ValueError: view_up is parallel to the view direction ...
    """

    _FIELDS = ("eye", "look_at", "view_up", "d", "w", "h", "nx", "ny", "parallel", "near", "far", "shift")

    def __init__(
        self,
        eye: Any,
        look_at: Any,
        view_up: Any,
        *,
        d: float = 1.0,
        w: float | None = None,
        h: float | None = None,
        nx: int = 640,
        ny: int = 480,
        view_angle: float | None = None,
        parallel: bool = False,
        near: float = 0.0,
        far: float = math.inf,
        shift: Any = (0.0, 0.0),
    ) -> None:
        eye_v, look_v, up_v = _vector(eye, "eye"), _vector(look_at, "look_at"), _vector(view_up, "view_up")
        d = _positive(d, "d")
        nx, ny = _pixels(nx, "nx"), _pixels(ny, "ny")
        if view_angle is not None and (w is not None or h is not None):
            raise ValueError("give either view_angle or the window size w/h, not both")
        if w is None and h is None:
            angle = 30.0 if view_angle is None else float(view_angle)
            if not (0.0 < angle < 180.0):
                raise ValueError(f"view_angle must be strictly between 0 and 180 degrees, got {angle}")
            h = 2.0 * d * math.tan(math.radians(angle) / 2.0)
        if h is None:
            h = _positive(w, "w") * ny / nx
        if w is None:
            w = _positive(h, "h") * nx / ny
        w, h = _positive(w, "w"), _positive(h, "h")
        near, far = float(near), float(far)
        if math.isnan(near) or math.isnan(far) or near < 0 or far <= near:
            raise ValueError(f"need 0 <= near < far, got near={near}, far={far}")
        with np.errstate(over="ignore"):
            forward = look_v - eye_v
        if not forward.any():
            raise ValueError("eye and look_at coincide: the view direction is undefined")
        if not np.isfinite(forward).all():
            raise ValueError("eye and look_at are too far apart: their difference overflows float64")
        shift_v = np.array(shift, dtype=np.float64).reshape(-1)
        if shift_v.shape != (2,) or not np.isfinite(shift_v).all():
            raise ValueError(f"shift must be two finite numbers, got {shift!r}")
        values = (eye_v, look_v, up_v, d, w, h, nx, ny, bool(parallel), near, far, shift_v)
        for name, value in zip(self._FIELDS, values):
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
            object.__setattr__(self, name, value)
        # The frame once (it validates view_up against the view direction): every cast
        # reads it, and numpy's small-vector calls cost 0.2 ms of a 14 ms frog re-cast here.
        frame = np.vstack((eye_v, *self._axes()))
        frame.flags.writeable = False
        object.__setattr__(self, "_frame", frame)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("Camera is immutable; use Camera.replace(...) for a changed copy")

    def __repr__(self) -> str:
        parts = []
        for name in self._FIELDS:
            value = getattr(self, name)
            parts.append(f"{name}={value.tolist() if isinstance(value, np.ndarray) else value!r}")
        return f"Camera({', '.join(parts)})"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Camera):
            return NotImplemented
        return all(np.array_equal(getattr(self, n), getattr(other, n)) for n in self._FIELDS)

    __hash__ = None  # type: ignore[assignment]

    def replace(self, **changes: Any) -> Camera:
        """A copy with some parameters changed (keywords as in the constructor)."""
        kwargs = {n: getattr(self, n) for n in self._FIELDS}
        if "view_angle" in changes:
            kwargs.pop("w"), kwargs.pop("h")
        kwargs.update(changes)
        return Camera(kwargs.pop("eye"), kwargs.pop("look_at"), kwargs.pop("view_up"), **kwargs)

    def _axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        backward = _unit(self.eye - self.look_at)
        right = np.cross(_unit(self.view_up), backward)
        norm = np.linalg.norm(right)
        if not norm > 1e-12:
            raise ValueError("view_up is parallel to the view direction (or zero): the image orientation is undefined")
        right = right / norm
        return right, np.cross(backward, right), backward

    @property
    def right(self) -> np.ndarray:
        """Unit x axis of camera space (right on the image), in world coordinates."""
        return self._frame[1]

    @property
    def up(self) -> np.ndarray:
        """Unit y axis of camera space: ``view_up`` made orthogonal to the view direction."""
        return self._frame[2]

    @property
    def backward(self) -> np.ndarray:
        """Unit z axis of camera space: the eye looks along ``-backward``."""
        return self._frame[3]

    @property
    def frame(self) -> np.ndarray:
        """Rows ``eye, right, up, backward``: the camera-to-world frame the native core takes
        (read-only)."""
        return self._frame

    @property
    def view_angle(self) -> float:
        """Vertical view angle in degrees, ``2 atan(h / 2d)``."""
        return math.degrees(2.0 * math.atan(self.h / (2.0 * self.d)))

    def pixel_center(self, i: int, j: int) -> np.ndarray:
        """Centre of pixel ``(i, j)`` in camera coordinates, ``j`` counted from the top (the seed)."""
        return np.array(
            [
                (self.shift[0] - self.w * 0.5) + self.w / self.nx * (i + 0.5),
                (self.shift[1] + self.h * 0.5) - self.h / self.ny * (j + 0.5),
                -self.d,
            ]
        )

    def rays(self) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Every pixel's ray as the core builds it: origins and directions ``(nx * ny, 3)`` in
        VTK image order (pixel ``(i, r)`` at ``i + r * nx``, row 0 at the bottom), and the
        ``tmin, tmax`` of ``near`` and ``far``. A hit's Depth is ``t`` times ``d`` (pinhole)
        or ``t`` (parallel)."""
        i = np.tile(np.arange(self.nx), self.ny)
        j = self.ny - 1 - np.repeat(np.arange(self.ny), self.nx)
        x = (self.shift[0] - self.w * 0.5) + self.w / self.nx * (i + 0.5)
        y = (self.shift[1] + self.h * 0.5) - self.h / self.ny * (j + 0.5)
        if self.parallel:
            origins = self.eye + x[:, None] * self.right + y[:, None] * self.up
            return origins, np.broadcast_to(-self.backward, origins.shape), self.near, self.far
        directions = x[:, None] * self.right + y[:, None] * self.up + (-self.d) * self.backward
        return np.broadcast_to(self.eye, directions.shape), directions, self.near / self.d, self.far / self.d

    @classmethod
    def from_vtk(cls, camera: Any, nx: int | None = None, ny: int | None = None) -> Camera:
        """The camera of a ``vtkCamera``, ``pyvista.Camera``, ``vtkRenderer`` or ``pyvista.Plotter``.

        Copies position, focal point, view up, view angle (or parallel scale) and the
        clipping range. A renderer or plotter also gives ``nx, ny`` (its size in pixels)
        when they are not passed, so the cast overlays its screenshot pixel for pixel.

        Examples
        --------
        >>> from vtkmodules.vtkRenderingCore import vtkCamera
        >>> vc = vtkCamera()
        >>> vc.SetPosition(0, 0, 10); vc.SetViewAngle(40); vc.SetClippingRange(1, 100)
        >>> cam = Camera.from_vtk(vc, nx=200, ny=100)
        >>> round(cam.view_angle, 6), cam.nx, cam.ny, cam.near, cam.far
        (40.0, 200, 100, 1.0, 100.0)
        """
        size = None
        renderer = None
        if hasattr(camera, "renderer") and hasattr(camera, "window_size"):  # pyvista.Plotter
            renderer = camera.renderer
            size = tuple(camera.window_size)
        elif hasattr(camera, "GetActiveCamera") and hasattr(camera, "GetSize"):  # vtkRenderer
            renderer = camera
            size = tuple(camera.GetSize())
        if renderer is not None:
            camera = renderer.GetActiveCamera()
        if not hasattr(camera, "GetPosition") or not hasattr(camera, "GetParallelScale"):
            raise TypeError(
                f"expected a vtkCamera, pyvista.Camera, vtkRenderer or pyvista.Plotter, got {type(camera).__name__}"
            )
        if tuple(camera.GetWindowCenter()) != (0.0, 0.0) or camera.GetUseOffAxisProjection():
            raise ValueError("off-centre and off-axis vtkCamera projections are not supported")
        if nx is None or ny is None:
            if size is None or min(size) < 1:
                size = (640, 480)
            nx = size[0] if nx is None else nx
            ny = size[1] if ny is None else ny
        nx, ny = _pixels(nx, "nx"), _pixels(ny, "ny")
        eye = np.array(camera.GetPosition(), dtype=np.float64)
        focal = np.array(camera.GetFocalPoint(), dtype=np.float64)
        near, far = camera.GetClippingRange()
        d = float(np.linalg.norm(focal - eye)) or 1.0
        common = dict(d=d, nx=nx, ny=ny, near=near, far=far)
        if camera.GetParallelProjection():
            h = 2.0 * camera.GetParallelScale()
            return cls(eye, focal, camera.GetViewUp(), h=h, parallel=True, **common)
        angle = math.radians(camera.GetViewAngle())
        if camera.GetUseHorizontalViewAngle():
            return cls(eye, focal, camera.GetViewUp(), w=2.0 * d * math.tan(angle / 2.0), **common)
        return cls(eye, focal, camera.GetViewUp(), h=2.0 * d * math.tan(angle / 2.0), **common)

    @classmethod
    def framing(
        cls,
        bounds: Any,
        *,
        view: str = "iso",
        nx: int = 640,
        ny: int = 480,
        view_angle: float = 30.0,
        parallel: bool = False,
    ) -> Camera:
        """A camera that frames ``bounds``: a box ``(xmin, xmax, ymin, ymax, zmin, zmax)``, or
        the ``(n, 3)`` points of a mesh (then the object itself, not its box, fills the view:
        a sparse object's empty box corners leave no margin of empty pixels).

        ``view`` names the side the eye looks from: ``"iso"`` (from +x +y +z),
        ``"+x"``, ``"-x"``, ``"+y"``, ``"-y"``, ``"+z"``, ``"-z"``, or pyvista's
        ``"xy"``, ``"xz"``, ``"yz"`` (from +z, -y and +x). Everything fits in the window
        with a 5 % margin, centred in it.

        Examples
        --------
        >>> cam = Camera.framing((-1, 1, -1, 1, -1, 1), view="+z", nx=10, ny=10)
        >>> cam.look_at.tolist(), cam.right.round(6).tolist()
        ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
        """
        given = np.asarray(bounds, dtype=np.float64)
        points = None
        if given.ndim == 2 and given.shape[1] == 3 and len(given) and np.isfinite(given).all():
            points = given
            b = np.column_stack((given.min(axis=0), given.max(axis=0))).reshape(-1)
        else:
            b = given.reshape(-1)
        if b.shape != (6,) or not np.isfinite(b).all() or (b[1::2] < b[0::2]).any():
            raise ValueError(
                f"bounds must be finite (xmin, xmax, ymin, ymax, zmin, zmax) or (n, 3) points, got {given.shape}"
            )
        try:
            direction, up = _VIEWS[view]
        except KeyError:
            raise ValueError(f"unknown view {view!r}; choose one of {', '.join(_VIEWS)}") from None
        centre = 0.5 * (b[0::2] + b[1::2])
        direction = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
        up = np.asarray(up, dtype=np.float64)
        right = np.cross(up, direction)
        right /= np.linalg.norm(right)
        true_up = np.cross(direction, right)
        # The box corners (or the points) in camera axes, relative to the centre of their
        # extent across the view; then the nearest eye distance that keeps all inside.
        if points is None:
            corners = np.array(np.meshgrid(*b.reshape(3, 2), indexing="ij")).reshape(3, -1).T - centre
        else:
            corners = points - centre
        x, y, z = corners @ right, corners @ true_up, corners @ direction
        mid_x, mid_y = (x.max() + x.min()) / 2, (y.max() + y.min()) / 2
        centre = centre + mid_x * right + mid_y * true_up
        x, y = x - mid_x, y - mid_y
        tan_y = math.tan(math.radians(view_angle) / 2.0)
        tan_x = tan_y * nx / ny
        scale = 1.05  # a margin around the box
        if parallel:
            h = 2.0 * scale * max(float(np.abs(y).max()), float(np.abs(x).max()) * ny / nx, 1e-300)
            distance = 2.0 * float(np.abs(z).max()) + h
            return cls(centre + distance * direction, centre, up, d=distance, h=h, nx=nx, ny=ny, parallel=True)
        distance = float(np.max(z + scale * np.maximum(np.abs(x) / tan_x, np.abs(y) / tan_y)))
        distance = max(distance, float(np.abs(z).max()) * 1.01, 1e-300)
        return cls(centre + distance * direction, centre, up, d=distance, view_angle=view_angle, nx=nx, ny=ny)

    @classmethod
    def from_intrinsics(
        cls,
        intrinsic: Any,
        extrinsic: Any,
        width: int,
        height: int,
        *,
        near: float = 0.0,
        far: float = math.inf,
        pixel_origin: str = "corner",
    ) -> Camera:
        """The camera of an intrinsic matrix ``K`` (3x3: fx, fy, cx, cy; no skew) and a 4x4
        ``extrinsic`` mapping world to camera coordinates (x right, y down, z forward), for
        an image ``width`` x ``height`` pixels: the convention of COLMAP, OpenCV and Open3D.

        ``pixel_origin="corner"`` puts the top-left pixel's centre at (0.5, 0.5) (COLMAP,
        Open3D's ``create_rays_pinhole``), ``"center"`` at (0, 0) (OpenCV). An off-centre
        principal point and non-square pixels are kept. The image plane is at z = 1, so
        Depth is the camera z of the hit. Casts come out in VTK image order like every cast
        (row 0 at the bottom: ``image["Depth"].reshape(height, width)[::-1]`` is row-major
        from the top).

        Examples
        --------
        >>> import numpy as np
        >>> from vtkraycast import Camera
        >>> K = [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]]
        >>> cam = Camera.from_intrinsics(K, np.eye(4), 640, 480)
        >>> cam.eye.tolist(), cam.backward.tolist()  # at the origin, looking down +z
        ([0.0, 0.0, 0.0], [0.0, 0.0, -1.0])
        >>> np.allclose(cam.to_intrinsics()[0], K)
        True
        """
        k = np.asarray(intrinsic, dtype=np.float64)
        e = np.asarray(extrinsic, dtype=np.float64)
        if k.shape != (3, 3) or e.shape != (4, 4) or not (np.isfinite(k).all() and np.isfinite(e).all()):
            raise ValueError("need a finite 3x3 intrinsic matrix and a finite 4x4 extrinsic matrix")
        fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
        if k[0, 1] != 0 or k[1, 0] != 0 or k[2, 0] != 0 or k[2, 1] != 0 or k[2, 2] != 1 or not (fx > 0 and fy > 0):
            raise ValueError("the intrinsic matrix must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
        rotation, translation = e[:3, :3], e[:3, 3]
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-9) or np.linalg.det(rotation) < 0:
            raise ValueError("the extrinsic matrix's 3x3 block must be a rotation")
        if pixel_origin not in ("corner", "center"):
            raise ValueError(f"pixel_origin must be 'corner' (COLMAP, Open3D) or 'center' (OpenCV): {pixel_origin!r}")
        if pixel_origin == "center":  # the same centres, counted from the corner
            cx, cy = cx + 0.5, cy + 0.5
        nx, ny = _pixels(width, "width"), _pixels(height, "height")
        eye = -rotation.T @ translation
        return cls(
            eye,
            eye + rotation[2],
            -rotation[1],
            d=1.0,
            w=nx / fx,
            h=ny / fy,
            nx=nx,
            ny=ny,
            near=near,
            far=far,
            shift=((nx / 2 - cx) / fx, (cy - ny / 2) / fy),
        )

    def to_intrinsics(self) -> tuple[np.ndarray, np.ndarray]:
        """``(K, extrinsic)`` of this pinhole camera, as :meth:`from_intrinsics` takes them
        (``pixel_origin="corner"``)."""
        if self.parallel:
            raise ValueError("a parallel camera has no intrinsic matrix")
        fx, fy = self.d * self.nx / self.w, self.d * self.ny / self.h
        cx = self.nx / 2 - self.shift[0] * fx / self.d
        cy = self.ny / 2 + self.shift[1] * fy / self.d
        rotation = np.vstack((self.right, -self.up, -self.backward))
        extrinsic = np.eye(4)
        extrinsic[:3, :3] = rotation
        extrinsic[:3, 3] = -rotation @ self.eye
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]), extrinsic

    def to_vtk(self) -> Any:
        """An equivalent ``vtkCamera`` (position, focal point, view up, angle or scale, clipping range).

        An unbounded depth range becomes the clipping range ``(1e-6 d, 1e30)``, which leaves
        a z-buffer no precision: call the renderer's ``ResetCameraClippingRange()`` after
        making it the active camera.
        """
        # Registers the OpenGL camera as vtkCamera's implementation; a plain vtkCamera made
        # before that crashes VTK when a renderer draws with it.
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401
        from vtkmodules.vtkRenderingCore import vtkCamera

        camera = vtkCamera()
        camera.SetPosition(*self.eye)
        camera.SetFocalPoint(*self.look_at)
        camera.SetViewUp(*self.up)
        camera.SetParallelProjection(self.parallel)
        camera.SetParallelScale(self.h / 2.0)
        camera.SetViewAngle(self.view_angle)
        # VTK needs 0 < near < far: an unbounded range becomes a very wide finite one.
        far = self.far if math.isfinite(self.far) else 1e30
        camera.SetClippingRange(self.near if self.near > 0 else 1e-6 * self.d, far)
        return camera


_VIEWS = {
    "iso": ((1.0, 1.0, 1.0), (0.0, 0.0, 1.0)),
    "+x": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "-x": ((-1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "+y": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    "-y": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    "+z": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    "-z": ((0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
    "xy": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    "xz": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    "yz": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
}
