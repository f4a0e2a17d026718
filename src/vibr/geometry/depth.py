"""Depth preparation (paper §5.1–5.3, docs/explanation/method.md §2).

Everything downstream works with **orthogonal** depth ``z`` (the third coordinate of
``R X + t``, see :mod:`vibr.camera`), NaN where unknown. This module converts the other
kinds of depth once, computes the spatial derivatives ``(z_x, z_y)`` that orient each
pixel's surface element, and fills holes with a joint bilateral filter guided by the
image (Kopf et al. 2007).

Unknown depth is always NaN and is never treated as depth 0: every kernel here tests
``z == z`` (finite) before using a value.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..errors import VibrInputError

__all__ = [
    "radial_to_orthogonal",
    "radial_to_orthogonal_derivatives",
    "disparity_to_depth",
    "depth_derivatives",
    "fill_depth_holes",
    "DEFAULT_EDGE_REL",
]

#: Central differences are used where the forward and backward differences agree within
#: ``DEFAULT_EDGE_REL · z`` (a smooth surface: they differ by the curvature term
#: ``z_xx``, a tiny fraction of z); otherwise the pixel sits on a depth discontinuity and
#: the one-sided difference of smaller magnitude (the side the pixel belongs to) is used.
DEFAULT_EDGE_REL = 0.01


def _rays(K: np.ndarray, shape) -> np.ndarray:
    """H×W×3 float64 rays ``K⁻¹ x̄`` for every pixel centre (third coordinate 1)."""
    H, W = shape
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    xb = np.stack([x, y, np.ones_like(x)], axis=-1)
    return xb @ np.linalg.inv(np.asarray(K, dtype=np.float64)).T


def radial_to_orthogonal(h, K) -> np.ndarray:
    """Radial distance → orthogonal depth (docs/explanation/method.md §2 eq. orth).

    ``z_m = h_m / ‖K⁻¹ x̄_m‖``, x̄ = (x, y, 1), pixel centres in vibr's convention.

    Parameters
    ----------
    h : (H, W) array
        Distance from the camera centre along the pixel's ray, scene units; NaN unknown.
    K : (3, 3) array
        Intrinsics.

    Returns
    -------
    (H, W) float32 orthogonal depth, scene units, NaN where ``h`` is unknown.
    """
    h = np.asarray(h, dtype=np.float64)
    n = np.linalg.norm(_rays(K, h.shape), axis=-1)
    return (h / n).astype(np.float32)


def radial_to_orthogonal_derivatives(h, h_x, h_y, K):
    """Derivatives of the orthogonal depth from those of the radial distance.

    With ``r = K⁻¹ x̄`` and ``n = ‖r‖``, ``z = h / n`` gives (docs/explanation/method.md §2)
    ``z_x = (h_x − h · rᵀ K⁻¹[:, 0] / n²) / n`` and the same for ``y`` with column 1.

    Returns ``(z_x, z_y)``, (H, W) float64, scene units per pixel.
    """
    h, h_x, h_y = (np.asarray(a, dtype=np.float64) for a in (h, h_x, h_y))
    Kinv = np.linalg.inv(np.asarray(K, dtype=np.float64))
    r = _rays(K, h.shape)
    n2 = np.einsum("...i,...i->...", r, r)
    n = np.sqrt(n2)
    z_x = (h_x - h * (r @ Kinv[:, 0]) / n2) / n
    z_y = (h_y - h * (r @ Kinv[:, 1]) / n2) / n
    return z_x, z_y


def disparity_to_depth(d, focal_px: float, baseline: float, z0: float = np.inf, source=None) -> np.ndarray:
    """Light-field disparity → orthogonal depth.

    ``z = 1 / (d / (f·b) + 1/Z0)`` where ``d`` is the disparity in pixels per view step,
    ``f`` the focal length in pixels, ``b`` the baseline between adjacent views and
    ``Z0`` the depth of zero disparity (the focus plane of a light field whose views were
    shifted to converge there; ``inf`` for parallel cameras, then ``z = f·b / d``).

    Disparities giving a non-positive or infinite depth (points at or beyond infinity)
    become NaN (unknown), as do NaN disparities. Returns (H, W) float32.
    """
    d = np.asarray(d, dtype=np.float64)
    if focal_px <= 0 or baseline == 0:
        raise VibrInputError(f"disparity_to_depth: bad focal {focal_px} or baseline {baseline}", source)
    inv = d / (focal_px * baseline) + (0.0 if np.isinf(z0) else 1.0 / z0)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = 1.0 / inv
    z[~(np.isfinite(z) & (z > 0))] = np.nan
    return z.astype(np.float32)


@njit(parallel=True, cache=True)
def _derivatives_kernel(z, edge_rel, zx, zy):
    H, W = z.shape
    for i in prange(H):
        for j in range(W):
            c = z[i, j]
            if not (c == c):
                zx[i, j] = np.nan
                zy[i, j] = np.nan
                continue
            for axis in range(2):
                has_f = False
                has_b = False
                f = 0.0
                b = 0.0
                if axis == 0:
                    if j + 1 < W and z[i, j + 1] == z[i, j + 1]:
                        f = z[i, j + 1] - c
                        has_f = True
                    if j > 0 and z[i, j - 1] == z[i, j - 1]:
                        b = c - z[i, j - 1]
                        has_b = True
                else:
                    if i + 1 < H and z[i + 1, j] == z[i + 1, j]:
                        f = z[i + 1, j] - c
                        has_f = True
                    if i > 0 and z[i - 1, j] == z[i - 1, j]:
                        b = c - z[i - 1, j]
                        has_b = True
                if has_f and has_b:
                    if abs(f - b) <= edge_rel * c:
                        g = 0.5 * (f + b)
                    elif abs(f) < abs(b):
                        g = f
                    else:
                        g = b
                elif has_f:
                    g = f
                elif has_b:
                    g = b
                else:
                    g = 0.0  # isolated pixel: fronto-parallel element
                if axis == 0:
                    zx[i, j] = g
                else:
                    zy[i, j] = g


def depth_derivatives(z, edge_rel: float = DEFAULT_EDGE_REL):
    """Spatial derivatives ``(z_x, z_y)`` of a depth map, robust at discontinuities.

    Central differences ``(z[x+1] − z[x−1]) / 2`` where the surface is smooth, i.e. when
    the forward and backward differences agree within ``edge_rel · z``. Across a depth
    discontinuity a central difference mixes two surfaces and gives a huge, meaningless
    slope (the pixel's quad would then stretch across the gap, and its deformation
    weight ``1/|det ∂tau/∂x|`` would collapse or explode); there the one-sided difference
    of smaller magnitude is used, i.e. the slope of the surface the pixel belongs to.
    A missing neighbour (NaN or image border) also gives a one-sided difference; a pixel
    with no known neighbour on an axis gets slope 0 there.

    Parameters
    ----------
    z : (H, W) array
        Orthogonal depth, scene units, NaN unknown.
    edge_rel : float
        Relative jump above which forward/backward differences count as an edge.

    Returns
    -------
    z_x, z_y : (H, W) float64
        Scene units per pixel (x along columns, y along rows); NaN where ``z`` is NaN.
    """
    z = np.ascontiguousarray(z, dtype=np.float64)
    zx = np.empty_like(z)
    zy = np.empty_like(z)
    _derivatives_kernel(z, float(edge_rel), zx, zy)
    return zx, zy


@njit(parallel=True, cache=True)
def _bilateral_fill_pass(cur, guide, radius, inv2ss, inv2sr, min_weight, out):
    H, W = cur.shape
    C = guide.shape[2]
    n_filled = np.zeros(H, np.int64)
    for i in prange(H):
        for j in range(W):
            if cur[i, j] == cur[i, j]:
                out[i, j] = cur[i, j]
                continue
            acc = 0.0
            wsum = 0.0
            for di in range(-radius, radius + 1):
                ii = i + di
                if ii < 0 or ii >= H:
                    continue
                for dj in range(-radius, radius + 1):
                    jj = j + dj
                    if jj < 0 or jj >= W:
                        continue
                    v = cur[ii, jj]
                    if not (v == v):
                        continue
                    dc = 0.0
                    for ch in range(C):
                        t = guide[i, j, ch] - guide[ii, jj, ch]
                        dc += t * t
                    w = np.exp(-(di * di + dj * dj) * inv2ss - dc * inv2sr)
                    acc += w * v
                    wsum += w
            if wsum > min_weight:
                out[i, j] = acc / wsum
                n_filled[i] += 1
            else:
                out[i, j] = np.nan
    return n_filled.sum()


def fill_depth_holes(depth, image, *, radius: int = 4, sigma_space: float = 2.0,
                     sigma_color: float = 0.1, min_weight: float = 1e-3,
                     max_passes: int = 10):
    """Fill unknown depth with a joint bilateral filter guided by the image (Kopf 2007).

    Every unknown pixel ``p`` takes the weighted mean of the known depths ``z_q`` in a
    ``(2·radius+1)²`` window,
    ``z_p = Σ_q w_pq z_q / Σ_q w_pq``,
    ``w_pq = exp(−‖p−q‖² / 2σ_s² − ‖I_p − I_q‖² / 2σ_c²)``,
    so depth flows from pixels of similar colour (the same surface) rather than across
    colour edges. Known depths are never changed. Passes are repeated (each reads the
    previous pass's result, so the output is deterministic) until nothing more fills or
    ``max_passes`` is reached; a pixel whose total weight stays ≤ ``min_weight`` (no
    known depth near it and of similar colour) stays NaN.

    Parameters
    ----------
    depth : (H, W) array, scene units, NaN unknown.
    image : (H, W, 3) float image in [0, 1] (the guide), or None for a purely spatial filter.
    radius, sigma_space : window half size and spatial sigma, pixels.
    sigma_color : colour sigma, image units ([0, 1]).

    Returns
    -------
    filled : (H, W) float32, NaN where still unknown.
    was_filled : (H, W) bool, pixels that were unknown and got a value.
    """
    d = np.ascontiguousarray(depth, dtype=np.float64)
    unknown = ~np.isfinite(d)
    if not unknown.any() or unknown.all():
        return d.astype(np.float32), np.zeros(d.shape, bool)
    if image is None:
        g = np.zeros(d.shape + (1,), np.float64)
    else:
        g = np.ascontiguousarray(image, dtype=np.float64)
        if g.ndim == 2:
            g = g[..., None]
    cur = d.copy()
    out = np.empty_like(cur)
    for _ in range(max_passes):
        n = _bilateral_fill_pass(cur, g, int(radius), 0.5 / sigma_space**2,
                                 0.5 / sigma_color**2, float(min_weight), out)
        cur, out = out, cur
        if n == 0 or np.all(np.isfinite(cur)):
            break
    return cur.astype(np.float32), unknown & np.isfinite(cur)


#: Depth uncertainty of a view that carries none: ``sigma_z = DEFAULT_SIGMA_Z_REL ·
#: median(depth)`` (1 % of the depth, the order of the error of good MVS / light-field
#: estimates; the renderer's geometric weight, docs/explanation/method.md §3, scales with it).
DEFAULT_SIGMA_Z_REL = 0.01

