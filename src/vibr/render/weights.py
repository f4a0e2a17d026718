"""Per-sample weights of the data term (paper §5.6, docs/explanation/method.md §3; after Pujades et al. 2014).

``W_km = pi_km · omega_km · |det ∂tau_k/∂x_m|⁻¹`` (``pi_km`` the optional view prior,
:func:`view_prior`, 1 without: a per-sample factor like the robust one) with the geometric
weight

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

from ..geometry.gradient import _grad_row
from ..geometry.samples import Samples
from .operators import Splat, _row_coef, _sum_in_order, accumulate_bucket, grad_central, sample_at
from .solver import median

__all__ = ["luminance", "luminance_gradient", "deformation_weight", "geometric_weights", "ROBUST_LOSSES",
           "robust_factor", "sample_weight", "weighted_normal", "coverage_blend", "view_prior", "ulr_pixels",
           "gradient_consistency", "misregistration", "shared_error_beta"]

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

    lum = np.ascontiguousarray(luminance(u))[None]  # planar (1, H, W)
    return np.ascontiguousarray(grad_central(lum)[0].transpose(1, 2, 0))


def deformation_weight(samples: Samples, cap: float | None = None) -> np.ndarray:
    """``1/|det ∂tau/∂x|`` (N,) float64, optionally capped (the authors cap it at 1 for
    unstructured scenes, so a source closer than the target does not dominate)."""
    w = np.asarray(samples.inv_det, np.float64)
    w = np.where(np.isfinite(w), w, 0.0)
    return np.minimum(w, cap) if cap is not None else w


@njit(cache=True)
def grad_at(g, x, y, a, b):
    """∇u at a sample's landing point: ``g`` (H, W, 2) bilinearly interpolated in the cell
    (x, y) with fractions (a, b) (float64)."""
    gx = ((1 - a) * (1 - b) * g[y, x, 0] + a * (1 - b) * g[y, x + 1, 0]
          + (1 - a) * b * g[y + 1, x, 0] + a * b * g[y + 1, x + 1, 0])
    gy = ((1 - a) * (1 - b) * g[y, x, 1] + a * (1 - b) * g[y, x + 1, 1]
          + (1 - a) * b * g[y + 1, x, 1] + a * b * g[y + 1, x + 1, 1])
    return gx, gy


@njit(cache=True)
def misregistration(sz, dtau_x, dtau_y, gx, gy):
    """``a = sigma_z · ∂tau/∂z · ∇u(tau(x_m))``, one sample, float64: the colour error (in
    ``scale`` units) one standard deviation of depth error makes, signed; a non-finite
    ``sz`` counts as 0."""
    s = sz
    if not math.isfinite(s):
        s = 0.0
    return s * (dtau_x * gx + dtau_y * gy)


@njit(cache=True)
def sample_weight(inv_det, cap, sz, dtau_x, dtau_y, gx, gy, sigma_s2, z_corr=0.0, beta=0.0):
    """THE per-sample weight ``W_km`` (docs/explanation/method.md §3), one sample, float64:
    ``min(1/|det|, cap) / (sigma_s² + a²)``, ``a`` the :func:`misregistration`; non-finite
    ``inv_det`` counts as 0. With depth errors shared by the views (``z_corr`` ρ > 0,
    docs/explanation/renderer.md, "Depth errors the views share"):
    ``min(1/|det|, cap) / (sigma_s² + (1 − ρ) a²) · max(0, 1 − a β)``, ``β`` the landing
    point's :func:`shared_error_beta`. Every kernel that weights samples calls this function
    (:func:`geometric_weights` here, the fused assembly of :func:`weighted_normal`)."""
    d = inv_det
    if not math.isfinite(d):
        d = 0.0
    d = min(d, cap)
    p = misregistration(sz, dtau_x, dtau_y, gx, gy)
    if z_corr > 0:
        return d / (sigma_s2 + (1.0 - z_corr) * p * p) * max(0.0, 1.0 - p * beta)
    return d / (sigma_s2 + p * p)


@njit(cache=True)
def _beta_at(beta, bx0, y, fx, fy, coef, use_coef, i):
    """``(B β)_i``: the shared-error map ``beta`` (H, W) at sample i, whose row of B is the
    2×2 block at (bx0[i], y)."""
    w00, w01, w10, w11 = _row_coef(fx, fy, coef, use_coef, i)
    x = bx0[i]
    return w00 * beta[y, x] + w01 * beta[y, x + 1] + w10 * beta[y + 1, x] + w11 * beta[y + 1, x + 1]


@njit(parallel=True, cache=True)
def _weights_kernel(x0, y0, fx, fy, g, dtau, sz, sz_scalar, inv_det, cap, sigma_s2, z_corr, beta, bx0, by0, coef,
                    out):
    """out_m = :func:`sample_weight` with ∇u bilinearly interpolated from ``g`` (H, W, 2)
    (and β from ``beta`` (H, W) through B's rows ``bx0, by0, coef`` when ``z_corr`` > 0)."""
    n = x0.shape[0]
    use_map = sz.shape[0] == n
    use_coef = coef.shape[0] == n and n > 0
    for i in prange(n):
        gx, gy = grad_at(g, x0[i], y0[i], np.float64(fx[i]), np.float64(fy[i]))
        s = sz[i] if use_map else sz_scalar
        bm = _beta_at(beta, bx0, by0[i], fx, fy, coef, use_coef, i) if z_corr > 0 else 0.0
        out[i] = sample_weight(np.float64(inv_det[i]), cap, np.float64(s), np.float64(dtau[i, 0]),
                               np.float64(dtau[i, 1]), gx, gy, sigma_s2, z_corr, bm)


@njit(parallel=True, cache=True)
def _shared_error_kernel(x0, y0, fx, fy, bx0, coef, order, starts, inv_det, cap, sz, sz_scalar, dtau, g, sigma_s2,
                         z_corr, sw, rf, out):
    """``out[0] = Bᵀ(P a)`` and ``out[1] = Bᵀ(P a²)`` (2, H, W), ``a`` each sample's
    :func:`misregistration` (∇u from ``g``) and ``P = min(1/|det|, cap) · sw · rf / (sigma_s² + (1 − ρ) a²)``
    its precision without the shared error (:func:`sample_weight` at β = 0; ``sw``, ``rf``
    empty: 1); row buckets of one parity at a time, as
    :func:`vibr.render.operators.accumulate_bucket`."""
    n = fx.shape[0]
    W = out.shape[2]
    n_rows = starts.shape[0] - 1
    use_coef = coef.shape[0] == n and n > 0
    use_map = sz.shape[0] == n
    use_sw = sw.shape[0] == n
    use_rf = rf.shape[0] == n
    for parity in range(2):
        for r in prange(n_rows):
            q0, q1 = starts[r], starts[r + 1]
            if r % 2 != parity or q0 == q1:
                continue
            la = np.zeros((2, W, 2), np.float64)
            for q in range(q0, q1):
                i = sample_at(order, q)
                gx, gy = grad_at(g, x0[i], y0[i], np.float64(fx[i]), np.float64(fy[i]))
                s = np.float64(sz[i] if use_map else sz_scalar)
                tx, ty = np.float64(dtau[i, 0]), np.float64(dtau[i, 1])
                a = misregistration(s, tx, ty, gx, gy)
                pr = sample_weight(np.float64(inv_det[i]), cap, s, tx, ty, gx, gy, sigma_s2, z_corr, 0.0)
                if use_sw:
                    pr *= sw[i]
                if use_rf:
                    pr *= rf[i]
                v1 = pr * a
                v2 = v1 * a
                w00, w01, w10, w11 = _row_coef(fx, fy, coef, use_coef, i)
                x = bx0[i]
                la[0, x, 0] += w00 * v1
                la[0, x, 1] += w00 * v2
                la[0, x + 1, 0] += w01 * v1
                la[0, x + 1, 1] += w01 * v2
                la[1, x, 0] += w10 * v1
                la[1, x, 1] += w10 * v2
                la[1, x + 1, 0] += w11 * v1
                la[1, x + 1, 1] += w11 * v2
            for ra in range(2):
                for j in range(W):
                    out[0, r + ra, j] += la[ra, j, 0]
                    out[1, r + ra, j] += la[ra, j, 1]


def shared_error_beta(samples: Samples, splat, g, sigma_z, sigma_s: float, z_corr: float, factor=None,
                      inv_det_cap: float | None = None) -> np.ndarray:
    """The shared depth error's correction per target pixel (docs/explanation/renderer.md, "Depth errors
    the views share"):

        ``β = ρ Σ_m B_m P_m a_m / (1 + ρ Σ_m B_m P_m a_m²)``,  ``P_m = 1/|det| · f_m / (σ_s² + (1 − ρ) a_m²)``

    (H, W) float32, ``a_m`` the :func:`misregistration` (∇u from ``g`` (H, W, 2), the
    weights' gradient), ``ρ`` = ``z_corr``, ``f_m`` = ``factor`` (N,) times
    ``meta["sample_weight"]`` (None: 1), ``1/|det|`` capped as the weights cap it
    (``inv_det_cap``, None: not). A sample's weight is then its
    :func:`sample_weight` with ``β`` read at it through B: the generalised least-squares
    weights of samples whose errors ``a_m δ`` share one depth error δ with correlation ρ.
    One pass over the samples."""
    H, W = samples.target_shape
    sz_map, sz_scalar = _sigma_z_arg(samples, sigma_z)
    out = np.zeros((2, H, W), np.float64)
    _shared_error_kernel(splat.x0, splat.y0, splat.fx, splat.fy, splat.bx0, splat.coef, splat.order, splat.starts,
                         samples.inv_det, np.inf if inv_det_cap is None else float(inv_det_cap), sz_map, sz_scalar,
                         samples.dtau_dz, np.ascontiguousarray(g, np.float32),
                         float(sigma_s) ** 2, float(z_corr), _opt(samples.meta.get("sample_weight")), _opt(factor), out)
    return (z_corr * out[0] / (1.0 + z_corr * out[1])).astype(np.float32)


def geometric_weights(samples: Samples, u, sigma_s: float = 1.0, sigma_z=None, *,
                      scale: float = 255.0, grad_max: float | None = 64.0,
                      inv_det_cap: float | None = None, splat=None, dtype=np.float64,
                      prior=None, z_corr: float = 0.0, factor=None) -> np.ndarray:
    """Data-term weights ``W_km`` (docs/explanation/method.md §3), (N,) ``dtype`` (float64 by default).

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
    z_corr : float
        Correlation ρ in [0, 1] of the views' depth errors at a target pixel (0: independent,
        the paper's model; :func:`shared_error_beta`).
    factor : (N,) array, optional
        The weight's other factors (``meta["sample_weight"]`` excepted) that the shared
        error's precision sums read (:func:`shared_error_beta`; default ``prior``); they do
        not multiply the result.
    """
    w = _geometric_weights(samples, u, sigma_s, sigma_z, scale, grad_max, inv_det_cap, splat, dtype, z_corr,
                           factor, prior)
    if prior is not None:
        w *= np.asarray(prior, w.dtype)
    return w


def _geometric_weights(samples, u, sigma_s, sigma_z, scale, grad_max, inv_det_cap, splat, dtype, z_corr, factor,
                       prior):
    sz = samples.sigma_z if sigma_z is None else sigma_z
    sz = np.asarray(sz, np.float64)
    base = 1.0 / (sigma_s ** 2)
    if u is None or not np.any(np.nan_to_num(sz) > 0):
        return (deformation_weight(samples, inv_det_cap) * base).astype(dtype, copy=False)

    g = _weight_gradient(u, scale, grad_max)
    sp = splat if splat is not None else Splat(samples.xy, samples.target_shape)
    out = np.empty(len(samples), dtype)
    sz_map = sz if sz.ndim == 1 else np.zeros(0)
    sz_scalar = float(sz) if sz.ndim == 0 else 0.0
    beta = (shared_error_beta(samples, sp, g, sigma_z, sigma_s, z_corr, prior if factor is None else factor,
                              inv_det_cap)
            if z_corr > 0 else np.zeros((0, 0), np.float32))
    _weights_kernel(sp.x0, sp.y0, sp.fx, sp.fy, np.ascontiguousarray(g), np.asarray(samples.dtau_dz),
                    sz_map, sz_scalar, np.asarray(samples.inv_det),
                    np.inf if inv_det_cap is None else float(inv_det_cap), float(sigma_s) ** 2, float(z_corr), beta,
                    sp.bx0, sp.by0, sp.coef, out)
    return out


@njit(parallel=True, cache=True)
def _weight_gradient_kernel(u, scale, grad_max, clamp, out):
    """:func:`_weight_gradient` in one pass: the luminance rows, their central gradient
    (:func:`vibr.geometry.gradient._grad_row`), the scale and the clamp, in float32 in
    the order of the numpy expressions (bit-identical to them)."""
    H, W, _ = u.shape
    l0, l1, l2 = _LUMA[0], _LUMA[1], _LUMA[2]
    lum = np.empty((H, W), np.float32)
    for i in prange(H):
        for j in range(W):
            lum[i, j] = l0 * u[i, j, 0] + l1 * u[i, j, 1] + l2 * u[i, j, 2]
    tiny = np.float32(1e-12)
    one = np.float32(1.0)
    for i in prange(H):
        gx = np.empty(W, np.float32)
        gy = np.empty(W, np.float32)
        _grad_row(lum, i, False, gx, gy)
        for j in range(W):
            a = gx[j] * scale
            b = gy[j] * scale
            if clamp:
                f = min(one, grad_max / max(np.sqrt(a * a + b * b), tiny))
                a *= f
                b *= f
            out[i, j, 0] = a
            out[i, j, 1] = b


def _weight_gradient(u, scale, grad_max):
    """``∇u`` of the weights: the luminance gradient (:func:`luminance_gradient`) on the
    ``scale``, its magnitude clamped at ``grad_max``; (H, W, 2) float32."""
    u = np.ascontiguousarray(u, np.float32)  # one layout: a strided view would compile the kernel again
    out = np.empty(u.shape[:2] + (2,), np.float32)
    _weight_gradient_kernel(u, np.float32(scale), np.float32(0.0 if grad_max is None else grad_max),
                            grad_max is not None, out)
    return out


#: Robust data terms: ``"none"`` (least squares) or ``"cauchy"`` (IRLS).
ROBUST_LOSSES = ("none", "cauchy")


def robust_factor(samples: Samples, u, splat, c: float = 3.0, loss: str = "cauchy") -> np.ndarray:
    """IRLS factor of the data term's weights for a robust loss (N,) float32.

    With the residual of each sample against the current estimate,
    ``r_m = ‖v_m − (B u)(m)‖ / √3`` (RGB root mean square), and the robust scale
    ``s = c · 1.4826 · median(r)`` (``c`` times the median absolute deviation's estimate of
    the residuals' standard deviation), the Cauchy (Lorentzian) loss
    ``ρ(r) = ½ s² log(1 + (r/s)²)`` gives the reweighting factor
    ``ρ'(r)/r = 1 / (1 + (r/s)²)``: samples that disagree with the others (occluded or
    mismatched ones, the speckles) lose their weight in the next outer pass,
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
    s = c * 1.4826 * float(np.sqrt(median(r2)))
    s2 = max(s * s, 1e-12)
    return (1.0 / (1.0 + r2 / s2)).astype(np.float32)


# ----------------------------------------------------------------------------- fused assembly
# The weights are only ever needed inside the normal equations: the kernels below compute
# each sample's weight (sample_weight, the one formula) while splatting it, bucket by bucket
# of target rows (operators.accumulate_bucket), so the weights never make an (N,) pass of
# their own. They live in this module so that numba's cache, keyed by the file, is rebuilt
# whenever the formula changes.

@njit(parallel=True, cache=True)
def _coverage_kernel(bx0, fx, fy, coef, order, starts, sw, bf, gvals, inv_det, sigma_s2, colour, S0, A0, rhs0,
                     wsum, bw):
    """One pass for the coverage and the initial blend: ``Σ Bᵀ diag(sw) B`` (S0 = 9, into
    A0) or ``Bᵀ sw`` (S0 = 1, into A0[0]), ``Bᵀ (sw·gvals)`` (into rhs0), and ``Bᵀ w``
    (into wsum[0]), ``Bᵀ (w·colour)`` (into bw) with the deformation-only weight
    ``w = sw · bf · sample_weight(u unknown)`` (``bf`` empty: 1); returns ``½ Σ sw |gvals|²``."""
    n = fx.shape[0]
    W = bw.shape[2]
    n_rows = starts.shape[0] - 1
    use_coef = coef.shape[0] == n and n > 0
    use_sw = sw.shape[0] == n
    use_bf = bf.shape[0] == n
    cpart = np.zeros(n_rows, np.float64)
    for parity in range(2):
        for r in prange(n_rows):
            q0, q1 = starts[r], starts[r + 1]
            if r % 2 != parity or q0 == q1:
                continue
            la = np.empty((2, W, max(S0 + gvals.shape[1], 4)), np.float64)
            wb = np.empty(q1 - q0, np.float32)
            for q in range(q0, q1):
                wb[q - q0] = sw[sample_at(order, q)] if use_sw else np.float32(1.0)
            cpart[r] = accumulate_bucket(r, q0, q1, order, wb, bx0, fx, fy, coef, use_coef, gvals, S0, la,
                                         A0, rhs0)
            for q in range(q0, q1):
                i = sample_at(order, q)
                w = np.float32(sample_weight(np.float64(inv_det[i]), np.inf, 0.0, 0.0, 0.0, 0.0, 0.0, sigma_s2))
                wb[q - q0] = w * sw[i] if use_sw else w
                if use_bf:
                    wb[q - q0] = wb[q - q0] * bf[i]
            accumulate_bucket(r, q0, q1, order, wb, bx0, fx, fy, coef, use_coef, colour, 1, la, wsum, bw)
    return _sum_in_order(cpart)


@njit(parallel=True, cache=True)
def _weighted_kernel(x0, y0, fx, fy, bx0, coef, order, starts, inv_det, sz, sz_scalar, dtau, g, use_g, sigma_s2,
                     z_corr, beta, wscale, sw, rf, colour, A, rhs, w_out):
    """``A = Σ Bᵀ diag(W) B``, ``b = Σ Bᵀ (W·colour)``, returns ``½ Σ W |colour|²`` with
    ``W = float32(sample_weight) · wscale · sw · rf`` computed on the fly (∇u from ``g``
    when ``use_g``, else u unknown: deformation only; β from ``beta`` when ``z_corr`` > 0;
    ``sw``, ``rf`` empty: 1); the weights go to ``w_out`` too when it has N entries."""
    n = fx.shape[0]
    W = rhs.shape[2]
    n_rows = starts.shape[0] - 1
    use_coef = coef.shape[0] == n and n > 0
    use_map = sz.shape[0] == n
    use_sw = sw.shape[0] == n
    use_rf = rf.shape[0] == n
    keep = w_out.shape[0] == n
    use_beta = use_g and z_corr > 0
    cpart = np.zeros(n_rows, np.float64)
    for parity in range(2):
        for r in prange(n_rows):
            q0, q1 = starts[r], starts[r + 1]
            if r % 2 != parity or q0 == q1:
                continue
            wb = np.empty(q1 - q0, np.float32)
            for q in range(q0, q1):
                i = sample_at(order, q)
                gx = gy = 0.0
                if use_g:
                    gx, gy = grad_at(g, x0[i], y0[i], np.float64(fx[i]), np.float64(fy[i]))
                s = sz[i] if use_map else sz_scalar
                bm = _beta_at(beta, bx0, r, fx, fy, coef, use_coef, i) if use_beta else 0.0
                w = np.float32(sample_weight(np.float64(inv_det[i]), np.inf, np.float64(s), np.float64(dtau[i, 0]),
                                             np.float64(dtau[i, 1]), gx, gy, sigma_s2,
                                             z_corr if use_beta else 0.0, bm)) * wscale
                if use_sw:
                    w = w * sw[i]
                if use_rf:
                    w = w * rf[i]
                wb[q - q0] = w
                if keep:
                    w_out[i] = w
            la = np.empty((2, W, 9 + colour.shape[1]), np.float64)
            cpart[r] = accumulate_bucket(r, q0, q1, order, wb, bx0, fx, fy, coef, use_coef, colour, 9, la, A, rhs)
    return _sum_in_order(cpart)


def _sigma_z_arg(samples: Samples, sigma_z):
    """The kernels' depth uncertainty: (N,) float32 map or an empty one, and the scalar
    (``sigma_z`` None: the samples' own). One dtype, so that each kernel compiles once."""
    sz = np.asarray(samples.sigma_z if sigma_z is None else sigma_z)
    if sz.ndim == 0:
        return np.zeros(0, np.float32), float(sz)
    return np.ascontiguousarray(sz, np.float32), 0.0


def _opt(a, dtype=np.float32):
    """An optional per-sample array for the kernels: the array, or an empty one."""
    return np.zeros(0, dtype) if a is None else np.ascontiguousarray(a, dtype)


def coverage_blend(samples: Samples, splat, sigma_s: float = 1.0, gradient: bool = True, blend_factor=None,
                   stencils: bool = True):
    """One pass over the samples for what the render needs before its first estimate.

    Returns ``(A0, rhs0, c0, wsum, bw)``: with ``gradient``, ``A0 = Σ Bᵀ diag(sw) B`` (9, H, W)
    and ``rhs0 = Bᵀ (sw·∇v)`` (6, H, W), ``c0 = ½ Σ sw |∇v|²`` (the gradient term's stencils
    at unit weight, ``sw`` = ``meta["sample_weight"]`` or 1), or with ``stencils=False``
    ``A0 = Bᵀ sw`` (1, H, W) beside that ``rhs0`` (what :func:`gradient_consistency` needs);
    without ``gradient``, ``A0 = Bᵀ sw`` (1, H, W) and an empty ``rhs0``; and the
    deformation-only weighted splat of the
    initial blend, ``wsum = Bᵀ w`` (1, H, W), ``bw = Bᵀ (w·colour)`` (3, H, W), ``w = sw ·``
    :func:`sample_weight` (u unknown) ``· blend_factor`` (N,) when given (e.g. :func:`view_prior`).
    float32 outputs, float64 sums."""
    H, W = samples.target_shape
    n = len(samples)
    sw = samples.meta.get("sample_weight")
    if gradient:
        gv = np.ascontiguousarray(samples.grad, np.float32).reshape(n, -1)
        A0, rhs0 = np.zeros((9 if stencils else 1, H, W), np.float32), np.zeros((gv.shape[1], H, W), np.float32)
    else:
        gv = np.zeros((n, 0), np.float32)
        A0, rhs0 = np.zeros((1, H, W), np.float32), np.zeros((0, H, W), np.float32)
    wsum, bw = np.zeros((1, H, W), np.float32), np.zeros((3, H, W), np.float32)
    c0 = _coverage_kernel(splat.bx0, splat.fx, splat.fy, splat.coef, splat.order, splat.starts, _opt(sw), _opt(blend_factor), gv,
                          samples.inv_det, float(sigma_s) ** 2, samples.colour, A0.shape[0],
                          A0, rhs0, wsum, bw)
    return A0, rhs0, float(c0), wsum, bw


@njit(parallel=True, cache=True)
def _consistency_kernel(bx0, fx, fy, coef, order, starts, g, G, inv_c2, acc, inv_t, sw, A, rhs, conf):
    """Per row bucket: each sample's consistency weight ``w_m = min(1, (B acc)_m · inv_t) /
    (1 + |g_m − (B G)_m|² · inv_c2)`` (G (H, W, K): a pixel's K values side by side; ``acc``
    (H, W) the coverage, ``inv_t`` 0: no coverage factor), then ``A = Σ Bᵀ diag(sw·w) B``
    and ``rhs = Bᵀ (sw·w·g)`` in the same pass (:func:`vibr.render.operators.accumulate_bucket`),
    the weights kept in ``conf`` when it has N entries; returns ``½ Σ sw·w |g|²``."""
    n = fx.shape[0]
    K = G.shape[2]
    W = rhs.shape[2]
    n_rows = starts.shape[0] - 1
    use_coef = coef.shape[0] == n and n > 0
    use_sw = sw.shape[0] == n
    keep = conf.shape[0] == n
    use_t = inv_t > 0
    cpart = np.zeros(n_rows, np.float64)
    for parity in range(2):
        for r in prange(n_rows):
            q0, q1 = starts[r], starts[r + 1]
            if r % 2 != parity or q0 == q1:
                continue
            wb = np.empty(q1 - q0, np.float32)
            gb = np.empty((4, K + 1), np.float64)  # the mean (and the coverage) at the block's 4 pixels
            cur = -1
            for q in range(q0, q1):
                i = sample_at(order, q)
                w00, w01, w10, w11 = _row_coef(fx, fy, coef, use_coef, i)
                x = bx0[i]
                if x != cur:  # the samples come block by block: read each block's means once
                    cur = x
                    for k in range(K):
                        gb[0, k] = G[r, x, k]
                        gb[1, k] = G[r, x + 1, k]
                        gb[2, k] = G[r + 1, x, k]
                        gb[3, k] = G[r + 1, x + 1, k]
                    gb[0, K] = acc[r, x]
                    gb[1, K] = acc[r, x + 1]
                    gb[2, K] = acc[r + 1, x]
                    gb[3, K] = acc[r + 1, x + 1]
                r2 = 0.0
                for k in range(K):
                    m = w00 * gb[0, k] + w01 * gb[1, k] + w10 * gb[2, k] + w11 * gb[3, k]
                    d = np.float64(g[i, k]) - m
                    r2 += d * d
                f = 1.0
                if use_t:
                    f = min(1.0, (w00 * gb[0, K] + w01 * gb[1, K] + w10 * gb[2, K] + w11 * gb[3, K]) * inv_t)
                w = np.float32(f / (1.0 + r2 * inv_c2))
                if keep:
                    conf[i] = w
                wb[q - q0] = w * sw[i] if use_sw else w
            la = np.empty((2, W, 9 + K), np.float64)
            cpart[r] = accumulate_bucket(r, q0, q1, order, wb, bx0, fx, fy, coef, use_coef, g, 9, la, A, rhs)
    return _sum_in_order(cpart)


def gradient_consistency(samples: Samples, splat, btg, acc, c: float, keep_weights: bool = True,
                         min_coverage: float = 0.0):
    """The gradient term's stencils with each sample's consistency weight (docs/explanation/renderer.md,
    "The gradient term's consistency weights"):

        ``w_m = min(1, (B acc)_m / t) / (1 + |∇v_m − (B Ḡ)_m|² / c²)``,  ``Ḡ = Bᵀ(sw ∇v) / Bᵀ sw``

    the Cauchy M-estimator's weight (Holland & Welsch 1977) of the sample's gradient against
    the mean of every view's gradients at the target pixels it lands on (``sw`` =
    ``meta["sample_weight"]`` or 1), times the coverage where it lands over ``t`` =
    ``min_coverage`` (0: no such factor): where fewer than ``t`` samples land, the mean is
    mostly the sample itself and confirms nothing (docs/explanation/renderer.md, "The gradient term where
    few samples land"). ``btg`` (K, H, W) ``Bᵀ (sw ∇v)`` and ``acc`` (H, W) ``Bᵀ sw``, both
    from :func:`coverage_blend` (``stencils=False``); ``c`` in the gradients' units
    (intensity per pixel), ``t`` in samples.

    Returns ``(A, b, cst, w)``: the stencil ``Σ Bᵀ diag(sw·w) B`` (9, H, W), ``Bᵀ (sw·w·∇v)``
    (K, H, W), ``½ Σ sw·w |∇v|²`` (what :meth:`vibr.render.operators.Splat.normal` gives with
    those weights) and ``w`` (N,) float32 in (0, 1] (None without ``keep_weights``). One pass
    over the samples."""
    n = len(samples)
    gv = np.ascontiguousarray(samples.grad, np.float32).reshape(n, -1)
    G = np.ascontiguousarray((btg / np.maximum(acc, 1e-12)).transpose(1, 2, 0), np.float32)
    H, W = acc.shape
    A, b = np.zeros((9, H, W), np.float32), np.zeros((gv.shape[1], H, W), np.float32)
    w = np.empty(n if keep_weights else 0, np.float32)
    inv_t = 1.0 / float(min_coverage) if min_coverage > 0 else 0.0
    cst = _consistency_kernel(splat.bx0, splat.fx, splat.fy, splat.coef, splat.order, splat.starts, gv, G,
                              1.0 / float(c) ** 2, np.ascontiguousarray(acc, np.float32), inv_t,
                              _opt(samples.meta.get("sample_weight")), A, b, w)
    return A, b, float(cst), w if keep_weights else None


def weighted_normal(samples: Samples, splat, u, sigma_s: float = 1.0, sigma_z=None, *, scale: float = 255.0,
                    grad_max: float | None = 64.0, wscale: float = 1.0, factor=None, keep_weights: bool = False,
                    z_corr: float = 0.0):
    """The colour term's normal equations with the weights :func:`geometric_weights` would
    give (times ``wscale``, ``meta["sample_weight"]`` and ``factor`` (N,), e.g.
    :func:`robust_factor`; ``z_corr`` as there, its sums reading ``factor``), computed inside
    the assembly: ``(A, b, c, W)`` with ``A`` (9, H, W), ``b`` (3, H, W) float32 as
    :meth:`vibr.render.operators.Splat.normal` and ``W`` (N,) float32 when ``keep_weights``
    (else None). Bit-identical to ``splat.normal`` of the float32 weights (tested); with
    ``z_corr`` > 0 one more pass over the samples (:func:`shared_error_beta`)."""
    H, W = samples.target_shape
    n = len(samples)
    sz_map, sz_scalar = _sigma_z_arg(samples, sigma_z)
    use_g = u is not None and max(float(np.nanmax(sz_map, initial=0.0)), sz_scalar) > 0
    g = _weight_gradient(u, scale, grad_max) if use_g else np.zeros((1, 1, 2), np.float32)
    A = np.zeros((9, H, W), np.float32)
    b = np.zeros((3, H, W), np.float32)
    w_out = np.empty(n if keep_weights else 0, np.float32)
    z_corr = float(z_corr) if use_g else 0.0
    beta = (shared_error_beta(samples, splat, g, sigma_z, sigma_s, z_corr, factor) if z_corr > 0
            else np.zeros((0, 0), np.float32))
    c = _weighted_kernel(splat.x0, splat.y0, splat.fx, splat.fy, splat.bx0, splat.coef, splat.order, splat.starts,
                         samples.inv_det, sz_map, sz_scalar, samples.dtau_dz, g, use_g,
                         float(sigma_s) ** 2, z_corr, beta, np.float32(wscale), _opt(samples.meta.get("sample_weight")),
                         _opt(factor), np.asarray(samples.colour), A, b, w_out)
    return A, b, float(c), (w_out if keep_weights else None)


@njit(cache=True, inline="always")
def fast_acos(x):
    """arccos(x) for x in [−1, 1], absolute error ≤ 2.2e-8 rad (tested): Abramowitz &
    Stegun 4.4.46, ``arccos|x| = √(1 − |x|) · Σ_k a_k |x|^k`` (k ≤ 7), and
    ``arccos x = π − arccos(−x)`` for x < 0. Why: ``math.acos``, one call per sample, was
    the costliest step of the view prior's splat; this error is below the float32 sums the
    prior accumulates (docs/explanation/renderer.md, "Speed round 2")."""
    ax = abs(x)
    p = -0.0012624911
    p = p * ax + 0.0066700901
    p = p * ax - 0.0170881256
    p = p * ax + 0.0308918810
    p = p * ax - 0.0501743046
    p = p * ax + 0.0889789874
    p = p * ax - 0.2145988016
    p = p * ax + 1.5707963050
    r = math.sqrt(max(1.0 - ax, 0.0)) * p
    return r if x >= 0.0 else math.pi - r


@njit(cache=True)
def _ulr_penalty_one(X, c, cu, beta_res):
    """Buehler's penalty of one sample (see :func:`vibr.render.ulr.ulr_penalty`; the angle
    by :func:`fast_acos`)."""
    ax = np.float64(X[0]) - c[0]
    ay = np.float64(X[1]) - c[1]
    az = np.float64(X[2]) - c[2]
    bx = np.float64(X[0]) - cu[0]
    by = np.float64(X[1]) - cu[1]
    bz = np.float64(X[2]) - cu[2]
    na = math.sqrt(ax * ax + ay * ay + az * az)
    nb = math.sqrt(bx * bx + by * by + bz * bz)
    cosang = min(1.0, max(-1.0, (ax * bx + ay * by + az * bz) / max(na * nb, 1e-300)))
    return fast_acos(cosang) + beta_res * max(0.0, na - nb) / max(nb, 1e-300)


@njit(parallel=True, cache=True)
def _prior_splat(bx0, by0, fx, fy, coef, order, starts, view, X, Cs, Cu, beta_res, colour, acc):
    """``acc[y, x, v] += (B_m· pen_m, B_m·)`` per view: each view's penalty splat and
    coverage, one pass over the samples (row buckets of even then odd rows: threads never
    write the same row). The view is the fast axis: a pixel's views lie together. With
    ``colour`` (N, 3) (else (0, 3)), ``B_m· colour_m`` into ``acc[..., 2:5]`` too (ULR)."""
    n = fx.shape[0]
    n_rows = starts.shape[0] - 1
    use_coef = coef.shape[0] == n and n > 0
    with_colour = colour.shape[0] == n and n > 0
    for parity in range(2):
        for r in prange(n_rows):
            if r % 2 != parity or starts[r] == starts[r + 1]:
                continue
            for q in range(starts[r], starts[r + 1]):
                i = sample_at(order, q)
                v = view[i]
                pen = _ulr_penalty_one(X[i], Cs[v], Cu, beta_res)
                b0, b1, b2, b3 = _row_coef(fx, fy, coef, use_coef, i)
                x = bx0[i]
                y = by0[i]
                acc[y, x, v, 0] += b0 * pen
                acc[y, x, v, 1] += b0
                acc[y, x + 1, v, 0] += b1 * pen
                acc[y, x + 1, v, 1] += b1
                acc[y + 1, x, v, 0] += b2 * pen
                acc[y + 1, x, v, 1] += b2
                acc[y + 1, x + 1, v, 0] += b3 * pen
                acc[y + 1, x + 1, v, 1] += b3
                if with_colour:
                    for c in range(3):
                        cv = colour[i, c]
                        acc[y, x, v, 2 + c] += b0 * cv
                        acc[y, x + 1, v, 2 + c] += b1 * cv
                        acc[y + 1, x, v, 2 + c] += b2 * cv
                        acc[y + 1, x + 1, v, 2 + c] += b3 * cv


@njit(cache=True)
def _buehler_weights(a, k, eps, tie, p, srt):
    """Buehler's weights of one pixel's views into ``p`` (V,) (:func:`vibr.render.ulr.ulr_view_weights`,
    not normalised, ``tie`` its threshold's floor over the best penalty): from ``a`` (V, ≥2),
    each view's penalty sum and coverage; a view counts where its coverage > 1e-3. ``srt``
    (V,) scratch. Returns the largest weight."""
    V = p.shape[0]
    kk = min(k, V - 1)
    nfin = 0
    for v in range(V):
        c = a[v, 1]
        p[v] = a[v, 0] / c if c > 1e-3 else np.inf
        # insertion sort of the V penalties (V is small)
        j = v
        while j > 0 and srt[j - 1] > p[v]:
            srt[j] = srt[j - 1]
            j -= 1
        srt[j] = p[v]
        if c > 1e-3:
            nfin += 1
    thresh = srt[kk] if V > k else np.inf
    if not math.isfinite(thresh):  # fewer than k+1 views: the largest present, inflated
        thresh = srt[max(nfin - 1, 0)] * 1.01 + eps
    if tie > 0.0:  # (0 · inf where no view lands would be NaN)
        thresh = max(thresh, tie * srt[0])
    thresh = max(thresh, eps)  # k+1 views tied at zero penalty (at the target's centre): alike
    top = 0.0
    for v in range(V):
        w = 0.0
        if math.isfinite(p[v]):
            w = max(0.0, 1.0 - p[v] / thresh) / (p[v] + eps)
        p[v] = w
        top = max(top, w)
    return top


@njit(parallel=True, cache=True)
def _prior_pixels(acc, k, eps, tie, wt):
    """Per pixel: each view's mean penalty (where its coverage > 1e-3), Buehler's weights of
    the ``k`` best views (:func:`_buehler_weights`, ``tie`` the threshold's floor), divided by
    the largest.
    ``acc`` (H, W, V, 2), ``wt`` (H, W, V); ``wt`` may be ``acc[..., 0]`` (a pixel's sums
    are read before its weights are written)."""
    H, W, V = wt.shape
    for y in prange(H):
        p = np.empty(V, np.float64)
        srt = np.empty(V, np.float64)
        for x in range(W):
            top = max(_buehler_weights(acc[y, x], k, eps, tie, p, srt), 1e-300)
            for v in range(V):
                wt[y, x, v] = p[v] / top


@njit(parallel=True, cache=True)
def _ulr_pixels(acc, k, eps, img, cover, var):
    """ULR's blend per pixel from ``acc`` (H, W, V, 5) of :func:`_prior_splat` with colour:
    ``Σ_v w_v c_v / Σ_v w_v`` with each view's splatted colour ``c_v`` and Buehler's weights
    (:func:`_buehler_weights`) into ``img`` (H, W, 3), the views' summed coverage into
    ``cover`` (H, W), and with ``var`` (H, W) (else (0, 0)) ``Σ_v w_v ‖c_v − c‖² / (3 Σ_v w_v)``.
    A pixel no view covers is 0."""
    H, W, V = acc.shape[0], acc.shape[1], acc.shape[2]
    spread = var.shape[0] == H
    for y in prange(H):
        p = np.empty(V, np.float64)
        srt = np.empty(V, np.float64)
        for x in range(W):
            a = acc[y, x]
            _buehler_weights(a, k, eps, 0.0, p, srt)
            sw = 0.0
            s0 = s1 = s2 = 0.0
            cov = 0.0
            for v in range(V):
                cv = np.float64(a[v, 1])
                cov += cv
                if p[v] > 0.0:
                    sw += p[v]
                    s0 += p[v] * (a[v, 2] / cv)
                    s1 += p[v] * (a[v, 3] / cv)
                    s2 += p[v] * (a[v, 4] / cv)
            cover[y, x] = cov
            if sw <= 0.0:
                img[y, x, 0] = img[y, x, 1] = img[y, x, 2] = 0.0
                if spread:
                    var[y, x] = 0.0
                continue
            m0, m1, m2 = s0 / sw, s1 / sw, s2 / sw
            img[y, x, 0], img[y, x, 1], img[y, x, 2] = m0, m1, m2
            if spread:
                d = 0.0
                for v in range(V):
                    if p[v] > 0.0:
                        cv = np.float64(a[v, 1])
                        e0 = a[v, 2] / cv - m0
                        e1 = a[v, 3] / cv - m1
                        e2 = a[v, 4] / cv - m2
                        d += p[v] * (e0 * e0 + e1 * e1 + e2 * e2)
                var[y, x] = d / (3.0 * sw)


@njit(parallel=True, cache=True)
def _prior_gather(bx0, by0, fx, fy, coef, view, wt, out):
    """``out_m = clip((B wt_{view_m})(m), 0, 1)``: each sample reads its view's map."""
    n = bx0.shape[0]
    use_coef = coef.shape[0] == n and n > 0
    for i in prange(n):
        b0, b1, b2, b3 = _row_coef(fx, fy, coef, use_coef, i)
        x = bx0[i]
        y = by0[i]
        v = view[i]
        val = b0 * wt[y, x, v] + b1 * wt[y, x + 1, v] + b2 * wt[y + 1, x, v] + b3 * wt[y + 1, x + 1, v]
        out[i] = np.float32(min(1.0, max(0.0, val)))


def view_prior(samples: Samples, source_centres, target_centre, k: int = 4, beta_res: float = 0.1,
               eps: float = 1e-6, splat=None, tie: float = 0.0) -> np.ndarray:
    """What ULR knows, as a per-sample factor of the data weight (N,) float32 in [0, 1].

    Buehler et al.'s penalty of each sample (:func:`vibr.render.ulr.ulr_penalty`: the angle
    between the target's and the source's rays to the sample's 3D point, plus ``beta_res``
    times the source's relative excess distance, a resolution penalty), averaged per view
    and target pixel (splat ``B``: ``splat``, else the bilinear one of ``samples.xy``); per
    pixel the ``k`` best views get Buehler's weight ``(1 − p/p_(k+1)) / p``
    (:func:`vibr.render.ulr.ulr_view_weights`), divided by the pixel's largest, so the best
    view has 1, the (k+1)-th and worse 0; ``tie`` > 1 keeps ``p_(k+1)`` at least ``tie`` times
    the pixel's best penalty, so that views which nearly tie with the best are not cut by the
    order of their penalties (the render's ``view_tie``). A sample reads its view's map
    through ``B`` at its landing point. Computed once per render (it does not depend on u); three compiled
    passes (penalty splat, per-pixel weights, gather)."""

    H, W = samples.target_shape
    Cs = np.ascontiguousarray(source_centres, np.float64).reshape(-1, 3)
    Cu = np.ascontiguousarray(target_centre, np.float64).reshape(3)
    sp = splat if splat is not None else Splat(samples.xy, (H, W))
    view = np.ascontiguousarray(samples.view)
    # float32 sums of a few samples' penalties (radians), and each pixel's weights written
    # over its penalty sums once read: the maps are (H, W, V), the largest of a render's
    acc = np.zeros((H, W, len(Cs), 2), np.float32)
    _prior_splat(sp.bx0, sp.by0, sp.fx, sp.fy, sp.coef, sp.order, sp.starts, view, np.ascontiguousarray(samples.X),
                 Cs, Cu, float(beta_res), np.zeros((0, 3), np.float32), acc)
    wt = acc[..., 0]
    _prior_pixels(acc, int(k), float(eps), float(tie), wt)
    out = np.empty(len(samples), np.float32)
    _prior_gather(sp.bx0, sp.by0, sp.fx, sp.fy, sp.coef, view, wt, out)
    return out


def ulr_pixels(samples: Samples, source_centres, target_centre, k: int = 4, beta_res: float = 0.1,
               eps: float = 1e-6, spread: bool = False):
    """ULR's blend (:func:`vibr.render.ulr.ulr_blend`) in two compiled passes: each view's
    colour, penalty and coverage splatted per target pixel (float32 sums, ``(H, W, V, 5)``),
    then Buehler's weights and the blend per pixel. Returns ``(image (H, W, 3), coverage
    (H, W), variance (H, W) or None)`` float32."""

    H, W = samples.target_shape
    Cs = np.ascontiguousarray(source_centres, np.float64).reshape(-1, 3)
    Cu = np.ascontiguousarray(target_centre, np.float64).reshape(3)
    sp = Splat(samples.xy, (H, W))
    acc = np.zeros((H, W, len(Cs), 5), np.float32)
    _prior_splat(sp.bx0, sp.by0, sp.fx, sp.fy, sp.coef, sp.order, sp.starts, np.ascontiguousarray(samples.view),
                 np.ascontiguousarray(samples.X), Cs, Cu, float(beta_res),
                 np.ascontiguousarray(samples.colour, np.float32), acc)
    img = np.empty((H, W, 3), np.float32)
    cover = np.empty((H, W), np.float32)
    var = np.empty((H, W) if spread else (0, 0), np.float32)
    _ulr_pixels(acc, int(k), float(eps), img, cover, var)
    return img, cover, (var if spread else None)
