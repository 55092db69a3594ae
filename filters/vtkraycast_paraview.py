"""ParaView plugin: the vtkraycast ray caster as the filter "Ray Cast" (proxy ``RayCast``).

Input: any dataset (polygonal data directly, other datasets by their outer surface).
Output: the geometry buffer image, the same arrays as ``vtkraycast.cast``: ``TriangleId``,
``CellId``, ``Barycentric``, ``Depth``, ``vtkValidPointMask`` and the input's own point and
cell arrays (or the ``Arrays`` asked for, ``Position`` and ``Normal`` among them).

The filter is ``vtkraycast.RayCastFilter`` (the native core, one BVH build per input);
this file only maps ParaView properties onto it. The camera properties mean what they
mean on a ``vtkCamera`` (and on ParaView's render view): ``CameraViewAngle`` is the
vertical angle in degrees, ``ParallelScale`` half the image height. Every hit in front of
the eye counts: no clipping range.

Loading
-------
The ``vtkraycast`` package (built for ParaView's Python version) must be on ParaView's
Python path, e.g. installed with ``python3 -m pip install --no-deps --target DIR .`` from
the vtkraycast checkout and ``PYTHONPATH=DIR`` in ParaView's environment (README,
"ParaView"). Then Tools > Manage Plugins > Load New... in the GUI, or in ``pvpython`` /
``pvbatch``::

    from paraview.simple import *
    LoadPlugin("/path/to/filters/vtkraycast_paraview.py", ns=globals())
    cast = RayCast(Input=Sphere(), Resolution=[800, 600], CameraPosition=[0, 0, 3])
    cast.UpdatePipeline()

    # or through a render view's camera, pixel for pixel:
    view = GetActiveViewOrCreate("RenderView")
    cast.Resolution = view.ViewSize
    for name in ("CameraPosition", "CameraFocalPoint", "CameraViewUp", "CameraViewAngle"):
        setattr(cast, name, getattr(view, name))
    cast.ParallelProjection = view.CameraParallelProjection
    cast.ParallelScale = view.CameraParallelScale

ParaView 5.11 on Python >= 3.11 (Debian 12's ``paraview``): ParaView's own Python-plugin
loader imports ``inspect.getargspec``, which Python 3.11 removed, *before* it reads this
file; ``filters/paraview_usercustomize.py``, copied as ``usercustomize.py`` into the
directory on ``PYTHONPATH``, restores it at start-up (README, "ParaView").

Only ParaView's own VTK (``vtkmodules``) and numpy are imported on this path: never
pyvista, never the pip ``vtk`` package. Everything here works with VTK 9.2 (no ``>>``
pipelines, no ``update()``).
"""

from __future__ import annotations

import atexit
import inspect
import math
import weakref
from typing import Any
from xml.sax.saxutils import escape

# Compatibility shim, ParaView 5.11 with Python >= 3.11: paraview.util.vtkAlgorithm
# (paraview/detail/pythonalgorithm.py) does `from inspect import getargspec`, removed in
# Python 3.11. It only reads `.args` of the result, which getfullargspec has too. This
# covers importing this file directly; ParaView's LoadPlugin imports that module before
# this file runs, which is what filters/paraview_usercustomize.py is for.
if not hasattr(inspect, "getargspec"):
    inspect.getargspec = inspect.getfullargspec

from paraview.util.vtkAlgorithm import smdomain, smhint, smproperty, smproxy
from vtkmodules.vtkCommonCore import vtkOutputWindow
from vtkmodules.vtkCommonDataModel import vtkDataObject, vtkImageData

try:
    import vtkraycast as vrc
    from vtkraycast.image import image_geometry
except ImportError as error:  # the usual first-time problem: say how to fix it
    raise ImportError(
        f"the Ray Cast plugin needs the vtkraycast package on ParaView's Python path ({error}); "
        "install it for ParaView's Python version, e.g. `python3 -m pip install --no-deps "
        "--target DIR .` in the vtkraycast checkout, and start ParaView with PYTHONPATH=DIR"
    ) from error

paraview_plugin_name = "vtkraycast"
paraview_plugin_version = vrc.__version__

#: Arrays the caster computes besides the input's own (for the documentation).
_GEOMETRY_ARRAYS = "TriangleId, CellId, Barycentric, Depth, Position, Normal, vtkValidPointMask"


def _doc(text: str):
    """The property's <Documentation> (the GUI's tooltip and help)."""
    return smdomain.xml(f"<Documentation>{escape(text)}</Documentation>")


def _string_list(values) -> Any:
    """A drop-down list of ``values`` (not enforced by ParaView: the setter checks)."""
    entries = "".join(f'<String value="{escape(v)}"/>' for v in values)
    return smdomain.xml(f'<StringListDomain name="list">{entries}</StringListDomain>')


_boolean = smdomain.xml('<BooleanDomain name="bool"/>')

#: Every RayCast alive. ParaView's proxies still hold them when Python shuts down, after
#: the native core's module is gone, which then reports their scenes as leaked objects.
_instances: weakref.WeakSet = weakref.WeakSet()


@atexit.register
def _release_scenes() -> None:
    for instance in list(_instances):
        instance._scene = None


@smproxy.filter(name="RayCast", label="Ray Cast")
@smhint.xml('<ShowInMenu category="vtkraycast"/>')
@smproperty.xml(
    '<Documentation short_help="Ray casts a mesh into a geometry buffer image.">'
    "Casts one ray per pixel of the camera into the input (polygons and strips are "
    "triangulated; other datasets contribute their outer surface; the blocks of a composite "
    "dataset are cast as one scene, with CompositeIndex) and writes, per pixel, "
    "the first triangle hit, its barycentric coordinates, the depth and the input's fields "
    "at the hit (vtkraycast).</Documentation>"
)
@smproperty.input(name="Input", port_index=0)
@smdomain.datatype(dataTypes=["vtkDataSet", "vtkCompositeDataSet"], composite_data_supported=True)
class RayCast(vrc.RayCastFilter):
    """``vrc.RayCastFilter`` with the camera given by ParaView properties.

    Bad property values never raise out of a setter (ParaView would only print a
    traceback and keep the old value silently): the setter remembers the problem, and the
    next execution reports it as a VTK error, empties the output and fails, until the
    property gets a good value again.
    """

    def __init__(self) -> None:
        super().__init__()
        # vtkCamera's defaults; set through the properties below.
        self._position = (0.0, 0.0, 1.0)
        self._focal_point = (0.0, 0.0, 0.0)
        self._view_up = (0.0, 1.0, 0.0)
        self._view_angle = 30.0
        self._parallel = False
        self._parallel_scale = 1.0
        self._array_list: list[str] = []
        self._invalid: dict[str, str] = {}
        _instances.add(self)

    # -- helpers ------------------------------------------------------------------------

    def _checked(self, name: str, setter: Any, *values: Any) -> None:
        """Calls the base class's ``setter``; a rejected value is kept as an error of
        property ``name`` (reported at the next execution) instead of raising."""
        try:
            setter(*values)
        except (TypeError, ValueError) as error:
            self._invalid[name] = f"{name}: {error}"
            self.Modified()
        else:
            if self._invalid.pop(name, None) is not None:
                self.Modified()

    def _camera_value(self, name: str, value: Any) -> None:
        if getattr(self, name) != value:
            setattr(self, name, value)
            self.Modified()

    def _fail(self, message: str) -> int:
        vtkOutputWindow.GetInstance().DisplayErrorText(f"ERROR: In RayCast (vtkraycast): {message}\n")
        return 0

    # -- camera -------------------------------------------------------------------------

    @smproperty.doublevector(name="CameraPosition", default_values=[0.0, 0.0, 1.0])
    @_doc("Eye position (as vtkCamera::SetPosition).")
    def SetCameraPosition(self, x: float, y: float, z: float) -> None:
        self._camera_value("_position", (float(x), float(y), float(z)))

    @smproperty.doublevector(name="CameraFocalPoint", default_values=[0.0, 0.0, 0.0])
    @_doc("The point the eye looks at; its distance from the eye is the image plane's distance d.")
    def SetCameraFocalPoint(self, x: float, y: float, z: float) -> None:
        self._camera_value("_focal_point", (float(x), float(y), float(z)))

    @smproperty.doublevector(name="CameraViewUp", default_values=[0.0, 1.0, 0.0])
    @_doc("Up direction of the image (made orthogonal to the view direction, as vtkCamera does).")
    def SetCameraViewUp(self, x: float, y: float, z: float) -> None:
        self._camera_value("_view_up", (float(x), float(y), float(z)))

    @smproperty.doublevector(name="CameraViewAngle", default_values=30.0)
    @smdomain.doublerange(min=0.0, max=180.0)
    @_doc("Vertical view angle in degrees (perspective projection), strictly between 0 and 180.")
    def SetCameraViewAngle(self, angle: float) -> None:
        self._camera_value("_view_angle", float(angle))

    @smproperty.intvector(name="ParallelProjection", default_values=0)
    @_boolean
    @_doc("Parallel rays along the view direction, starting on the plane through the eye.")
    def SetParallelProjection(self, parallel: int) -> None:
        self._camera_value("_parallel", bool(parallel))

    @smproperty.doublevector(name="ParallelScale", default_values=1.0)
    @_doc("Half the image height in world units, for the parallel projection.")
    def SetParallelScale(self, scale: float) -> None:
        self._camera_value("_parallel_scale", float(scale))

    def _view(self, data: Any) -> vrc.Camera:
        """The camera of the properties. Overrides RayCastFilter's hook (which otherwise
        reads the vtkCamera given to SetCamera), so the camera is built in one piece from
        the property values: no vtkCamera state in between (vtkCamera moves the focal point
        when a new position meets it, and clamps view angles), and no clipping range."""
        nx, ny = self.GetResolution()
        d = math.dist(self._position, self._focal_point)
        if not d > 0:
            raise ValueError("CameraPosition and CameraFocalPoint coincide: the view direction is undefined")
        if self._parallel:
            return vrc.Camera(
                self._position, self._focal_point, self._view_up,
                d=d, h=2.0 * self._parallel_scale, nx=nx, ny=ny, parallel=True,
            )  # fmt: skip
        return vrc.Camera(
            self._position, self._focal_point, self._view_up, d=d, view_angle=self._view_angle, nx=nx, ny=ny
        )

    # -- image and cast options ---------------------------------------------------------

    @smproperty.intvector(name="Resolution", default_values=[640, 480])
    @_doc("Image size in pixels, nx by ny (at least 1 each).")
    def SetResolution(self, nx: int, ny: int) -> None:
        self._checked("Resolution", super().SetResolution, nx, ny)

    @smproperty.stringvector(name="Strategy", default_values="auto")
    @_string_list(vrc.STRATEGIES)
    @_doc(
        "Ray-triangle test: watertight (Woop, Benthin, Wald 2013), moller-trumbore, the seed's "
        "plane and cramer strategies, or auto (the fastest exact one)."
    )
    def SetStrategy(self, strategy: str) -> None:
        self._checked("Strategy", super().SetStrategy, strategy)

    @smproperty.stringvector(name="Precision", default_values="float64")
    @_string_list(tuple(vrc.PRECISIONS))
    @_doc("Arithmetic of the intersection test and type of the floating-point output arrays.")
    def SetPrecision(self, precision: str) -> None:
        self._checked("Precision", super().SetPrecision, precision)

    @smproperty.stringvector(
        name="Arrays",
        command="AddArray",
        clean_command="ClearArrays",
        repeat_command=1,
        number_of_elements_per_command=1,
        number_of_elements=0,
    )
    @_doc(
        f"Names of the arrays to compute ({_GEOMETRY_ARRAYS} or the input's own point and cell "
        "arrays); empty: TriangleId, CellId, Barycentric, Depth, vtkValidPointMask and, with "
        "Interpolate, the input's arrays."
    )
    def AddArray(self, name: str) -> None:
        self._array_list.append(str(name))
        super().SetArrays(list(self._array_list))

    def ClearArrays(self) -> None:
        self._array_list = []
        super().SetArrays(None)

    @smproperty.intvector(name="Interpolate", default_values=1)
    @_boolean
    @_doc("Add the input's point arrays (interpolated at the hits) and cell arrays to the default output.")
    def SetInterpolate(self, interpolate: int) -> None:
        super().SetInterpolate(bool(interpolate))

    @smproperty.intvector(name="BackfaceCulling", default_values=0, panel_visibility="advanced")
    @_boolean
    @_doc("Skip triangles whose normal (right-hand rule over their points) faces away from the eye.")
    def SetBackfaceCulling(self, culling: int) -> None:
        super().SetBackfaceCulling(bool(culling))

    @smproperty.intvector(name="WorldSpace", default_values=0, panel_visibility="advanced")
    @_boolean
    @_doc("Place the image on the camera's image plane in world coordinates instead of pixel space.")
    def SetWorldSpace(self, world_space: int) -> None:
        super().SetWorldSpace(bool(world_space))

    @smproperty.intvector(name="NumberOfSceneBuilds", information_only=1, number_of_elements=1, default_values=0)
    @_doc("How many times the acceleration structure was built (a diagnostic): camera changes do not rebuild it.")
    def GetNumberOfSceneBuilds(self) -> int:
        return super().GetNumberOfSceneBuilds()

    # -- pipeline -----------------------------------------------------------------------

    def RequestInformation(self, request: Any, in_info: Any, out_info: Any) -> int:
        """As RayCastFilter's; in world space, the image's placement too (the camera is
        known before the data, so downstream image filters see where the image lies)."""
        if not super().RequestInformation(request, in_info, out_info):
            return 0
        if self.GetWorldSpace():
            try:
                origin, spacing, direction = image_geometry(self._view(None), True)
            except ValueError:
                return 1  # a bad camera: RequestData reports it
            info = out_info.GetInformationObject(0)
            info.Set(vtkDataObject.ORIGIN(), *origin)
            info.Set(vtkDataObject.SPACING(), *spacing)
            vtkDataObject.DIRECTION().Set(info, direction.ravel().tolist(), 9)
        return 1

    def RequestData(self, request: Any, in_info: Any, out_info: Any) -> int:
        if self._invalid:
            vtkImageData.GetData(out_info).Initialize()
            return self._fail("; ".join(self._invalid.values()))
        return super().RequestData(request, in_info, out_info)
