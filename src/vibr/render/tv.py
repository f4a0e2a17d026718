"""Total variation: value and proximal operator (METHOD §5, E_prior = TV(u)).

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

__all__ = ["tv_value", "TVProx"]


@njit(parallel=True, cache=True, fastmath=True)
def _tv_value(u, coupled):
    C, H, W = u.shape
    rows = np.zeros(H)
    for i in prange(H):
        acc = np.zeros(W, np.float32)
        nxt = min(i + 1, H - 1)  # last row: gy = 0
        s = 0.0
        for c in range(C):
            ur = u[c, i]
            un = u[c, nxt]
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
                    s += math.sqrt(gx * gx + gy * gy)
                s += abs(un[W - 1] - ur[W - 1])
        if coupled:
            for j in range(W):
                s += math.sqrt(acc[j])
        rows[i] = s
    return rows.sum()


def tv_value(u, coupled: bool = True) -> float:
    """``TV(u)`` of a planar (C, H, W) image (or (H, W)), see the module docstring."""
    if u.ndim == 2:
        u = u[None]
    return float(_tv_value(u, coupled))


@njit(cache=True, fastmath=True)
def _primal_row(z, r, mu, dinv, use_d, k, o):
    """Row k of x = z + mu · d⁻¹ · div r into o (C, W)."""
    C, H, W = z.shape
    for c in range(C):
        px = r[c, 0, k]
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
                py = r[c, 1, k]
                for j in range(W):
                    orow[j] += py[j]
            if k > 0:
                pm = r[c, 1, k - 1]
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


@njit(parallel=True, cache=True, fastmath=True)
def _primal(z, r, mu, dinv, use_d, x):
    """x = z + mu · d⁻¹ · div r, planar: z, x (C, H, W), r (C, 2, H, W)."""
    for i in prange(z.shape[1]):
        _primal_row(z, r, mu, dinv, use_d, i, x[:, i])


@njit(parallel=True, cache=True, fastmath=True)
def _dual_fused(z, r_in, p_old, r_out, p_new, mu, dinv, use_d, step, beta, coupled):
    """One accelerated dual step with the primal computed on the fly:
    x = z + mu d⁻¹ div r_in (rows i, i+1), q = P(r_in + step ∇x),
    r_out = q + beta (q − p_old), p_new = q.

    r_in is read at rows i−1..i+1, so r_out must not alias it (nor p_new, unless p_old is
    not r_in); p_old is read at row i only, so p_new may alias p_old."""
    C, H, W = z.shape
    for i in prange(H):
        xi = np.empty((C, W), np.float32)
        xn = np.empty((C, W), np.float32)
        _primal_row(z, r_in, mu, dinv, use_d, i, xi)
        if i < H - 1:
            _primal_row(z, r_in, mu, dinv, use_d, i + 1, xn)
        q = np.empty((C, 2, W), np.float32)
        nrm = np.zeros(W, np.float32)
        for c in range(C):
            xr = xi[c]
            qx = q[c, 0]
            qy = q[c, 1]
            rx = r_in[c, 0, i]
            ry = r_in[c, 1, i]
            for j in range(W - 1):
                qx[j] = rx[j] + step * (xr[j + 1] - xr[j])
            qx[W - 1] = rx[W - 1]
            if i < H - 1:
                xnr = xn[c]
                for j in range(W):
                    qy[j] = ry[j] + step * (xnr[j] - xr[j])
            else:
                for j in range(W):
                    qy[j] = ry[j]
            if coupled:
                for j in range(W):
                    nrm[j] += qx[j] * qx[j] + qy[j] * qy[j]
        if coupled:
            for j in range(W):
                nrm[j] = 1.0 / max(1.0, math.sqrt(nrm[j]))
        for c in range(C):
            if not coupled:
                for j in range(W):
                    nrm[j] = 1.0 / max(1.0, math.sqrt(q[c, 0, j] ** 2 + q[c, 1, j] ** 2))
            for d in range(2):
                qd = q[c, d]
                ro = r_out[c, d, i]
                po = p_old[c, d, i]
                pn = p_new[c, d, i]
                for j in range(W):
                    v = qd[j] * nrm[j]
                    ro[j] = v + beta * (v - po[j])
                    pn[j] = v


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
    """

    def __init__(self, shape, coupled: bool = True, n_iter: int = 5, dtype=np.float32):
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

    def __call__(self, z, mu: float, d=None, out=None, n_iter=None) -> np.ndarray:
        """``argmin_x ½ Σ d |x − z|² + mu TV(x)`` for planar (C, H, W) float32 ``z``;
        ``d`` (H, W) or None."""
        if out is None:
            out = np.empty_like(z)
        if mu <= 0:
            out[:] = z
            return out
        use_d = d is not None
        dinv = np.ascontiguousarray(1.0 / np.asarray(d, dtype=np.float32)) if use_d else self._one
        dmax = float(dinv.max()) if use_d else 1.0
        step = np.float32(1.0 / (8.0 * mu * dmax))
        mu32 = np.float32(mu)
        n = self.n_iter if n_iter is None else n_iter
        # three dual buffers rotate: p (the iterate kept between calls), r (the
        # extrapolated point) and a free one, so no copy is needed (see _dual_fused)
        p, a, b = self.p, self._r, self._s
        r = p
        t = 1.0
        for k in range(n):
            t_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * t * t))
            beta = np.float32((t - 1.0) / t_new)
            if k == 0:
                # r_in is p: write q to fresh buffers (r → a, p → b), p's buffer is free
                _dual_fused(z, p, p, a, b, mu32, dinv, use_d, step, beta, self.coupled)
                r, p, a = a, b, p
            else:
                _dual_fused(z, r, p, a, p, mu32, dinv, use_d, step, beta, self.coupled)
                r, a = a, r
            t = t_new
        self.p, self._r, self._s = p, r, a
        _primal(z, self.p, mu32, dinv, use_d, out)
        return out
