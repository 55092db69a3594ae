"""Runs the Ray Cast plugin inside ParaView: ``pvbatch raycast_pvbatch.py PLAN.json``.

Run by tests/test_paraview.py, which writes the plan (plugin path, inputs, property
values) and compares what this script writes against ``vrc.cast`` in the project's own
environment. Uses only what ParaView ships (its Python, its VTK 9.2, its numpy), plus the
vtkraycast package on ``PYTHONPATH``, as a ParaView user's script would.

Writes into the plan's ``out`` directory: ``CASE.vti`` (the filter's output image) for
every cast, ``sphere_input.vtp`` (the ParaView source's mesh, so the reference casts the
very same points), and ``report.json`` (versions, modules, build counts, error checks).
"""

import json
import sys

plan = json.load(open(sys.argv[1]))

from paraview.simple import (  # noqa: E402
    GetParaViewSourceVersion,
    GroupDatasets,
    LoadPlugin,
    OpenDataFile,
    Sphere,
)
from vtkmodules.vtkCommonCore import vtkVersion  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkDataObject  # noqa: E402
from vtkmodules.vtkIOXML import vtkXMLImageDataWriter, vtkXMLPolyDataWriter  # noqa: E402

LoadPlugin(plan["plugin"], ns=globals())  # defines RayCast here, as in a user's script
out = plan["out"]
report = {
    "paraview": GetParaViewSourceVersion(),
    "vtk": vtkVersion.GetVTKVersion(),
    "python": list(sys.version_info[:3]),
    "casts": {},
}


def save(case, data):
    """Writes the output image and records its placement exactly (JSON keeps doubles)."""
    writer = vtkXMLImageDataWriter()
    writer.SetInputData(data)
    writer.SetFileName(f"{out}/{case}.vti")
    if not writer.Write():
        raise RuntimeError(f"could not write {case}.vti")
    direction = data.GetDirectionMatrix()
    report["casts"][case] = {
        "dimensions": list(data.GetDimensions()),
        "origin": list(data.GetOrigin()),
        "spacing": list(data.GetSpacing()),
        "direction": [direction.GetElement(r, c) for r in range(3) for c in range(3)],
        "points": data.GetNumberOfPoints(),
    }


def cast(case, proxy):
    """Updates ``proxy`` the way ParaView does and saves its output image, and the
    placement the pipeline announced before the data (what image filters downstream use)."""
    proxy.UpdatePipeline()
    algorithm = proxy.GetClientSideObject()
    save(case, algorithm.GetOutputDataObject(0))
    info = algorithm.GetOutputInformation(0)
    report["casts"][case]["information"] = {
        "origin": list(info.Get(vtkDataObject.ORIGIN())),
        "spacing": list(info.Get(vtkDataObject.SPACING())),
        "direction": list(info.Get(vtkDataObject.DIRECTION())),
    }


def builds(proxy):
    """GetNumberOfSceneBuilds, through the server-side object and the information property."""
    proxy.UpdatePropertyInformation()
    return [proxy.GetClientSideObject().GetNumberOfSceneBuilds(), proxy.GetProperty("NumberOfSceneBuilds")[0]]


# -- a ParaView source; then a camera change (no rebuild) and a mesh change (rebuild) ----
spec = plan["sphere"]
sphere = Sphere(**spec["source"])
ray_cast = RayCast(Input=sphere, **spec["cast"])  # noqa: F821 (defined by LoadPlugin)
cast("sphere", ray_cast)
mesh_writer = vtkXMLPolyDataWriter()
mesh_writer.SetInputData(sphere.GetClientSideObject().GetOutputDataObject(0))
mesh_writer.SetFileName(f"{out}/sphere_input.vtp")
mesh_writer.Write()
report["builds_first"] = builds(ray_cast)
for name, value in spec["moved"].items():
    setattr(ray_cast, name, value)
cast("sphere_moved", ray_cast)
report["builds_after_camera_change"] = builds(ray_cast)
sphere.Radius = spec["source"]["Radius"] * 0.5
ray_cast.UpdatePipeline()
report["builds_after_mesh_change"] = builds(ray_cast)

# -- files the test wrote, through ParaView's readers ---------------------------------
for case, spec in plan["files"].items():
    reader = OpenDataFile(spec["path"])
    cast(case, RayCast(Input=reader, **spec["cast"]))  # noqa: F821

# -- a composite input: files grouped into a multiblock dataset, cast as one scene ------
spec = plan["composite"]
group = GroupDatasets(Input=[OpenDataFile(path) for path in spec["paths"]])
cast("composite", RayCast(Input=group, **spec["cast"]))  # noqa: F821

# -- bad property values: an error message and an empty output, never a crash ---------
spec = plan["errors"]
reader = OpenDataFile(spec["path"])
ray_cast = RayCast(Input=reader, **spec["cast"])  # noqa: F821
ray_cast.UpdatePipeline()
good = ray_cast.GetDataInformation().GetNumberOfPoints()
report["errors"] = {"good": good}
for name, bad in spec["bad"]:
    before = getattr(ray_cast, name)
    before = list(before) if hasattr(before, "__len__") and not isinstance(before, str) else before
    setattr(ray_cast, name, bad)
    ray_cast.UpdatePipeline()
    failed = ray_cast.GetDataInformation().GetNumberOfPoints()
    setattr(ray_cast, name, before)
    ray_cast.UpdatePipeline()
    report["errors"][name] = [failed, ray_cast.GetDataInformation().GetNumberOfPoints()]
    print(f"checked bad {name}={bad!r}", file=sys.stderr, flush=True)

report["modules"] = sorted(m for m in sys.modules if m.split(".")[0] in ("pyvista", "vtk", "vtkraycast"))
report["vtkraycast_file"] = sys.modules["vtkraycast"].__file__
report["completed"] = True
with open(f"{out}/report.json", "w") as stream:
    json.dump(report, stream, indent=1)
