"""The four rendering methods and their default parameters.

=========  ==========================================================================
ulr        Unstructured Lumigraph Rendering (Buehler et al. 2001): direct blend of the
           k best views per pixel with angle and resolution penalties; no solve.
savsr      Wanner & Goldluecke 2012: variational, W = deformation weight only
           (omega = 1/sigma_s², no geometric uncertainty), gamma = 0, one solve.
bvs        Pujades et al. 2014: variational with the Bayesian weights of docs/METHOD.md §3
           (omega re-estimated from u in outer iterations), gamma = 0.
gradient   Nieto et al. 2016 (this paper, the default): bvs + the gradient term, gamma > 0.
=========  ==========================================================================

Parameter defaults (paper names; intensities on the scale ``scale`` = 255, docs/METHOD.md §9):

* ``alpha = 1.0`` colour-term weight (eq. energy_final; the paper's light-field setting).
* ``gamma = 1.0`` gradient-term weight for ``gradient`` (eq. energy_final; the paper tests
  0..3); forced to 0 for savsr and bvs.
* ``lam = 0.1`` TV weight (eq. energy_final; the paper's light-field value, for [0, 255]
  intensities: a 1-grey-level step costs 0.1 per pixel of edge).
* ``sigma_s = 1.0`` sensor noise, grey levels of 255 (docs/METHOD.md §3, the authors' value).
* ``sigma_z = None`` depth std. dev., scene units: the samples' own (the geometry stage's
  per-view value, default 1 % of the median depth).
* ``psf = "bilinear"`` the image-formation model ``v_k = B_k u`` (paper §4.1 eq. normal,
  docs/METHOD.md §4): ``"bilinear"`` (unit-square transformed PSF: the bilinear coefficients of
  ``tau_k(x_m)``) or ``"footprint"`` (``B_kmp = area(P_km ∩ p) / area(P_km)``, the source
  pixel's parallelogram ``P_km = tau_k(x_m) + ∂tau_k/∂x_m·[-½, ½]²``, paper fig.
  discretization right; footprints larger than a target pixel shrunk per axis to 1 px, see
  :class:`vibr.render.operators.Splat`). Worth it when the sources are finer than the
  target. ulr ignores it.
"""

from __future__ import annotations

METHODS = ("ulr", "savsr", "bvs", "gradient")

#: Defaults shared by the variational methods; see the module docstring for the reasons.
DEFAULTS = dict(
    alpha=1.0, gamma=1.0, lam=0.1, sigma_s=1.0, sigma_z=None, scale=255.0,
    n_outer=2, max_iter=60, tol=1e-4, min_iter=3, tv_iter=2, coupled_tv=True,
    grad_weighting="visibility", grad_max=64.0, precond=False, d_floor=0.05,
    hole_threshold=0.5, normalise=True, ulr_k=4, ulr_beta_res=0.1, psf="bilinear",
)

#: Per-method overrides.
METHOD_OVERRIDES = {
    "ulr": dict(gamma=0.0, n_outer=0),
    "savsr": dict(gamma=0.0, n_outer=1),
    "bvs": dict(gamma=0.0),
    "gradient": dict(),
}

GRAD_WEIGHTINGS = ("visibility", "none", "W")

#: Image-formation models (:class:`vibr.render.operators.Splat`).
PSFS = ("bilinear", "footprint")


def method_params(method: str, **params) -> dict:
    """Defaults for ``method`` updated with ``params`` (None values keep the default;
    gamma is forced to 0 for ulr, savsr and bvs)."""
    from ..errors import VibrInputError

    if method not in METHODS:
        raise VibrInputError(f"unknown method {method!r} (choose from {', '.join(METHODS)})")
    unknown = set(params) - set(DEFAULTS)
    if unknown:
        raise TypeError(f"unknown render parameter(s): {', '.join(sorted(unknown))}")
    p = dict(DEFAULTS)
    p.update(METHOD_OVERRIDES[method])
    for k, v in params.items():
        if v is not None or k == "sigma_z":
            if k == "gamma" and method != "gradient":
                continue
            p[k] = v
    if p["psf"] not in PSFS:
        raise VibrInputError(f"psf must be one of {PSFS}, got {p['psf']!r}")
    if p["grad_weighting"] not in GRAD_WEIGHTINGS:
        raise VibrInputError(f"grad_weighting must be one of {GRAD_WEIGHTINGS}, got {p['grad_weighting']!r}")
    return p
