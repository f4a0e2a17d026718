"""Push–pull hole filling (Gortler et al. 1996, "The Lumigraph", §3.4; docs/explanation/method.md §6).

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
from numba import njit, prange

__all__ = ["push_pull"]


@njit(parallel=True, cache=True)
def _down(c, w):
    """One push level: 2×2 weighted averages of ``c`` (H, W, C) with weights ``w`` (H, W)
    (odd sizes padded with weight 0), and the weights' sums clamped to 1."""
    H, W, C = c.shape
    h, wd = (H + 1) // 2, (W + 1) // 2
    cd = np.zeros((h, wd, C), np.float32)
    ws = np.empty((h, wd), np.float32)
    for i in prange(h):
        cs = np.empty(C, np.float32)
        for j in range(wd):
            s = np.float32(0.0)
            cs[:] = 0.0
            for di in range(2):
                ii = 2 * i + di
                if ii >= H:
                    continue
                for dj in range(2):
                    jj = 2 * j + dj
                    if jj >= W:
                        continue
                    wv = w[ii, jj]
                    s += wv
                    for k in range(C):
                        cs[k] += c[ii, jj, k] * wv
            if s > 0:
                for k in range(C):
                    cd[i, j, k] = cs[k] / s
            ws[i, j] = min(s, np.float32(1.0))
    return cd, ws


@njit(cache=True)
def _axis(n, m):
    """Bilinear up-sampling from m to n samples, aligned on pixel centres (coarse pixel k
    covers fine 2k, 2k + 1): (lower index, upper index, fraction) per fine sample."""
    i0 = np.empty(n, np.int64)
    i1 = np.empty(n, np.int64)
    f = np.zeros(n, np.float32)
    for i in range(n):
        t = min(max((i - 0.5) / 2.0, 0.0), m - 1.0)
        k = min(int(np.floor(t)), max(m - 2, 0))
        i0[i] = k
        i1[i] = min(k + 1, m - 1)
        if m > 1:
            f[i] = np.float32(t - k)
    return i0, i1, f


@njit(parallel=True, cache=True)
def _pull(c_up, cl, wl):
    """One pull level: ``cl + (1 − wl)(up(c_up) − cl)`` with ``up`` the bilinear
    up-sampling of the coarser level ``c_up`` to the shape of ``cl``."""
    H, W, C = cl.shape
    h, w = c_up.shape[:2]
    y0, y1, fy = _axis(H, h)
    x0, x1, fx = _axis(W, w)
    out = np.empty_like(cl)
    one = np.float32(1.0)
    for i in prange(H):
        a, b, ty = y0[i], y1[i], fy[i]
        for j in range(W):
            p, q, tx = x0[j], x1[j], fx[j]
            for k in range(C):
                r0 = c_up[a, p, k] * (one - ty) + c_up[b, p, k] * ty
                r1 = c_up[a, q, k] * (one - ty) + c_up[b, q, k] * ty
                up = r0 * (one - tx) + r1 * tx
                out[i, j, k] = cl[i, j, k] + (one - wl[i, j]) * (up - cl[i, j, k])
    return out


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
    c = np.where(w[..., None] > eps, S / np.maximum(w, np.float32(eps))[..., None], np.float32(0.0))
    w = np.minimum(w, np.float32(1.0))
    levels = [(np.ascontiguousarray(c, np.float32), np.ascontiguousarray(w))]
    while max(levels[-1][1].shape) > 1:
        levels.append(_down(*levels[-1]))
    c_up = levels[-1][0]
    for cl, wl in reversed(levels[:-1]):
        c_up = _pull(c_up, cl, wl)  # w·c + (1 − w)·up
    out = c_up
    return out[..., 0] if squeeze else out
