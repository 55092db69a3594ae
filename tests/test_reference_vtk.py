"""vtkraycast against VTK's own rendering of the same camera (off-screen OpenGL).

The rasteriser samples every pixel at its centre, as our rays do, so with multisampling
off the covered pixels and the z-buffer depth must match our hit mask and ``Depth``.
``Plotter.get_image_depth`` returns a (ny, nx) array whose row 0 is the *top* of the
picture (negative camera-space z, NaN on the background); our images have row 0 at the
bottom (VTK image order), so our arrays are reshaped to (ny, nx) and flipped vertically.

The camera is set through pyvista's own ``Camera`` properties: pyvista caches the
projection type, so a raw ``SetParallelProjection`` makes ``get_image_depth`` convert a
parallel z-buffer with the perspective formula (depths off by tens of percent).
"""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv
from pyvista import examples

import vtkraycast as vrc

MESHES = {
    "airplane": examples.load_airplane,
    "ant": examples.load_ant,
    "nut": examples.load_nut,
    "sphere": examples.load_sphere,
}
#: (Camera.framing view, parallel)
VIEWS = [("iso", False), ("+z", False), ("xy", True), ("+x", True)]
NX, NY = 200, 150


@pytest.fixture(scope="module", params=list(MESHES))
def named_mesh(request) -> tuple[str, pv.PolyData]:
    return request.param, MESHES[request.param]()


def _theme() -> pv.themes.Theme:
    theme = pv.themes.Theme()
    theme.multi_samples = 0  # one sample per pixel, at its centre: what a ray does
    theme.anti_aliasing = None
    return theme


def clipping_range(mesh: pv.PolyData, cam: vrc.Camera) -> tuple[float, float]:
    """Near/far just around the mesh's bounding box: the z-buffer's 24 bits then resolve
    depth to ~1e-7 relative."""
    b = np.asarray(mesh.bounds, dtype=np.float64).reshape(3, 2)
    corners = np.array(np.meshgrid(*b, indexing="ij")).reshape(3, -1).T
    z = (cam.eye - corners) @ cam.backward
    far = 1.01 * z.max()
    return max(0.99 * z.min(), 1e-3 * far), far


def render(mesh: pv.PolyData, cam: vrc.Camera | None = None, clip: tuple[float, float] | None = None):
    """VTK's depth image (ny, nx; row 0 at the top; NaN background) and the camera read back
    from the plotter *after* rendering (``Camera.from_vtk``). With ``cam=None`` pyvista
    chooses the camera itself (isometric view, reset to the data)."""
    pl = pv.Plotter(off_screen=True, window_size=(NX, NY), theme=_theme())
    try:
        pl.add_mesh(mesh)
        if cam is None:
            pl.view_isometric()
        else:
            c = pl.camera
            c.position = tuple(cam.eye)
            c.focal_point = tuple(cam.look_at)
            c.up = tuple(cam.up)
            if cam.parallel:
                c.enable_parallel_projection()
                c.parallel_scale = cam.h / 2.0
            else:
                c.disable_parallel_projection()
                c.view_angle = cam.view_angle
            c.clipping_range = clip
        pl.show(auto_close=False)
        assert pl.ren_win.GetMultiSamples() == 0
        depth = np.asarray(pl.get_image_depth(reset_camera_clipping_range=False))
        back = vrc.Camera.from_vtk(pl)
    finally:
        pl.close()
    assert depth.shape == (NY, NX)
    return depth, back


def ours(mesh: pv.PolyData, cam: vrc.Camera) -> tuple[np.ndarray, np.ndarray]:
    """Our hit mask and Depth as (ny, nx) pictures with row 0 at the top (flipped)."""
    image = vrc.cast(mesh, cam, arrays=["vtkValidPointMask", "Depth"])
    mask = image["vtkValidPointMask"].reshape(cam.ny, cam.nx)[::-1].astype(bool)
    depth = image["Depth"].reshape(cam.ny, cam.nx)[::-1]
    return mask, depth


def compare(mesh, cam, vtk_depth, label):
    """Mask agreement >= 99% of the pixels and >= 98% of the union of the two coverages
    (so a nearly empty picture cannot pass by agreeing on background); depth relative error
    median < 1e-6 and 99th percentile < 1e-5 where both hit. One z-buffer step with these
    clipping ranges is ~1e-7 relative and the GPU transforms vertices in float32 (a few
    1e-7); larger errors are left to the 1% of pixels where a silhouette edge lands on the
    pixel centre and the two pick different surfaces."""
    mask, depth = ours(mesh, cam)
    covered = np.isfinite(vtk_depth)
    agree = float((mask == covered).mean())
    union = int((mask | covered).sum())
    differ = int((mask != covered).sum())
    both = mask & covered
    rel = np.abs(-vtk_depth[both] - depth[both]) / depth[both]
    print(
        f"\n[vtk {label}] coverage ours {mask.mean():.3f} vtk {covered.mean():.3f}; mask agreement "
        f"{agree:.4%} ({differ} px differ, {differ / union:.3%} of union); depth rel err median "
        f"{np.median(rel):.2e}, p99 {np.percentile(rel, 99):.2e}, max {rel.max():.2e}"
    )
    assert covered.mean() > 0.005, "VTK drew (almost) nothing: the camera is not the one intended"
    assert agree >= 0.99
    assert differ <= 0.02 * union
    assert np.median(rel) < 1e-6
    assert np.percentile(rel, 99) < 1e-5
    assert np.isnan(depth[~mask]).all()
    return agree, rel


@pytest.mark.parametrize("view,parallel", VIEWS, ids=[f"{v}-{'parallel' if p else 'perspective'}" for v, p in VIEWS])
def test_mask_and_depth_match_vtk_rendering(named_mesh, view, parallel):
    """Our camera, copied into VTK: same pixels covered, same depth as the z-buffer."""
    name, mesh = named_mesh
    cam = vrc.Camera.framing(mesh.bounds, view=view, nx=NX, ny=NY, parallel=parallel)
    near, far = clipping_range(mesh, cam)
    vtk_depth, back = render(mesh, cam, (near, far))
    # the camera VTK rendered with is the one we set (nothing reset it on the way)
    np.testing.assert_allclose(back.eye, cam.eye, rtol=0, atol=1e-12 * np.abs(cam.eye).max())
    np.testing.assert_allclose(back.look_at, cam.look_at, rtol=0, atol=1e-12 * np.abs(cam.eye).max())
    np.testing.assert_allclose(back.up, cam.up, rtol=0, atol=1e-12)
    assert (back.nx, back.ny, back.parallel) == (NX, NY, parallel)
    assert back.w == pytest.approx(cam.w, rel=1e-12) and back.h == pytest.approx(cam.h, rel=1e-12)
    assert (back.near, back.far) == pytest.approx((near, far), rel=1e-12)
    compare(mesh, back, vtk_depth, f"{name} {view} {'parallel' if parallel else 'perspective'}")


def test_mask_and_depth_match_a_camera_pyvista_chose(named_mesh):
    """The usual workflow: pyvista places the camera (isometric, reset to the data, its own
    clipping range); Camera.from_vtk(plotter) reproduces that view."""
    name, mesh = named_mesh
    vtk_depth, back = render(mesh)
    assert (back.nx, back.ny) == (NX, NY) and not back.parallel
    compare(mesh, back, vtk_depth, f"{name} pyvista iso")


@pytest.mark.parametrize("parallel", [False, True], ids=["perspective", "parallel"])
def test_picture_orientation_matches_vtk(parallel):
    """A small square seen in the upper-left of the view: VTK's depth image has it in its
    first rows and columns, our output in the last rows (row 0 at the bottom) and first columns."""
    square = pv.Plane(center=(-0.6, 0.4, 0.0), direction=(0, 0, 1), i_size=0.3, j_size=0.3).triangulate()
    cam = vrc.Camera(
        (0, 0, 4),
        (0, 0, 0),
        (0, 1, 0),
        nx=NX,
        ny=NY,
        parallel=parallel,
        **({"h": 2.0} if parallel else {"view_angle": 30.0}),
    )
    vtk_depth, back = render(square, cam, (1.0, 10.0))
    rows, cols = np.nonzero(np.isfinite(vtk_depth))
    assert rows.max() < NY // 2 and cols.max() < NX // 2
    image = vrc.cast(square, back, arrays=["vtkValidPointMask"])
    hit = image["vtkValidPointMask"].reshape(NY, NX).astype(bool)
    out_rows, out_cols = np.nonzero(hit)
    assert out_rows.min() >= NY // 2 and out_cols.max() < NX // 2
    compare(square, back, vtk_depth, f"square orientation {'parallel' if parallel else 'perspective'}")
