"""Unstructured Lumigraph Rendering (Buehler et al. 2001, SIGGRAPH) on warped samples.

Each sample (k, m) carries the penalty of view k for the 3D point X it sees:

    penalty = angle(X − C_k, X − C_u) + beta_res · max(0, ‖X − C_k‖ − ‖X − C_u‖) / ‖X − C_u‖

(angle in radians; the resolution term is relative, so it is unit-free). Per target pixel,
each view's colour and penalty are splatted (bilinear), the k best views get the weights
``w̃ = 1 − p / p_(k+1)`` (``p_(k+1)`` the (k+1)-th smallest penalty, Buehler eq. 2),
``w = w̃ / p`` normalised: the blend is continuous as views enter and leave the k best.

The renders run compiled kernels (:func:`vibr.render.weights.ulr_pixels`, and the view
prior's :func:`vibr.render.weights.view_prior`); :func:`ulr_penalty` and
:func:`ulr_view_weights` are the same formulas in numpy, the reference the tests hold the
kernels to (tests/test_render_ulr.py, tests/test_view_prior.py).
"""

from __future__ import annotations

import numpy as np

from ..geometry.samples import Samples
from .weights import ulr_pixels

__all__ = ["ulr_blend", "ulr_penalty", "ulr_view_weights"]


def ulr_blend(samples: Samples, source_centres, target_centre, *, k: int = 4,
              beta_res: float = 0.1, eps: float = 1e-6, spread: bool = False):
    """ULR colour per target pixel.

    Parameters
    ----------
    samples : Samples
    source_centres : (K, 3) array, world coordinates of the source cameras
    target_centre : (3,) array
    k : int
        Views blended per pixel (Buehler's k = 4 by default).
    beta_res : float
        Weight of the relative resolution penalty against the angle (radians).

    Returns
    -------
    image : (H, W, 3) float32, 0 where no view lands
    weight : (H, W) float32, the accumulated bilinear splat weight (coverage)
    variance : (H, W) float32, only with ``spread=True``
        ``Σ_v w_v ‖c_v − c‖² / (3 Σ_v w_v)``: the ULR-weighted variance of the blended views'
        colours around the blend (per channel, [0, 1] units; 0 where no view lands).
    """

    # compiled: a numpy pass per view does not scale to a light field's 80 views
    # (docs/explanation/renderer.md, "Density with the view prior")
    img, acc, var = ulr_pixels(samples, source_centres, target_centre, k, beta_res, eps, spread)
    return (img, acc) if not spread else (img, acc, var)


def ulr_penalty(samples: Samples, source_centres, target_centre, beta_res: float = 0.1) -> np.ndarray:
    """Buehler's penalty of each sample (N,) float64: the angle (radians) between the rays from
    the source and from the target centre to the sample's 3D point, plus ``beta_res`` times
    the relative excess distance of the source, ``max(0, ‖X − C_k‖ − ‖X − C_u‖) / ‖X − C_u‖``."""
    Cs = np.asarray(source_centres, np.float64)
    Cu = np.asarray(target_centre, np.float64)
    X = samples.X
    a = X - Cs[samples.view]
    b = X - Cu
    na = np.linalg.norm(a, axis=1)
    nb = np.linalg.norm(b, axis=1)
    cosang = np.clip((a * b).sum(1) / np.maximum(na * nb, 1e-300), -1.0, 1.0)
    return np.arccos(cosang) + beta_res * np.maximum(0.0, na - nb) / np.maximum(nb, 1e-300)


def ulr_view_weights(pview, k: int = 4, eps: float = 1e-6, tie: float = 0.0) -> np.ndarray:
    """Buehler's blending weights (V, H, W) float64 (not normalised) from the per-view
    penalties ``pview`` (V, H, W), +inf where a view does not land: the k best views get
    ``w = (1 − p / p_(k+1)) / p`` with ``p_(k+1)`` the (k+1)-th smallest penalty (where
    fewer than k+1 views land: the largest present penalty, inflated by 1 %; at least
    ``eps``, so that views tied at zero penalty weigh alike), the others 0.

    ``tie`` > 1 keeps the threshold at least ``tie`` times the best view's penalty, so that
    views which nearly tie with the best share the weight instead of the order of their
    penalties' last digits choosing among them (the view prior's default,
    docs/explanation/renderer.md "Views that tie"); 0 (ULR as published) leaves Buehler's threshold."""
    V = pview.shape[0]
    order = np.sort(pview, axis=0)
    kk = min(k, V - 1)
    thresh = order[kk] if V > k else np.full(pview.shape[1:], np.inf)
    # fewer than k+1 views here: use the largest present penalty (slightly inflated)
    nfin = np.isfinite(order).sum(0)
    last = np.take_along_axis(order, np.maximum(nfin - 1, 0)[None], 0)[0]
    thresh = np.where(np.isfinite(thresh), thresh, last * 1.01 + eps)
    # k+1 views tied at zero penalty (they share the target's centre): they weigh alike
    if tie > 0:  # (0 · inf where no view lands would be NaN)
        thresh = np.maximum(thresh, tie * order[0])
    thresh = np.maximum(thresh, eps)
    with np.errstate(invalid="ignore", divide="ignore"):  # absent views: inf penalties
        return np.where(np.isfinite(pview), np.maximum(0.0, 1.0 - pview / thresh[None]) / (pview + eps), 0.0)
