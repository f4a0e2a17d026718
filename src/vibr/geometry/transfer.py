"""Depth transfer to views that have none (light fields with a single centre disparity).

The renderer always works from per-source depth, as in the paper. When a scene carries
depth on some views only (the HCI loader puts the ground-truth disparity on the centre
view), every other view gets its own depth by **forward splatting** the surface of the
views with depth into it, with a z-buffer (:mod:`vibr.geometry.visibility`: by default the
triangle mesh through the pixel centres, broken at depth edges, optionally the per-pixel
tangent-plane quads of the target z-buffer), then filling the holes (disocclusions, the strip seen by
this view only) with the joint bilateral filter guided by the view's own image
(:func:`vibr.geometry.depth.fill_depth_holes`). Pixels that stay unknown are NaN.
"""

from __future__ import annotations

import numpy as np

from ..errors import VibrInputError
from ..scene import Scene
from .depth import DEFAULT_EDGE_REL, depth_derivatives, fill_depth_holes
from .visibility import DEFAULT_MAX_QUAD_PX, new_zbuffers, reduce_zbuffers, splat_mesh, splat_zbuffer
from .warp import warp_constants

__all__ = ["ensure_source_depth", "transfer_depth"]


def transfer_depth(scene: Scene, camera, *, from_views=None, mode: str = "mesh",
                   edge_rel: float = DEFAULT_EDGE_REL, mesh_edge_rel: float = 0.02,
                   max_quad_px: int = DEFAULT_MAX_QUAD_PX) -> np.ndarray:
    """Forward-splat the depth of ``from_views`` (default: every view with depth) into
    ``camera``: (H, W) float32 orthogonal depth seen from ``camera``, NaN where nothing
    lands (no hole filling here).

    ``mode="mesh"`` (default) splats the triangle mesh through the pixel centres
    (:func:`vibr.geometry.visibility.splat_mesh`: a continuous surface, broken at depth
    edges where the relative depth spread of a cell exceeds ``mesh_edge_rel``); it is
    exact for light fields (disparity interpolated piecewise linearly). ``mode="quads"``
    splats per-pixel tangent-plane quads like the target z-buffer (slopes from
    :func:`depth_derivatives` with ``edge_rel``); their depth is only first-order
    accurate between pixel centres (the mesh's error is smaller:
    ``test_geometry_transfer.py``).
    """
    srcs = [v for v in scene.views if v.depth is not None] if from_views is None else list(from_views)
    if not srcs:
        raise VibrInputError("no view has depth to transfer", scene.root)
    bufs = new_zbuffers(camera.shape)
    for v in srcs:
        z = np.ascontiguousarray(v.depth, dtype=np.float64)
        M, c = warp_constants(v.camera, camera)
        if mode == "mesh":
            splat_mesh(bufs, M, c, z, mesh_edge_rel, max_quad_px)
        elif mode == "quads":
            zx, zy = depth_derivatives(z, edge_rel)
            splat_zbuffer(bufs, M, c, z, zx, zy, max_quad_px)
        else:
            raise ValueError(f"transfer mode must be 'mesh' or 'quads', got {mode!r}")
    zb = reduce_zbuffers(bufs)
    zb[~np.isfinite(zb)] = np.nan
    return zb.astype(np.float32)


def ensure_source_depth(scene: Scene, *, fill_holes: bool = True, mode: str = "mesh",
                        **fill_kw) -> Scene:
    """Give every view a depth map.

    Views that already have depth are kept as they are. Each view without depth gets the
    depth transferred from all views that have it (:func:`transfer_depth`: mesh or quads, z-buffer,
    nearest surface wins), then, if ``fill_holes``, its holes filled by the joint bilateral
    filter guided by its own image (keyword arguments go to :func:`fill_depth_holes`).
    Pixels still unknown stay NaN. ``scene.meta["depth_transferred"]`` lists the views
    that received transferred depth, and ``scene.meta["depth_filled"]`` maps each to its
    (H, W) bool mask of hole-filled pixels.

    Raises VibrInputError if no view has depth.
    """
    have = [v for v in scene.views if v.depth is not None]
    if len(have) == len(scene.views):
        return scene
    if not have:
        raise VibrInputError("no view has depth: nothing to transfer (estimate depth first)", scene.root)
    views = []
    transferred = []
    filled = {}
    for v in scene.views:
        if v.depth is not None:
            views.append(v)
            continue
        d = transfer_depth(scene, v.camera, from_views=have, mode=mode)
        mask = np.zeros(d.shape, bool)
        if fill_holes:
            d, mask = fill_depth_holes(d, v.image, **fill_kw)
        views.append(v.replace(depth=d))
        transferred.append(v.name)
        filled[v.name] = mask
    meta = dict(scene.meta, depth_transferred=transferred, depth_filled=filled)
    return scene.replace(views=views, meta=meta)
