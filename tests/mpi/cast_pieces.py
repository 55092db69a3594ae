"""Run under MPI by tests/test_mpi.py: ``mpiexec -n N python cast_pieces.py OUT.npz``.

Every rank builds the same test mesh (a torus with point and cell arrays, and the input's
cell order as global cell ids), keeps its own piece of the cells (rank 0 none when asked:
a rank without triangles; with ghosts, its neighbours' boundary cells flagged duplicate;
for "twins", two coincident squares on different ranks; for "pieces", messages sent in
pieces of 4 KiB, shared memory off; for "tight", no room for shared memory; for
"float32", cast in that precision; for "lacking", the last rank's piece without two of the
arrays), casts it
with ``vrc.cast(piece, camera, comm=...)`` and the image reaches rank 0 (``root=0``:
through the ranks' shared memory, as they run on one node) or every rank (``root=None``:
by direct send), and again to the last rank and to rank 0 from one scene; rank 0 writes
the arrays.
"""

import sys

import numpy as np
from mpi4py import MPI

import vtkraycast as vrc

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parent.parent))
from test_mpi import CAMERA, pieces, torus, twin_pieces, twin_planes

comm = MPI.COMM_WORLD
out, mode = sys.argv[1], sys.argv[2]
if mode == "pieces":  # (messages beyond MPI's int counts, as a 4 KiB piece stands for; sent, not shared)
    vrc.parallel.MESSAGE_PIECE = 4096
    vrc.shared_frames.ENABLED = False
if mode == "tight":  # (a shared-memory file system too small for the frames, as a container's may be)
    vrc.shared_frames.HEADROOM = 2**62
if mode == "twins":
    piece = twin_pieces(twin_planes(), comm.size)[comm.rank]
else:
    piece = pieces(torus(), comm.size, empty_first=mode == "empty_first", ghosts=mode == "ghosts")[comm.rank]
if mode == "lacking" and comm.rank == comm.size - 1:  # (its hits carry no Temperature and no Material)
    del piece.point_data["Temperature"], piece.cell_data["Material"]
before = piece.copy(deep=True)
options = {"precision": "float32"} if mode == "float32" else {}
image = vrc.cast(piece, CAMERA, comm=comm, root=0, **options)
scene = vrc.Scene(piece, comm=comm)
everywhere = scene.cast(CAMERA, root=None, arrays=["Depth", "CellId"], **options)
# The image on the last rank, then on rank 0 again, from one scene (the shared segments
# change hands): each equals the first.
last = scene.cast(CAMERA, root=comm.size - 1, **options)
again = scene.cast(CAMERA, root=0, **options)
assert (last is not None) == (comm.rank == comm.size - 1) and (again is not None) == (comm.rank == 0)
if comm.size > 1:
    if comm.rank == comm.size - 1:
        comm.send({name: last[name] for name in last.array_names}, dest=0)
    if comm.rank == 0:
        last = comm.recv(source=comm.size - 1)
if comm.rank == 0:
    for other in (last, again):
        for name in image.array_names:
            np.testing.assert_array_equal(other[name], image[name], err_msg=name)
assert piece == before  # the input is never modified
# The ranks run on one node: the image reached rank 0 through their shared memory unless
# that was turned off.
shared = [frames for frames in vrc.shared_frames._BY_COMM.values() if frames is not None and frames._window]
assert bool(shared) == (vrc.shared_frames.ENABLED and mode != "tight")
assert (image is not None) == (comm.rank == 0) and everywhere is not None
gathered = comm.gather(everywhere["Depth"], root=0)
if comm.rank == 0:
    for depth in gathered:  # every rank received the same image
        np.testing.assert_array_equal(depth, gathered[0])
    np.savez(
        out,
        names=np.array(image.array_names),
        **{name: image[name] for name in image.array_names},
        everywhere_depth=everywhere["Depth"],
        everywhere_cell=everywhere["CellId"],
    )
