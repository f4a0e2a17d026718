"""Checks of the render's parameters and memory, at the API boundary, before any work.

A NaN weight, an infinite one or zero iterations do not fail inside the solver: they make
it return the initial blend, and ``sigma_s = 0`` divides by zero. :func:`check_render_params`
(called by :func:`vibr.render.methods.method_params` on the filled parameters, paper names,
eq. energy_final) refuses such values with a one-line :class:`~vibr.errors.VibrInputError`
naming the parameter, its value and the allowed range: ``alpha``, ``gamma``, ``lam`` ≥ 0,
``sigma_s`` > 0 (grey levels), ``sigma_z`` > 0 (scene units) or None, ``scale`` (the
intensity scale) > 0, all finite; ``max_iter`` ≥ 1, ``n_outer`` ≥ 0, ``tv_iter`` ≥ 1,
``ulr_k`` ≥ 1 integers. :func:`check_render_memory` refuses a render whose estimated peak
(:func:`render_memory`) exceeds the memory available.
"""

from __future__ import annotations

import numpy as np

from .._runtime.memory import check_memory
from ..errors import check_int, check_real
from ..geometry.samples import Samples
from ..geometry.sampling import OPTIONAL_FIELDS


def check_render_params(p: dict) -> dict:
    """Check a filled render-parameter dict (see the module docstring); returns it."""
    for k in ("alpha", "gamma", "lam", "d_floor", "ulr_beta_res", "tol", "grad_consistency",
              "grad_coverage"):
        if k in p:
            check_real(k, p[k], lo=0.0)
    for k in ("sigma_s", "scale", "grad_max"):
        if k in p:
            check_real("intensity_scale (scale)" if k == "scale" else k, p[k], lo=0.0, lo_open=True)
    if "grid_source_size" in p:
        check_real("grid_source_size", p["grid_source_size"], lo=0.0, lo_open=True)
    if "lam_density" in p:
        check_real("lam_density", p["lam_density"], lo=0.0, none_ok=True)
    if "tol_outer" in p:
        check_real("tol_outer", p["tol_outer"], lo=0.0, none_ok=True)
    if "sigma_z" in p:
        check_real("sigma_z", p["sigma_z"], lo=0.0, lo_open=True, none_ok=True)
    if "view_tie" in p:
        check_real("view_tie", p["view_tie"], lo=0.0)
    if "z_corr" in p:
        check_real("z_corr", p["z_corr"], lo=0.0, hi=1.0, none_ok=True)
    if "hole_threshold" in p:
        check_real("hole_threshold", p["hole_threshold"], lo=0.0, hi=1.0)
    for k, lo in (("max_iter", 1), ("n_outer", 0), ("min_iter", 0), ("tv_iter", 1), ("ulr_k", 1), ("grid_factor", 1)):
        if k in p:
            check_int("iterations (max_iter)" if k == "max_iter" else k, p[k], lo=lo)
    return p


# ----------------------------------------------------------------------------- memory
#: Estimated bytes per target pixel of a variational render besides its samples: the
#: stencils (9 + 9 planes), right-hand sides (3 + 6), the image and the solver's buffers
#: (≈ 18 planes), the TV duals (3 × 6 planes), float64 accumulations; float32 unless noted.
RENDER_BYTES_PER_TARGET_PIXEL = 400
#: Geometry buffers per target pixel and source view (z-buffer and visibility, float64).
GEOMETRY_BYTES_PER_TARGET_PIXEL_VIEW = 16
#: A render on a coarser grid enlarged to the target (RenderResult.enlarged): per target
#: pixel, the image and its start twice in float64 (3 channels) and once in float32, σ, coverage.
ENLARGE_BYTES_PER_TARGET_PIXEL = 2 * (3 * 8 * 2 + 3 * 4) + 4 + 1


def sample_bytes(keep=()) -> int:
    """Bytes of one :class:`vibr.geometry.Samples` entry, from its arrays' dtypes: the
    optional fields (:data:`vibr.geometry.sampling.OPTIONAL_FIELDS`) only when in ``keep``."""

    e = Samples.concatenate([], (1, 1))
    return sum(int(a.dtype.itemsize * np.prod(a.shape[1:], dtype=np.int64))
               for name, a in vars(e).items()
               if isinstance(a, np.ndarray) and (name not in OPTIONAL_FIELDS or name in keep))


def render_memory(source_shapes, target_shape, keep=()) -> int:
    """Estimated peak bytes of a render of ``target_shape`` (H, W) from sources of the
    given shapes: samples (at most one per source pixel landing in the target, ×1.5 for
    the geometry's temporaries; with the optional fields ``keep``, :func:`sample_bytes`)
    plus the per-pixel buffers of the solve and the geometry (docs/reference/errors-and-limits.md)."""
    th, tw = target_shape
    tpx = float(th) * float(tw)
    n_samples = sum(min(float(h) * float(w), 4.0 * tpx) for h, w in source_shapes)
    return int(1.5 * n_samples * sample_bytes(keep) + tpx * RENDER_BYTES_PER_TARGET_PIXEL
               + tpx * len(source_shapes) * GEOMETRY_BYTES_PER_TARGET_PIXEL_VIEW)


def check_render_memory(source_shapes, target_shape, source=None, keep=(), way_out=None,
                        output_shape=None) -> None:
    """Refuse a render whose :func:`render_memory` exceeds the available memory; with
    ``output_shape`` (a render on a coarser grid enlarged to it) that enlargement counted too,
    and named."""
    need = render_memory(source_shapes, target_shape, keep)
    if output_shape is not None and tuple(output_shape) != tuple(target_shape):
        need += int(float(output_shape[0]) * float(output_shape[1]) * ENLARGE_BYTES_PER_TARGET_PIXEL)
        target_shape = output_shape
    th, tw = target_shape
    check_memory(need,
                 f"rendering {tw}x{th} from {len(source_shapes)} views",
                 way_out or "render at a lower resolution (--scale 0.5, or a smaller camera) or from "
                 "fewer views (--views K)", source)
