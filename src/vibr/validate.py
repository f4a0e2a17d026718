"""Parameter validation at the API boundary (the CLI and Python callers get the same checks).

A NaN weight, an infinite one or zero iterations do not fail inside the solver: they make
it return the initial blend, and ``sigma_s = 0`` or ``step_px = 0`` divide by zero. These
functions refuse such values with a one-line :class:`~vibr.errors.VibrInputError` naming the
parameter, its value and the allowed range, before any work.

* :func:`check_render_params` — called by :func:`vibr.render.methods.method_params` on the
  filled parameter dict (paper names, eq. energy_final): ``alpha``, ``gamma``, ``lam`` ≥ 0,
  ``sigma_s`` > 0 (grey levels), ``sigma_z`` > 0 (scene units) or None, ``scale`` (the
  intensity scale) > 0, all finite; ``max_iter`` ≥ 1, ``n_outer`` ≥ 0, ``tv_iter`` ≥ 1,
  ``ulr_k`` ≥ 1 integers.
* :func:`check_depth_params` — called by :func:`vibr.stereo.estimate_depth` on its keyword
  arguments: ``step_px`` > 0, ``max_planes`` ≥ 2, ``n_planes`` ≥ 2 or None,
  ``median_radius`` ≥ 0 or None, ``refine_iter`` ≥ 0, ``n_neighbours`` ≥ 1, ``radius`` ≥ 1
  or None, ``max_cost``, ``eps``, ``rel_tol``, ``px_tol`` finite and > 0, ``mem_bytes`` > 0.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from .errors import VibrInputError


def _real(name: str, v, *, lo: float | None = None, lo_open: bool = False, hi: float | None = None,
          none_ok: bool = False) -> None:
    if v is None and none_ok:
        return
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise VibrInputError(f"{name} must be a number, got {v!r}")
    x = float(v)
    if not math.isfinite(x):
        raise VibrInputError(f"{name} must be finite, got {x}")
    if lo is not None and (x <= lo if lo_open else x < lo):
        raise VibrInputError(f"{name} must be {'>' if lo_open else '>='} {lo:g}, got {x:g}")
    if hi is not None and x > hi:
        raise VibrInputError(f"{name} must be <= {hi:g}, got {x:g}")


def _int(name: str, v, *, lo: int, none_ok: bool = False) -> None:
    if v is None and none_ok:
        return
    if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(float(v)) or int(v) != v:
        raise VibrInputError(f"{name} must be an integer, got {v!r}")
    if v < lo:
        raise VibrInputError(f"{name} must be >= {lo}, got {int(v)}")


def check_render_params(p: dict) -> dict:
    """Check a filled render-parameter dict (see the module docstring); returns it."""
    for k in ("alpha", "gamma", "lam", "d_floor", "ulr_beta_res", "tol", "grad_consistency",
              "grad_coverage"):
        if k in p:
            _real(k, p[k], lo=0.0)
    for k in ("sigma_s", "scale", "grad_max"):
        if k in p:
            _real("intensity_scale (scale)" if k == "scale" else k, p[k], lo=0.0, lo_open=True)
    if "grid_source_size" in p:
        _real("grid_source_size", p["grid_source_size"], lo=0.0, lo_open=True)
    if "lam_density" in p:
        _real("lam_density", p["lam_density"], lo=0.0, none_ok=True)
    if "tol_outer" in p:
        _real("tol_outer", p["tol_outer"], lo=0.0, none_ok=True)
    if "sigma_z" in p:
        _real("sigma_z", p["sigma_z"], lo=0.0, lo_open=True, none_ok=True)
    if "view_tie" in p:
        _real("view_tie", p["view_tie"], lo=0.0)
    if "z_corr" in p:
        _real("z_corr", p["z_corr"], lo=0.0, hi=1.0, none_ok=True)
    if "hole_threshold" in p:
        _real("hole_threshold", p["hole_threshold"], lo=0.0, hi=1.0)
    for k, lo in (("max_iter", 1), ("n_outer", 0), ("min_iter", 0), ("tv_iter", 1), ("ulr_k", 1), ("grid_factor", 1)):
        if k in p:
            _int("iterations (max_iter)" if k == "max_iter" else k, p[k], lo=lo)
    return p


def check_depth_params(**kw) -> None:
    """Check :func:`vibr.stereo.estimate_depth`'s numeric keyword arguments (module docstring)."""
    checks = {
        "step_px": lambda v: _real("step_px", v, lo=0.0, lo_open=True),
        "max_planes": lambda v: _int("max_planes", v, lo=2),  # one plane is no sweep
        "n_planes": lambda v: _int("n_planes", v, lo=2, none_ok=True),
        "median_radius": lambda v: _int("median_radius", v, lo=0, none_ok=True),
        "refine_iter": lambda v: _int("refine_iter", v, lo=0),
        "coarse_iter": lambda v: _int("coarse_iter", v, lo=0),
        "n_neighbours": lambda v: _int("n_neighbours", v, lo=1),
        "n_partners": lambda v: _int("n_partners", v, lo=1),
        "min_agree": lambda v: _int("min_agree", v, lo=0),
        "radius": lambda v: _int("radius", v, lo=1, none_ok=True),
        "n_best": lambda v: _int("n_best", v, lo=1, none_ok=True),
        "scale": lambda v: _real("scale", v, lo=0.0, lo_open=True, hi=1.0 + 1e-9),
        "sweep_scale": lambda v: _real("sweep_scale", v, lo=0.0, lo_open=True, hi=1.0 + 1e-9),
        "max_cost": lambda v: _real("max_cost", v, lo=0.0, lo_open=True),
        "eps": lambda v: _real("eps", v, lo=0.0, lo_open=True),
        "rel_tol": lambda v: _real("rel_tol", v, lo=0.0, lo_open=True),
        "px_tol": lambda v: _real("px_tol", v, lo=0.0, lo_open=True),
        "mem_bytes": lambda v: _real("mem_bytes", v, lo=0.0, lo_open=True),
        "coverage_gain": lambda v: _real("coverage_gain", v, lo=0.0) if v is not None else None,
    }
    for k, v in kw.items():
        if k in checks:
            checks[k](v)
    dr = kw.get("depth_range")
    if dr is not None:
        try:
            near, far = (float(x) for x in dr)
        except (TypeError, ValueError):
            raise VibrInputError(f"depth_range must be two numbers (near, far), got {dr!r}") from None
        if not (math.isfinite(near) and math.isfinite(far) and 0 < near < far):
            raise VibrInputError(f"depth_range must be finite with 0 < near < far, got ({near:g}, {far:g})")


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


def available_memory() -> int | None:
    """Bytes vibr may use: ``$VIBR_MEMORY_LIMIT_GB`` when set, else the system's
    MemAvailable (Linux), else None (no check)."""
    import os

    env = os.environ.get("VIBR_MEMORY_LIMIT_GB")
    if env:
        try:
            return int(float(env) * 2**30)
        except ValueError:
            raise VibrInputError(f"VIBR_MEMORY_LIMIT_GB must be a number of GB, got {env!r}") from None
    try:
        with open("/proc/meminfo") as f:
            for ln in f:
                if ln.startswith("MemAvailable:"):
                    return int(ln.split()[1]) * 1024
    except OSError:
        pass
    return None


def check_memory(need: float, what: str, way_out: str, source=None) -> None:
    """Refuse (one line) when ``need`` bytes exceed :func:`available_memory`."""
    avail = available_memory()
    if avail is not None and need > avail:
        raise VibrInputError(f"{what} needs about {need / 2**30:.1f} GB of memory, "
                             f"{avail / 2**30:.1f} GB available: {way_out}", source)


def sample_bytes(keep=()) -> int:
    """Bytes of one :class:`vibr.geometry.Samples` entry, from its arrays' dtypes: the
    optional fields (:data:`vibr.geometry.sampling.OPTIONAL_FIELDS`) only when in ``keep``."""
    from .geometry.samples import Samples
    from .geometry.sampling import OPTIONAL_FIELDS

    e = Samples.concatenate([], (1, 1))
    return sum(int(a.dtype.itemsize * np.prod(a.shape[1:], dtype=np.int64))
               for name, a in vars(e).items()
               if isinstance(a, np.ndarray) and (name not in OPTIONAL_FIELDS or name in keep))


def render_memory(source_shapes, target_shape, keep=()) -> int:
    """Estimated peak bytes of a render of ``target_shape`` (H, W) from sources of the
    given shapes: samples (at most one per source pixel landing in the target, ×1.5 for
    the geometry's temporaries; with the optional fields ``keep``, :func:`sample_bytes`)
    plus the per-pixel buffers of the solve and the geometry (docs/ERRORS.md)."""
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
