"""Per-sample weights of the data term (paper §5.6, docs/METHOD.md §3; after Pujades et al. 2014).

``W_km = pi_km · omega_km · |det ∂tau_k/∂x_m|⁻¹`` (``pi_km`` the optional view prior,
:func:`view_prior`, 1 without; the formula in ONE function, :func:`sample_weight`) with the
geometric weight

    omega_km = 1 / (sigma_s² + sigma_z,k² · (∂tau_k/∂z · ∇u(tau_k(x_m)))²)

``sigma_s`` is the sensor noise and ``∇u`` the gradient of the current estimate's luminance
sampled at the sample's landing point. **Intensity scale**: ``sigma_s`` and the gradient
are expressed on the scale ``scale`` (default 255: sigma_s = 1 means one grey level of an
8-bit image, the authors' setting), while images are [0, 1] float32 in memory; the
conversion happens here, once. The returned weights are therefore in ``scale``⁻² units.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..geometry.samples import Samples

__all__ = ["luminance", "luminance_gradient", "deformation_weight", "geometric_weights", "ROBUST_LOSSES",
           "robust_factor", "sample_weight", "view_prior"]

_LUMA = np.array([0.299, 0.587, 0.114], np.float32)  # Rec. 601


def luminance(u) -> np.ndarray:
    """(H, W, 3) → (H, W) Rec. 601 luminance (float32)."""
    u = np.asarray(u, np.float32)
    if u.ndim == 2:
        return u
    # per channel, so that a (H, W, 3) view of a planar (3, H, W) image reads whole planes
    return _LUMA[0] * u[..., 0] + _LUMA[1] * u[..., 1] + _LUMA[2] * u[..., 2]


def luminance_gradient(u) -> np.ndarray:
    """Central-difference gradient of the luminance: (H, W, 2) float32, (d/dx, d/dy) per
    target pixel (replicated border)."""
    from .operators import grad_central

    lum = np.ascontiguousarray(luminance(u))[None]  # planar (1, H, W)
    return np.ascontiguousarray(grad_central(lum)[0].transpose(1, 2, 0))


def deformation_weight(samples: Samples, cap: float | None = None) -> np.ndarray:
    """``1/|det ∂tau/∂x|`` (N,) float64, optionally capped (the authors cap it at 1 for
    unstructured scenes, so a source closer than the target does not dominate)."""
    w = np.asarray(samples.inv_det, np.float64)
    w = np.where(np.isfinite(w), w, 0.0)
    return np.minimum(w, cap) if cap is not None else w


@njit(cache=True)
def sample_weight(inv_det, cap, sz, dtau_x, dtau_y, gx, gy, sigma_s2, prior):
    """The per-sample data weight (the ONE place of the formula, docs/METHOD.md §3):

    ``W = prior · min(1/|det|, cap) / (sigma_s² + (sz · (∂tau/∂z · ∇u))²)``

    ``inv_det`` = 1/|det ∂tau/∂x|, ``sz`` = sigma_z (scene units), ``(dtau_x, dtau_y)`` =
    ∂tau/∂z, ``(gx, gy)`` = ∇u at tau (scale units/px), ``prior`` the sample's view prior
    (:func:`view_prior`, 1 without). Non-finite ``inv_det`` or ``sz`` count as 0."""
    if not math.isfinite(sz):
        sz = 0.0
    d = inv_det
    if not math.isfinite(d):
        d = 0.0
    d = min(d, cap)
    p = sz * (dtau_x * gx + dtau_y * gy)
    return prior * d / (sigma_s2 + p * p)


@njit(parallel=True, cache=True)
def _weights_kernel(x0, y0, fx, fy, g, dtau, sz, sz_scalar, inv_det, cap, sigma_s2, prior, out):
    """out_m = :func:`sample_weight` with ∇u bilinearly interpolated from ``g`` (H, W, 2);
    ``prior`` (N,) or empty (= 1)."""
    n = x0.shape[0]
    use_map = sz.shape[0] == n
    use_prior = prior.shape[0] == n
    for i in prange(n):
        a = np.float64(fx[i])
        b = np.float64(fy[i])
        x = x0[i]
        y = y0[i]
        gx = ((1 - a) * (1 - b) * g[y, x, 0] + a * (1 - b) * g[y, x + 1, 0]
              + (1 - a) * b * g[y + 1, x, 0] + a * b * g[y + 1, x + 1, 0])
        gy = ((1 - a) * (1 - b) * g[y, x, 1] + a * (1 - b) * g[y, x + 1, 1]
              + (1 - a) * b * g[y + 1, x, 1] + a * b * g[y + 1, x + 1, 1])
        s = sz[i] if use_map else sz_scalar
        pr = np.float64(prior[i]) if use_prior else 1.0
        out[i] = sample_weight(np.float64(inv_det[i]), cap, np.float64(s), np.float64(dtau[i, 0]),
                               np.float64(dtau[i, 1]), gx, gy, sigma_s2, pr)


def geometric_weights(samples: Samples, u, sigma_s: float = 1.0, sigma_z=None, *,
                      scale: float = 255.0, grad_max: float | None = 64.0,
                      inv_det_cap: float | None = None, splat=None, dtype=np.float64,
                      prior=None) -> np.ndarray:
    """Data-term weights ``W_km`` (docs/METHOD.md §3), (N,) ``dtype`` (float64 by default).

    Parameters
    ----------
    samples : Samples
    u : (H, W, 3) float32 in [0, 1] or None
        Current estimate; None (or ``sigma_z`` = 0) gives ``omega = 1/sigma_s²`` (the SAVSR
        weight: deformation only).
    sigma_s : float
        Sensor noise standard deviation, in intensity units of ``scale`` (default 1 grey
        level of 255).
    sigma_z : float, (N,) array or None
        Depth standard deviation in scene units; None uses ``samples.sigma_z`` (NaN → 0).
    scale : float
        The intensity scale ``sigma_s`` and ``grad_max`` refer to (images are [0, 1]).
    grad_max : float or None
        Clamp of the luminance gradient magnitude, ``scale`` units per pixel (the authors
        clamp it too): at strong edges every view is unreliable, and the clamp keeps the
        weights from collapsing so the data term still dominates the TV prior there.
    inv_det_cap : float or None
        Cap of the deformation weight (see :func:`deformation_weight`).
    splat : vibr.render.operators.Splat, optional
        Precomputed bilinear interpolation of ``samples.xy`` (saves its set-up).
    prior : (N,) array, optional
        Per-sample view prior (:func:`view_prior`), a factor of the weight.
    """
    sz = samples.sigma_z if sigma_z is None else sigma_z
    sz = np.asarray(sz, np.float64)
    base = 1.0 / (sigma_s ** 2)
    if u is None or not np.any(np.nan_to_num(sz) > 0):
        w = deformation_weight(samples, inv_det_cap) * base
        if prior is not None:
            w *= prior
        return w.astype(dtype, copy=False)
    from .operators import Splat

    g = luminance_gradient(u) * np.float32(scale)
    if grad_max is not None:
        mag = np.sqrt((g ** 2).sum(-1, keepdims=True))
        g *= np.minimum(1.0, grad_max / np.maximum(mag, 1e-12)).astype(np.float32)
    sp = splat if splat is not None else Splat(samples.xy, samples.target_shape)
    out = np.empty(len(samples), dtype)
    sz_map = sz if sz.ndim == 1 else np.zeros(0)
    sz_scalar = float(sz) if sz.ndim == 0 else 0.0
    _weights_kernel(sp.x0, sp.y0, sp.fx, sp.fy, np.ascontiguousarray(g), np.asarray(samples.dtau_dz),
                    sz_map, sz_scalar, np.asarray(samples.inv_det),
                    np.inf if inv_det_cap is None else float(inv_det_cap), float(sigma_s) ** 2,
                    np.zeros(0, np.float32) if prior is None else np.asarray(prior), out)
    return out


#: Robust data terms (issue 22): ``"none"`` (least squares) or ``"cauchy"`` (IRLS).
ROBUST_LOSSES = ("none", "cauchy")


def robust_factor(samples: Samples, u, splat, c: float = 3.0, loss: str = "cauchy") -> np.ndarray:
    """IRLS factor of the data term's weights for a robust loss (N,) float32.

    With the residual of each sample against the current estimate,
    ``r_m = ‖v_m − (B u)(m)‖ / √3`` (RGB root mean square), and the robust scale
    ``s = c · 1.4826 · median(r)`` (``c`` times the median absolute deviation's estimate of
    the residuals' standard deviation), the Cauchy (Lorentzian) loss
    ``ρ(r) = ½ s² log(1 + (r/s)²)`` gives the reweighting factor
    ``ρ'(r)/r = 1 / (1 + (r/s)²)``: samples that disagree with the others (occluded or
    mismatched ones, the speckles of issue 22) lose their weight in the next outer pass,
    the inliers keep theirs (Holland & Welsch 1977, "Robust regression using iteratively
    reweighted least-squares"). ``loss="none"`` gives ones.
    """
    if loss not in ROBUST_LOSSES:
        raise ValueError(f"robust must be one of {ROBUST_LOSSES}, got {loss!r}")
    n = len(samples)
    if loss == "none" or u is None or n == 0:
        return np.ones(n, np.float32)
    bu = splat.apply(np.ascontiguousarray(u, dtype=np.float32))
    r2 = ((bu - samples.colour) ** 2).sum(1) / 3.0
    s = c * 1.4826 * float(np.sqrt(np.median(r2)))
    s2 = max(s * s, 1e-12)
    return (1.0 / (1.0 + r2 / s2)).astype(np.float32)


def view_prior(samples: Samples, source_centres, target_centre, k: int = 4, beta_res: float = 0.1,
               eps: float = 1e-6) -> np.ndarray:
    """What ULR knows, as a per-sample factor of the data weight (N,) float32 in [0, 1].

    Buehler et al.'s penalty of each sample (:func:`vibr.render.ulr.ulr_penalty`: the angle
    between the target's and the source's rays to the sample's 3D point, plus ``beta_res``
    times the source's relative excess distance, a resolution penalty), averaged per view
    and target pixel (bilinear splat); per pixel the ``k`` best views get Buehler's weight
    ``(1 − p/p_(k+1)) / p`` (:func:`vibr.render.ulr.ulr_view_weights`), divided by the
    pixel's largest, so the best view has 1, the (k+1)-th and worse 0. A sample reads its
    view's map bilinearly at its landing point. Computed once per render (it does not
    depend on u)."""
    from .operators import Splat
    from .ulr import ulr_penalty, ulr_view_weights

    H, W = samples.target_shape
    n = len(samples)
    pen = ulr_penalty(samples, source_centres, target_centre, beta_res)
    V = len(np.asarray(source_centres))
    pview = np.full((V, H, W), np.inf)
    splats = []
    for v in range(V):
        sel = np.flatnonzero(samples.view == v)
        sp = Splat(samples.xy[sel], (H, W)) if sel.size else None
        splats.append((sel, sp))
        if sp is None:
            continue
        s = sp.adjoint(np.stack([pen[sel], np.ones(sel.size)], 1))
        ok = s[..., 1] > 1e-3
        pview[v][ok] = s[ok, 0] / s[ok, 1]
    wt = ulr_view_weights(pview, k, eps)
    wt /= np.maximum(wt.max(0), 1e-300)[None]
    out = np.zeros(n, np.float32)
    for v, (sel, sp) in enumerate(splats):
        if sp is not None:
            out[sel] = np.clip(sp.apply(wt[v]), 0.0, 1.0)
    return out
