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
  arguments: ``step_px`` > 0, ``max_planes`` ≥ 1, ``n_planes`` ≥ 2 or None,
  ``median_radius`` ≥ 0 or None, ``refine_iter`` ≥ 0, ``n_neighbours`` ≥ 1, ``radius`` ≥ 1
  or None, ``max_cost``, ``eps``, ``rel_tol``, ``px_tol`` finite and > 0, ``mem_bytes`` > 0.
"""

from __future__ import annotations

import math
import numbers

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
    for k in ("alpha", "gamma", "lam", "d_floor", "ulr_beta_res", "tol"):
        if k in p:
            _real(k, p[k], lo=0.0)
    for k in ("sigma_s", "scale", "grad_max"):
        if k in p:
            _real("intensity_scale (scale)" if k == "scale" else k, p[k], lo=0.0, lo_open=True)
    if "sigma_z" in p:
        _real("sigma_z", p["sigma_z"], lo=0.0, lo_open=True, none_ok=True)
    if "hole_threshold" in p:
        _real("hole_threshold", p["hole_threshold"], lo=0.0, hi=1.0)
    for k, lo in (("max_iter", 1), ("n_outer", 0), ("min_iter", 0), ("tv_iter", 1), ("ulr_k", 1)):
        if k in p:
            _int("iterations (max_iter)" if k == "max_iter" else k, p[k], lo=lo)
    return p


def check_depth_params(**kw) -> None:
    """Check :func:`vibr.stereo.estimate_depth`'s numeric keyword arguments (module docstring)."""
    checks = {
        "step_px": lambda v: _real("step_px", v, lo=0.0, lo_open=True),
        "max_planes": lambda v: _int("max_planes", v, lo=1),
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
