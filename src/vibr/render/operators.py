"""Linear operators of the image-formation model (paper §4.1, METHOD §4-5), with adjoints.

* ``B`` (:class:`Splat`): the bilinear PSF. Row m of ``B_k`` holds the 4 bilinear
  coefficients of ``tau_k(x_m)`` in the target grid, ``(B u)(m) = Σ_p B_mp u(p)``
  (METHOD §4, eq. v_k = B_k u). Its adjoint ``Bᵀ`` splats sample values back.
* The weighted normal operator ``A = Σ_k B_kᵀ W_k B_k``. Because each row of ``B`` touches
  a 2×2 block of target pixels, ``A`` only couples pixels at offsets in {-1,0,1}²:
  it is a **9-point stencil with spatially varying coefficients** whatever the warps.
  :func:`assemble` builds it (plus ``Bᵀ W v`` and ``½ Σ W v²``) once per weight update and
  :func:`stencil_apply` applies it; ``½ uᵀAu − bᵀu + c = ½ Σ W (Bu − v)²`` (METHOD §5).
* ``∇`` / ``div = -∇ᵀ``: forward differences with Neumann boundary (Chambolle 2004),
  used by TV.
* ``D`` / ``Dᵀ``: central differences with replicated border, used by the gradient term
  (METHOD §5) because the source gradients ``∇v_k`` of :class:`~vibr.geometry.Samples` are
  central differences too (same half-pixel phase).

Inside the solver images are **planar** (C, H, W) float32 (C = 3 for RGB; contiguous rows
vectorise), gradients (C, 2, H, W); stencils are (9, H, W) with entry
``s = 3 (dy + 1) + (dx + 1)`` coupling pixel (i, j) to (i + dy, j + dx). ``B`` itself reads
(H, W, C) images (sample interpolation, used outside the iterations).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = [
    "Splat", "assemble", "stencil_apply", "stencil_to_sparse", "explicit_B",
    "grad_fwd", "div_bwd", "grad_central", "grad_central_adj", "dot", "norm_sq",
]


# ----------------------------------------------------------------------------- helpers
@njit(cache=True)
def _bucket_by_row(y0, n_rows):
    """Counting sort of samples by their top bilinear row: (order, starts)."""
    n = y0.shape[0]
    counts = np.zeros(n_rows + 1, np.int64)
    for i in range(n):
        counts[y0[i] + 1] += 1
    for r in range(n_rows):
        counts[r + 1] += counts[r]
    starts = counts.copy()
    fill = counts[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        r = y0[i]
        order[fill[r]] = i
        fill[r] += 1
    return order, starts


@njit(parallel=True, cache=True)
def _bilinear_setup(xy, H, W):
    n = xy.shape[0]
    x0 = np.empty(n, np.int32)
    y0 = np.empty(n, np.int32)
    fx = np.empty(n, np.float64)
    fy = np.empty(n, np.float64)
    for i in prange(n):
        x = min(max(xy[i, 0], 0.0), W - 1.0)
        y = min(max(xy[i, 1], 0.0), H - 1.0)
        # clamp the cell so that x0 + 1 stays inside; x = W-1 gives fx = 1
        xi = min(int(np.floor(x)), max(W - 2, 0))
        yi = min(int(np.floor(y)), max(H - 2, 0))
        x0[i] = xi
        y0[i] = yi
        fx[i] = x - xi
        fy[i] = y - yi
    return x0, y0, fx, fy


@njit(parallel=True, cache=True)
def _B_apply(u, x0, y0, fx, fy):
    n = x0.shape[0]
    C = u.shape[2]
    out = np.empty((n, C), np.float64)
    for i in prange(n):
        a, b = fx[i], fy[i]
        w00 = (1 - a) * (1 - b)
        w01 = a * (1 - b)
        w10 = (1 - a) * b
        w11 = a * b
        x, y = x0[i], y0[i]
        for c in range(C):
            out[i, c] = (w00 * u[y, x, c] + w01 * u[y, x + 1, c]
                         + w10 * u[y + 1, x, c] + w11 * u[y + 1, x + 1, c])
    return out


@njit(parallel=True, cache=True)
def _assemble_kernel(x0, y0, fx, fy, order, starts, w, vals, H, W, with_stencil):
    """Σ Bᵀ diag(w) B (9-point stencil), Σ Bᵀ (w·vals) and ½ Σ w |vals|².

    Rows of samples are processed in two passes of even / odd top rows: a sample with
    top row r writes rows r and r+1 only, so buckets of one parity never collide.
    """
    K = vals.shape[1]
    A = np.zeros((9, H, W), np.float64) if with_stencil else np.zeros((9, 1, 1), np.float64)
    rhs = np.zeros((K, H, W), np.float64)
    n_rows = starts.shape[0] - 1
    cpart = np.zeros(n_rows, np.float64)
    for parity in range(2):
        for r in prange(n_rows):
            if r % 2 != parity:
                continue
            bw = np.empty(4)  # per row: private to the thread
            acc = 0.0
            for q in range(starts[r], starts[r + 1]):
                i = order[q]
                wi = w[i]
                if wi == 0.0:
                    continue
                a, b = fx[i], fy[i]
                bw[0] = (1 - a) * (1 - b)
                bw[1] = a * (1 - b)
                bw[2] = (1 - a) * b
                bw[3] = a * b
                x, y = x0[i], y0[i]
                for ca in range(4):
                    ya = y + ca // 2
                    xa = x + ca % 2
                    wa = wi * bw[ca]
                    for k in range(K):
                        rhs[k, ya, xa] += wa * vals[i, k]
                    if with_stencil:
                        for cb in range(4):
                            dy = cb // 2 - ca // 2
                            dx = cb % 2 - ca % 2
                            A[3 * (dy + 1) + dx + 1, ya, xa] += wa * bw[cb]
                s = 0.0
                for k in range(K):
                    s += vals[i, k] * vals[i, k]
                acc += 0.5 * wi * s
            cpart[r] = acc
    return A, rhs, cpart.sum()


@njit(parallel=True, cache=True)
def _stencil_apply(A, u, out):
    """out[c] = Σ_s A[s] · shift_s(u[c]); planar (C, H, W) images, (9, H, W) stencil.

    Entries of A that point outside the image are zero by construction (no sample
    touches an outside pixel), so only the index range needs guarding: the interior
    j-loop is branch-free (vectorisable)."""
    C, H, W = u.shape
    for i in prange(H):
        for c in range(C):
            for j in range(W):
                out[c, i, j] = 0.0
            for dy in range(-1, 2):
                ii = i + dy
                if ii < 0 or ii >= H:
                    continue
                for dx in range(-1, 2):
                    a = A[3 * (dy + 1) + dx + 1, i]
                    ur = u[c, ii]
                    o = out[c, i]
                    j0 = 1 if dx < 0 else 0
                    j1 = W - 1 if dx > 0 else W
                    for j in range(j0, j1):
                        o[j] += a[j] * ur[j + dx]
    return out


@njit(parallel=True, cache=True)
def _dot(a, b):
    a1 = a.ravel()
    b1 = b.ravel()
    n = a1.shape[0]
    nb = 256
    chunk = (n + nb - 1) // nb
    parts = np.zeros(nb)
    for k in prange(nb):
        s = 0.0
        for i in range(k * chunk, min(n, (k + 1) * chunk)):
            s += np.float64(a1[i]) * np.float64(b1[i])
        parts[k] = s
    return parts.sum()


def dot(a, b) -> float:
    """⟨a, b⟩ accumulated in float64 (parallel)."""
    return float(_dot(np.ascontiguousarray(a), np.ascontiguousarray(b)))


def norm_sq(a) -> float:
    return dot(a, a)


# ----------------------------------------------------------------------------- B
class Splat:
    """The bilinear PSF ``B`` of a set of sample positions (METHOD §4).

    Parameters
    ----------
    xy : (N, 2) float64
        Target pixel coordinates ``tau_k(x_m)`` (x = column, y = row; centre of the top-left
        pixel at (0, 0)), inside ``[0, W-1] × [0, H-1]`` (clamped otherwise).
    shape : (H, W)
        Target image shape.

    ``B`` is N × (H·W) with 4 non-zeros per row: the bilinear coefficients
    ``(1-fx)(1-fy), fx(1-fy), (1-fx)fy, fx·fy`` of the cell containing ``xy``.
    """

    def __init__(self, xy, shape):
        self.shape = (int(shape[0]), int(shape[1]))
        H, W = self.shape
        xy = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2)
        self.n = xy.shape[0]
        self.x0, self.y0, self.fx, self.fy = _bilinear_setup(xy, H, W)
        self.order, self.starts = _bucket_by_row(self.y0, max(H - 1, 1))

    def apply(self, u) -> np.ndarray:
        """``B u``: (H, W, C) image (or (H, W)) → (N, C) float64 sample values."""
        u = np.asarray(u)
        squeeze = u.ndim == 2
        if squeeze:
            u = u[..., None]
        out = _B_apply(np.ascontiguousarray(u), self.x0, self.y0, self.fx, self.fy)
        return out[:, 0] if squeeze else out

    def adjoint(self, vals, weight=None) -> np.ndarray:
        """``Bᵀ (w · vals)``: (N, C) → (H, W, C) float64 (splatting); (N,) → (H, W)."""
        vals = np.asarray(vals, dtype=np.float64)
        squeeze = vals.ndim == 1
        if squeeze:
            vals = vals[:, None]
        w = np.ones(self.n) if weight is None else np.ascontiguousarray(weight, dtype=np.float64)
        _, rhs, _ = _assemble_kernel(self.x0, self.y0, self.fx, self.fy, self.order, self.starts,
                                     w, np.ascontiguousarray(vals), self.shape[0], self.shape[1], False)
        return rhs[0] if squeeze else np.ascontiguousarray(rhs.transpose(1, 2, 0))

    def normal(self, weight, vals):
        """Assemble the stencil ``A = Bᵀ diag(w) B`` (9, H, W), ``b = Bᵀ (w·vals)`` (K, H, W)
        and ``c = ½ Σ w |vals|²``, all float64, so that for a planar image u (K, H, W)
        ``½ Σ_m w_m |(Bu)(m) − vals_m|² = ½⟨u, Au⟩ − ⟨b, u⟩ + c``."""
        w = np.ascontiguousarray(weight, dtype=np.float64)
        vals = np.ascontiguousarray(vals, dtype=np.float64)
        if vals.ndim == 1:
            vals = vals[:, None]
        return _assemble_kernel(self.x0, self.y0, self.fx, self.fy, self.order, self.starts,
                                w, vals, self.shape[0], self.shape[1], True)


def assemble(splat: Splat, weight, vals):
    """See :meth:`Splat.normal`."""
    return splat.normal(weight, vals)


def stencil_apply(A, u, out=None) -> np.ndarray:
    """Apply the 9-point stencil ``A`` (9, H, W) to a planar image ``u`` (C, H, W) or
    (H, W): ``(Au)(p) = Σ_{d ∈ {-1,0,1}²} A[d, p] u(p + d)``, ``s = 3(dy+1) + dx+1``."""
    squeeze = u.ndim == 2
    if squeeze:
        u = u[None]
    if out is None:
        out = np.empty(u.shape, np.result_type(A.dtype, u.dtype))
    _stencil_apply(A, u, out)
    return out[0] if squeeze else out


def explicit_B(splat: Splat):
    """``B`` as a scipy.sparse CSR matrix N × (H·W) (for tests)."""
    import scipy.sparse as sp

    H, W = splat.shape
    a, b = splat.fx, splat.fy
    rows = np.repeat(np.arange(splat.n), 4)
    y, x = splat.y0.astype(np.int64), splat.x0.astype(np.int64)
    cols = np.stack([y * W + x, y * W + x + 1, (y + 1) * W + x, (y + 1) * W + x + 1], 1).ravel()
    vals = np.stack([(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b], 1).ravel()
    return sp.csr_matrix((vals, (rows, cols)), shape=(splat.n, H * W))


def stencil_to_sparse(A):
    """The (H·W) × (H·W) sparse matrix of a stencil (for tests)."""
    import scipy.sparse as sp

    _, H, W = A.shape
    ii, jj = np.mgrid[0:H, 0:W]
    rows, cols, vals = [], [], []
    for s in range(9):
        dy, dx = s // 3 - 1, s % 3 - 1
        ok = (ii + dy >= 0) & (ii + dy < H) & (jj + dx >= 0) & (jj + dx < W)
        rows.append((ii * W + jj)[ok])
        cols.append(((ii + dy) * W + jj + dx)[ok])
        vals.append(A[s][ok])
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(H * W, H * W))


# ----------------------------------------------------------------------------- ∇ / div
# Planar layout: images (C, H, W), gradients (C, 2, H, W) with [:, 0] = d/dx, [:, 1] = d/dy.
@njit(parallel=True, cache=True)
def _grad_fwd(u, g):
    C, H, W = u.shape
    for i in prange(H):
        for c in range(C):
            ur = u[c, i]
            gx = g[c, 0, i]
            for j in range(W - 1):
                gx[j] = ur[j + 1] - ur[j]
            gx[W - 1] = 0.0
            gy = g[c, 1, i]
            if i < H - 1:
                un = u[c, i + 1]
                for j in range(W):
                    gy[j] = un[j] - ur[j]
            else:
                for j in range(W):
                    gy[j] = 0.0
    return g


@njit(parallel=True, cache=True)
def _div_bwd(p, out):
    C, _, H, W = p.shape
    for i in prange(H):
        for c in range(C):
            px = p[c, 0, i]
            o = out[c, i]
            if W == 1:
                o[0] = 0.0
            else:
                o[0] = px[0]
                for j in range(1, W - 1):
                    o[j] = px[j] - px[j - 1]
                o[W - 1] = -px[W - 2]
            if H > 1:
                if i < H - 1:
                    py = p[c, 1, i]
                    for j in range(W):
                        o[j] += py[j]
                if i > 0:
                    pm = p[c, 1, i - 1]
                    for j in range(W):
                        o[j] -= pm[j]
    return out


def grad_fwd(u, out=None) -> np.ndarray:
    """Forward-difference gradient, Neumann boundary (Chambolle 2004):
    (C, H, W) → (C, 2, H, W)."""
    if out is None:
        out = np.empty((u.shape[0], 2) + u.shape[1:], u.dtype)
    return _grad_fwd(u, out)


def div_bwd(p, out=None) -> np.ndarray:
    """Divergence ``div = -∇ᵀ`` of :func:`grad_fwd`: (C, 2, H, W) → (C, H, W)."""
    if out is None:
        out = np.empty((p.shape[0],) + p.shape[2:], p.dtype)
    return _div_bwd(p, out)


@njit(parallel=True, cache=True)
def _grad_central(u, g):
    C, H, W = u.shape
    for i in prange(H):
        im, ip = max(i - 1, 0), min(i + 1, H - 1)
        for c in range(C):
            ur = u[c, i]
            gx = g[c, 0, i]
            if W > 1:
                gx[0] = 0.5 * (ur[1] - ur[0])
                for j in range(1, W - 1):
                    gx[j] = 0.5 * (ur[j + 1] - ur[j - 1])
                gx[W - 1] = 0.5 * (ur[W - 1] - ur[W - 2])
            else:
                gx[0] = 0.0
            up, um = u[c, ip], u[c, im]
            gy = g[c, 1, i]
            for j in range(W):
                gy[j] = 0.5 * (up[j] - um[j])
    return g


@njit(parallel=True, cache=True)
def _grad_central_adj(g, out):
    # per axis: out[k] = ½(g[k-1]·[k≥1] + g[k]·[k=n-1]) − ½(g[k+1]·[k≤n-2] + g[k]·[k=0])
    C, _, H, W = g.shape
    for i in prange(H):
        for c in range(C):
            gx = g[c, 0, i]
            o = out[c, i]
            if W > 1:
                o[0] = -0.5 * (gx[1] + gx[0])
                for j in range(1, W - 1):
                    o[j] = 0.5 * (gx[j - 1] - gx[j + 1])
                o[W - 1] = 0.5 * (gx[W - 2] + gx[W - 1])
            else:
                o[0] = 0.0
            if H > 1:
                if i >= 1:
                    a = g[c, 1, i - 1]
                    for j in range(W):
                        o[j] += 0.5 * a[j]
                if i == H - 1:
                    a = g[c, 1, i]
                    for j in range(W):
                        o[j] += 0.5 * a[j]
                if i <= H - 2:
                    a = g[c, 1, i + 1]
                    for j in range(W):
                        o[j] -= 0.5 * a[j]
                if i == 0:
                    a = g[c, 1, i]
                    for j in range(W):
                        o[j] -= 0.5 * a[j]
    return out


def grad_central(u, out=None) -> np.ndarray:
    """Central-difference gradient ``D u``, replicated border: (C, H, W) → (C, 2, H, W),
    ``(Du)_x(i,j) = ½ (u(i, min(j+1,W-1)) − u(i, max(j-1,0)))`` (same for y)."""
    if out is None:
        out = np.empty((u.shape[0], 2) + u.shape[1:], u.dtype)
    return _grad_central(u, out)


def grad_central_adj(g, out=None) -> np.ndarray:
    """Adjoint ``Dᵀ`` of :func:`grad_central`: (C, 2, H, W) → (C, H, W)."""
    if out is None:
        out = np.empty((g.shape[0],) + g.shape[2:], g.dtype)
    return _grad_central_adj(g, out)
