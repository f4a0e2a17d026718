"""Per-pixel confidence of a rendered view (issue 28; derivation in docs/RENDERER.md,
section "Uncertainty").

The variational renderer computes the MAP estimate of a posterior whose smooth part is the
quadratic ``f(u) = ½⟨u, H u⟩ − ⟨r, u⟩ + c`` with the Hessian (docs/METHOD.md §5)

    H = alpha · Σ_k B_kᵀ W_k B_k + gamma · Dᵀ (Σ_k B_kᵀ C_k B_k) D

(two 9-point stencils, :mod:`vibr.render.operators`). On the intensity scale ``s`` the
parameters refer to (grey levels of 255 by default) the Laplace approximation of the
posterior (TV left out) has covariance ``H⁻¹``; its diagonal is approximated by the Jacobi
value ``1 / diag(H)`` (a lower bound of ``(H⁻¹)_pp`` for an SPD matrix). The Gaussian model
misses what breaks its assumptions (occlusions, wrong depth, specularities); the
disagreement of the sources measures it: the W-weighted variance of the warped samples
around the rendered image,

    s²(p) = Σ_km W_km B_kmp ‖v_k(m) − (B_k u)(m)‖² / (3 Σ_km W_km B_kmp)     (grey levels²).

The spread is the variance of one sample; the weighted mean of ``n_eff = (Σ W B)² / Σ W² B``
samples has the variance ``s²/n_eff`` on top (the standard error), so the spread term is
``s²·(1 + 1/n_eff)``. Pixels next to a push–pull filled region border a disocclusion, where
the depth is least reliable: they get ``(σ_hole / (1 + d))²`` with ``d`` the distance in
pixels to the nearest filled pixel (:func:`hole_distance`). The rendered view's standard
deviation is

    σ(p) = min(σ_hole, sqrt(1/diag(H)_p + s²(p)·(1 + 1/n_eff(p)) + (σ_hole/(1 + d(p)))²))
                                                     where the samples cover p,
    σ(p) = σ_hole                                   where push–pull filled it,

with ``σ_hole = s / √12`` the standard deviation of an intensity known only to lie in
``[0, s]`` (uniform): a filled pixel is known no better than that, and no pixel is known
worse. For ULR the same rule applies to the ULR-weighted variance of the blended views.

Two baselines for comparison (:func:`sample_spread_sigma`, :func:`view_count_sigma`): the
spread of the source samples alone, and one over the number of views seeing a pixel.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from numba import njit, prange

from .operators import _row_coef

logger = logging.getLogger(__name__)

__all__ = ["HOLE_SIGMA_FRACTION", "hole_sigma", "hessian_diagonal", "model_variance",
           "sample_spread", "sample_statistics", "hole_distance", "HOLE_RANGE", "TERMS",
           "variational_sigma", "ulr_sigma", "sample_spread_sigma",
           "view_count_sigma"]

#: σ of a pixel filled by push–pull, as a fraction of the intensity scale: the standard
#: deviation of a uniform distribution on [0, scale] (1/√12 ≈ 0.289; 73.6 grey levels of 255).
HOLE_SIGMA_FRACTION = 1.0 / math.sqrt(12.0)


def hole_sigma(scale: float = 255.0) -> float:
    """``scale / √12``: the std. dev. of an intensity known only to lie in ``[0, scale]``."""
    return float(scale) * HOLE_SIGMA_FRACTION


def hessian_diagonal(A, Ag=None, alpha: float = 1.0, gamma: float = 0.0) -> np.ndarray:
    """``diag(H)`` (H, W) float64 of ``H = alpha·A + gamma·DᵀA_gD``.

    ``A``, ``Ag`` are (9, H, W) stencils (entry 4 is the centre). With central differences
    ``(Du)_x(i, j) = ½(u(i, j+1) − u(i, j−1))``, pixel p enters ``D u`` at its four
    neighbours with coefficient ±½ and the two entries of one axis are 2 px apart (outside
    the 3×3 stencil), so ``diag(DᵀA_gD)_p = ¼ Σ_{q ∈ N4(p)} A_g[centre, q]`` (the replicated
    border is approximated by the interior formula)."""
    d = alpha * np.asarray(A[4], np.float64)
    if Ag is not None and gamma != 0:
        g = np.pad(np.asarray(Ag[4], np.float64), 1, mode="edge")
        d = d + gamma * 0.25 * (g[:-2, 1:-1] + g[2:, 1:-1] + g[1:-1, :-2] + g[1:-1, 2:])
    return d


def model_variance(A, Ag=None, alpha: float = 1.0, gamma: float = 0.0) -> np.ndarray:
    """Jacobi approximation ``1 / diag(H)`` of the posterior variance (H, W) float64, in
    units of the intensity scale squared; ``inf`` where ``diag(H) = 0``."""
    d = hessian_diagonal(A, Ag, alpha, gamma)
    with np.errstate(divide="ignore"):
        return np.where(d > 0, 1.0 / np.maximum(d, 1e-300), np.inf)


def sample_spread(splat, weight, colour, centre_values=None):
    """Weighted variance of the samples around per-sample centre values, per pixel.

    ``s²(p) = Σ_m w_m B_mp ‖colour_m − centre_m‖² / (C Σ_m w_m B_mp)`` (C channels), with
    ``centre_m = (B u)(m)`` (pass ``splat.apply(u)``) or, when ``centre_values`` is None, the
    weighted mean of the samples at p (the variance of the splatted samples:
    ``Σ w B ‖c‖² / Σ w B − ‖Σ w B c / Σ w B‖²``). Intensities as given (scale them first).

    Returns ``(s2, wsum)``: (H, W) float64 each; ``s2`` is 0 where ``wsum = 0``."""
    colour = np.asarray(colour, np.float64)
    C = colour.shape[1]
    if centre_values is None:
        vals = np.concatenate([colour, (colour * colour).sum(1, keepdims=True)], 1)
        agg = splat.adjoint(vals, weight)
        wsum = splat.adjoint(np.ones(splat.n), weight)
        inv = np.where(wsum > 0, 1.0 / np.maximum(wsum, 1e-300), 0.0)
        mean = agg[..., :C] * inv[..., None]
        s2 = (agg[..., C] * inv - (mean * mean).sum(-1)) / C
    else:
        r = colour - np.asarray(centre_values, np.float64)
        vals = np.stack([(r * r).sum(1) / C, np.ones(len(r))], 1)
        agg = splat.adjoint(vals, weight)
        wsum = agg[..., 1]
        s2 = np.where(wsum > 0, agg[..., 0] / np.maximum(wsum, 1e-300), 0.0)
    return np.maximum(s2, 0.0), wsum


@njit(cache=True, inline="always")
def _add4(o, b, v0, v1, v2, v3, with_pos):
    o[0] += b * v0
    o[1] += b * v1
    o[2] += b * v2
    if with_pos:
        o[3] += b * v3


@njit(parallel=True, cache=True)
def _sigma_splat(x0, y0, fx, fy, coef, order, starts, w, colour, u, sigma_z, dtau_dz, out):
    """One pass over the samples, splats into the interleaved ``out`` (H, W, K):
    ``out[..., 0] = Σ_m w_m B_m· ‖colour_m − (B u)(m)‖² / C`` (the residual),
    ``out[..., 1] = Σ_m w_m² B_m·`` (for the effective number of samples),
    ``out[..., 2] = Σ_m w_m B_m·`` (the weight sum) and, when K = 4,
    ``out[..., 3] = Σ_m w_m B_m· sigma_z_m² ‖∂tau/∂z_m‖²`` (the position variance, target px²).
    Interleaved so that one sample's four corners write contiguous memory; buckets of even
    then odd top rows, so that threads never write the same row (as
    :func:`vibr.render.operators._assemble_kernel`)."""
    C, H, W = u.shape
    n_rows = starts.shape[0] - 1
    use_coef = coef.shape[0] == x0.shape[0] and x0.shape[0] > 0
    with_pos = out.shape[2] == 4
    for parity in range(2):
        for r in prange(n_rows):
            if r % 2 != parity or starts[r] == starts[r + 1]:
                continue
            for q in range(starts[r], starts[r + 1]):
                i = order[q]
                wi = np.float64(w[i])
                if wi == 0.0:
                    continue
                b0, b1, b2, b3 = _row_coef(fx, fy, coef, use_coef, i)
                x = x0[i]
                y = y0[i]
                e = 0.0
                for c in range(C):
                    uc = u[c]
                    bu = b0 * uc[y, x] + b1 * uc[y, x + 1] + b2 * uc[y + 1, x] + b3 * uc[y + 1, x + 1]
                    d = np.float64(colour[i, c]) - bu
                    e += d * d
                v0 = e * wi / C
                v1 = wi * wi
                v3 = 0.0
                if with_pos:
                    sz = np.float64(sigma_z[i])
                    tx = np.float64(dtau_dz[i, 0])
                    ty = np.float64(dtau_dz[i, 1])
                    v3 = wi * sz * sz * (tx * tx + ty * ty)
                _add4(out[y, x], b0, v0, v1, wi, v3, with_pos)
                _add4(out[y, x + 1], b1, v0, v1, wi, v3, with_pos)
                _add4(out[y + 1, x], b2, v0, v1, wi, v3, with_pos)
                _add4(out[y + 1, x + 1], b3, v0, v1, wi, v3, with_pos)


def sample_statistics(splat, weight, colour, u, wsum=None, sigma_z=None, dtau_dz=None):
    """Per-pixel statistics of the samples around the rendered image ``u`` (planar (C, H, W),
    units of ``colour``), from one pass (:func:`_sigma_splat`); ``wsum = Σ_m w_m B_mp``
    (None: accumulated in the same pass).
    Returns a dict of (H, W) float64 arrays (0 where ``wsum = 0``): ``s2`` the weighted
    variance of the samples around ``B u`` (units of ``colour`` squared), ``n_eff`` the
    effective number of samples ``(Σ w B)² / Σ w² B``, ``pos_var`` the weighted mean of the
    samples' position variance ``sigma_z² ‖∂tau/∂z‖²`` (target pixels²; 0 without ``sigma_z``)."""
    with_pos = sigma_z is not None
    if not with_pos:
        sigma_z, dtau_dz = np.zeros(0, np.float32), np.zeros((0, 2), np.float32)
    H, W = splat.shape
    acc = np.zeros((H, W, 4 if with_pos else 3), np.float64)
    _sigma_splat(splat.bx0, splat.by0, splat.fx, splat.fy, splat.coef, splat.order, splat.starts,
                 np.ascontiguousarray(weight), np.ascontiguousarray(colour), np.ascontiguousarray(u, np.float32),
                 np.ascontiguousarray(sigma_z), np.ascontiguousarray(dtau_dz), acc)
    ws = acc[..., 2] if wsum is None else np.asarray(wsum, np.float64)
    ok = ws > 0
    inv = np.where(ok, 1.0 / np.where(ok, ws, 1.0), 0.0)
    w2 = acc[..., 1]
    return {"s2": acc[..., 0] * inv, "n_eff": np.where(w2 > 0, ws * ws / np.where(w2 > 0, w2, 1.0), 0.0),
            "pos_var": acc[..., 3] * inv if with_pos else np.zeros((H, W))}


def _finish(var, coverage, scale):
    """σ = min(σ_hole, sqrt(var)) on covered pixels, σ_hole elsewhere; float32."""
    sh = hole_sigma(scale)
    sig = np.sqrt(np.minimum(np.nan_to_num(var, nan=np.inf), sh * sh))
    sig[~np.asarray(coverage, bool)] = sh
    return sig.astype(np.float32)


#: The terms of σ² (docs/RENDERER.md "Uncertainty": chosen by measurement).
TERMS = ("model", "spread", "hole")


#: Range (pixels) of the variance inflation next to push–pull filled pixels:
#: σ² is multiplied by ``1 + HOLE_RANGE / d`` (docs/RENDERER.md "Uncertainty").
HOLE_RANGE = 4.0


def hole_distance(coverage) -> np.ndarray:
    """Euclidean distance (pixels, (H, W) float64) of each pixel to the nearest pixel
    push–pull filled (``~coverage``); 0 on those, ``inf`` when there is none."""
    from scipy.ndimage import distance_transform_edt

    cov = np.asarray(coverage, bool)
    if cov.all():
        return np.full(cov.shape, np.inf)
    return distance_transform_edt(cov)


def variational_sigma(model, splat, weight, colour, u, coverage, *, scale: float = 255.0,
                      density: float = 1.0, terms=TERMS) -> np.ndarray:
    """σ per pixel (H, W) float32, grey levels of ``scale``, of a variational render.

    Parameters
    ----------
    model : vibr.render.solver.QuadraticModel
        The last pass's model (its stencils ``A``, ``Ag`` and weights ``alpha``, ``gamma``).
    splat : vibr.render.operators.Splat
        ``B`` of the samples.
    weight : (N,) array
        The last pass's data-term weights ``W_km`` (those ``A`` was assembled with).
    colour : (N, 3) array
        Sample colours ``v_k(m)`` in [0, 1].
    u : (3, H, W) planar (or (H, W, 3)) array in [0, 1]
        The rendered image.
    coverage : (H, W) bool
        Pixels reached by the samples; the rest get ``σ_hole`` (:func:`hole_sigma`).
    density : float
        The density normalisation rho the data terms were divided by
        (``RenderResult.params["density"]``): the model's variance is that of the
        unnormalised energy (the paper's), ``1 / (rho · diag(H))``.
    terms : sequence of {"model", "spread", "hole"} or a "+"-joined string
        The variances added: the model's ``1/diag(H)`` and the disagreement of the sources
        ``s²·(1 + 1/n_eff)``; ``hole`` multiplies their sum by ``1 + HOLE_RANGE / d`` near
        push–pull filled pixels (module docstring); default all three.
    """
    if terms is True:
        terms = TERMS
    if isinstance(terms, str):
        terms = tuple(terms.split("+"))
    bad = set(terms) - set(TERMS)
    if bad or not terms:
        raise ValueError(f"uncertainty terms must be among {TERMS}, got {terms!r}")
    var = np.zeros(np.shape(coverage))
    if "model" in terms:
        var = var + model_variance(model.A, model.Ag if model.use_grad else None, model.alpha,
                                   model.gamma if model.use_grad else 0.0) / float(density)
    if "spread" in terms:
        up = np.asarray(u)
        if not (up.ndim == 3 and up.shape[0] == np.shape(colour)[1]):
            up = up.transpose(2, 0, 1)  # (H, W, C) → planar
        st = sample_statistics(splat, weight, colour, up)  # Σ w B: the row sums of A, same pass
        neff = st["n_eff"]
        inv_n = np.where(neff > 0, 1.0 / np.where(neff > 0, neff, 1.0), 0.0)
        var = var + st["s2"] * (1.0 + inv_n) * float(scale) ** 2
    if "hole" in terms:
        with np.errstate(divide="ignore", invalid="ignore"):  # holes: σ_hole below
            var = var * (1.0 + HOLE_RANGE / hole_distance(coverage))
    return _finish(var, coverage, scale)


def ulr_sigma(spread_var, coverage, *, scale: float = 255.0) -> np.ndarray:
    """σ per pixel of a ULR render from the ULR-weighted variance of the blended views
    around the blend (``spread_var``, [0, 1]-intensity units squared, see
    :func:`vibr.render.ulr.ulr_blend`); ``σ_hole`` where not covered."""
    return _finish(np.asarray(spread_var, np.float64) * float(scale) ** 2, coverage, scale)


def sample_spread_sigma(samples, *, scale: float = 255.0, coverage=None,
                        hole_threshold: float = 0.5) -> np.ndarray:
    """Baseline: the spread of the source samples alone, σ(p) = sqrt of the variance of the
    splatted samples around their mean (weights: bilinear × deformation ``1/|det ∂tau/∂x|``,
    no model), ``σ_hole`` where the samples' bilinear coverage is below ``hole_threshold``
    (or outside ``coverage`` when given)."""
    from .weights import deformation_weight
    from .operators import Splat

    sp = Splat(samples.xy, samples.target_shape)
    s2, _ = sample_spread(sp, deformation_weight(samples), np.asarray(samples.colour) * float(scale))
    if coverage is None:
        coverage = sp.adjoint(np.ones(sp.n)) >= hole_threshold
    return _finish(s2, coverage, scale)


def view_count_sigma(samples) -> np.ndarray:
    """Baseline: σ(p) = 1 / (number of source views with a sample landing on p, rounded to
    the nearest pixel); ``inf`` where none does. Unit-free (a ranking, not a std. dev.)."""
    from ..geometry.samples import view_counts

    n = view_counts(samples).astype(np.float64)
    with np.errstate(divide="ignore"):
        return np.where(n > 0, 1.0 / np.maximum(n, 1), np.inf).astype(np.float32)
