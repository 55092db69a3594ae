"""Runs the Ray Cast plugin in ParaView on every MPI rank: ``mpirun -np N pvbatch
raycast_mpi_pvbatch.py PLAN.json`` (N = 1 gives the serial reference).

Run by tests/test_paraview.py. Casts ParaView's Sphere (generated in pieces, one per rank)
directly and after RedistributeDataSet (boundary cells assigned to one region, and to all
regions: duplicated, flagged as ghost cells) and saves each image with ParaView's parallel
writer (each rank its block of the extent, one .pvti), with the points ParaView's data
information counts for it (one image, not one per rank).
"""

import json
import sys

plan = json.load(open(sys.argv[1]))

from paraview.simple import LoadPlugin, RedistributeDataSet, SaveData, Sphere  # noqa: E402
from vtkmodules.vtkParallelCore import vtkMultiProcessController  # noqa: E402

LoadPlugin(plan["plugin"], ns=globals())
out, tag = plan["out"], plan["tag"]
sphere = Sphere(**plan["sphere"])
inputs = {
    "pieces": sphere,
    "unique": RedistributeDataSet(Input=sphere, BoundaryMode="Assign to one region"),
    "duplicated": RedistributeDataSet(Input=sphere, BoundaryMode="Assign to all regions"),
}
report = {"ranks": vtkMultiProcessController.GetGlobalController().GetNumberOfProcesses(), "points": {}}
for case, source in inputs.items():
    ray_cast = RayCast(Input=source, **plan["cast"])  # noqa: F821 (defined by LoadPlugin)
    ray_cast.UpdatePipeline()
    report["points"][case] = ray_cast.GetDataInformation().GetNumberOfPoints()
    SaveData(f"{out}/{tag}-{case}.pvti", proxy=ray_cast)
with open(f"{out}/{tag}-report.json", "w") as stream:
    json.dump(report, stream)
