"""Picking: the triangles under a rectangle of pixels.
===================================================

A cast's ``TriangleId`` (and ``CellId``) image answers "what is under this pixel?" for
every pixel at once, so a rectangular pick is a slice of it: the unique ids in the slice
are the visible triangles in the rectangle. The picked cells are extracted and drawn red
on the grey mesh, seen through the picking camera (with the rectangle) and from the
side (the rest of the mesh see-through), where the pick frustum shows that the triangles
it meets behind the picked ones were not picked.

Checks: every hit point (``Position``) under the rectangle projects back through the
camera model into its own pixel, hence inside the rectangle's frustum; the same pixels
traced as individual rays with ``Scene.intersect`` (directions from the seed's
``pixel_center``) hit exactly the same triangles; the extracted cells are exactly the
unique ids; and VTK's own hardware selector (``vtkHardwareSelector`` on the same
rectangle of the rendered window) picks nearly the same set.

Run: ``python examples/picking.py [--out DIR]``, writes ``picking.png``.
"""

from __future__ import annotations

import argparse
import pathlib

import numpy as np
import pyvista as pv
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkCommonDataModel import vtkDataObject
from vtkmodules.vtkRenderingCore import vtkHardwareSelector

import vtkraycast as vrc

pv.OFF_SCREEN = True


def vtk_selection(plotter: pv.Plotter, i0: int, i1: int, j0: int, j1: int) -> set[int]:
    """Cells VTK's hardware selector sees in pixel columns [i0, i1) and rows [j0, j1) (rows
    counted from the top, display coordinates from the bottom)."""
    ny = plotter.window_size[1]
    selector = vtkHardwareSelector()
    selector.SetRenderer(plotter.renderer)
    selector.SetFieldAssociation(vtkDataObject.FIELD_ASSOCIATION_CELLS)
    selector.SetArea(i0, ny - j1, i1 - 1, ny - 1 - j0)
    selection = selector.Select()
    ids: set[int] = set()
    for k in range(selection.GetNumberOfNodes()):
        ids |= set(vtk_to_numpy(selection.GetNode(k).GetSelectionList()).tolist())
    return ids


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("."), help="output directory")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    mesh = pv.examples.load_nut()
    nx = ny = 400

    # The picking view: a VTK render window, and the same camera for the ray caster.
    plotter = pv.Plotter(off_screen=True, window_size=(nx, ny))
    plotter.disable_anti_aliasing()
    plotter.add_mesh(mesh, color="lightgrey")
    plotter.camera_position = "iso"
    plotter.reset_camera()
    plotter.show(auto_close=False)
    cam = vrc.Camera.from_vtk(plotter)

    scene = vrc.Scene(mesh)
    image = scene.cast(cam, arrays=["TriangleId", "CellId", "Position"])
    # Rows top-first, as on screen.
    tid = image["TriangleId"].reshape(ny, nx)[::-1]
    cid = image["CellId"].reshape(ny, nx)[::-1]
    pos = image["Position"].reshape(ny, nx, 3)[::-1]

    # The rectangle: columns i0..i1-1, rows j0..j1-1 (from the top), across the rim of the hole.
    i0, i1, j0, j1 = 150, 250, 130, 200
    region = tid[j0:j1, i0:i1]
    picked = np.unique(region[region >= 0])
    assert np.array_equal(cid[j0:j1, i0:i1], region), "an all-triangle mesh has CellId == TriangleId"
    assert 20 < picked.size < mesh.n_cells // 2, f"implausible pick of {picked.size} triangles"

    # -- every hit under the rectangle projects back into its own pixel -------------------
    jj, ii = np.nonzero(region >= 0)
    jj, ii = jj + j0, ii + i0
    v = pos[jj, ii] - cam.eye
    z = -(v @ cam.backward)  # distance in front of the eye along the view direction
    assert (z > 0).all()
    x = cam.d * (v @ cam.right) / z  # on the image plane (the seed's P_ij)
    y = cam.d * (v @ cam.up) / z
    column = (x + cam.w / 2) / (cam.w / cam.nx) - 0.5
    row = (cam.h / 2 - y) / (cam.h / cam.ny) - 0.5
    np.testing.assert_allclose(column, ii, atol=1e-6)
    np.testing.assert_allclose(row, jj, atol=1e-6)
    assert (column > i0 - 0.5).all() and (column < i1 - 0.5).all()
    assert (row > j0 - 0.5).all() and (row < j1 - 0.5).all()
    # ... and lies on the triangle it claims to hit.
    corners = np.asarray(mesh.points, dtype=np.float64)[mesh.regular_faces[region[region >= 0]]]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    off_plane = np.abs(np.einsum("nd,nd->n", pos[jj, ii] - corners[:, 0], normals))
    assert off_plane.max() < 1e-9 * mesh.length

    # -- the same pixels as individual rays of the seed's model ---------------------------
    to_world = np.column_stack((cam.right, cam.up, cam.backward))
    jg, ig = np.mgrid[j0:j1, i0:i1]
    directions = np.array([to_world @ cam.pixel_center(i, j) for i, j in zip(ig.ravel(), jg.ravel())])
    hits = scene.intersect(np.broadcast_to(cam.eye, directions.shape), directions)
    assert np.array_equal(hits["triangle_id"].reshape(region.shape), region)

    # -- the highlighted cells ----------------------------------------------------------------
    selected = mesh.extract_cells(picked)
    assert set(selected["vtkOriginalCellIds"].tolist()) == set(picked.tolist())

    # -- VTK's own answer: the hardware selector on the same rectangle ------------------------
    theirs = vtk_selection(plotter, i0, i1, j0, j1)
    plotter.close()
    ours = set(picked.tolist())
    jaccard = len(ours & theirs) / len(ours | theirs)
    # Only slivers cut by the rectangle's border, a pixel centre on one side and a
    # rasterised fragment on the other, may differ.
    assert jaccard > 0.9, f"vtkHardwareSelector agrees on only {jaccard:.2f} of the union"

    # -- the picture: the picking view with the rectangle, and a view from the side -----------
    def through(i: float, j: float, depth: float) -> np.ndarray:
        """The point at ``depth`` on the ray through pixel corner (i, j), j from the top."""
        p = np.array([-cam.w / 2 + cam.w / nx * i, cam.h / 2 - cam.h / ny * j, -cam.d])
        return cam.eye + depth / cam.d * (to_world @ p)

    corners_ij = [(i0, j0), (i1, j0), (i1, j1), (i0, j1)]
    # The rectangle just beyond the near clipping plane: in front of everything.
    rect = np.array([through(i, j, 1.05 * cam.near) for i, j in corners_ij])
    # The pick frustum, from just in front of the hits to behind the whole nut.
    z_lo = 0.9 * float(z.min())
    z_hi = float(-(np.array(mesh.center) - cam.eye) @ cam.backward) + 0.6 * mesh.length
    box = [through(i, j, z_lo) for i, j in corners_ij] + [through(i, j, z_hi) for i, j in corners_ij]
    edges = [(k, (k + 1) % 4) for k in range(4)]  # the near rectangle
    edges += [(4 + k, 4 + (k + 1) % 4) for k in range(4)]  # the far one
    edges += [(k, 4 + k) for k in range(4)]  # and the rays through the corners
    frustum = pv.PolyData(np.array(box), lines=np.array([(2, a, b) for a, b in edges]).ravel())
    rest = mesh.extract_cells(np.setdiff1d(np.arange(mesh.n_cells), picked))  # grey, no z-fighting

    picture = pv.Plotter(off_screen=True, shape=(1, 2), window_size=(800, 400), border=False)
    picture.subplot(0, 0)
    picture.add_mesh(rest, color="lightgrey")
    picture.add_mesh(selected, color="red")
    picture.add_lines(rect[[0, 1, 1, 2, 2, 3, 3, 0]], color="blue", width=3)
    picture.camera.DeepCopy(cam.to_vtk())  # the pick camera (a plain vtkCamera)
    picture.add_text("picking view and rectangle", font_size=10)
    picture.subplot(0, 1)
    picture.add_mesh(rest, color="lightgrey", opacity=0.35)
    picture.add_mesh(selected, color="red")
    picture.add_mesh(frustum, color="blue", line_width=2)
    side = 0.6 * cam.backward + 0.8 * cam.right + 0.3 * cam.up  # to the right of the eye
    picture.camera_position = [np.array(mesh.center) + 3 * mesh.length * side, mesh.center, cam.up]
    picture.reset_camera(bounds=frustum.bounds)
    picture.add_text(
        f"{picked.size} picked triangles and the pick frustum\n(hidden triangles inside it are not picked)",
        font_size=10,
    )
    path = args.out / "picking.png"
    picture.screenshot(path)
    picture.close()
    print(
        f"picked {picked.size} triangles under {(i1 - i0)}x{(j1 - j0)} pixels; "
        f"vtkHardwareSelector agrees on {len(ours & theirs)} of {len(ours | theirs)}; wrote {path}"
    )


if __name__ == "__main__":
    main()
