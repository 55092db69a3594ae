"""RayCastFilter: the ray caster as a VTK pipeline algorithm (vtkDataSet or composite
dataset -> vtkImageData).

Imports only vtkmodules, numpy and the native core (never pyvista), so it runs inside other
VTK distributions too.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from vtkmodules.util.vtkAlgorithm import VTKPythonAlgorithmBase
from vtkmodules.vtkCommonCore import vtkCommand, vtkOutputWindow
from vtkmodules.vtkCommonDataModel import vtkCompositeDataSet, vtkDataObject, vtkDataSet, vtkImageData
from vtkmodules.vtkCommonExecutionModel import vtkAlgorithm, vtkStreamingDemandDrivenPipeline

from .camera import Camera, _pixels
from .composite import leaves
from .image import fill_image, image_geometry, set_arrays
from .scene import Scene, _precision, _strategy, _threads

__all__ = ["RayCastFilter"]


class RayCastFilter(VTKPythonAlgorithmBase):
    """Ray casts its input (any vtkDataSet; polygonal data directly, other datasets by
    their surface; or a composite dataset, cast as one scene with ``CompositeIndex``) from
    a vtkCamera into a geometry buffer image.

    The acceleration structure is built once per input: a camera change (the camera's
    own ``ModifiedEvent``, e.g. ``Azimuth(10)``) re-casts without rebuilding; a new input,
    or a change of the input's modification time, rebuilds it. Errors raise in Python
    from ``Update()``/``update()`` and are reported as VTK errors too.

    Examples
    --------
    >>> from vtkmodules.vtkFiltersSources import vtkSphereSource
    >>> from vtkmodules.vtkRenderingCore import vtkCamera
    >>> import vtkraycast as vrc
    >>> camera = vtkCamera()
    >>> camera.SetPosition(0, 0, 3)
    >>> caster = vrc.RayCastFilter()
    >>> caster.SetCamera(camera)
    >>> caster.SetResolution(64, 48)
    >>> sphere = vtkSphereSource()
    >>> image = (sphere >> caster).update().output
    >>> image.GetDimensions(), caster.GetNumberOfSceneBuilds()
    ((64, 48, 1), 1)
    >>> camera.Azimuth(10)
    >>> _ = caster.update()
    >>> caster.GetNumberOfSceneBuilds()
    1
    """

    def __init__(self) -> None:
        super().__init__(nInputPorts=1, inputType="vtkDataObject", nOutputPorts=1, outputType="vtkImageData")
        self._camera: Any = None
        self._camera_observer: int | None = None
        self._resolution = (640, 480)
        self._strategy = "auto"
        self._precision = "float64"
        self._arrays: tuple[str, ...] | None = None
        self._interpolate = True
        self._backface_culling = False
        self._threads: int | None = None
        self._world_space = False
        self._scene: Scene | None = None
        self._scene_key: tuple[Any, int] | None = None
        self._builds = 0
        self._error: BaseException | None = None

    # -- settings: each calls Modified() only when the value changes -----------------

    def _set(self, name: str, value: Any) -> None:
        if getattr(self, name) != value:
            setattr(self, name, value)
            self.Modified()

    def SetCamera(self, camera: Any) -> None:
        """The vtkCamera (or pyvista.Camera) to cast from; its changes re-execute the filter.
        Without one, the filter frames its input's bounds from the +x +y +z side."""
        if camera is self._camera:
            return
        if camera is not None and not hasattr(camera, "GetParallelScale"):
            raise TypeError(f"SetCamera expects a vtkCamera, got {type(camera).__name__}")
        if self._camera is not None and self._camera_observer is not None:
            self._camera.RemoveObserver(self._camera_observer)
        self._camera = camera
        self._camera_observer = None
        if camera is not None:
            self._camera_observer = camera.AddObserver(vtkCommand.ModifiedEvent, lambda *_: self.Modified())
        self.Modified()

    def GetCamera(self) -> Any:
        return self._camera

    def SetResolution(self, nx: int, ny: int) -> None:
        """Image size in pixels."""
        self._set("_resolution", (_pixels(nx, "nx"), _pixels(ny, "ny")))

    def GetResolution(self) -> tuple[int, int]:
        return self._resolution

    def SetStrategy(self, strategy: str) -> None:
        """Ray-triangle test, one of ``vtkraycast.STRATEGIES``."""
        _strategy(strategy)
        self._set("_strategy", strategy)

    def GetStrategy(self) -> str:
        return self._strategy

    def SetPrecision(self, precision: str) -> None:
        """``"float64"`` or ``"float32"``."""
        _precision(precision)
        self._set("_precision", precision)

    def GetPrecision(self) -> str:
        return self._precision

    def SetArrays(self, arrays: Iterable[str] | str | None) -> None:
        """Names of the arrays to compute; None for the defaults."""
        value = None if arrays is None else ((arrays,) if isinstance(arrays, str) else tuple(arrays))
        self._set("_arrays", value)

    def GetArrays(self) -> tuple[str, ...] | None:
        return self._arrays

    def SetInterpolate(self, interpolate: bool) -> None:
        """Whether the input's own arrays are part of the default output."""
        self._set("_interpolate", bool(interpolate))

    def GetInterpolate(self) -> bool:
        return self._interpolate

    def SetBackfaceCulling(self, culling: bool) -> None:
        self._set("_backface_culling", bool(culling))

    def GetBackfaceCulling(self) -> bool:
        return self._backface_culling

    def SetThreads(self, threads: int | None) -> None:
        """Worker threads; None (or 0) for all cores."""
        threads = None if threads in (None, 0) else threads
        _threads(threads)
        self._set("_threads", threads)

    def GetThreads(self) -> int | None:
        return self._threads

    def SetWorldSpace(self, world_space: bool) -> None:
        """Place the image on the camera's image plane in world coordinates."""
        self._set("_world_space", bool(world_space))

    def GetWorldSpace(self) -> bool:
        return self._world_space

    def SetInputData(self, data: vtkDataObject) -> None:
        """Uses ``data`` as the input, without an upstream algorithm."""
        self.SetInputDataObject(0, data)

    def GetOutput(self) -> vtkImageData:
        """The output image (as vtkImageAlgorithm::GetOutput)."""
        return vtkImageData.SafeDownCast(self.GetOutputDataObject(0))

    def GetNumberOfSceneBuilds(self) -> int:
        """How many times the acceleration structure was built (a diagnostic)."""
        return self._builds

    # -- pipeline --------------------------------------------------------------------

    def FillInputPortInformation(self, port: int, info: Any) -> int:
        # Composite datasets whole (one scene), not block by block as the executive would
        # loop over them for an algorithm taking vtkDataSet only.
        info.Set(vtkAlgorithm.INPUT_REQUIRED_DATA_TYPE(), "vtkDataSet")
        info.Append(vtkAlgorithm.INPUT_REQUIRED_DATA_TYPE(), "vtkCompositeDataSet")
        return 1

    def _view(self, data: vtkDataObject | None) -> Camera:
        nx, ny = self._resolution
        if self._camera is not None:
            return Camera.from_vtk(self._camera, nx=nx, ny=ny)
        return Camera.framing(_bounds(data), nx=nx, ny=ny)

    def _report(self, error: BaseException) -> int:
        """Keeps ``error`` for Update() to raise and reports it as a VTK error."""
        self._error = error
        vtkOutputWindow.GetInstance().DisplayErrorText(f"ERROR: In RayCastFilter: {error}\n")
        return 0

    def RequestInformation(self, request: Any, in_info: Any, out_info: Any) -> int:
        self._error = None
        try:
            nx, ny = self._resolution
            info = out_info.GetInformationObject(0)
            info.Set(vtkStreamingDemandDrivenPipeline.WHOLE_EXTENT(), 0, nx - 1, 0, ny - 1, 0, 0)
            # Under MPI each rank produces the block of the image the pipeline asks of it
            # (its piece of the extent), so ParaView assembles one image, as
            # vtkPResampleToImage does.
            info.Set(vtkAlgorithm.CAN_PRODUCE_SUB_EXTENT(), 1)
            # Where the image lies is known before the data only for an explicit camera.
            world = self._world_space and self._camera is not None
            origin, spacing, direction = image_geometry(self._view(None) if world else None, world)
            info.Set(vtkDataObject.ORIGIN(), *origin)
            info.Set(vtkDataObject.SPACING(), *spacing)
            vtkDataObject.DIRECTION().Set(info, direction.ravel().tolist(), 9)
        except Exception as error:
            return self._report(error)
        return 1

    def RequestData(self, request: Any, in_info: Any, out_info: Any) -> int:
        self._error = None
        data = vtkDataObject.GetData(in_info[0])
        output = vtkImageData.GetData(out_info)
        try:
            key = _data_key(data)
            controller = _parallel_controller()
            if self._scene is None or key != self._scene_key:
                self._scene = Scene(data, threads=self._threads, comm=controller)
                self._scene_key = key
                self._builds += 1
            if controller is not None:
                self._cast_block(output, out_info.GetInformationObject(0), data)
                return 1
            self._scene._cast_into(
                output, self._view(data), world_space=self._world_space, progress=self._progress, **self._options()
            )
        except InterruptedError:
            output.Initialize()  # aborted on request (AbortExecuteOn): not an error
            self.SetAbortExecute(0)  # VTK leaves the flag on; the next update runs again
        except Exception as error:
            output.Initialize()
            return self._report(error)
        return 1

    def _options(self) -> dict[str, Any]:
        """The cast's options, as the properties set them."""
        return {
            "arrays": self._arrays,
            "strategy": self._strategy,
            "precision": self._precision,
            "threads": self._threads,
            "backface_culling": self._backface_culling,
            "interpolate": self._interpolate,
        }

    def _cast_block(self, output: vtkImageData, info: Any, data: vtkDataObject) -> None:
        """The collective cast under MPI; this rank's output is the block of rows and
        columns the pipeline asks of it (its update extent)."""
        x0, x1, y0, y1 = info.Get(vtkStreamingDemandDrivenPipeline.UPDATE_EXTENT())[:4]
        camera, block = self._scene._cast_parallel(
            self._view(data), root=None, extent=(x0, x1, y0, y1), **self._options()
        )
        fill_image(output, camera, {}, world_space=self._world_space)
        output.SetExtent(x0, x1, y0, y1, 0, 0)
        set_arrays(output, block)

    def _progress(self, done: int, total: int) -> bool:
        self.UpdateProgress(done / total)
        return not self.GetAbortExecute()

    def _raise_pending(self) -> None:
        error, self._error = self._error, None
        if error is not None:
            raise error

    def Update(self, *args: Any) -> Any:
        """Updates the pipeline; an error inside RequestData is raised here."""
        result = super().Update(*args)
        self._raise_pending()
        return result

    def update(self, **kwargs: Any) -> Any:
        """Updates (VTK's ``>>`` pipeline syntax); errors raise as in :meth:`Update`."""
        result = super().update(**kwargs)
        self._raise_pending()
        return result


def _datasets(data: vtkDataObject | None) -> list[vtkDataSet]:
    if isinstance(data, vtkCompositeDataSet):
        return [leaf for _, leaf in leaves(data)]
    return [data] if isinstance(data, vtkDataSet) else []


def _data_key(data: vtkDataObject) -> tuple:
    """What identifies the input's state: a composite's own modification time does not
    follow its blocks', so each block's address and time count."""
    return (
        data.GetAddressAsString("vtkDataObject"),
        data.GetMTime(),
        tuple((leaf.GetAddressAsString("vtkDataObject"), leaf.GetMTime()) for leaf in _datasets(data)),
    )


def _bounds(data: vtkDataObject | None) -> tuple[float, ...]:
    """The input's bounds (every block's, for a composite); a unit box when it has no points."""
    boxes = [leaf.GetBounds() for leaf in _datasets(data) if leaf.GetNumberOfPoints()]
    if not boxes:
        return (-1, 1, -1, 1, -1, 1)
    low = [min(box[k] for box in boxes) for k in (0, 2, 4)]
    high = [max(box[k] for box in boxes) for k in (1, 3, 5)]
    return (low[0], high[0], low[1], high[1], low[2], high[2])


def _parallel_controller() -> Any:
    """VTK's global controller when the pipeline runs on several MPI ranks (ParaView's
    pvbatch and pvserver under mpirun), else None."""
    try:
        from vtkmodules.vtkParallelCore import vtkMultiProcessController
    except ImportError:
        return None
    controller = vtkMultiProcessController.GetGlobalController()
    return controller if controller is not None and controller.GetNumberOfProcesses() > 1 else None
