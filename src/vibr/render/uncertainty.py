"""Per-pixel confidence of a rendered view (derivation in docs/explanation/renderer.md,
section "Uncertainty").

The variational renderer computes the MAP estimate of a posterior whose smooth part is the
quadratic ``f(u) = ½⟨u, H u⟩ − ⟨r, u⟩ + c`` with the Hessian (docs/explanation/method.md §5)

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
``s²·(1 + 1/n_eff)``. The views' exposures differ: view k's samples share an offset ``b_k``
(their mean residual, :func:`view_offsets`), the target has its own, drawn from the same
distribution. The spread is taken around ``B u + b_k`` and the render's mix of offsets
``mix(p) = Σ W B b_k / Σ W B`` adds ``v_views = ‖mix − β̂‖²/3 + σ_β²(1 + π/(2V))`` (``β̂``,
``σ_β``: median and 1.4826·MAD of the V views' offsets, :func:`view_offset_prior`); where
one view dominates the sources agree but the render carries its offset. An exposure is a
gain and moves black by nothing, so by default (the ``gain`` term; ``views`` keeps the
offsets additive) each view's offset is a gain ``g_k = b_k / mean_m∈k (B u)(m)``
(:func:`view_gains`), a sample's offset ``g_k (B u)(m)``, and the same bias and variance of
the gains are scaled by the pixel's intensity:
``v_gain(p) = (‖mix_g − ĝ‖²/3 + σ_g²(1 + π/(2V))) · ‖u(p)‖²/3``. Pixels near a
push–pull filled region border a disocclusion, where the depth is least reliable: the sum
is multiplied by ``1 + HOLE_RANGE/d``, ``d`` the distance in pixels to the nearest filled
pixel (:func:`hole_distance`). The rendered view's standard deviation is

    σ(p) = min(σ_hole, sqrt((1/diag(H)_p + s²(p)·(1 + 1/n_eff(p)) + v_gain(p)) · (1 + HOLE_RANGE/d(p))))
                                                     where the samples cover p,
    σ(p) = min(σ_hole, sqrt(v_fill(p)))             where push–pull filled it,

with ``σ_hole = s / √12`` the standard deviation of an intensity known only to lie in
``[0, s]`` (uniform): no pixel is known worse. ``v_fill`` (the ``fill`` term,
:func:`fill_variance`) is what push–pull fills the pixel from: the spread of those pixels
around their weighted mean plus their own variance, both push–pulled like the colour; a hole
amid a uniform backdrop is known as well as the backdrop, one across a depth edge as little as
its two sides differ (without ``fill``: ``σ_hole``). ULR's σ is the ULR-weighted variance of
the blended views, and ``σ_hole`` where push–pull filled it (:func:`ulr_sigma`).

Two baselines for comparison (:func:`sample_spread_sigma`, :func:`view_count_sigma`): the
spread of the source samples alone, and one over the number of views seeing a pixel.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from numba import njit, prange

from ..geometry.samples import view_counts
from .operators import Splat, _row_coef, sample_at
from .weights import deformation_weight

logger = logging.getLogger(__name__)

__all__ = ["HOLE_SIGMA_FRACTION", "hole_sigma", "hessian_diagonal", "model_variance",
           "sample_spread", "sample_statistics", "view_offsets", "view_offset_prior",
           "hole_distance", "HOLE_RANGE", "TERMS", "KNOWN_TERMS", "view_gains", "fill_variance",
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


#: Fixed number of chunks of :func:`_view_offsets` (its partial sums are added in chunk
#: order, so the offsets do not depend on the number of threads).
_OFFSET_CHUNKS = 64
#: :func:`view_offsets` reads every ``max(1, N // OFFSET_SAMPLES)``-th sample: a mean over
#: hundreds of thousands of samples per view is exact enough, at a fraction of a pass.
OFFSET_SAMPLES = 1 << 19


@njit(parallel=True, cache=True)
def _view_offsets(x0, y0, fx, fy, coef, view, colour, u, stride, part):
    """``part[j, k, c]`` = Σ of ``colour_m,c − (B u)(m)_c`` and ``part[j, k, C]`` the count,
    over every ``stride``-th sample m of view k in chunk j of the samples
    (``part.shape[0]`` chunks)."""
    C = u.shape[0]
    n = x0.shape[0]
    use_coef = coef.shape[0] == n and n > 0
    J = part.shape[0]
    n_s = (n + stride - 1) // stride
    for j in prange(J):
        for t in range(j * n_s // J, (j + 1) * n_s // J):
            i = t * stride
            b0, b1, b2, b3 = _row_coef(fx, fy, coef, use_coef, i)
            x = x0[i]
            y = y0[i]
            k = view[i]
            for c in range(C):
                uc = u[c]
                bu = b0 * uc[y, x] + b1 * uc[y, x + 1] + b2 * uc[y + 1, x] + b3 * uc[y + 1, x + 1]
                part[j, k, c] += np.float64(colour[i, c]) - bu
            part[j, k, C] += 1.0


def view_offsets(splat, colour, u, view, n_views=None, stride=None):
    """Per-view photometric offset: the mean residual ``b_k = mean_m∈k (v_k(m) − (B u)(m))``
    (n_views, C) float64 over the samples of view k (all of them, whatever their weight:
    an exposure / view-dependent brightness is shared by the view's samples, and the
    render's trust in a sample, W, does not change what it says about its view's offset),
    in the units of ``colour``; and the number of samples used per view (n_views,).
    ``u`` planar (C, H, W). ``stride``: every stride-th sample (default
    ``max(1, N // OFFSET_SAMPLES)``)."""
    view = np.ascontiguousarray(view)
    n = len(view)
    V = int(n_views) if n_views is not None else (int(view.max()) + 1 if n else 0)
    C = np.shape(u)[0]
    stride = max(1, n // OFFSET_SAMPLES) if stride is None else max(1, int(stride))
    part = np.zeros((_OFFSET_CHUNKS, V, C + 1))
    _view_offsets(splat.bx0, splat.by0, splat.fx, splat.fy, splat.coef, view,
                  np.ascontiguousarray(colour), np.ascontiguousarray(u, np.float32), stride, part)
    tot = part.sum(0)  # in chunk order
    counts = tot[:, C]
    return tot[:, :C] / np.maximum(counts, 1.0)[:, None], counts


@njit(parallel=True, cache=True)
def _sigma_splat(x0, y0, fx, fy, coef, order, starts, w, colour, u, view, offs, relative, sigma_z, dtau_dz, out):
    """One pass over the samples, splats into the interleaved ``out`` (H, W, K):
    ``out[..., 0] = Σ_m w_m B_m· ‖colour_m − (B u)(m) − b_k(m)‖² / C`` (the residual, less its
    view's offset ``b_k = offs[view_m]`` when ``offs`` has rows, else none; ``relative``: the
    offsets are gains, ``b_k(m) = offs[view_m] · (B u)(m)``),
    ``out[..., 1] = Σ_m w_m² B_m·`` (for the effective number of samples),
    ``out[..., 2] = Σ_m w_m B_m·`` (the weight sum), then with offsets
    ``out[..., 3:3+C] = Σ_m w_m B_m· b_k(m)`` (the render's mix of view offsets) and, when
    ``sigma_z`` has rows, last ``Σ_m w_m B_m· sigma_z_m² ‖∂tau/∂z_m‖²`` (the position
    variance, target px²).
    Interleaved so that one sample's corners write contiguous memory; buckets of even
    then odd top rows, so that threads never write the same row (as
    :func:`vibr.render.operators._assemble_kernel`)."""
    C, H, W = u.shape
    n_rows = starts.shape[0] - 1
    use_coef = coef.shape[0] == x0.shape[0] and x0.shape[0] > 0
    with_views = offs.shape[0] > 0
    with_pos = sigma_z.shape[0] > 0
    kp = out.shape[2] - 1
    for parity in range(2):
        for r in prange(n_rows):
            if r % 2 != parity or starts[r] == starts[r + 1]:
                continue
            for q in range(starts[r], starts[r + 1]):
                i = sample_at(order, q)
                wi = np.float64(w[i])
                if wi == 0.0:
                    continue
                b0, b1, b2, b3 = _row_coef(fx, fy, coef, use_coef, i)
                x = x0[i]
                y = y0[i]
                k = view[i] if with_views else 0
                e = 0.0
                for c in range(C):
                    uc = u[c]
                    bu = b0 * uc[y, x] + b1 * uc[y, x + 1] + b2 * uc[y + 1, x] + b3 * uc[y + 1, x + 1]
                    d = np.float64(colour[i, c]) - bu
                    if with_views:
                        d -= offs[k, c] * bu if relative else offs[k, c]
                    e += d * d
                v0 = e * wi / C
                v1 = wi * wi
                v3 = 0.0
                if with_pos:
                    sz = np.float64(sigma_z[i])
                    tx = np.float64(dtau_dz[i, 0])
                    ty = np.float64(dtau_dz[i, 1])
                    v3 = wi * sz * sz * (tx * tx + ty * ty)
                for corner in range(4):
                    # plain indices (no per-corner view of out): the loop stays in registers
                    yy = y + (corner >> 1)
                    xx = x + (corner & 1)
                    bc = b0 if corner == 0 else b1 if corner == 1 else b2 if corner == 2 else b3
                    out[yy, xx, 0] += bc * v0
                    out[yy, xx, 1] += bc * v1
                    out[yy, xx, 2] += bc * wi
                    if with_views:
                        for c in range(C):
                            out[yy, xx, 3 + c] += bc * wi * offs[k, c]
                    if with_pos:
                        out[yy, xx, kp] += bc * v3


@njit(parallel=True, cache=True)
def _finish_stats(acc, wsum, own_wsum, centre, with_views, with_pos, s2, neff, bias2, pos):
    """Per pixel from :func:`_sigma_splat`'s ``acc``: ``s2``, ``n_eff``, ``bias2`` =
    ``‖Σ w B b_k / Σ w B − centre‖² / C`` (with offsets) and ``pos`` (with positions); all
    0 where ``Σ w B = 0`` (``wsum``, or ``acc[..., 2]`` when ``own_wsum``)."""
    H, W, K = acc.shape
    C = centre.shape[0]
    for y in prange(H):
        for x in range(W):
            a = acc[y, x]
            ws = a[2] if own_wsum else wsum[y, x]
            if ws > 0:
                inv = 1.0 / ws
                s2[y, x] = a[0] * inv
                neff[y, x] = ws * ws / a[1] if a[1] > 0 else 0.0
                if with_views:
                    e = 0.0
                    for c in range(C):
                        d = a[3 + c] * inv - centre[c]
                        e += d * d
                    bias2[y, x] = e / C
                if with_pos:
                    pos[y, x] = a[K - 1] * inv
            else:
                s2[y, x] = 0.0
                neff[y, x] = ws * ws / a[1] if a[1] > 0 else 0.0
                if with_views:
                    bias2[y, x] = 0.0
                if with_pos:
                    pos[y, x] = 0.0


def sample_statistics(splat, weight, colour, u, wsum=None, sigma_z=None, dtau_dz=None, view=None, offsets=None,
                      centre=None, relative: bool = False):
    """Per-pixel statistics of the samples around the rendered image ``u`` (planar (C, H, W),
    units of ``colour``), from one pass (:func:`_sigma_splat`); ``wsum = Σ_m w_m B_mp``
    (None: accumulated in the same pass).
    Returns a dict of (H, W) float64 arrays (0 where ``wsum = 0``): ``s2`` the weighted
    variance of the samples around ``B u`` (units of ``colour`` squared; with ``view`` (N,)
    and ``offsets`` (V, C), :func:`view_offsets`, around ``B u + b_k``: the offset of the
    sample's view removed), ``n_eff`` the effective number of samples ``(Σ w B)² / Σ w² B``,
    ``pos_var`` the weighted mean of the samples' position variance ``sigma_z² ‖∂tau/∂z‖²``
    (target pixels²; 0 without ``sigma_z``); with offsets also ``bias2``
    ``‖mix − centre‖² / C``, ``mix = Σ w B b_k / Σ w B`` the W-weighted mean of the offsets
    of the views the render blends at p (``centre`` (C,), default 0); ``relative``: the
    offsets are gains less one (:func:`view_gains`), a sample's offset ``offsets[k]·(B u)(m)``."""
    with_pos = sigma_z is not None
    with_views = view is not None and offsets is not None
    if not with_pos:
        sigma_z, dtau_dz = np.zeros(0, np.float32), np.zeros((0, 2), np.float32)
    C = np.shape(u)[0]
    if with_views:
        view, offs = np.ascontiguousarray(view), np.ascontiguousarray(offsets, np.float64).reshape(-1, C)
    else:
        view, offs = np.zeros(0, np.int32), np.zeros((0, C))
    H, W = splat.shape
    acc = np.zeros((H, W, 3 + (C if with_views else 0) + (1 if with_pos else 0)), np.float64)
    _sigma_splat(splat.bx0, splat.by0, splat.fx, splat.fy, splat.coef, splat.order, splat.starts,
                 np.ascontiguousarray(weight, np.float64), np.ascontiguousarray(colour),
                 np.ascontiguousarray(u, np.float32), view, offs, bool(relative),
                 np.ascontiguousarray(sigma_z, np.float32),
                 np.ascontiguousarray(dtau_dz), acc)
    out = {k: np.empty((H, W)) for k in ("s2", "n_eff")}
    out["pos_var"] = np.empty((H, W)) if with_pos else np.zeros((H, W))
    bias2 = np.empty((H, W)) if with_views else np.zeros((1, 1))
    cen = np.zeros(C) if centre is None else np.ascontiguousarray(centre, np.float64).reshape(C)
    ws = np.zeros((1, 1)) if wsum is None else np.ascontiguousarray(wsum, np.float64)
    _finish_stats(acc, ws, wsum is None, cen, with_views, with_pos, out["s2"], out["n_eff"], bias2,
                  out["pos_var"] if with_pos else np.zeros((1, 1)))
    if with_views:
        out["bias2"] = bias2
    return out


def _finish(var, coverage, scale, hole_var=None):
    """σ = min(σ_hole, sqrt(var)) on covered pixels, σ_hole elsewhere (``hole_var`` given:
    min(σ_hole, sqrt(hole_var)) there); float32."""
    sh = hole_sigma(scale)
    sig = np.sqrt(np.minimum(np.nan_to_num(var, nan=np.inf), sh * sh))
    holes = ~np.asarray(coverage, bool)
    sig[holes] = sh if hole_var is None else np.sqrt(np.minimum(np.nan_to_num(hole_var[holes], nan=np.inf), sh * sh))
    return sig.astype(np.float32)


#: The terms of σ² by default (docs/explanation/renderer.md "Uncertainty": chosen on
#: procedural scenes by benchmarks/quality/uncertainty_table.py).
TERMS = ("model", "spread", "gain", "hole", "fill")
#: every term a caller may name: ``views`` is ``gain`` with additive offsets, the same at
#: every intensity (one of the two at a time)
KNOWN_TERMS = ("model", "spread", "views", "gain", "hole", "fill")


#: Range (pixels) of the variance inflation next to push–pull filled pixels:
#: σ² is multiplied by ``1 + HOLE_RANGE / d`` (docs/explanation/renderer.md "Uncertainty").
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
                      density: float = 1.0, terms=TERMS, view=None,
                      grad_density: float | None = None) -> np.ndarray:
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
        Pixels reached by the samples; the rest get ``σ_hole`` (:func:`hole_sigma`), or
        with ``fill`` their fill's (:func:`fill_variance`) up to it.
    density : float
        The density the colour term was divided by (``RenderResult.params["colour_density"]``,
        rho_c): the model's variance is that of the unnormalised energy (the paper's),
        ``1 / diag(rho_c · alpha · A + rho · gamma · DᵀA_gD)``.
    grad_density : float, optional
        The density the gradient term was divided by (``RenderResult.params["density"]``,
        rho); None: ``density``.
    terms : sequence of {"model", "spread", "gain", "views", "hole", "fill"} or a "+"-joined string
        The variances added: the model's ``1/diag(H)``, the disagreement of the sources
        ``s²·(1 + 1/n_eff)`` and the view offsets (``gain``: the spread is then taken with
        each view's offset removed, and the offsets' bias and variance are added, the
        offsets being gains, proportional to the pixel's intensity; ``views``: the same with
        additive offsets; one of the two;
        needs ``view``); ``hole`` multiplies their sum by ``1 + HOLE_RANGE / d`` near
        push–pull filled pixels (module docstring); ``fill``: a filled pixel's σ from the
        pixels it is filled from (:func:`fill_variance`) instead of ``σ_hole``; default
        :data:`TERMS`.
    view : (N,) int array, optional
        The source view of each sample (``Samples.view``), for the offset terms (without it
        they are left out).
    """
    if terms is True:
        terms = TERMS
    if isinstance(terms, str):
        terms = tuple(terms.split("+"))
    bad = set(terms) - set(KNOWN_TERMS)
    if bad or not terms or {"views", "gain"} <= set(terms):
        raise ValueError(f"uncertainty terms must be among {KNOWN_TERMS}, views and gain not both, got {terms!r}")
    var = np.zeros(np.shape(coverage))
    s2_scale = float(scale) ** 2
    if "model" in terms:
        rg = float(density if grad_density is None else grad_density)
        var = var + model_variance(model.A, model.Ag if model.use_grad else None, model.alpha * float(density),
                                   model.gamma * rg if model.use_grad else 0.0)
    with_views = ("views" in terms or "gain" in terms) and view is not None and len(view) > 0
    up = np.asarray(u)
    if not (up.ndim == 3 and up.shape[0] == np.shape(colour)[1]):
        up = up.transpose(2, 0, 1)  # (H, W, C) → planar
    if "spread" in terms or with_views:
        offs = centre = None
        gain = "gain" in terms
        if with_views:
            offs, counts = view_offsets(splat, colour, up, view)
            if gain:
                offs = view_gains(offs, colour, view, len(counts))
            centre, v_off = view_offset_prior(offs, counts)
        st = sample_statistics(splat, weight, colour, up, view=view if with_views else None, offsets=offs,
                               centre=centre, relative=gain)
        if "spread" in terms:
            neff = st["n_eff"]
            inv_n = np.where(neff > 0, 1.0 / np.where(neff > 0, neff, 1.0), 0.0)
            var = var + st["s2"] * (1.0 + inv_n) * s2_scale
        if with_views:
            v_views = st["bias2"] + v_off
            if gain:  # a gain's offset at p: the gain times the pixel's intensity
                v_views = v_views * (up.astype(np.float64) ** 2).mean(0)
            var = var + v_views * s2_scale
    if "hole" in terms:
        with np.errstate(divide="ignore", invalid="ignore"):  # holes: σ_hole below
            var = var * (1.0 + HOLE_RANGE / hole_distance(coverage))
    hole_var = fill_variance(up, var, coverage, scale) if "fill" in terms else None
    return _finish(var, coverage, scale, hole_var)


def fill_variance(u, var, coverage, scale: float = 255.0) -> np.ndarray:
    """Variance (H, W) float64, grey levels², of a push–pull filled pixel (``u`` planar
    (C, H, W) in [0, 1], ``var`` (H, W) grey levels²): the pixels it is
    filled from vary around their weighted mean (push–pull of ``u²`` less the square of the
    push–pull of ``u``, mean over channels), and carry their own variance ``var`` (its
    push–pull). A hole amid a uniform backdrop is known as well as the backdrop; one
    between two surfaces as little as they differ. Covered pixels: their own ``var``."""
    from .pushpull import push_pull

    up = np.asarray(u, np.float64).transpose(1, 2, 0)  # push_pull reads (H, W, C)
    w = np.asarray(coverage, np.float32)
    stack = np.concatenate([up, up * up, np.nan_to_num(np.asarray(var, np.float64), posinf=0.0)[..., None]
                            / float(scale) ** 2], axis=-1) * w[..., None]
    f = push_pull(stack, w).astype(np.float64)
    C = up.shape[-1]
    spread = np.maximum(f[..., C:2 * C] - f[..., :C] ** 2, 0.0).mean(-1)
    return np.where(np.asarray(coverage, bool), var, (spread + f[..., 2 * C]) * float(scale) ** 2)


def view_gains(offsets, colour, view, n_views, stride=None):
    """The views' offsets (:func:`view_offsets`, same ``stride``) as gains less one:
    ``g_k = b_k / mean_m∈k (B u)(m)``, the mean prediction being the view's mean colour less its
    offset (the same samples); 0 for a view without samples or light."""
    view = np.asarray(view)
    stride = max(1, len(view) // OFFSET_SAMPLES) if stride is None else max(1, int(stride))
    v, col = view[::stride], np.asarray(colour)[::stride].astype(np.float64)  # stride first: N can be millions
    n = np.bincount(v, minlength=n_views).astype(np.float64)
    mean = np.stack([np.bincount(v, col[:, c], n_views) for c in range(col.shape[1])], 1) / np.maximum(n, 1.0)[:, None]
    pred = mean - np.asarray(offsets, np.float64)
    return np.where(pred > 1e-6, np.asarray(offsets, np.float64) / np.maximum(pred, 1e-6), 0.0)


def view_offset_prior(offsets, counts):
    """Where the target's photometric offset is expected and how far from it (docs/explanation/renderer.md
    "Uncertainty", *View offsets*): ``(centre (C,), var)``.

    Model: view k's samples carry an offset ``β_k`` (exposure, view-dependent brightness),
    the target's ``β_t`` drawn from the same distribution as the V sources'. The render
    blends the views' offsets with its own weights, ``mix(p) = Σ w B b_k / Σ w B``; its
    error ``mix(p) − β_t`` has the mean square ``‖mix(p) − centre‖²/C + var``, with
    ``centre`` the median of the V sources' offsets per channel (``b_k``,
    :func:`view_offsets`, known up to a constant that cancels; the median, as a view with an
    odd exposure is common) and ``var = σ_β²(1 + π/(2V))``, ``σ_β = 1.4826 · MAD`` their
    robust spread (``π/(2V)``: the variance of the median of V samples in units of σ_β²).
    Views without samples (``counts`` 0) are left out; one view: ``var = 0``."""
    offs = np.asarray(offsets, np.float64)
    b = offs[np.asarray(counts) > 0]
    V, C = b.shape
    if V == 0:
        return np.zeros(C), 0.0
    med = np.median(b, 0)
    sb2 = float(np.mean((1.4826 * np.median(np.abs(b - med), 0)) ** 2)) if V > 1 else 0.0
    return med, sb2 * (1.0 + math.pi / (2.0 * V))


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

    sp = Splat(samples.xy, samples.target_shape)
    s2, _ = sample_spread(sp, deformation_weight(samples), np.asarray(samples.colour) * float(scale))
    if coverage is None:
        coverage = sp.adjoint(np.ones(sp.n)) >= hole_threshold
    return _finish(s2, coverage, scale)


def view_count_sigma(samples) -> np.ndarray:
    """Baseline: σ(p) = 1 / (number of source views with a sample landing on p, rounded to
    the nearest pixel); ``inf`` where none does. Unit-free (a ranking, not a std. dev.)."""

    n = view_counts(samples).astype(np.float64)
    with np.errstate(divide="ignore"):
        return np.where(n > 0, 1.0 / np.maximum(n, 1), np.inf).astype(np.float32)
