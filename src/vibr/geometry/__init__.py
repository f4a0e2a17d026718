"""Geometry stage (paper §5, docs/explanation/method.md §2): depth preparation, warps, Jacobians,
visibility → :class:`Samples` (what the renderer consumes).

Main entry points
-----------------
compute_samples(sources, target, *, options=SampleOptions(...), **kw) -> Samples
ensure_source_depth(scene) -> Scene        (depth transfer to views without depth)
planar_proxy(sources, target_camera, depth=None, sigma_z=None) -> Scene

Modules: ``depth`` (radial/disparity → orthogonal depth, slopes, bilateral hole filling),
``warp`` (tau_k and its Jacobians), ``visibility`` (z-buffer splatting, occlusion test),
``transfer``, ``proxy``, ``sampling`` (the stage end to end) (the weights are the renderer's: :mod:`vibr.render.weights`).
"""

from .depth import (
                    depth_derivatives,
                    disparity_to_depth,
                    fill_depth_holes,
                    radial_to_orthogonal,
                    radial_to_orthogonal_derivatives,
)
from .proxy import FALLBACK_MODES, apply_fallback, fallback_depth, planar_proxy, plane_depth, sphere_proxy
from .samples import Samples
from .sampling import SampleOptions, compute_samples, prepare_depth, target_depth
from .transfer import ensure_source_depth, transfer_depth
from .visibility import new_zbuffers, reduce_zbuffers, splat_mesh, splat_zbuffer, visibility_mask
from .warp import warp_constants, warp_points, warp_view

__all__ = [
    "Samples", "compute_samples", "SampleOptions", "prepare_depth", "target_depth", "ensure_source_depth", "transfer_depth",
    "planar_proxy", "plane_depth", "sphere_proxy", "fallback_depth", "apply_fallback", "FALLBACK_MODES", "depth_derivatives", "disparity_to_depth", "fill_depth_holes",
    "radial_to_orthogonal", "radial_to_orthogonal_derivatives", "warp_constants", "warp_points",
    "warp_view", "new_zbuffers", "splat_zbuffer", "splat_mesh", "reduce_zbuffers", "visibility_mask",
]
