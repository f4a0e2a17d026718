"""One-pass kernels of the FISTA iteration (speed; the maths is in :mod:`.operators`).

:func:`hessian_terms` computes, for a planar image ``x`` (C, H, W),

    h = alpha · A x + gamma · Dᵀ A_g D x              (the Hessian product H x)

together with the inner products the energy needs, ``⟨x, Ax⟩``, ``⟨b, x⟩``,
``⟨x, DᵀA_gDx⟩``, ``⟨Dᵀb_g, x⟩`` and ``TV(x)``, in **one pass over memory**: it reads the two
9-point stencils, ``x``, ``b`` and ``Dᵀb_g`` once and writes ``h`` once. The intermediate
``D x`` and ``A_g D x`` (six planes each) never leave the cache: each thread walks a band of
rows and keeps three-row ring buffers of them (``A_g D x`` at row k needs ``D x`` at rows
k−1..k+1, ``Dᵀ(A_g D x)`` at row i needs ``A_g D x`` at rows i−1..i+1). The result equals the
composition ``stencil_apply``, ``grad_image``, ``grad_image_adj`` of
:mod:`.operators` to float rounding (tested).

:func:`forward_step` is the FISTA forward step at the extrapolated point from the stored
Hessian products (f is quadratic, so ``H y`` is the same combination of ``H x`` and
``H x_prev`` as ``y`` of ``x`` and ``x_prev``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._runtime.jit import FASTMATH
from .operators import _grad_adj_row, _grad_row, _is_forward, _stencil_row, _sum_in_order
from .tv import _weight_arg

__all__ = ["hessian_terms", "hessian_power", "forward_step", "power_start", "power_scale", "power_unscale",
           "row_sum_bound"]

#: rows per band of :func:`hessian_terms` (halo work ≈ 3 / BAND of a pass)
BAND = 24


@njit(cache=True, fastmath=FASTMATH)
def _dx_row(x, k, forward, dst):
    """Row k of ``D x`` (:func:`.operators._grad_row`, the one gradient) into ``dst``
    (C, 2, W + 2), columns shifted by one so that the zero pads at 0 and W + 1 make the
    stencil's border terms vanish."""
    C, H, W = x.shape
    for c in range(C):
        _grad_row(x[c], k, forward, dst[c, 0, 1:W + 1], dst[c, 1, 1:W + 1])


@njit(cache=True, fastmath=FASTMATH)
def _stencil_row_padded(A, k, um, u0, up, out):
    """out[j] = Σ_s A[s, k, j] · u_dy[j + dx + 1] for padded rows (W + 2) above, at and
    below row k (all-zero rows where they fall outside the image)."""
    W = out.shape[0]
    a0, a1, a2 = A[0, k], A[1, k], A[2, k]
    a3, a4, a5 = A[3, k], A[4, k], A[5, k]
    a6, a7, a8 = A[6, k], A[7, k], A[8, k]
    for j in range(W):
        out[j] = (a0[j] * um[j] + a1[j] * um[j + 1] + a2[j] * um[j + 2]
                  + a3[j] * u0[j] + a4[j] * u0[j + 1] + a5[j] * u0[j + 2]
                  + a6[j] * up[j] + a7[j] * up[j + 1] + a8[j] * up[j + 2])


@njit(cache=True, fastmath=FASTMATH)
def _tv_cols(ur, un, coupled, tvacc, wr, use_w, col):
    """One channel's share of a row of TV into the per-column sums ``col`` (float64):
    coupled, |∇u_c|² into ``tvacc`` (the caller adds w·√tvacc with :func:`_sqrt_cols`);
    else w_j |∇u_c(j)| into col[j] (the terms of :func:`.tv._tv_row`)."""
    W = ur.shape[0]
    if coupled:
        for j in range(W - 1):
            gxv = ur[j + 1] - ur[j]
            gyv = un[j] - ur[j]
            tvacc[j] += gxv * gxv + gyv * gyv
        gyv = un[W - 1] - ur[W - 1]
        tvacc[W - 1] += gyv * gyv
    else:
        for j in range(W - 1):
            gxv = ur[j + 1] - ur[j]
            gyv = un[j] - ur[j]
            col[j] += (wr[j] if use_w else 1.0) * math.sqrt(gxv * gxv + gyv * gyv)
        col[W - 1] += (wr[W - 1] if use_w else 1.0) * abs(un[W - 1] - ur[W - 1])


@njit(cache=True, fastmath=FASTMATH)
def _sqrt_cols(tvacc, wr, use_w, col):
    """col[j] += w_j √tvacc[j] (the coupled TV of a row, per column)."""
    if use_w:
        for j in range(tvacc.shape[0]):
            col[j] += wr[j] * math.sqrt(tvacc[j])
    else:
        for j in range(tvacc.shape[0]):
            col[j] += math.sqrt(tvacc[j])


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _hessian_terms(A, Ag, x, b, bgt, alpha, gamma, use_grad, forward, coupled, wmap, use_w, with_terms, band,
                   h, parts):
    C, H, W = x.shape
    n_bands = parts.shape[0]
    for t in prange(n_bands):
        r0 = t * band
        r1 = min(H, r0 + band)
        # the inner products are summed per column over the band's rows, then over the
        # columns in order: every row loop stays free of a loop-carried sum (it vectorises
        # without fast-math) and the result does not depend on the thread count
        acc = np.zeros((6, W))
        s_xAx, s_bx, s_xGx, s_gx, s_tv, s_hh = acc[0], acc[1], acc[2], acc[3], acc[4], acc[5]
        ax = np.empty(W, np.float32)
        tvacc = np.empty(W, np.float32)
        # ring buffers (row mod 3): D x padded, A_g D x; tags = the row a slot holds
        dring = np.zeros((3, C, 2, W + 2), np.float32)
        gring = np.zeros((3, C, 2, W), np.float32)
        zero = np.zeros(W + 2, np.float32)
        dtag = np.full(3, -10, np.int64)
        gx_row = np.empty(W, np.float32)
        for k in range(r0 - 1, r1 + 1):
            if use_grad and 0 <= k < H:
                # A_g D x at row k, from D x at rows k-1..k+1
                for kk in range(max(k - 1, 0), min(k + 2, H)):
                    s = kk % 3
                    if dtag[s] != kk:
                        _dx_row(x, kk, forward, dring[s])
                        dtag[s] = kk
                g = gring[k % 3]
                for c in range(C):
                    for d in range(2):
                        um = dring[(k - 1) % 3, c, d] if k >= 1 else zero
                        up = dring[(k + 1) % 3, c, d] if k + 1 < H else zero
                        _stencil_row_padded(Ag, k, um, dring[k % 3, c, d], up, g[c, d])
            i = k - 1
            if i < r0 or i >= r1:
                continue
            # output row i
            if coupled:
                tvacc[:] = 0.0
            nxt = min(i + 1, H - 1)
            wr = wmap[min(np.int64(i), wmap.shape[0] - 1)]
            for c in range(C):
                _stencil_row(A, x, c, i, ax)
                xr = x[c, i]
                br = b[c, i]
                hr = h[c, i]
                if use_grad:
                    # Dᵀ(A_g D x) at row i (slots of rows outside the image are not read)
                    _grad_adj_row(gring[i % 3, c, 0], gring[(i - 1) % 3, c, 1], gring[i % 3, c, 1],
                                  gring[(i + 1) % 3, c, 1], i, H, forward, gx_row)
                    if with_terms:
                        gr = bgt[c, i]
                        for j in range(W):
                            xv = np.float64(xr[j])
                            s_xAx[j] += xv * ax[j]
                            s_bx[j] += xv * br[j]
                            s_xGx[j] += xv * gx_row[j]
                            s_gx[j] += xv * gr[j]
                            hr[j] = alpha * ax[j] + gamma * gx_row[j]
                    else:
                        for j in range(W):
                            xv = np.float64(xr[j])
                            s_xAx[j] += xv * ax[j]
                            s_xGx[j] += xv * gx_row[j]
                            hv = alpha * ax[j] + gamma * gx_row[j]
                            hr[j] = hv
                            s_hh[j] += np.float64(hv) * hv
                elif with_terms:
                    for j in range(W):
                        xv = np.float64(xr[j])
                        s_xAx[j] += xv * ax[j]
                        s_bx[j] += xv * br[j]
                        hr[j] = alpha * ax[j]
                else:
                    for j in range(W):
                        s_xAx[j] += np.float64(xr[j]) * ax[j]
                        hv = alpha * ax[j]
                        hr[j] = hv
                        s_hh[j] += np.float64(hv) * hv
                if with_terms:
                    _tv_cols(xr, x[c, nxt], coupled, tvacc, wr, use_w, s_tv)
            if coupled and with_terms:
                _sqrt_cols(tvacc, wr, use_w, s_tv)
        for q in range(6):
            tot = 0.0
            for j in range(W):
                tot += acc[q, j]
            parts[t, q] = tot


def hessian_terms(A, Ag, x, b, bgt, alpha, gamma, coupled=True, out=None, scheme="forward", tv_weight=None):
    """``(h, (⟨x,Ax⟩, ⟨b,x⟩, ⟨x,DᵀA_gDx⟩, ⟨Dᵀb_g,x⟩, TV(x)))`` in one pass (module doc).

    ``A``, ``Ag`` (9, H, W) float32 stencils (``Ag`` None or gamma = 0: colour term only;
    the gradient entries are then 0); ``scheme`` the discretisation of D
    (:data:`.operators.GRAD_SCHEMES`); ``tv_weight`` (H, W) the spatially varying TV's
    weight map (:func:`.tv.tv_value`), ``x``, ``b``, ``bgt`` (C, H, W) float32 planar;
    ``h`` = ``alpha·Ax + gamma·DᵀA_gDx`` is written to ``out`` (allocated when None).
    Inner products are accumulated in float64."""
    h, s = _run(A, Ag, x, b, bgt, alpha, gamma, coupled, True, out, scheme, tv_weight)
    return h, (float(s[0]), float(s[1]), float(s[2]), float(s[3]), float(s[4]))


def hessian_power(A, Ag, x, alpha, gamma, out=None, scheme="forward"):
    """One power-iteration pass: ``h = alpha·Ax + gamma·DᵀA_gDx`` into ``out``, with
    ``(⟨x,Ax⟩, ⟨x,DᵀA_gDx⟩, ‖h‖²)``; reads only the stencils and ``x`` (no energy terms)."""
    h, s = _run(A, Ag, x, x, x, alpha, gamma, True, False, out, scheme, None)
    return h, (float(s[0]), float(s[2]), float(s[5]))


def _run(A, Ag, x, b, bgt, alpha, gamma, coupled, with_terms, out, scheme, tv_weight):
    C, H, W = x.shape
    use_grad = Ag is not None and gamma != 0
    if out is None:
        out = np.empty_like(x)
    n_bands = (H + BAND - 1) // BAND
    parts = np.zeros((n_bands, 6))
    if not use_grad:
        Ag, bgt = A, b  # unused placeholders of the right types
    _hessian_terms(A, Ag, x, b, bgt, np.float32(alpha), np.float32(gamma), use_grad,
                   _is_forward(scheme), bool(coupled), *_weight_arg(tv_weight),
                   bool(with_terms), BAND, out, parts)
    return out, parts.sum(0)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _power_scale(x, s, v, xs):
    """``x ← x / v``, ``xs = s · x`` (x (C, n), s (n,)): the numpy ``x /= v`` (v float32)
    and ``np.multiply(x, s)`` of the preconditioned power iteration in one pass."""
    C, n = x.shape
    blk = 4096
    for t in prange((n + blk - 1) // blk):
        i0 = t * blk
        i1 = min(n, i0 + blk)
        sb = s[i0:i1]
        for c in range(C):
            xb, ob = x[c, i0:i1], xs[c, i0:i1]
            for i in range(i1 - i0):
                xv = xb[i] / v
                xb[i] = xv
                ob[i] = xv * sb[i]


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _power_unscale(y, s, x):
    """``y ← s · y`` (y, x flat (C·n,), s (n,)) with ``(⟨x, y⟩, ⟨y, y⟩)`` of the new y,
    summed in the chunks and order of :func:`.operators.dot` (bit-identical to it)."""
    N = y.shape[0]
    n = s.shape[0]
    nb = 256
    chunk = (N + nb - 1) // nb
    parts = np.zeros((2, nb))
    for k in prange(nb):
        i0 = k * chunk
        i1 = min(N, i0 + chunk)
        j = i0 % n if i0 < N else 0
        sxy = 0.0
        syy = 0.0
        for i in range(i0, i1):
            yv = y[i] * s[j]
            y[i] = yv
            sxy += np.float64(x[i]) * np.float64(yv)
            syy += np.float64(yv) * np.float64(yv)
            j += 1
            if j == n:
                j = 0
        parts[0, k] = sxy
        parts[1, k] = syy
    return _sum_in_order(parts[0]), _sum_in_order(parts[1])


def power_scale(x, s, nx, out):
    """Normalise ``x`` (C, H, W) in place by ``√nx`` (float32, as numpy's ``x /= √nx``)
    and write ``s · x`` (``s`` (H, W)) to ``out``: the scaled vector a preconditioned
    power iteration multiplies by H."""
    C = x.shape[0]
    _power_scale(x.reshape(C, -1), s.reshape(-1), np.float32(math.sqrt(max(nx, 1e-300))), out.reshape(C, -1))
    return out


def power_unscale(y, s, x):
    """``y ← s · y`` in place and ``(⟨x, y⟩, ⟨y, y⟩)`` (float64, as :func:`.operators.dot`)."""
    a, b = _power_unscale(y.reshape(-1), s.reshape(-1), x.reshape(-1))
    return float(a), float(b)


@njit(parallel=True, cache=True)
def _power_start(out):
    # a deterministic, zero-mean pseudo-random vector (splitmix-style integer hash): every
    # eigenvector has a component, and it costs one write pass (no RNG state)
    n = out.shape[0]
    for i in prange(n):
        z = np.uint64(i + 1) * np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(31))) * np.uint64(0xBF58476D1CE4E5B9)
        z = z ^ (z >> np.uint64(29))
        out[i] = np.float32(np.float64(z >> np.uint64(40)) / 16777216.0 - 0.5)


def power_start(shape):
    """A deterministic start vector for power iterations (float32, uniform in [−½, ½))."""
    out = np.empty(shape, np.float32)
    _power_start(out.reshape(-1))
    return out


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _forward_kernel(x, xp, hx, hxp, r, beta, dinv, step, out):
    # blocks of contiguous pixels, channels outside the inner loop: every stream is
    # read sequentially and the inner loop vectorises
    C, n = x.shape
    use_d = dinv.shape[0] == n
    blk = 4096
    for t in prange((n + blk - 1) // blk):
        i0 = t * blk
        i1 = min(n, i0 + blk)
        m = i1 - i0
        dv = dinv[i0:i1] if use_d else dinv[:0]
        for c in range(C):
            # slices indexed from 0: with range(i0, i1) numba's negative-index wraparound
            # made LLVM gather each element instead of loading vectors (docs/explanation/renderer.md)
            xc, xpc, hc, hpc = x[c, i0:i1], xp[c, i0:i1], hx[c, i0:i1], hxp[c, i0:i1]
            rc, oc = r[c, i0:i1], out[c, i0:i1]
            if use_d:
                for i in range(m):
                    y = xc[i] + beta * (xc[i] - xpc[i])
                    hy = hc[i] + beta * (hc[i] - hpc[i])
                    oc[i] = y - step * dv[i] * (hy - rc[i])
            else:
                for i in range(m):
                    y = xc[i] + beta * (xc[i] - xpc[i])
                    hy = hc[i] + beta * (hc[i] - hpc[i])
                    oc[i] = y - step * (hy - rc[i])


def forward_step(x, hx, r, step, dinv=None, x_prev=None, h_prev=None, beta=0.0, out=None):
    """``y − step · d⁻¹ · (H y − r)`` at ``y = x + beta (x − x_prev)``, with
    ``H y = hx + beta (hx − h_prev)``: planar (C, H, W) float32; ``dinv`` (H, W) or None."""
    if x_prev is None or beta == 0.0:
        x_prev, h_prev, beta = x, hx, 0.0
    C = x.shape[0]
    if out is None:
        out = np.empty_like(x)
    d = np.zeros(0, np.float32) if dinv is None else np.ascontiguousarray(dinv, np.float32).ravel()
    flat = lambda a: a.reshape(C, -1)  # noqa: E731
    _forward_kernel(flat(x), flat(x_prev), flat(hx), flat(h_prev), flat(r), np.float32(beta), d,
                    np.float32(step), flat(out))
    return out


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _row_sum_bound(A, Ag, alpha, gk, use_grad, rg, out):
    S, H, W = A.shape
    if use_grad:
        for i in prange(H):
            for j in range(W):
                s = abs(Ag[0, i, j])
                for k in range(1, S):
                    s += abs(Ag[k, i, j])
                rg[i, j] = s
    for i in prange(H):
        for j in range(W):
            s = abs(A[0, i, j])
            for k in range(1, S):
                s += abs(A[k, i, j])
            d = alpha * s
            if use_grad:
                m = rg[i, j]
                for ii in range(max(i - 1, 0), min(i + 2, H)):
                    for jj in range(max(j - 1, 0), min(j + 2, W)):
                        m = max(m, rg[ii, jj])
                d = d + gk * m
            out[i, j] = d


def row_sum_bound(A, Ag, alpha, gamma_k):
    """``alpha · Σ_s |A_s| + gamma_k · max₃ₓ₃(Σ_s |Ag_s|)`` (H, W) float32 in one pass each
    (the 3×3 maximum with the border pixels repeated, scipy's ``mode="nearest"``; ``Ag``
    None: the first term only). Sums in stencil order, float32, as numpy's axis-0 sum."""
    use_grad = Ag is not None
    S, H, W = A.shape
    out = np.empty((H, W), np.float32)
    rg = np.empty((H, W) if use_grad else (0, 0), np.float32)
    _row_sum_bound(A, A if Ag is None else Ag, np.float32(alpha), np.float32(gamma_k), use_grad, rg, out)
    return out
