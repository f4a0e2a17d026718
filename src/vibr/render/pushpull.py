"""Push–pull hole filling (Gortler et al. 1996, "The Lumigraph", §3.4; docs/METHOD.md §6).

Given a splatted colour sum ``S(p) = Σ w c`` and weight ``w(p)`` (H, W), the *push* phase
builds a pyramid by 2×2 weighted averaging, weights clamped to 1 at every level
(``w_{l+1} = min(1, Σ_children w_l / 4·4)``); the *pull* phase goes back up, blending each
level with the bilinear upsampling of the coarser one:
``c_l ← w_l c_l + (1 − w_l) up(c_{l+1})`` with ``w_l ∈ [0, 1]``. A pixel with weight ≥ 1
keeps its colour; any pixel with weight 0 gets a smooth (diffusion-like) fill, so no hole
remains as soon as one pixel has weight > 0.
"""

from __future__ import annotations

import numpy as np

__all__ = ["push_pull"]


def _down(c, w):
    H, W = w.shape
    Hp, Wp = H + (H % 2), W + (W % 2)
    cw = np.zeros((Hp, Wp) + c.shape[2:], np.float32)
    ww = np.zeros((Hp, Wp), np.float32)
    cw[:H, :W] = c * w[..., None]
    ww[:H, :W] = w
    cs = cw.reshape(Hp // 2, 2, Wp // 2, 2, -1).sum((1, 3))
    ws = ww.reshape(Hp // 2, 2, Wp // 2, 2).sum((1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        cd = np.where(ws[..., None] > 0, cs / np.maximum(ws, 1e-300)[..., None], 0.0)
    return cd, np.minimum(ws, 1.0)


def _up(c, shape):
    H, W = shape
    h, w = c.shape[:2]
    # bilinear upsampling aligned on pixel centres (coarse pixel k covers fine 2k, 2k+1)
    ys = np.clip((np.arange(H) - 0.5) / 2.0, 0, h - 1)
    xs = np.clip((np.arange(W) - 0.5) / 2.0, 0, w - 1)
    y0 = np.minimum(np.floor(ys).astype(int), max(h - 2, 0))
    x0 = np.minimum(np.floor(xs).astype(int), max(w - 2, 0))
    fy = (ys - y0)[:, None, None] if h > 1 else np.zeros((H, 1, 1))
    fx = (xs - x0)[None, :, None] if w > 1 else np.zeros((1, W, 1))
    y1 = np.minimum(y0 + 1, h - 1)
    x1 = np.minimum(x0 + 1, w - 1)
    fy = fy.astype(np.float32)
    fx = fx.astype(np.float32)
    rows = c[y0] * (1 - fy) + c[y1] * fy  # bilinear = linear along y, then along x
    return rows[:, x0] * (1 - fx) + rows[:, x1] * fx


def push_pull(colour_sum, weight, eps: float = 1e-8) -> np.ndarray:
    """Fill an image from a splat.

    Parameters
    ----------
    colour_sum : (H, W, C) array
        ``Σ w·c`` per pixel (weighted colour sum).
    weight : (H, W) array
        ``Σ w`` per pixel (≥ 0). A weight ≥ 1 means "fully observed".

    Returns
    -------
    (H, W, C) float32: the normalised colour where ``weight ≥ 1``, a blend with the coarser
    levels where ``0 < weight < 1``, the pulled-up fill where ``weight = 0``.
    """
    S = np.asarray(colour_sum, np.float32)
    squeeze = S.ndim == 2
    if squeeze:
        S = S[..., None]
    w = np.maximum(np.asarray(weight, np.float32), np.float32(0.0))
    c = np.where(w[..., None] > eps, S / np.maximum(w, eps)[..., None], 0.0)
    w = np.minimum(w, 1.0)
    levels = [(c, w)]
    while max(levels[-1][1].shape) > 1:
        levels.append(_down(*levels[-1]))
    c_up = levels[-1][0]
    for cl, wl in reversed(levels[:-1]):
        up = _up(c_up, wl.shape)
        c_up = cl + (1 - wl[..., None]) * (up - cl)  # w·c + (1 − w)·up
    out = c_up.astype(np.float32)
    return out[..., 0] if squeeze else out
