"""Total variation: value and proximal operator (docs/explanation/method.md §5, E_prior = TV(u)).

``TV(u) = Σ_p |∇u(p)|`` with forward differences (:func:`~vibr.render.operators.grad_fwd`);
``coupled=True`` is the vectorial (colour-coupled) TV ``Σ_p sqrt(Σ_c |∇u_c(p)|²)``,
``coupled=False`` the channel-wise sum ``Σ_c Σ_p |∇u_c(p)|``.

The proximal step of FISTA solves the (weighted) ROF problem

    x = argmin_x ½ Σ_p d(p) |x(p) − z(p)|² + mu · TV(x)

by the Beck–Teboulle (2009, "Fast gradient-based algorithms for constrained total
variation image denoising and deblurring") fast gradient projection on the dual:
``x = z + mu · d⁻¹ · div p``, ``p ← P_{|p|≤1}(r + ∇x / (8 mu max d⁻¹))`` with Nesterov momentum
on ``p``. ``d ≡ 1`` is the plain prox; a per-pixel ``d`` is the prox in the diagonal metric
of a preconditioned (variable-metric) FISTA. The dual ``p`` is kept between calls (warm
start), so a few inner iterations per outer step suffice.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._runtime.jit import FASTMATH
from .operators import _sum_in_order

__all__ = ["tv_value", "TVProx"]


@njit(cache=True, fastmath=FASTMATH)
def _tv_row(ur, un, coupled, acc, wr, use_w):
    """One channel's share of a row of TV (forward differences, Neumann): ``ur`` the row,
    ``un`` the next one (the row itself on the last row). Coupled: adds |∇u_c|² to ``acc``
    (W,) and returns 0 (the caller sums w·√acc over channels); else returns Σ_j w_j |∇u_c|
    (``wr`` the row of the TV weight map, used when ``use_w``)."""
    W = ur.shape[0]
    s = 0.0
    if coupled:
        for j in range(W - 1):
            gx = ur[j + 1] - ur[j]
            gy = un[j] - ur[j]
            acc[j] += gx * gx + gy * gy
        gy = un[W - 1] - ur[W - 1]
        acc[W - 1] += gy * gy
    else:
        for j in range(W - 1):
            gx = ur[j + 1] - ur[j]
            gy = un[j] - ur[j]
            s += (wr[j] if use_w else 1.0) * math.sqrt(gx * gx + gy * gy)
        s += (wr[W - 1] if use_w else 1.0) * abs(un[W - 1] - ur[W - 1])
    return s


@njit(cache=True, fastmath=FASTMATH)
def _sqrt_sum(acc, wr, use_w):
    s = 0.0
    if use_w:
        for j in range(acc.shape[0]):
            s += wr[j] * math.sqrt(acc[j])
    else:
        for j in range(acc.shape[0]):
            s += math.sqrt(acc[j])
    return s


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _tv_value(u, coupled, wmap, use_w):
    C, H, W = u.shape
    rows = np.zeros(H)
    for i in prange(H):
        acc = np.zeros(W, np.float32)
        nxt = min(i + 1, H - 1)  # last row: gy = 0
        wr = wmap[min(np.int64(i), wmap.shape[0] - 1)]
        s = 0.0
        for c in range(C):
            s += _tv_row(u[c, i], u[c, nxt], coupled, acc, wr, use_w)
        if coupled:
            s += _sqrt_sum(acc, wr, use_w)
        rows[i] = s
    return _sum_in_order(rows)  # not rows.sum(): a parallel reduction, thread-count dependent


def tv_value(u, coupled: bool = True, weight=None) -> float:
    """``TV(u)`` of a planar (C, H, W) image (or (H, W)), see the module docstring;
    ``weight`` (H, W): the spatially varying TV ``Σ_p weight(p) |∇u(p)|``."""
    if u.ndim == 2:
        u = u[None]
    w, use_w = _weight_arg(weight)
    return float(_tv_value(u, coupled, w, use_w))


def _weight_arg(weight):
    """(array, use) for the kernels: the (H, W) float32 weight map, or a dummy."""
    if weight is None:
        return np.ones((1, 1), np.float32), False
    return np.ascontiguousarray(weight, dtype=np.float32), True


#: rows per band of :func:`_dual_step` (each thread walks its band once)
BAND = 24


@njit(cache=True, fastmath=FASTMATH)
def _r_row(p, p_old, beta, k, out):
    """Row k of the extrapolated dual r = p + beta (p − p_old) into out (C, 2, W)."""
    C = p.shape[0]
    W = p.shape[3]
    for c in range(C):
        for d in range(2):
            pr = p[c, d, k]
            po = p_old[c, d, k]
            o = out[c, d]
            for j in range(W):
                o[j] = pr[j] + beta * (pr[j] - po[j])


@njit(cache=True, fastmath=FASTMATH)
def _x_row(z, rk, rkm, mu, dinv, use_d, k, o):
    """Row k of x = z + mu · d⁻¹ · div r from the dual rows k (rk) and k − 1 (rkm),
    (C, 2, W) each (``div_bwd``: Neumann, r_x[W−1] and r_y[H−1] are 0)."""
    C, H, W = z.shape
    for c in range(C):
        px = rk[c, 0]
        orow = o[c]
        if W > 1:
            orow[0] = px[0]
            for j in range(1, W - 1):
                orow[j] = px[j] - px[j - 1]
            orow[W - 1] = -px[W - 2]
        else:
            orow[0] = 0.0
        if H > 1:
            if k < H - 1:
                py = rk[c, 1]
                for j in range(W):
                    orow[j] += py[j]
            if k > 0:
                pm = rkm[c, 1]
                for j in range(W):
                    orow[j] -= pm[j]
        zr = z[c, k]
        if use_d:
            dr = dinv[k]
            for j in range(W):
                orow[j] = zr[j] + mu * dr[j] * orow[j]
        else:
            for j in range(W):
                orow[j] = zr[j] + mu * orow[j]


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _primal(z, p, mu, dinv, use_d, band, x):
    """x = z + mu · d⁻¹ · div p, planar: z, x (C, H, W), p (C, 2, H, W).

    Rows go through contiguous buffers: the strided (C, 2, W) view of one row of p
    (or (C, W) of x) would keep the row loops from vectorising (6× slower)."""
    C, H, W = z.shape
    n_bands = (H + band - 1) // band
    for t in prange(n_bands):
        r0 = t * band
        r1 = min(H, r0 + band)
        ring = np.zeros((2, C, 2, W), np.float32)
        xrow = np.empty((C, W), np.float32)
        for i in range(max(r0 - 1, 0), r1):
            _r_row(p, p, np.float32(0.0), i, ring[i % 2])
            if i >= r0:
                _x_row(z, ring[i % 2], ring[(i + 1) % 2], mu, dinv, use_d, i, xrow)
                for c in range(C):
                    x[c, i, :] = xrow[c]


@njit(parallel=True, cache=True, fastmath=FASTMATH, error_model="numpy")
def _dual_step(z, p, p_old, beta, mu, dinv, use_d, step, coupled, wmap, use_w, band, p_new, primal,
               x_out):
    """One accelerated dual step (Beck & Teboulle 2009, FGP): at r = p + beta (p − p_old),
    x = z + mu d⁻¹ div r, p_new = P_{|·|≤w}(r + step ∇x) (w = 1, or the weight map
    ``wmap`` of the spatially varying TV when ``use_w``); with ``primal``, also the
    prox's result ``x_out = z + mu d⁻¹ div p_new`` (the last step of a call).

    Each thread walks a band of rows keeping two-row rings of r, x and p_new, so every row
    of them is formed once, in cache, and r and x are never stored: the pass reads z, p
    (and p_old when beta ≠ 0) and writes p_new (and x_out). p_new must not alias p or
    p_old. ``x_out`` at the band's first row needs p_new one row above: that row is
    recomputed (halo) rather than read from another thread's band."""
    C, H, W = z.shape
    n_bands = (H + band - 1) // band
    for t in prange(n_bands):
        r0 = t * band
        r1 = min(H, r0 + band)
        i0 = r0 - 1 if primal and r0 > 0 else r0
        rr = np.zeros((2, C, 2, W), np.float32)
        xr = np.empty((2, C, W), np.float32)
        pr = np.zeros((2, C, 2, W), np.float32)
        xo = np.empty((C, W), np.float32)
        q = np.empty((C, 2, W), np.float32)
        nrm = np.empty(W, np.float32)
        one = np.float32(1.0)
        if i0 > 0:
            _r_row(p, p_old, beta, i0 - 1, rr[(i0 - 1) % 2])
        _r_row(p, p_old, beta, i0, rr[i0 % 2])
        _x_row(z, rr[i0 % 2], rr[(i0 + 1) % 2], mu, dinv, use_d, i0, xr[i0 % 2])
        for i in range(i0, r1):
            if i + 1 < H:
                # r row i−1 is no longer needed: its slot takes row i+1
                _r_row(p, p_old, beta, i + 1, rr[(i + 1) % 2])
                _x_row(z, rr[(i + 1) % 2], rr[i % 2], mu, dinv, use_d, i + 1, xr[(i + 1) % 2])
            ri = rr[i % 2]
            xi = xr[i % 2]
            xn = xr[(i + 1) % 2]
            if coupled:
                nrm[:] = 0.0
            for c in range(C):
                xrow = xi[c]
                qx = q[c, 0]
                qy = q[c, 1]
                rx = ri[c, 0]
                ry = ri[c, 1]
                for j in range(W - 1):
                    qx[j] = rx[j] + step * (xrow[j + 1] - xrow[j])
                qx[W - 1] = rx[W - 1]
                if i < H - 1:
                    xnr = xn[c]
                    for j in range(W):
                        qy[j] = ry[j] + step * (xnr[j] - xrow[j])
                else:
                    for j in range(W):
                        qy[j] = ry[j]
                if coupled:
                    for j in range(W):
                        nrm[j] += qx[j] * qx[j] + qy[j] * qy[j]
            wr = wmap[min(np.int64(i), wmap.shape[0] - 1)]
            if coupled:
                if use_w:
                    for j in range(W):
                        nrm[j] = one / max(one, math.sqrt(nrm[j]) / wr[j])
                else:
                    for j in range(W):
                        nrm[j] = one / max(one, math.sqrt(nrm[j]))
            pi = pr[i % 2]
            for c in range(C):
                if not coupled:
                    for j in range(W):
                        a = math.sqrt(q[c, 0, j] * q[c, 0, j] + q[c, 1, j] * q[c, 1, j])
                        nrm[j] = one / max(one, a / wr[j] if use_w else a)
                for d in range(2):
                    qd = q[c, d]
                    pd = pi[c, d]
                    for j in range(W):
                        pd[j] = qd[j] * nrm[j]
            if i < r0:
                continue  # the halo row: only needed as p_new one row above r0
            for c in range(C):
                for d in range(2):
                    p_new[c, d, i, :] = pi[c, d]
            if primal:
                _x_row(z, pi, pr[(i + 1) % 2], mu, dinv, use_d, i, xo)
                for c in range(C):
                    x_out[c, i, :] = xo[c]


class TVProx:
    """Warm-started prox of ``mu·TV`` (optionally in a diagonal metric ``d``).

    Parameters
    ----------
    shape : (C, H, W)
        Planar image shape.
    coupled : bool
        Vectorial colour TV (default) or channel-wise.
    n_iter : int
        Inner dual iterations per call (warm start makes a handful enough).
    weight : (H, W) array, optional
        Spatially varying TV ``Σ_p weight(p) |∇x(p)|`` (weight ≥ 1 relative to ``mu``): the
        dual is projected on the balls ``|p(q)| ≤ weight(q)``.
    """

    def __init__(self, shape, coupled: bool = True, n_iter: int = 5, dtype=np.float32, weight=None):
        self.wmap, self.use_w = _weight_arg(weight)
        self.shape = tuple(shape)
        self.coupled = bool(coupled)
        self.n_iter = int(n_iter)
        C, H, W = self.shape
        self.p = np.zeros((C, 2, H, W), dtype)
        self._r = np.zeros_like(self.p)
        self._s = np.zeros_like(self.p)
        self._one = np.ones((1, 1), dtype)

    def reset(self):
        self.p[:] = 0

    def __call__(self, z, mu: float, d=None, out=None, n_iter=None, dinv=None) -> np.ndarray:
        """``argmin_x ½ Σ d |x − z|² + mu TV(x)`` for planar (C, H, W) float32 ``z``;
        ``d`` (H, W) or None; ``dinv`` = ``1 / d`` (float32) when the caller has it (FISTA
        calls the prox with the same metric every iteration)."""
        if out is not None and np.shares_memory(out, z):
            # the fused last step reads z a row beyond each band while writing out
            out[:] = self(z.copy(), mu, d, None, n_iter, dinv)
            return out
        if out is None:
            out = np.empty_like(z)
        if mu <= 0:
            out[:] = z
            return out
        use_d = d is not None
        if not use_d:
            dinv = self._one
        elif dinv is None:
            dinv = np.ascontiguousarray(1.0 / np.asarray(d, dtype=np.float32))
        else:
            dinv = np.ascontiguousarray(dinv, dtype=np.float32)
        dmax = float(dinv.max()) if use_d else 1.0
        step = np.float32(1.0 / (8.0 * mu * dmax))
        mu32 = np.float32(mu)
        n = self.n_iter if n_iter is None else n_iter
        # three dual buffers rotate (p, the previous p, a free one): no copies; the
        # extrapolated point is formed on the fly in _dual_step
        p, p_old, free = self.p, self._r, self._s
        t = 1.0
        beta = 0.0
        for k in range(n):
            # the last step also forms the primal result (no separate pass)
            _dual_step(z, p, p_old if beta != 0.0 else p, np.float32(beta), mu32, dinv, use_d, step,
                       self.coupled, self.wmap, self.use_w, BAND, free, k == n - 1, out)
            p_old, p, free = p, free, p_old
            t_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * t * t))
            beta = (t - 1.0) / t_new
            t = t_new
        self.p, self._r, self._s = p, p_old, free
        if n == 0:
            _primal(z, self.p, mu32, dinv, use_d, BAND, out)
        return out
