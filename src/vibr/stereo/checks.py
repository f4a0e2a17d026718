"""Checks of :func:`vibr.stereo.estimate_depth`'s numeric options, before any work.

``step_px`` > 0, ``max_planes`` >= 2, ``n_planes`` >= 2 or None, ``median_radius`` >= 0 or
None, ``refine_iter`` >= 0, ``n_neighbours`` >= 1, ``radius`` >= 1 or None, ``max_cost``,
``eps``, ``rel_tol``, ``px_tol`` finite and > 0, ``mem_bytes`` > 0: a zero step or plane
count would divide by zero inside the sweep rather than fail with a message.
"""

from __future__ import annotations

import math

from ..errors import VibrInputError, check_int, check_real


def check_depth_params(**kw) -> None:
    """Check :func:`vibr.stereo.estimate_depth`'s numeric keyword arguments (module docstring)."""
    checks = {
        "step_px": lambda v: check_real("step_px", v, lo=0.0, lo_open=True),
        "max_planes": lambda v: check_int("max_planes", v, lo=2),  # one plane is no sweep
        "n_planes": lambda v: check_int("n_planes", v, lo=2, none_ok=True),
        "median_radius": lambda v: check_int("median_radius", v, lo=0, none_ok=True),
        "refine_iter": lambda v: check_int("refine_iter", v, lo=0),
        "coarse_iter": lambda v: check_int("coarse_iter", v, lo=0),
        "n_neighbours": lambda v: check_int("n_neighbours", v, lo=1),
        "n_partners": lambda v: check_int("n_partners", v, lo=1),
        "min_agree": lambda v: check_int("min_agree", v, lo=0),
        "radius": lambda v: check_int("radius", v, lo=1, none_ok=True),
        "n_best": lambda v: check_int("n_best", v, lo=1, none_ok=True),
        "scale": lambda v: check_real("scale", v, lo=0.0, lo_open=True, hi=1.0 + 1e-9),
        "sweep_scale": lambda v: check_real("sweep_scale", v, lo=0.0, lo_open=True, hi=1.0 + 1e-9),
        "max_cost": lambda v: check_real("max_cost", v, lo=0.0, lo_open=True),
        "eps": lambda v: check_real("eps", v, lo=0.0, lo_open=True),
        "rel_tol": lambda v: check_real("rel_tol", v, lo=0.0, lo_open=True),
        "px_tol": lambda v: check_real("px_tol", v, lo=0.0, lo_open=True),
        "mem_bytes": lambda v: check_real("mem_bytes", v, lo=0.0, lo_open=True),
        "consensus_tol": lambda v: check_real("consensus_tol", v, lo=0.0),
        "coverage_gain": lambda v: check_real("coverage_gain", v, lo=0.0) if v is not None else None,
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

