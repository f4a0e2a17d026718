"""Warps ``tau_k`` and their analytic Jacobians (paper §5.2–5.4, docs/explanation/method.md §2).

For a source view k with camera (K_k, R_k, t_k, centre C_k) and the target u, the warp
of source pixel x_m with orthogonal depth z_m is (eq. projection)

    tau_k(x_m) = N_e( K_u ( R_u ( z_m R_kᵀ K_k⁻¹ x̄_m + C_k ) + t_u ) ),

which we write ``x̃_p = z_m · M x̄_m + c`` with the two per-view constants

    M = K_u R_u R_kᵀ K_k⁻¹          (3×3)
    c = K_u ( R_u C_k + t_u )        (3,)

and ``N_e(x, y, w) = (x/w, y/w)``. The third coordinate ``w`` of x̃_p is the sample's
orthogonal depth seen from the target (K's last row is (0, 0, 1)).

Jacobians, with ``J_e(x̃) = [[1/w, 0, −x/w²], [0, 1/w, −y/w²]]``:

* w.r.t. the source pixel (eq. deformation), z = z(x, y) with slopes (z_x, z_y):
  ``∂tau/∂x_m = J_e(x̃_p) · M · [[z_x x + z, z_y x], [z_x y, z_y y + z], [z_x, z_y]]
  = J_e(x̃_p) · ( z M[:, :2] + (M x̄) (z_x, z_y) )``;
* w.r.t. depth (eq. geometrie): ``∂tau/∂z = J_e(x̃_p) · M x̄``.

The deformation weight is ``1/|det ∂tau/∂x_m|``, capped at ``max_inv_det`` (see
:data:`DEFAULT_MAX_INV_DET`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..camera import Camera
from .depth import depth_derivatives

__all__ = ["warp_constants", "warp_view", "warp_points", "DEFAULT_MAX_INV_DET"]

#: Cap of the deformation weight ``1/|det ∂tau/∂x_m|``. The determinant is the area of a
#: source pixel's footprint in the target; it goes to 0 where a surface is seen at a
#: grazing angle from the source (or where a residual slope at a depth edge shears the
#: quad), and 1/det would then give one sample an unbounded weight. The cap is a safety
#: bound, not the weighting policy: 4 = a source pixel covering a quarter of a target
#: pixel (a source at twice the target's resolution); beyond that, extra resolution is not
#: rewarded. The authors' public code caps at 1 in unstructured scenes (docs/explanation/method.md §10): pass
#: ``max_inv_det=1`` to ``compute_samples`` (or cap in the renderer's
#: ``vibr.render.weights.deformation_weight``) to reproduce it.
DEFAULT_MAX_INV_DET = 4.0


def warp_constants(src: Camera, tgt: Camera):
    """Per-view constants of the warp: ``M = K_u R_u R_kᵀ K_k⁻¹`` and
    ``c = K_u (R_u C_k + t_u)`` (float64, shapes (3, 3) and (3,))."""
    M = tgt.K @ tgt.R @ src.R.T @ np.linalg.inv(src.K)
    c = tgt.K @ (tgt.R @ src.centre + tgt.t)
    return np.ascontiguousarray(M), np.ascontiguousarray(c)


@njit(cache=True, inline="always")
def _warp_one(x, y, z, zx, zy, M, c, out):
    """Fill out[0:10] = (u, v, w, J00, J01, J10, J11, dz0, dz1, det). Returns w."""
    # q = M x̄
    q0 = M[0, 0] * x + M[0, 1] * y + M[0, 2]
    q1 = M[1, 0] * x + M[1, 1] * y + M[1, 2]
    q2 = M[2, 0] * x + M[2, 1] * y + M[2, 2]
    p0 = z * q0 + c[0]
    p1 = z * q1 + c[1]
    w = z * q2 + c[2]
    iw = 1.0 / w
    u = p0 * iw
    v = p1 * iw
    # A = z M[:, :2] + q (z_x, z_y): ∂x̃_p/∂(x, y)
    a00 = z * M[0, 0] + q0 * zx
    a01 = z * M[0, 1] + q0 * zy
    a10 = z * M[1, 0] + q1 * zx
    a11 = z * M[1, 1] + q1 * zy
    a20 = z * M[2, 0] + q2 * zx
    a21 = z * M[2, 1] + q2 * zy
    # J_e A, J_e = [[1/w, 0, -u/w], [0, 1/w, -v/w]]
    j00 = (a00 - u * a20) * iw
    j01 = (a01 - u * a21) * iw
    j10 = (a10 - v * a20) * iw
    j11 = (a11 - v * a21) * iw
    out[0] = u
    out[1] = v
    out[2] = w
    out[3] = j00
    out[4] = j01
    out[5] = j10
    out[6] = j11
    out[7] = (q0 - u * q2) * iw
    out[8] = (q1 - v * q2) * iw
    out[9] = j00 * j11 - j01 * j10
    return w


@njit(cache=True, inline="always")
def _project_one(x, y, z, M, c):
    """``(u, v)`` of :func:`_warp_one`, with the same arithmetic (bit-identical), alone."""
    q0 = M[0, 0] * x + M[0, 1] * y + M[0, 2]
    q1 = M[1, 0] * x + M[1, 1] * y + M[1, 2]
    q2 = M[2, 0] * x + M[2, 1] * y + M[2, 2]
    iw = 1.0 / (z * q2 + c[2])
    return (z * q0 + c[0]) * iw, (z * q1 + c[1]) * iw


@njit(parallel=True, cache=True)
def _warp_field_kernel(xs, ys, z, zx, zy, M, c, out):
    n = xs.shape[0]
    for k in prange(n):
        buf = np.empty(10)
        if not (z[k] == z[k]):
            for t in range(10):
                out[k, t] = np.nan
            continue
        _warp_one(xs[k], ys[k], z[k], zx[k], zy[k], M, c, buf)
        for t in range(10):
            out[k, t] = buf[t]


def warp_points(src: Camera, tgt: Camera, xy, z, z_x=None, z_y=None) -> dict:
    """Warp arbitrary source points (vectorised over N points, float64).

    Parameters
    ----------
    xy : (N, 2) source pixel coordinates; z : (N,) orthogonal depth (scene units);
    z_x, z_y : (N,) depth slopes (scene units per pixel), default 0.

    Returns
    -------
    dict with ``tau`` (N, 2) target pixels, ``w`` (N,) depth seen from the target,
    ``jac`` (N, 2, 2) ∂tau/∂x_m, ``det`` (N,), ``dtau_dz`` (N, 2) target px per scene unit.
    Entries are NaN where z is NaN; where ``w ≤ 0`` (behind the target) they are
    meaningless and the caller must test ``w``.
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    z = np.asarray(z, dtype=np.float64).ravel()
    zx = np.zeros_like(z) if z_x is None else np.asarray(z_x, dtype=np.float64).ravel()
    zy = np.zeros_like(z) if z_y is None else np.asarray(z_y, dtype=np.float64).ravel()
    M, c = warp_constants(src, tgt)
    out = np.empty((z.size, 10))
    with np.errstate(all="ignore"):
        _warp_field_kernel(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
                           z, zx, zy, M, c, out)
    return {
        "tau": out[:, 0:2].copy(),
        "w": out[:, 2].copy(),
        "jac": out[:, 3:7].reshape(-1, 2, 2).copy(),
        "dtau_dz": out[:, 7:9].copy(),
        "det": out[:, 9].copy(),
    }


def warp_view(src: Camera, tgt: Camera, depth, z_x=None, z_y=None) -> dict:
    """Warp every pixel of a source depth map (fields of shape (H, W, ...)).

    Same outputs as :func:`warp_points`, reshaped to the source image: ``tau`` (H, W, 2),
    ``w`` (H, W), ``jac`` (H, W, 2, 2), ``det`` (H, W), ``dtau_dz`` (H, W, 2). If the slopes
    are not given they are computed with :func:`vibr.geometry.depth.depth_derivatives`.
    """

    z = np.asarray(depth, dtype=np.float64)
    H, W = z.shape
    if z_x is None or z_y is None:
        z_x, z_y = depth_derivatives(z)
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    r = warp_points(src, tgt, np.stack([x.ravel(), y.ravel()], 1), z.ravel(),
                    np.asarray(z_x).ravel(), np.asarray(z_y).ravel())
    return {
        "tau": r["tau"].reshape(H, W, 2),
        "w": r["w"].reshape(H, W),
        "jac": r["jac"].reshape(H, W, 2, 2),
        "dtau_dz": r["dtau_dz"].reshape(H, W, 2),
        "det": r["det"].reshape(H, W),
    }
