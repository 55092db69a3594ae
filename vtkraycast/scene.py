"""Scene: a mesh prepared once (triangles and BVH) and cast from any number of cameras."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

import numpy as np
from vtkmodules.vtkCommonDataModel import vtkImageData

from . import _core
from .buffers import BufferPool
from .camera import Camera
from .fields import (
    GEOMETRY_ARRAYS,
    allocate,
    mesh_arrays,
    mesh_arrays_for,
    output_layouts,
    request_outputs,
    row_layout,
    select_arrays,
)
from .image import fill_image, set_arrays
from .image_pool import ImagePool
from .magnitudes import LIMIT, SAFE_LONGEST, direction_shifts, scene_scale, shift_lengths
from .mesh import PreparedMesh, prepare_mesh
from .parallel import Workspace, cast_on_node, communicator, composite, default_threads, node_frames, triangle_keys
from .sensors import Lidar, Panorama
from .shared_frames import free_shared_bytes, segment_bytes
from .visibility import CROSSING_ARRAYS, crossing_arrays, ids_present, layered_arrays, visible_points

__all__ = ["PRECISIONS", "STRATEGIES", "Scene"]

#: Intersection strategies by name (DESIGN.md); "auto" picks the fastest exact one.
STRATEGIES = ("auto", "watertight", "moller-trumbore", "plane", "cramer")
ACCELS = ("bvh", "none")
PRECISIONS = {"float64": np.float64, "float32": np.float32}
#: Scene.intersect's arrays, by the names it returns them under, and the image arrays they are.
RAY_ARRAYS = {
    "triangle_id": "TriangleId",
    "cell_id": "CellId",
    "t": "Depth",
    "barycentric": "Barycentric",
    "position": "Position",
    "normal": "Normal",
    "composite_index": "CompositeIndex",
}
DEFAULT_RAY_ARRAYS = ("triangle_id", "cell_id", "t", "barycentric")
#: The arrays _core.quick_rays makes, in the order of its bits and outputs.
_QUICK_ARRAYS = ("triangle_id", "cell_id", "t", "barycentric", "position", "normal")
# contains answers batches of at least this many points with a grid of cells (about
# _GRID_CELLS_PER_TRIANGLE a triangle), made once per scene.
_GRID_POINTS = 4096
_GRID_CELLS_PER_TRIANGLE = 2.0
_GRID_MOST_PER_AXIS = 128
#: How far (in each coordinate, plus the scene's centre's largest) ray origins may lie
#: from the scene's centre in float64 casts of an unscaled scene (Scale.check_origins).
_ORIGIN_LIMIT = math.ldexp(1.0, LIMIT[np.float64])
#: Refuse images whose output arrays alone would exceed this many bytes.
_MAX_OUTPUT_BYTES = int(os.environ.get("VTKRAYCAST_MAX_OUTPUT_BYTES", 16 * 2**30))


def _threads(threads: int | None) -> int:
    if threads is None:
        return 0  # the core uses every hardware thread
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
        raise ValueError(f"threads must be a positive integer or None (all cores), got {threads!r}")
    return int(threads)


def _strategy(strategy: str) -> str:
    if strategy not in STRATEGIES:
        raise ValueError(f"unknown strategy {strategy!r}; choose one of {', '.join(STRATEGIES)}")
    return strategy


def _accel(accel: str) -> str:
    if accel not in ACCELS:
        raise ValueError(f"unknown accel {accel!r}; choose 'bvh' or 'none'")
    return accel


def _precision(precision: str) -> type:
    try:
        return PRECISIONS[precision]
    except (KeyError, TypeError):
        raise ValueError(f"unknown precision {precision!r}; choose 'float64' or 'float32'") from None


def _shifted(bound: float, shift: int) -> float:
    """A t bound in the core's units: beyond float64 it bounds nothing the core returns."""
    try:
        return math.ldexp(bound, shift)
    except OverflowError:
        return math.inf


def _ray_rows(value: Any, name: str) -> np.ndarray:
    """``value`` as an array of shape (..., 3) and a numeric dtype, checked."""
    a = value if type(value) is np.ndarray else np.asarray(value)
    if a.ndim == 0 or a.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3), got {a.shape}")
    if a.dtype.kind not in "fiu":
        raise TypeError(f"{name} must be numeric, got dtype {a.dtype}")
    return a


def _ray_batch(origins: Any, directions: Any, threads: int) -> tuple[np.ndarray, np.ndarray, tuple[int, ...], tuple]:
    """Origins and directions of shapes (..., 3), broadcast against each other, as (n, 3)
    float64 rows, with the batch shape the outputs take and their extent (_core.ray_extent:
    least and greatest origin component, least and greatest direction length in max norm)."""
    # (straight-line code: a call of a few rays spends as long here as in the core)
    o, d = _ray_rows(origins, "origins"), _ray_rows(directions, "directions")
    shape = o.shape[:-1]
    if d.shape[:-1] != shape:
        try:
            shape = np.broadcast_shapes(shape, d.shape[:-1])
        except ValueError:
            raise ValueError(
                f"origins {o.shape} and directions {d.shape} do not broadcast against each other"
            ) from None
        o = o if o.shape[:-1] == shape else np.broadcast_to(o, (*shape, 3))
        d = d if d.shape[:-1] == shape else np.broadcast_to(d, (*shape, 3))
    o = np.ascontiguousarray(o.reshape(-1, 3), dtype=np.float64)
    d = np.ascontiguousarray(d.reshape(-1, 3), dtype=np.float64)
    finite, nonzero, *extent = _core.ray_extent(o, d, threads)
    if not finite:
        for a, name in ((o, "origins"), (d, "directions")):
            bad = np.flatnonzero(~np.isfinite(a).all(1))
            if len(bad):
                raise ValueError(f"{name} must be finite; row {int(bad[0])} is not")
    if not nonzero:
        raise ValueError("directions must be non-zero")
    return o, d, shape, tuple(extent)


class Scene:
    """A triangle mesh prepared for ray casting: triangles and a BVH, built once.

    Parameters
    ----------
    mesh : pyvista.PolyData, vtkDataSet or composite dataset
        Polygons and strips are triangulated (each triangle remembers its input cell);
        vertex and line cells are ignored; other datasets contribute their surface; the
        leaves of a composite dataset (pyvista.MultiBlock, vtkMultiBlockDataSet,
        vtkPartitionedDataSet) make one scene. Its points and cells are copied: later
        changes to them do not affect the scene. A vtkPolyData's point and cell arrays
        are read at each cast (arrays added, edited or removed since show in the next);
        other inputs' arrays are copied with their surface.
    threads : int, optional
        Threads for the build; all cores by default.
    bvh : bool, default: True
        Build the bounding volume hierarchy, which every later cast reuses. ``False`` builds
        none: a camera cast then bins the triangles to the image's tiles instead, which is
        cheaper for a single cast (what :func:`cast` does); :meth:`intersect` then needs
        ``accel="none"``.
    comm : mpi4py communicator or vtkMultiProcessController, optional
        ``mesh`` is this rank's piece of a mesh distributed over the ranks of ``comm``:
        every :meth:`cast` is then collective and gives the image of the whole mesh, equal
        to the serial one when the pieces carry global cell ids (ties between ranks go to
        the lowest). Cells flagged duplicate or hidden in ``vtkGhostType`` are skipped (in
        serial casts too). Threads default to the node's cores divided by its ranks.

    Examples
    --------
    >>> import pyvista as pv
    >>> import vtkraycast as vrc
    >>> scene = vrc.Scene(pv.Sphere())
    >>> scene.n_triangles
    1680
    >>> hits = scene.intersect([[0, 0, 2]], [[0, 0, -1]])
    >>> round(float(hits["t"][0]), 3)
    1.5
    """

    def __init__(self, mesh: Any, *, threads: int | None = None, bvh: bool = True, comm: Any = None) -> None:
        if not isinstance(bvh, (bool, np.bool_)):
            raise TypeError(f"bvh must be True or False, got {bvh!r}")
        self._comm = None if comm is None else communicator(comm)
        if comm is not None and threads is None:
            threads = default_threads(comm)
        self._threads = threads
        self._keys: np.ndarray | None = None  # each triangle's global key, for casts under MPI
        self._global_mesh: PreparedMesh | None = None  # the mesh with global cell ids as cell_ids
        self._work = Workspace()  # (compositing's buffers, kept from cast to cast)
        self._bounds: tuple[np.ndarray, np.ndarray] | None = None  # (contains' box)
        self._closed: bool | None = None  # whether every edge has an even number of triangles
        self._grid: _core.InsideGrid | bool | None = None  # contains' cells (False: cannot answer)
        self._mesh = prepare_mesh(mesh)
        self._outputs = BufferPool()  # the arrays of the last casts, reused once unreferenced
        self._images = ImagePool(self._outputs)  # the images of the last casts, likewise
        points, triangles = self._mesh.points, self._mesh.triangles
        self._core = _core.Scene(points, triangles, _threads(threads), bool(bvh))
        self._scale = scene_scale(self._core.point_bounds)
        # The box of the points the triangles use comes from the built scene; a scene beyond
        # 2**±32 across (rare) is built again, scaled, rather than every build paying a
        # pass over all triangles' points first.
        if self._scale.shift:
            with np.errstate(over="ignore"):  # (only points no triangle uses can overflow)
                points = np.ldexp(points, self._scale.shift)
            self._core = _core.Scene(points, triangles, _threads(threads), bool(bvh))

    @property
    def has_bvh(self) -> bool:
        """Whether the scene holds a BVH (see ``bvh``)."""
        return bool(self._core.has_bvh)

    @property
    def n_triangles(self) -> int:
        """Number of triangles after triangulation."""
        return self._mesh.n_triangles

    @property
    def memory_bytes(self) -> int:
        """Bytes held in the native core: the BVH (if any), the triangles and the points, and
        the working memory kept from camera casts for the next one (16 bytes per point and per
        BVH node, once the scene has been cast). Not counted: the output arrays of the last
        two casts, which the scene keeps to reuse for the next ones once nothing else refers
        to them (:attr:`kept_output_bytes`: those no image holds any more)."""
        return int(self._core.memory_bytes)

    @property
    def kept_output_bytes(self) -> int:
        """Bytes of the output arrays of earlier casts (cameras and :meth:`intersect`) that the
        scene keeps for the next ones (writing into kept memory spares the page faults of
        fresh arrays) and that no image, array or view holds any more: at most two casts'
        worth."""
        return self._outputs.unused_bytes + self._images.unused_bytes

    @property
    def prepared(self):
        """The triangulated mesh (points, triangles, cell map) the scene was built from."""
        return self._mesh

    def buffers(self, camera: Camera | Any, **options: Any) -> tuple[Camera, dict[str, np.ndarray]]:
        """The camera and its output arrays as flat numpy arrays, one row per pixel
        (pixel ``(i, r)`` at ``i + r * nx``, row 0 at the bottom). Keyword options are those
        of :meth:`cast` but ``world_space``; :meth:`cast` wraps the arrays in an image, this
        form needs no pyvista."""
        if "world_space" in options:
            raise TypeError("buffers() places no image: world_space is an option of cast()")
        return self._cast_into(None, camera, **options)[:2]

    def cast(self, camera: Camera | Any, *, root: int | None = 0, layers: int = 1, **options: Any) -> Any:
        """Casts one ray per pixel of ``camera`` and returns the geometry buffer.

        ``layers=k`` gives an image of dimensions ``(nx, ny, k)`` whose slice ``z = l`` holds
        the ``(l + 1)``-th surface crossing along each pixel ray (:meth:`intersect_all`;
        misses where a ray has fewer); ``layers=1`` is the ordinary cast. ``HitCount``
        (crossings along the pixel ray within near and far) and ``Thickness`` (length inside
        closed surfaces along it) are computed when named in ``arrays``.

        For a scene built with ``comm`` (MPI) the cast is collective: every rank casts its
        piece, and ``root`` receives the image of the whole mesh (every rank when None;
        the others get None).

        Parameters
        ----------
        camera : Camera, vtkCamera, pyvista.Camera, vtkRenderer or pyvista.Plotter
            The view; VTK objects are converted with :meth:`Camera.from_vtk`.
        arrays : str or sequence of str, optional
            Output arrays to compute (``TriangleId``, ``CellId``, ``Barycentric``, ``Depth``,
            ``Position``, ``Normal``, ``vtkValidPointMask`` and the mesh's own array
            names). Default: all but ``Position`` and ``Normal``, plus the mesh's arrays
            when ``interpolate``. Work for arrays not asked for is not done.
        strategy : str, default: "auto"
            Ray-triangle test: "watertight" (Woop, Benthin, Wald 2013),
            "moller-trumbore" (1997), the seed's "plane" (Strategy I) and "cramer"
            (Strategy II); "auto" is the fastest exact one.
        precision : {"float64", "float32"}
            Arithmetic of the intersection test and dtype of the floating outputs.
        accel : {"bvh", "none"}
            Acceleration structure; "none" is the seed's method (bounding sphere, then
            box, then every triangle): slow, a reference, fine for tiny meshes.
        threads : int, optional
            Worker threads; all cores by default.
        backface_culling : bool, default: False
            Skip triangles whose normal (right-hand rule over their points) faces away
            from the eye.
        interpolate : bool, default: True
            Include the mesh's point arrays (interpolated) and cell arrays by default.
        progress : callable, optional
            Called as ``progress(tiles_done, tiles_total)`` as the cast starts, then about
            every 50 ms; returning False aborts the cast (``InterruptedError``). Ctrl-C
            stops a cast too (``KeyboardInterrupt``), between tiles.
        progress_bar : bool, default: False
            Show a progress bar on the terminal (needs ``tqdm``).
        world_space : bool, default: False
            Place the image on the camera's image plane in world space (origin, spacing
            and direction matrix from the camera) instead of pixel space, to show it in
            3D next to the mesh.

        Returns
        -------
        pyvista.ImageData
            Dimensions ``(nx, ny, 1)``, spacing 1, origin 0 unless ``world_space``; the
            arrays as point data. It may be the image of an earlier cast, refilled, when
            nothing refers to that image or its arrays any more (see ``image_pool``).
        """
        import pyvista as pv

        if isinstance(camera, Panorama):
            return self._cast_panorama(camera, options)
        camera = camera if isinstance(camera, Camera) else Camera.from_vtk(camera)
        wanted = _names(options.get("arrays"))
        along = _along(wanted)
        if along or layers != 1:
            return self._cast_crossings(camera, layers, wanted, along, options)
        if self._comm is not None:
            world_space = options.get("world_space", False)
            camera, arrays = self._cast_parallel(camera, root=root, **options)
            return None if arrays is None else fill_image(pv.ImageData(), camera, arrays, world_space=world_space)
        return self._cast_into(self._images, camera, **options)[2]

    def _cast_crossings(self, camera: Camera, layers: int, wanted: list[str], along: list[str], options: dict) -> Any:
        """A cast with depth layers or with arrays of every crossing (see :meth:`cast`)."""
        import pyvista as pv

        if not isinstance(layers, (int, np.integer)) or isinstance(layers, bool) or layers < 1:
            raise ValueError(f"layers must be an integer >= 1, got {layers!r}")
        if self._comm is not None:
            raise ValueError("layers and HitCount / Thickness are not yet cast under MPI")
        unknown = set(options) - {"arrays", "interpolate", "threads", "world_space", "precision", "strategy"}
        if unknown:
            raise ValueError(f"{', '.join(sorted(unknown))} not supported with layers or HitCount / Thickness")
        rest = [name for name in wanted if name not in CROSSING_ARRAYS]
        threads, interpolate = options.get("threads"), options.get("interpolate", True)
        if layers == 1:
            image = pv.ImageData()
            if rest or not wanted:
                self._cast_into(image, camera, **{**options, "arrays": rest or None})
            else:
                fill_image(image, camera, {}, world_space=options.get("world_space", False))
            for name, values in crossing_arrays(self, camera, along, threads).items():
                image.point_data[name] = values
            return image
        if along:
            raise ValueError("HitCount and Thickness are per pixel ray: cast them with layers=1")
        values = layered_arrays(self, camera, layers, rest or None, interpolate, threads)
        image = fill_image(pv.ImageData(), camera, values, world_space=options.get("world_space", False))
        image.SetDimensions(camera.nx, camera.ny, layers)
        return image

    def cast_many(self, cameras: Iterable[Camera | Any], *, progress_bar: bool = False, **options: Any) -> list[Any]:
        """:meth:`cast` of each camera (options as there), one BVH for all: a list of images,
        with one progress bar over the cameras when ``progress_bar``.

        Examples
        --------
        >>> import pyvista as pv
        >>> import vtkraycast as vrc
        >>> views = [vrc.Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), nx=32, ny=24).replace(eye=e)
        ...          for e in [(0, 0, 3), (3, 0, 0), (0, 3, 0.1)]]
        >>> [image.dimensions for image in vrc.Scene(pv.Sphere()).cast_many(views)]
        [(32, 24, 1), (32, 24, 1), (32, 24, 1)]
        """
        cameras = list(cameras)
        if not progress_bar:
            return [self.cast(camera, **options) for camera in cameras]
        try:
            from tqdm import tqdm
        except ImportError:
            raise ImportError("progress_bar=True needs tqdm: pip install tqdm") from None
        return [self.cast(camera, **options) for camera in tqdm(cameras, desc="Ray casting", unit="image")]

    def _cast_panorama(self, panorama: Panorama, options: dict) -> Any:
        import pyvista as pv

        found = mesh_arrays(self._mesh)
        names = select_arrays(found, options.pop("arrays", None), options.pop("interpolate", True))
        _, directions = panorama.rays()
        culling = options.pop("backface_culling", False)
        unknown = set(options) - {"strategy", "precision", "accel", "threads"}
        if unknown:
            raise ValueError(f"{', '.join(sorted(unknown))} not supported for a panorama")
        buffers, _ = self._cast_rays(
            panorama.eye, directions, names, panorama.near, panorama.far, culling, options, sweep_rows=panorama.ny
        )
        image = pv.ImageData(dimensions=(panorama.nx, panorama.ny, 1))
        return set_arrays(image, buffers)

    def scan(
        self,
        lidar: Lidar,
        *,
        arrays: Iterable[str] | str | None = None,
        interpolate: bool = True,
        range_image: bool = False,
        threads: int | None = None,
    ) -> Any:
        """The returns of a spinning lidar: a ``pyvista.PolyData`` of the hit points (world
        coordinates) with point arrays ``Range`` (distance from the lidar), ``Elevation``
        and ``Azimuth`` (degrees), ``Ring``, ``TriangleId``, ``CellId``, ``Barycentric``
        and the mesh's arrays (``arrays`` and ``interpolate`` as in :meth:`cast`). With
        ``range_image``, also the ranges as a ``(rings, azimuth_steps)`` array, NaN where a
        beam returns nothing.
        """
        import pyvista as pv

        found = mesh_arrays(self._mesh)
        names = select_arrays(found, arrays, interpolate)
        wanted = list(dict.fromkeys([*names, "Depth", "Position"]))
        _, directions, ring, azimuth = lidar.rays()
        buffers, _ = self._cast_rays(
            lidar.position,
            directions,
            wanted,
            lidar.min_range,
            lidar.max_range,
            False,
            {"threads": threads},
            sweep_rows=len(lidar.elevations),
            returns_only=True,
        )
        ranges = buffers["Depth"].astype(np.float64, copy=False)
        returned = np.isfinite(ranges)
        every = bool(returned.all())
        beams = slice(None) if every else np.flatnonzero(returned)
        kept = [name for name in names if name not in ("Depth", "Position", "vtkValidPointMask")]
        picked = [buffers["Position"], ranges, azimuth, ring, *(buffers[name] for name in kept)]
        if every:  # the arrays the core wrote (the lidar's own, read-only, copied)
            picked[2:4] = [azimuth.copy(), ring]
        else:  # the returns' rows
            taken = [np.empty((len(beams), *a.shape[1:]), a.dtype) for a in picked]
            _core.take_rows(picked, beams, taken, _threads(threads))
            picked = taken

        cloud = pv.PolyData(picked[0])
        arrays = {"Range": picked[1], "Elevation": lidar.elevations[picked[3]], "Azimuth": picked[2]}
        arrays |= {"Ring": picked[3].astype(np.int32), **dict(zip(kept, picked[4:]))}
        for name, values in arrays.items():  # (through VTK: pyvista refuses a cloud of no point's (0, 3) arrays)
            cloud.GetPointData().AddArray(pv.convert_array(values, name=name))
        if range_image:
            return cloud, ranges.reshape(len(lidar.elevations), lidar.azimuth_steps).copy()
        return cloud

    def visible_cells(self, camera: Camera | Any, *, threads: int | None = None) -> np.ndarray:
        """Ids of the input cells the camera sees (those some pixel ray hits first), sorted.

        Examples
        --------
        >>> import pyvista as pv
        >>> import vtkraycast as vrc
        >>> cam = vrc.Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), nx=64, ny=64, view_angle=30)
        >>> ids = vrc.Scene(pv.Cube()).visible_cells(cam)
        >>> ids.tolist()  # the cube's face towards +z
        [5]
        """
        camera = camera if isinstance(camera, Camera) else Camera.from_vtk(camera)
        image = self.cast(camera, arrays=["CellId"], threads=threads)
        cells = np.asarray(image["CellId"])
        return ids_present(cells)

    def visible_points(
        self, camera: Camera | Any, *, tolerance: float = 1e-6, threads: int | None = None
    ) -> np.ndarray:
        """Ids of the mesh's points the camera sees, sorted: in the view and within near and
        far, with nothing between the eye and the point closer than ``1 - tolerance`` of the
        way (exact occlusion queries, :meth:`occluded`; the point's own triangles end at it).

        Examples
        --------
        >>> import pyvista as pv
        >>> import vtkraycast as vrc
        >>> cam = vrc.Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), nx=64, ny=64, view_angle=30)
        >>> len(vrc.Scene(pv.Cube()).visible_points(cam))  # the four corners of the +z face
        4
        """
        if not 0 <= tolerance < 1:
            raise ValueError(f"tolerance must be in [0, 1), got {tolerance}")
        camera = camera if isinstance(camera, Camera) else Camera.from_vtk(camera)
        return visible_points(self, camera, float(tolerance), threads)

    def extract_visible(self, camera: Camera | Any, *, threads: int | None = None) -> Any:
        """The part of the mesh the camera sees: the cells :meth:`visible_cells` finds, with
        their points and arrays, as a ``pyvista.UnstructuredGrid`` (``extract_cells`` of the
        cast surface; ``vtkOriginalCellIds`` maps its cells back).

        Examples
        --------
        >>> import pyvista as pv
        >>> import vtkraycast as vrc
        >>> cam = vrc.Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), nx=64, ny=64, view_angle=30)
        >>> vrc.Scene(pv.Sphere()).extract_visible(cam).n_cells < pv.Sphere().n_cells
        True
        """
        import pyvista as pv

        camera = camera if isinstance(camera, Camera) else Camera.from_vtk(camera)
        image = self.cast(camera, arrays=["TriangleId"], threads=threads)
        triangles = np.asarray(image["TriangleId"])
        surface_cells = ids_present(self._mesh.surface_cell_ids[triangles[triangles >= 0]])
        return pv.wrap(self._mesh.surface).extract_cells(surface_cells)

    def _cast_parallel(
        self, camera: Camera | Any, *, root: int | None, extent: tuple[int, int, int, int] | None = None, **options: Any
    ) -> tuple[Camera, dict[str, np.ndarray] | None]:
        """The collective cast of a scene built with ``comm`` (see :meth:`cast`): the camera
        and the image's arrays on ``root`` (every rank when None; None elsewhere), or, given
        ``extent`` (x0, x1, y0, y1: this rank's block of the image, as VTK's pipeline asks
        for it), that block's arrays on every rank."""
        camera, composite_now = self._cast_local(camera, root=root, extent=extent, **options)
        return camera, composite_now()

    def _cast_local(
        self, camera: Camera | Any, *, root: int | None, extent: tuple[int, int, int, int] | None = None, **options: Any
    ) -> tuple[Camera, Callable[[], dict[str, np.ndarray] | None]]:
        """A collective cast's first part (see :meth:`_cast_parallel`): this rank's piece
        cast at full resolution. Returns the camera and the compositing still to do (a
        collective call returning what :meth:`_cast_parallel` returns)."""
        comm = self._comm
        if root is not None and not 0 <= root < comm.size:
            raise ValueError(f"root must be a rank (0 to {comm.size - 1}) or None, got {root}")
        camera = camera if isinstance(camera, Camera) else Camera.from_vtk(camera)
        found = mesh_arrays(self._mesh)
        names = select_arrays(found, options.pop("arrays", None), options.pop("interpolate", True))
        real = _precision(options.get("precision", "float64"))
        layout = {name: row_layout(found, name, real) for name in names if name in found.point or name in found.cell}
        # Every rank's names, array layouts, block and triangles, merged in rank order: a
        # rank may lack a mesh array (an empty piece has none) and still take part.
        merged: dict[str, tuple] = {}
        regions, triangles, layouts, free = [], [], [], []
        gathered = comm.gather_object((names, layout, extent, len(self._mesh.cell_ids), free_shared_bytes()), None)
        for rank_names, rank_layout, rank_extent, rank_triangles, rank_free in gathered:
            for name in rank_names:
                merged.setdefault(name, rank_layout.get(name) or row_layout(found, name, real))
            regions.append(rank_extent)
            triangles.append(rank_triangles)
            layouts.append(rank_layout)
            free.append(rank_free)
        if extent is None:
            whole = (0, camera.nx - 1, 0, camera.ny - 1)
            regions = [whole if root is None or rank == root else None for rank in range(comm.size)]
        local = [name for name in merged if name in GEOMETRY_ARRAYS or name in found.point or name in found.cell]
        needed = list(dict.fromkeys([*local, "Depth", "TriangleId", "vtkValidPointMask"]))
        if options.get("threads") is None:  # (the node's cores shared among its ranks)
            options["threads"] = self._threads
        options.pop("world_space", None)
        if self._keys is None:  # (once per scene: a pass over every triangle)
            self._keys = triangle_keys(self._mesh.cell_ids, self._mesh.global_cell_ids, comm.rank)
            # CellId written as the global cell id, where the input has them.
            ids = self._mesh.global_cell_ids
            self._global_mesh = self._mesh if ids is None else replace(self._mesh, cell_ids=ids[self._mesh.cell_ids])
        tie = 32 * float(np.finfo(real).eps)  # the kernels' tie window (kTieTolerance, traverse.hpp)
        shape = (camera.ny, camera.nx)

        def cast(out: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
            return self._cast_into(None, camera, arrays=needed, mesh=self._global_mesh, out=out, **options)[1]

        # The whole image on one rank, the ranks on one node, every array laid out alike,
        # room for the frames: through their shared memory (shared_frames.py), else by
        # direct send.
        alike = all(merged[name] == values for rank_layout in layouts for name, values in rank_layout.items())
        frames = node_frames(comm) if extent is None and root is not None and alike else None
        if frames is not None:
            full = {name: merged.get(name) or row_layout(found, name, real) for name in [*merged, *needed]}
            pixels = camera.nx * camera.ny
            sizes = [0 if r == root else segment_bytes(full, pixels, n) for r, n in enumerate(triangles)]
            if frames.fits(sizes, min(free)):
                return camera, cast_on_node(
                    frames, cast, self._keys, full, merged, needed, root, sizes, triangles, pixels, tie
                )
        buffers = cast()
        return camera, lambda: composite(comm, buffers, self._keys, dict(merged), shape, regions, tie, self._work)

    def _cast_into(
        self,
        image: vtkImageData | ImagePool | None,
        camera: Camera | Any,
        *,
        mesh: PreparedMesh | None = None,
        out: dict[str, np.ndarray] | None = None,
        world_space: bool = False,
        arrays: Iterable[str] | str | None = None,
        strategy: str = "auto",
        precision: str = "float64",
        accel: str = "bvh",
        threads: int | None = None,
        backface_culling: bool = False,
        interpolate: bool = True,
        progress: Callable[[int, int], bool | None] | None = None,
        progress_bar: bool = False,
    ) -> tuple[Camera, dict[str, np.ndarray], vtkImageData | None]:
        """Casts (options as :meth:`cast`) and returns the camera, the output arrays and
        the image: ``image`` with the arrays set as its point data and its geometry, or an
        image of the pool ``image``, or None. ``mesh``: the scene's mesh with other cell ids
        to write as CellId (the parallel cast's global ids); ``out``: the arrays to write, by
        name (every one of ``arrays``), instead of new ones."""
        if not isinstance(camera, Camera):
            camera = Camera.from_vtk(camera)
        found = mesh_arrays(self._mesh)
        names = select_arrays(found, arrays, interpolate)
        real = _precision(precision)
        n = camera.nx * camera.ny
        layouts = output_layouts(found, names, n, real)
        per_ray = sum(dtype.itemsize * math.prod(shape[1:]) for dtype, shape in layouts.values())
        if n * per_ray > _MAX_OUTPUT_BYTES:
            raise MemoryError(
                f"a {camera.nx}x{camera.ny} image needs about {n * per_ray / 2**30:.1f} GiB for its "
                f"output arrays, above the {_MAX_OUTPUT_BYTES / 2**30:.1f} GiB limit "
                "(VTKRAYCAST_MAX_OUTPUT_BYTES); cast a smaller image or in parts"
            )
        request = self._request(strategy, precision, accel, threads, backface_culling)
        shift = self._scale.shift
        eye = camera.eye.tolist()  # (one point: its extent without numpy's calls)
        self._scale.check_origins(camera.eye[None], real, "the camera's eye", extent=(min(eye), max(eye)))
        frame = np.array(camera.frame)
        if shift:
            frame[0] = np.ldexp(frame[0], shift)
        request.frame = frame
        # A pinhole's window (d, w, h) scaled on its own changes no ray but the directions'
        # length: brought to about 1, as intersect's directions are. A parallel camera's
        # window is its rays' extent.
        window = shift
        if not camera.parallel:
            longest = max(abs(camera.d), abs(camera.w), abs(camera.h))
            window += direction_shifts(
                np.array([[camera.d, camera.w, camera.h]]), bounded=True, extent=(longest, longest)
            )
        request.d, request.width, request.height = (math.ldexp(x, window) for x in (camera.d, camera.w, camera.h))
        request.shift_x, request.shift_y = (math.ldexp(float(x), window) for x in camera.shift)
        request.near, request.far = _shifted(camera.near, shift), _shifted(camera.far, shift)
        request.nx, request.ny, request.parallel = camera.nx, camera.ny, camera.parallel
        # The image and the arrays the core writes are set up before the cast: Python run
        # right after a cast meets cold caches.
        pool = image if isinstance(image, ImagePool) else None
        if pool is not None:
            image, buffers = pool.image(layouts, camera, world_space)
        elif out is None:
            buffers = self._outputs.allocate(layouts)
        else:
            buffers = {name: out[name] for name in names}
        request_outputs(request, mesh or self._mesh, found, buffers)
        if image is not None and pool is None:
            fill_image(image, camera, buffers, world_space=world_space)
        if progress is None and not progress_bar:  # (the core still stops on Ctrl-C)
            done = _core.cast(self._core, request)
        else:
            with progress_reporter(progress, progress_bar, f"Ray casting {camera.nx}x{camera.ny}") as poll:
                request.progress = poll
                done = _core.cast(self._core, request)
        if not done:
            raise InterruptedError("the cast was aborted")
        for name in ("Depth", "Position"):
            if shift and name in buffers:
                shift_lengths(buffers[name], shift, name, distance=name == "Depth")
        if pool is not None:
            pool.written(image)
        return camera, buffers, image

    def _request(
        self, strategy: str, precision: str, accel: str, threads: int | None, backface_culling: bool
    ) -> _core.Request:
        """A request with the options every cast takes, checked."""
        request = _core.Request()
        request.strategy = _strategy(strategy)
        _precision(precision)
        request.precision = precision
        request.accel = _accel(accel)
        request.threads = _threads(threads)
        request.backface_culling = bool(backface_culling)
        return request

    def intersect(
        self,
        origins: Any,
        directions: Any,
        *,
        tmin: float = 0.0,
        tmax: float = math.inf,
        arrays: Iterable[str] | str | None = None,
        strategy: str = "auto",
        precision: str = "float64",
        accel: str = "bvh",
        threads: int | None = None,
        backface_culling: bool = False,
    ) -> dict[str, np.ndarray]:
        """Closest hits of arbitrary rays ``origin + t * direction``, ``tmin <= t <= tmax``.

        ``origins`` and ``directions`` have shapes ``(..., 3)`` and are broadcast against each
        other; every output has the broadcast batch shape ``(...)`` (``(..., 3)`` for vectors).
        ``arrays`` picks among ``triangle_id`` and ``cell_id`` (int64, -1 on a miss), ``t`` (in
        units of the direction's length), ``barycentric`` (weights of the triangle's points),
        ``position`` (the hit point) and ``normal`` (the triangle's unit normal, right-hand
        rule), NaN on a miss; by default the first four. For a composite input,
        ``composite_index`` (the hit leaf's flat index, -1 on a miss; ``cell_id`` is then
        local to the leaf) joins the defaults. Work for arrays not asked for is skipped.
        One origin ``(3,)`` with a 2-D batch of directions ``(rows, columns, 3)``, a camera
        or sensor of the caller's own, is traced in bundles of neighbouring rays, as
        :meth:`scan` does (the same answers, faster when neighbours point alike).

        ``tmin`` must be >= 0 (hits behind an origin are not cast). Rays far beyond what the
        precision's arithmetic holds, or hits whose ``t`` leaves the output type's range,
        raise a ValueError naming the limit (docs/exactness.md, "Supported range").

        Examples
        --------
        >>> import pyvista as pv
        >>> import vtkraycast as vrc
        >>> scene = vrc.Scene(pv.Plane(i_size=2, j_size=2))
        >>> hits = scene.intersect([0, 0, 1], [[0, 0, -1], [0.5, 0, -1]], arrays=["t", "position"])
        >>> hits["t"].tolist(), hits["position"][1].tolist()
        ([1.0, 1.0], [0.5, 0.0, 0.0])
        """
        names = _ray_arrays(arrays, self._mesh.composite_ids is not None)
        if strategy == "auto" and precision == "float64" and accel == "bvh":
            quick = self._quick_rays(origins, directions, tmin, tmax, threads, backface_culling, names)
            if quick is not None:
                return {name: quick[_QUICK_ARRAYS.index(name)] for name in names}
        options = dict(strategy=strategy, precision=precision, accel=accel, threads=threads)
        buffers, shape = self._cast_rays(
            origins, directions, [RAY_ARRAYS[name] for name in names], tmin, tmax, backface_culling, options
        )
        return {name: _batched(buffers[RAY_ARRAYS[name]], shape) for name in names}

    def _quick_rays(
        self,
        origins: Any,
        directions: Any,
        tmin: Any,
        tmax: Any,
        threads: int | None,
        backface_culling: bool,
        names: list[str] | None,
    ) -> tuple[np.ndarray | None, ...] | None:
        """Intersect's arrays ``names`` (None: occluded's answers), by the core's quick way,
        for the usual call: numeric origins and directions of one shape ``(n, 3)`` or
        ``(3,)`` (or one of them ``(3,)``), bounds given as numbers, a scene of one piece
        cast unscaled. The arrays come in _QUICK_ARRAYS's order (None where not asked for;
        occluded's first). None when the general way must run (_core.quick_rays tells the
        rest), which then raises what is wrong. A call of a few rays spent most of its time
        in the general way."""
        if self._scale.shift or self._mesh.composite_ids is not None or not {type(tmin), type(tmax)} <= {float, int}:
            return None
        # (np.asarray raises here what it would raise in the general way)
        o = origins if type(origins) is np.ndarray else np.asarray(origins)
        d = directions if type(directions) is np.ndarray else np.asarray(directions)
        # (one origin against a batch of directions, a sensor's rays: the core reads one row)
        one_origin = o.shape == (3,) and d.ndim == 2 and d.shape[1:] == (3,)
        if d.shape == (3,) and o.ndim == 2 and o.shape[1] == 3:
            d = np.broadcast_to(d, o.shape)
        if not (
            (one_origin or o.shape == d.shape)
            and d.shape[-1:] == (3,)
            and d.ndim <= 2
            and {o.dtype.kind, d.dtype.kind} <= set("fiu")
        ):
            return None
        mesh = self._mesh
        quick = _core.quick_rays(
            self._core,
            np.ascontiguousarray(o.reshape(-1, 3), dtype=np.float64),
            np.ascontiguousarray(d.reshape(-1, 3), dtype=np.float64),
            float(tmin),
            float(tmax),
            self._scale.reach,
            _ORIGIN_LIMIT,
            SAFE_LONGEST,
            None if mesh.cells_are_triangles else mesh.cell_ids,
            0 if names is None else sum(1 << _QUICK_ARRAYS.index(name) for name in names),
            names is None,
            bool(backface_culling),
            _threads(threads),
        )
        if quick is None or d.ndim == 2:
            return quick
        return tuple(None if a is None else a.reshape(a.shape[1:]) for a in quick)  # (one ray: shapes () and (3,))

    def _cast_rays(
        self,
        origins: Any,
        directions: Any,
        names: list[str],
        tmin: float,
        tmax: float,
        backface_culling: bool,
        options: dict,
        sweep_rows: int = 0,
        returns_only: bool = False,
    ) -> tuple[dict[str, np.ndarray], tuple[int, ...]]:
        """The output arrays ``names`` (image names: Depth is t) of arbitrary rays, one row
        per ray, and the batch shape (``sweep_rows``: see _ray_request). With
        ``returns_only``, the rows of misses hold NaN in Depth and anything elsewhere."""
        precision = options.get("precision", "float64")
        request, shape, (k, j) = self._ray_request(
            origins,
            directions,
            tmin,
            tmax,
            options.get("strategy", "auto"),
            precision,
            options.get("accel", "bvh"),
            options.get("threads"),
            backface_culling,
            sweep_rows,
            grid=True,
        )
        found = mesh_arrays_for(self._mesh, names)
        buffers = allocate(found, names, request.directions.shape[0], _precision(precision), self._outputs)
        request_outputs(request, self._mesh, found, buffers)
        request.returns_only = returns_only
        _core.cast(self._core, request)
        if "Depth" in names:
            shift_lengths(buffers["Depth"], k - j, "t")
        if "Position" in names and returns_only and k:  # (the rows of misses hold anything)
            returned = np.isfinite(buffers["Depth"])
            positions = buffers["Position"][returned]
            shift_lengths(positions, k, "position", distance=False)
            buffers["Position"][returned] = positions
        elif "Position" in names:
            shift_lengths(buffers["Position"], k, "position", distance=False)
        return buffers, shape

    def occluded(
        self,
        origins: Any,
        directions: Any,
        *,
        tmin: float = 0.0,
        tmax: float = math.inf,
        strategy: str = "auto",
        precision: str = "float64",
        accel: str = "bvh",
        threads: int | None = None,
        backface_culling: bool = False,
    ) -> np.ndarray:
        """Whether any triangle lies on each ray within ``tmin <= t <= tmax``: a bool array of
        the broadcast batch shape of ``origins`` and ``directions`` (``(..., 3)`` each). Each
        ray stops at the first triangle found; the decision is as exact as :meth:`intersect`'s
        (a ray is occluded exactly when ``intersect`` finds a hit in the range).

        Examples
        --------
        >>> import pyvista as pv
        >>> import vtkraycast as vrc
        >>> scene = vrc.Scene(pv.Sphere())
        >>> scene.occluded([0, 0, 2], [[0, 0, -1], [0, 0, 1]]).tolist()
        [True, False]
        >>> scene.occluded([0, 0, 2], [0, 0, -1], tmax=1.0).tolist()  # the sphere is 1.5 away
        False
        """
        if strategy == "auto" and precision == "float64" and accel == "bvh":
            quick = self._quick_rays(origins, directions, tmin, tmax, threads, backface_culling, None)
            if quick is not None:
                return quick[0].view(bool)
        request, shape, _ = self._ray_request(
            origins, directions, tmin, tmax, strategy, precision, accel, threads, backface_culling
        )
        request.any_hit = True
        mask = np.empty(request.origins.shape[0], np.uint8)
        request.valid = mask
        _core.cast(self._core, request)
        return mask.view(bool).reshape(shape)

    def intersect_all(
        self, origins: Any, directions: Any, *, tmin: float = 0.0, tmax: float = math.inf, threads: int | None = None
    ) -> dict[str, np.ndarray]:
        """Every surface crossing along each ray within ``tmin <= t <= tmax``, sorted by t, in
        a flat layout like Open3D's ``list_intersections``: ray ``i``'s crossings are rows
        ``ray_splits[i]:ray_splits[i + 1]`` of ``ray_ids``, ``triangle_id``, ``cell_id``,
        ``t`` and ``barycentric`` (rays are the flattened batch of ``origins`` and
        ``directions``, shapes ``(..., 3)`` broadcast as in :meth:`intersect`).

        Decided exactly (the watertight test in double with exact edge signs). A ray through
        an edge or a vertex the triangles share crosses the surface there once and is
        reported once, by the lowest of the triangles that face it the same way; a ray
        grazing a fold (the triangles around the point face it both ways) is reported twice
        there, in and out. Triangles must share their points (``clean()`` merges duplicates).

        Examples
        --------
        >>> import pyvista as pv
        >>> import vtkraycast as vrc
        >>> scene = vrc.Scene(pv.Cube())
        >>> hits = scene.intersect_all([[0, 0, -2], [0.5, 0.5, -2]], [0, 0, 1])
        >>> hits["ray_splits"].tolist(), hits["t"].tolist()  # the second ray meets an edge
        ([0, 2, 4], [1.5, 2.5, 1.5, 2.5])
        """
        (splits, ray, triangle, t, weights), _, (k, j) = self._crossings(
            origins, directions, tmin, tmax, threads, False
        )
        shift_lengths(t, (k - j[ray]) if np.ndim(j) else k - j, "t")
        return {
            "ray_splits": splits,
            "ray_ids": ray,
            "triangle_id": triangle,
            "cell_id": self._mesh.cell_ids[triangle],
            "t": t,
            "barycentric": weights,
        }

    def _crossings(
        self, origins: Any, directions: Any, tmin: float, tmax: float, threads: int | None, counts_only: bool
    ) -> tuple[tuple[np.ndarray, ...], Any, tuple]:
        """The core's crossings of the rays (checked and scaled as :meth:`intersect`'s, tested
        exactly), the batch shape and the length shifts."""
        request, shape, shifts = self._ray_request(
            origins, directions, tmin, tmax, "watertight", "float64", "bvh", threads, False
        )
        found = _core.intersect_all(
            self._core, request.origins, request.directions, request.tmin, request.tmax, request.threads, counts_only
        )
        return found, shape, shifts

    def count_intersections(
        self, origins: Any, directions: Any, *, tmin: float = 0.0, tmax: float = math.inf, threads: int | None = None
    ) -> np.ndarray:
        """Surface crossings along each ray (as :meth:`intersect_all` counts them): an int64
        array of the broadcast batch shape.

        Examples
        --------
        >>> import pyvista as pv
        >>> import vtkraycast as vrc
        >>> vrc.Scene(pv.Sphere()).count_intersections([0, 0, -2], [[0, 0, 1], [0, 1, 0]]).tolist()
        [2, 0]
        """
        (counts, _), shape, _ = self._crossings(origins, directions, tmin, tmax, threads, True)
        return counts.reshape(shape)

    def contains(self, points: Any, *, threads: int | None = None) -> np.ndarray:
        """Whether each point lies inside the closed surface: a bool array of the batch shape
        of ``points`` (``(..., 3)``).

        Exact for every point not on the surface, whatever its alignment with vertices and
        edges and whatever the triangles' orientation: the parity of the surface crossings
        (:meth:`intersect_all`) along a ray from the point. Points on the surface count as
        inside. The mesh must be closed (every edge shared by an even number of triangles),
        else a ValueError: inside has no meaning for an open surface. Batches of 4096 points
        or more are answered through a grid of cells made once per scene, most points by a
        lookup, the others by a short segment (docs/visibility.md): the same answers.

        Examples
        --------
        >>> import pyvista as pv
        >>> import vtkraycast as vrc
        >>> vrc.Scene(pv.Cube()).contains([[0, 0, 0], [0.5, 0.5, 0.5], [0.6, 0, 0]]).tolist()
        [True, True, False]
        """
        self._check_closed()
        points = np.asarray(points, dtype=np.float64)
        shape = points.shape[:-1]
        if points.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (..., 3), got {points.shape}")
        flat = np.ascontiguousarray(points.reshape(-1, 3))
        grid = self._inside_grid(len(flat))
        if grid is None or not np.isfinite(flat).all():  # (the rays name a point that is not finite)
            return self._contains_by_rays(flat, threads).reshape(shape)
        # Most points fall in cells that hold no triangle, answered by lookup; the others
        # by the crossings of a segment to a point whose answer the grid knows.
        answers, ends = grid.classify(flat)
        inside = (answers & 1).astype(bool)
        near = np.flatnonzero(answers >= 2)
        if len(near):
            starts = flat[near]
            (counts, on_surface), _, _ = self._crossings(starts, ends - starts, 0.0, 1.0, threads, True)
            inside[near] ^= (counts & 1).astype(bool)
            inside[near] |= on_surface.view(bool)
        return inside.reshape(shape)

    def _contains_by_rays(self, points: np.ndarray, threads: int | None) -> np.ndarray:
        """contains for (n, 3) points by the parity of the crossings along a ray from each."""
        # Any direction gives the same answer. Components of unequal size (no face of common
        # meshes holds such a direction), their signs chosen point by point towards the
        # nearer side of the mesh's box on each axis: the ray then leaves the box through its
        # nearest face, meeting fewer nodes and crossings on the way.
        direction = [0.5773502691896257, 0.5773502691896258, 0.5773502691896256]
        directions = _core.exit_directions(points, *self._box(), direction)
        (counts, on_surface), _, _ = self._crossings(points, directions, 0.0, math.inf, threads, True)
        return (counts & 1).astype(bool) | on_surface.view(bool)

    def _inside_grid(self, points: int) -> _core.InsideGrid | None:
        """contains' grid of cells (src/inside_grid.hpp), made at the first batch large enough
        to repay it (about two cells a triangle, at most 128 along the box's longest side, so
        that the lookups stay in the caches); None where the grid cannot answer (no empty
        cell, or a box far from the origin for its size)."""
        if self._grid is None and points >= _GRID_POINTS:
            mesh = self._mesh
            per_axis = int(
                np.clip(round(np.cbrt(_GRID_CELLS_PER_TRIANGLE * len(mesh.triangles))), 8, _GRID_MOST_PER_AXIS)
            )
            grid = _core.InsideGrid(mesh.points, mesh.triangles, *self._box(), per_axis)
            if grid.usable:
                grid.set_inside(self._contains_by_rays(grid.region_points(), None).astype(np.uint8))
            self._grid = grid if grid.usable else False
        return self._grid or None

    def _box(self) -> tuple[np.ndarray, np.ndarray]:
        """The least and greatest coordinates of the mesh's points (once per scene)."""
        if self._bounds is None:
            points = self._mesh.points
            self._bounds = (points.min(axis=0), points.max(axis=0)) if len(points) else (np.zeros(3), np.zeros(3))
        return self._bounds

    def _check_closed(self) -> None:
        if self._closed is None:
            triangles = self._mesh.triangles.astype(np.int64)
            edges = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
            keys = np.sort(edges[:, 0] << 32 | edges[:, 1])  # (point ids are below 2**32)
            runs = np.diff(np.flatnonzero(np.diff(keys, prepend=-1, append=-1)))  # lengths of equal keys
            self._closed = bool((runs % 2 == 0).all())
        if not self._closed:
            raise ValueError(
                "contains needs a closed surface (every edge shared by an even number of triangles); "
                "this mesh has boundary edges (pyvista's clean() merges duplicate points)"
            )

    def _ray_request(
        self,
        origins: Any,
        directions: Any,
        tmin: float,
        tmax: float,
        strategy: str,
        precision: str,
        accel: str,
        threads: int | None,
        backface_culling: bool,
        sweep_rows: int = 0,
        grid: bool = False,
    ) -> tuple[_core.Request, tuple[int, ...], tuple[int, int | np.ndarray]]:
        """The request for rays (checked, in the core's units), the batch shape, and the
        shifts k (lengths) and j (directions): t in the core is 2**(k - j) t. With
        ``sweep_rows``, a sensor's sweep: one origin (3,) and (n, 3) unit directions, row
        after row (the core traces them in bundles). With ``grid``, one origin and a 2-D
        batch of directions (a camera of the caller's own) go as a sweep too; the request
        then holds that one origin."""
        if _accel(accel) != "none" and not self._core.has_bvh:
            raise ValueError('this scene was built with bvh=False: intersect needs accel="none" (or bvh=True)')
        if sweep_rows:
            o, d = np.asarray(origins, dtype=np.float64).reshape(1, 3), directions
            shape = (len(d),)
            o_min, o_max, d_min, d_max = float(o.min()), float(o.max()), 0.5, 1.0  # (unit directions)
        else:
            o, d, shape, (o_min, o_max, d_min, d_max) = _ray_batch(origins, directions, _threads(threads))
            if grid and len(shape) == 2 and min(shape) > 1 and np.shape(origins) == (3,):
                o, sweep_rows = o[:1], shape[0]
        tmin, tmax = float(tmin), float(tmax)
        if math.isnan(tmin) or math.isnan(tmax) or tmin > tmax:
            raise ValueError(f"need tmin <= tmax, got tmin={tmin}, tmax={tmax}")
        if tmin < 0:
            raise ValueError(
                f"tmin must be >= 0, got {tmin}: hits behind a ray's origin are not cast "
                "(reverse the direction, or move the origin back, to find them)"
            )
        self._scale.check_origins(o, _precision(precision), "a ray origin", extent=(o_min, o_max))
        k = self._scale.shift
        j = direction_shifts(d, bounded=(tmin, tmax) != (0.0, math.inf), extent=(d_min, d_max))
        request = self._request(strategy, precision, accel, threads, backface_culling)
        request.origins = np.ldexp(o, k) if k else o
        request.directions = (
            np.ldexp(d, np.reshape(j, (-1, 1))) if (np.any(j) if isinstance(j, np.ndarray) else j) else d
        )
        request.sweep_rows = sweep_rows
        if not isinstance(j, np.ndarray):  # (else the bounds are 0 and inf, the same in any unit)
            request.tmin, request.tmax = (_shifted(tmin, k - j), _shifted(tmax, k - j)) if k != j else (tmin, tmax)
        return request, shape, (k, j)


def _ray_arrays(arrays: Iterable[str] | str | None, composite: bool) -> list[str]:
    if arrays is None:
        return list(DEFAULT_RAY_ARRAYS) + (["composite_index"] if composite else [])
    names = [arrays] if isinstance(arrays, str) else list(arrays)
    for name in names:
        if name not in RAY_ARRAYS:
            raise ValueError(f"unknown ray array {name!r}; available: {', '.join(RAY_ARRAYS)}")
        if name == "composite_index" and not composite:
            raise ValueError("composite_index exists for scenes of composite inputs (pyvista.MultiBlock, ...) only")
    return list(dict.fromkeys(names))


def _names(arrays: Iterable[str] | str | None) -> list[str]:
    return [arrays] if isinstance(arrays, str) else list(arrays or [])


def _along(names: list[str]) -> list[str]:
    """The names of arrays computed from every crossing along the pixel ray."""
    return [name for name in names if name in CROSSING_ARRAYS]


def _batched(values: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    return values if values.shape[:1] == shape else values.reshape(shape + values.shape[1:])


@contextmanager
def progress_reporter(
    progress: Callable[[int, int], bool | None] | None, progress_bar: bool, title: str
) -> Iterator[Callable[[int, int], bool] | None]:
    """The core's poll callback: forwards to ``progress`` and advances a tqdm bar.
    A ``progress`` that returns False aborts the cast."""
    if not progress_bar:
        yield None if progress is None else (lambda done, total: progress(done, total) is not False)
        return
    try:
        from tqdm import tqdm
    except ImportError:
        raise ImportError("progress_bar=True needs tqdm: pip install tqdm") from None
    with tqdm(total=100, desc=title, unit="%") as bar:

        def poll(done: int, total: int) -> bool:
            bar.update(int(100 * done / total) - bar.n)
            return progress is None or progress(done, total) is not False

        yield poll
        bar.update(100 - bar.n)


def cast(mesh: Any, camera: Camera | Any, *, comm: Any = None, root: int | None = 0, **options: Any) -> Any:
    """Casts ``mesh`` from ``camera`` once: ``Scene(mesh).cast(camera, ...)``.

    Under MPI, ``mesh`` is this rank's piece and ``comm`` an mpi4py communicator: the call
    is collective and ``root`` receives the image of the whole mesh (every rank when None,
    the others get None); see :class:`Scene`.

    Keyword options are those of :meth:`Scene.cast`. No BVH is built (``Scene(mesh,
    bvh=False)``): the triangles are binned to the image's tiles, all one cast needs. Build
    a :class:`Scene` when the same mesh is cast from several cameras: its BVH is then built
    once and makes each cast cheaper.

    Examples
    --------
    >>> import pyvista as pv
    >>> import vtkraycast as vrc
    >>> cam = vrc.Camera((0, 0, 3), (0, 0, 0), (0, 1, 0), view_angle=40, nx=64, ny=48)
    >>> image = vrc.cast(pv.Sphere(), cam)
    >>> image.dimensions
    (64, 48, 1)
    >>> int(image["vtkValidPointMask"].sum()) > 0
    True
    """
    if not isinstance(camera, Panorama):
        camera = camera if isinstance(camera, Camera) else Camera.from_vtk(camera)
    arrays = options.get("arrays")
    crossings = options.get("layers", 1) != 1 or bool(
        set([arrays] if isinstance(arrays, str) else arrays or []) & set(CROSSING_ARRAYS)
    )
    scene = one_shot_scene(mesh, camera, threads=options.get("threads"), comm=comm, rays=crossings)
    return scene.cast(camera, root=root, **options)


def one_shot_scene(
    mesh: Any, camera: Camera | Panorama, *, threads: int | None = None, comm: Any = None, rays: bool = False
) -> Scene:
    """The scene one cast from ``camera`` needs: without a BVH (its triangles are binned to
    the image's tiles) unless the image is wider or higher than binning allows
    (``_core.max_binned_pixels``), or its rays go one by one (a panorama; ``rays``: layers
    and the arrays of every crossing)."""
    binned = isinstance(camera, Camera) and not rays and max(camera.nx, camera.ny) <= _core.max_binned_pixels
    return Scene(mesh, threads=threads, bvh=not binned, comm=comm)
