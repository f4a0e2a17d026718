"""Linear operators of the image-formation model (paper §4.1, docs/explanation/method.md §4-5), with adjoints.

* ``B`` (:class:`Splat`): the PSF matrix, ``(B u)(m) = Σ_p B_mp u(p)`` (paper §4.1
  eq. normal, docs/explanation/method.md §4). Row m holds 4 coefficients on a 2×2 block of target pixels:
  the bilinear coefficients of ``tau_k(x_m)`` (``psf="bilinear"``, the default), or the
  overlap areas of the source pixel's footprint parallelogram with the block's pixels
  (``psf="footprint"``, the paper's figure fig:discretization, right). Its adjoint ``Bᵀ``
  splats sample values back.
* The weighted normal operator ``A = Σ_k B_kᵀ W_k B_k``. Because each row of ``B`` touches
  a 2×2 block of target pixels, ``A`` only couples pixels at offsets in {-1,0,1}²:
  it is a **9-point stencil with spatially varying coefficients** whatever the warps.
  :meth:`Splat.normal` builds it (plus ``Bᵀ W v`` and ``½ Σ W v²``) once per weight update and
  :func:`stencil_apply` applies it; ``½ uᵀAu − bᵀu + c = ½ Σ W (Bu − v)²`` (docs/explanation/method.md §5).
* ``∇`` / ``div = -∇ᵀ``: forward differences with Neumann boundary (Chambolle 2004),
  used by TV.
* ``D`` / ``Dᵀ`` (:func:`grad_image`): the gradient term's image gradient (docs/explanation/method.md §5),
  forward or central differences (:data:`GRAD_SCHEMES`). The source gradients ``∇v_k`` of
  :class:`~vibr.geometry.Samples` are computed by the same function, so both sides of the
  term use one discretisation with one border rule.

Inside the solver images are **planar** (C, H, W) float32 (C = 3 for RGB; contiguous rows
vectorise), gradients (C, 2, H, W); stencils are (9, H, W) with entry
``s = 3 (dy + 1) + (dx + 1)`` coupling pixel (i, j) to (i + dy, j + dx). ``B`` itself reads
(H, W, C) images (sample interpolation, used outside the iterations).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._runtime.jit import FASTMATH
from ..geometry.gradient import (  # noqa: F401
    DEFAULT_GRAD_SCHEME,
    GRAD_SCHEMES,
    _grad_adj_row,
    _grad_row,
    _is_forward,
    grad_image,
    grad_image_adj,
)

__all__ = [
    "PSFS", "Splat", "stencil_apply", "stencil_to_sparse", "explicit_B",
    "grad_fwd", "div_bwd", "grad_central", "grad_central_adj", "dot",
    "GRAD_SCHEMES", "DEFAULT_GRAD_SCHEME", "grad_image", "grad_image_adj",
]


# ----------------------------------------------------------------------------- helpers
@njit(cache=True, inline="always")
def sample_at(order, q):
    """The sample at place ``q`` of the bucketed order: ``order[q]``, or ``q`` itself when
    ``order`` is empty (the samples were already in block order)."""
    return order[q] if order.shape[0] > 0 else q


@njit(cache=True)
def _bucket_by_cell(x0, y0, n_rows, W):
    """Counting sort of samples by their 2×2 block (top row, then left column):
    ``(order, starts)``, ``starts[r]`` the first sample whose top row is r (so the
    samples of a row are contiguous, and within it those of one block). ``order`` is
    empty when the samples are in that order already (as
    :func:`vibr.geometry.compute_samples` returns them for the bilinear PSF): the
    identity, which :func:`sample_at` reads without an (N,) array."""
    n = y0.shape[0]
    counts = np.zeros(n_rows * W + 1, np.int64)
    ordered = True
    prev = -1
    for i in range(n):
        c = y0[i] * W + x0[i]
        counts[c + 1] += 1
        if c < prev:
            ordered = False
        prev = c
    for c in range(n_rows * W):
        counts[c + 1] += counts[c]
    starts = np.empty(n_rows + 1, np.int64)
    for r in range(n_rows + 1):
        starts[r] = counts[r * W]
    if ordered:
        return np.empty(0, np.int32), starts
    fill = counts[:-1].copy()
    order = np.empty(n, np.int32)  # (Splat refuses 2³¹ samples or more)
    for i in range(n):
        c = y0[i] * W + x0[i]
        order[fill[c]] = i
        fill[c] += 1
    return order, starts


@njit(parallel=True, cache=True)
def _cells_ordered(x0, y0, W):
    """Whether the samples' blocks ``y0·W + x0`` never decrease: the decreases between
    neighbours counted in parallel chunks (a loop without a carried value: it vectorises)."""
    n = y0.shape[0]
    nb = 64
    chunk = (n + nb - 1) // nb
    bad = np.zeros(nb, np.int64)
    for k in prange(nb):
        i0 = max(k * chunk, 1)
        i1 = min(n, (k + 1) * chunk)
        if i1 <= i0:
            continue
        xs, ys = x0[i0 - 1:i1], y0[i0 - 1:i1]  # from 0: indices the compiler knows are ≥ 0
        cnt = 0
        for i in range(1, xs.shape[0]):
            cnt += np.int64(ys[i]) * W + xs[i] < np.int64(ys[i - 1]) * W + xs[i - 1]
        bad[k] = cnt
    return bad.sum() == 0


def bucket_by_cell(x0, y0, n_rows: int, W: int):
    """:func:`_bucket_by_cell`'s ``(order, starts)``; when the samples are in block order
    already (as :func:`vibr.geometry.compute_samples` returns them), without its serial
    counting pass: ``starts[r]`` is then the number of samples whose top row is below r, a
    binary search in the sorted rows (the same values)."""
    if _cells_ordered(x0, y0, W):
        return np.empty(0, np.int32), np.searchsorted(y0, np.arange(n_rows + 1), side="left").astype(np.int64)
    return _bucket_by_cell(x0, y0, n_rows, W)


@njit(parallel=True, cache=True)
def _bilinear_setup(xy, H, W):
    n = xy.shape[0]
    x0 = np.empty(n, np.int32)
    y0 = np.empty(n, np.int32)
    # the fractions in float32 (error below 1e-7 px; 8 bytes a sample less): every reader
    # computes the coefficients in float64 (_row_coef)
    fx = np.empty(n, np.float32)
    fy = np.empty(n, np.float32)
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


@njit(cache=True)
def _clip(px, py, n, axis, c, sign, qx, qy):
    """Sutherland–Hodgman: the part of the convex polygon (px, py)[:n] where
    ``sign · (coord − c) <= 0`` (coord = x for axis 0, y for axis 1), into (qx, qy);
    returns its number of vertices."""
    m = 0
    for k in range(n):
        k1 = k + 1 if k + 1 < n else 0
        ax, ay = px[k], py[k]
        bx, by = px[k1], py[k1]
        da = sign * ((ax if axis == 0 else ay) - c)
        db = sign * ((bx if axis == 0 else by) - c)
        if da <= 0.0:
            qx[m] = ax
            qy[m] = ay
            m += 1
        if (da < 0.0 < db) or (db < 0.0 < da):
            t = da / (da - db)
            qx[m] = ax + t * (bx - ax)
            qy[m] = ay + t * (by - ay)
            m += 1
    return m


@njit(cache=True)
def _poly_area(px, py, n):
    """|area| of a simple polygon (shoelace)."""
    a = 0.0
    for k in range(n):
        k1 = k + 1 if k + 1 < n else 0
        a += px[k] * py[k1] - px[k1] * py[k]
    return abs(0.5 * a)


@njit(parallel=True, cache=True)
def _footprint_setup(xy, jac, H, W, coef, bx0, by0, flags):
    """Footprint PSF (paper §4.1, fig. discretization right): the source pixel's square
    ``[-½, ½]²`` maps under the local linear warp to the parallelogram
    ``P = tau(x_m) + J·[-½, ½]²``; ``coef[i, 2 dy + dx]`` = area(P ∩ pixel (by0 + dy,
    bx0 + dx)) / area(P).

    To keep each row of B on a 2×2 block (the 9-point stencil), a footprint whose bounding
    box is wider (higher) than one target pixel is shrunk about its centre along x (y),
    i.e. row 0 (1) of J is scaled, until the box is exactly 1 px wide (high); ``flags[i]``
    = 1 when it exceeded 1 px by more than 1e-6. Along an axis where it fits, the footprint
    keeps its exact extent; J = s·I with s ≥ 1 (a coarser source) degrades to the unit
    square, i.e. the bilinear PSF. Non-finite or singular J: the unit square (bilinear),
    ``flags[i]`` = 2. The centre is clamped to
    ``[0, W-1] × [0, H-1]`` as for the bilinear PSF, so P never leaves the image domain.
    """
    n = xy.shape[0]
    chunk = 2048
    n_chunks = (n + chunk - 1) // chunk
    for ch in prange(n_chunks):
        px = np.empty(8)
        py = np.empty(8)
        lx = np.empty(8)
        ly = np.empty(8)
        qx = np.empty(8)
        qy = np.empty(8)
        for i in range(ch * chunk, min(n, (ch + 1) * chunk)):
            xc = min(max(xy[i, 0], 0.0), W - 1.0)
            yc = min(max(xy[i, 1], 0.0), H - 1.0)
            j00, j01, j10, j11 = jac[i, 0, 0], jac[i, 0, 1], jac[i, 1, 0], jac[i, 1, 1]
            flag = 0
            ok = (np.isfinite(j00) and np.isfinite(j01) and np.isfinite(j10)
                  and np.isfinite(j11))
            if ok:
                ex = abs(j00) + abs(j01)  # bounding-box width / height of P
                ey = abs(j10) + abs(j11)
                if ex > 1.0:
                    j00 /= ex
                    j01 /= ex
                if ey > 1.0:
                    j10 /= ey
                    j11 /= ey
                if max(ex, ey) > 1.0 + 1e-6:  # (rounding of an exact 1 px is not counted)
                    flag = 1
                ex = abs(j00) + abs(j01)
                ey = abs(j10) + abs(j11)
                ok = abs(j00 * j11 - j01 * j10) > 1e-9 * max(ex * ey, 1e-300)
            if not ok:
                j00, j01, j10, j11 = 1.0, 0.0, 0.0, 1.0
                flag = 2
            hx = 0.5 * (abs(j00) + abs(j01))
            hy = 0.5 * (abs(j10) + abs(j11))
            # the block's left column / top row: the pixel holding the box's left / top side
            xi = min(max(int(np.floor(xc - hx + 0.5)), 0), max(W - 2, 0))
            yi = min(max(int(np.floor(yc - hy + 0.5)), 0), max(H - 2, 0))
            bx0[i] = xi
            by0[i] = yi
            flags[i] = flag
            # corners in cyclic order, c + ½J(∓1, ∓1), relative to the block's inner
            # corner (xi + ½, yi + ½) where its pixel borders cross (small numbers: the
            # shoelace areas keep their precision whatever the image size)
            ox = xc - (xi + 0.5)
            oy = yc - (yi + 0.5)
            ax, ay = 0.5 * j00, 0.5 * j10  # ½ J e_x
            bx, by = 0.5 * j01, 0.5 * j11  # ½ J e_y
            px[0] = ox - ax - bx
            py[0] = oy - ay - by
            px[1] = ox + ax - bx
            py[1] = oy + ay - by
            px[2] = ox + ax + bx
            py[2] = oy + ay + by
            px[3] = ox - ax + bx
            py[3] = oy - ay + by
            nl = _clip(px, py, 4, 0, 0.0, 1.0, lx, ly)  # left column (x <= 0)
            al = _poly_area(lx, ly, nl)
            m = _clip(lx, ly, nl, 1, 0.0, 1.0, qx, qy)  # its top pixel (y <= 0)
            a00 = _poly_area(qx, qy, m)
            nr = _clip(px, py, 4, 0, 0.0, -1.0, lx, ly)  # right column (x >= 0)
            ar = _poly_area(lx, ly, nr)
            m = _clip(lx, ly, nr, 1, 0.0, 1.0, qx, qy)
            a01 = _poly_area(qx, qy, m)
            tot = al + ar
            c00 = a00 / tot
            c01 = a01 / tot
            c10 = max(al - a00, 0.0) / tot
            c11 = max(ar - a01, 0.0) / tot
            coef[i, 0] = c00
            coef[i, 1] = c01
            coef[i, 2] = c10
            coef[i, 3] = c11


@njit(cache=True)
def _row_coef(fx, fy, coef, use_coef, i):
    """Row i of B on its 2×2 block (top-left, top-right, bottom-left, bottom-right), in
    float64: ``coef[i]`` (footprint) or the bilinear coefficients of (fx, fy)."""
    if use_coef:
        return coef[i, 0], coef[i, 1], coef[i, 2], coef[i, 3]
    a = np.float64(fx[i])
    b = np.float64(fy[i])
    return (1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b


@njit(parallel=True, cache=True)
def _B_apply(u, x0, y0, fx, fy, coef):
    """``B u`` at the 2×2 blocks (x0, y0): bilinear coefficients from (fx, fy) when
    ``coef`` is empty, else ``coef`` (N, 4), order (top-left, top-right, bottom-left,
    bottom-right)."""
    n = x0.shape[0]
    C = u.shape[2]
    use_coef = coef.shape[0] == n and n > 0
    out = np.empty((n, C), np.float64)
    for i in prange(n):
        w00, w01, w10, w11 = _row_coef(fx, fy, coef, use_coef, i)
        x, y = x0[i], y0[i]
        for c in range(C):
            out[i, c] = (w00 * u[y, x, c] + w01 * u[y, x + 1, c]
                         + w10 * u[y + 1, x, c] + w11 * u[y + 1, x + 1, c])
    return out


@njit(cache=True)
def _sum_in_order(a):
    """Σ a in index order. Inside a ``parallel=True`` kernel ``a.sum()`` becomes a parallel
    reduction whose partial sums depend on the number of threads; this sum does not, so a
    result is the same bit for bit on 1 thread or 16 (a process pool of N workers gives
    each cores // N threads)."""
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i]
    return s


@njit(cache=True)
def _flush_block(la, x, S, K, s00, s01, s02, s03, s11, s12, s13, s22, s23, s33, cv):
    """Add one 2×2 block's sums into the two-row buffer ``la`` (see :func:`accumulate_bucket`):
    ``s_ij = Σ w b_i b_j`` (corners 0..3 = top-left, top-right, bottom-left, bottom-right)
    and ``cv[i, k] = Σ w b_i v_k``."""
    if S == 9:
        # corner (dy, dx) couples to corner (dy', dx') through entry 3 (dy' − dy + 1) + (dx' − dx + 1)
        la[0, x, 4] += s00
        la[0, x, 5] += s01
        la[0, x, 7] += s02
        la[0, x, 8] += s03
        la[0, x + 1, 3] += s01
        la[0, x + 1, 4] += s11
        la[0, x + 1, 6] += s12
        la[0, x + 1, 7] += s13
        la[1, x, 1] += s02
        la[1, x, 2] += s12
        la[1, x, 4] += s22
        la[1, x, 5] += s23
        la[1, x + 1, 0] += s03
        la[1, x + 1, 1] += s13
        la[1, x + 1, 3] += s23
        la[1, x + 1, 4] += s33
    elif S == 1:  # the weight sums, kept in cv[:, K]
        la[0, x, 0] += cv[0, K]
        la[0, x + 1, 0] += cv[1, K]
        la[1, x, 0] += cv[2, K]
        la[1, x + 1, 0] += cv[3, K]
    for k in range(K):
        la[0, x, S + k] += cv[0, k]
        la[0, x + 1, S + k] += cv[1, k]
        la[1, x, S + k] += cv[2, k]
        la[1, x + 1, S + k] += cv[3, k]
    cv[:] = 0.0


@njit(cache=True)
def accumulate_bucket(r, q0, q1, order, wb, x0, fx, fy, coef, use_coef, vals, S, la, A, rhs):
    """Splat the samples ``order[q0:q1]`` (all with top row r, sorted by block) with weights
    ``wb[q - q0]``: adds ``Σ Bᵀ diag(w) B`` (S = 9: the 9-point stencil into ``A``; S = 1:
    only its row sums ``Bᵀ w`` into ``A[0]``; S = 0: nothing) and ``Σ Bᵀ (w·vals)`` (into
    ``rhs``) at rows r, r + 1; returns ``½ Σ w |vals|²``. Row i of B: 2×2 block at
    (x0[i], r), coefficients :func:`_row_coef`.

    The samples of one block are summed in registers (``s_ij = Σ w b_i b_j``: 10 sums, the
    stencil is symmetric) and added once per block to ``la`` (≥ (2, W, S + K) float64,
    zeroed here), a private two-row buffer laid out (row, x, entry), itself added to the
    (entry, row, x) outputs once. Callers run buckets of one parity of r at a time (a
    bucket writes rows r and r + 1 only): no two threads write the same row, and the sums
    do not depend on the number of threads."""
    K = vals.shape[1]
    W = rhs.shape[2]
    E = S + K
    for ra in range(2):
        for j in range(W):
            for e in range(E):
                la[ra, j, e] = 0.0
    cv = np.zeros((4, K + 1), np.float64)
    jmin = W
    jmax = -1
    acc = 0.0
    cur = -1
    s00 = s01 = s02 = s03 = s11 = s12 = s13 = s22 = s23 = s33 = 0.0
    for q in range(q0, q1):
        i = sample_at(order, q)
        wi = np.float64(wb[q - q0])
        if wi == 0.0:
            continue
        x = x0[i]
        if x != cur:
            if cur >= 0:
                _flush_block(la, cur, S, K, s00, s01, s02, s03, s11, s12, s13, s22, s23, s33, cv)
            s00 = s01 = s02 = s03 = s11 = s12 = s13 = s22 = s23 = s33 = 0.0
            cur = x
            jmin = min(jmin, x)
            jmax = max(jmax, x + 1)
        b0, b1, b2, b3 = _row_coef(fx, fy, coef, use_coef, i)
        w0 = wi * b0
        w1 = wi * b1
        w2 = wi * b2
        w3 = wi * b3
        if S == 9:
            s00 += w0 * b0
            s01 += w0 * b1
            s02 += w0 * b2
            s03 += w0 * b3
            s11 += w1 * b1
            s12 += w1 * b2
            s13 += w1 * b3
            s22 += w2 * b2
            s23 += w2 * b3
            s33 += w3 * b3
        elif S == 1:
            cv[0, K] += w0
            cv[1, K] += w1
            cv[2, K] += w2
            cv[3, K] += w3
        s = 0.0
        for k in range(K):
            v = np.float64(vals[i, k])
            cv[0, k] += w0 * v
            cv[1, k] += w1 * v
            cv[2, k] += w2 * v
            cv[3, k] += w3 * v
            s += v * v
        acc += 0.5 * wi * s
    if cur >= 0:
        _flush_block(la, cur, S, K, s00, s01, s02, s03, s11, s12, s13, s22, s23, s33, cv)
    for ra in range(2):
        ya = r + ra
        for e in range(S):
            Ae = A[e, ya]
            for j in range(jmin, jmax + 1):
                Ae[j] += la[ra, j, e]
        for k in range(K):
            rk = rhs[k, ya]
            for j in range(jmin, jmax + 1):
                rk[j] += la[ra, j, S + k]
    return acc


@njit(parallel=True, cache=True)
def _assemble_kernel(x0, y0, fx, fy, coef, order, starts, w, vals, A, rhs, with_stencil):
    """Σ Bᵀ diag(w) B (9-point stencil, into ``A``), Σ Bᵀ (w·vals) (into ``rhs``) and
    returns ½ Σ w |vals|². Row i of B: 2×2 block at (x0, y0), coefficients bilinear from
    (fx, fy) when ``coef`` is empty, else ``coef[i]`` (see :func:`_B_apply`); samples in
    buckets of their top row (``order``, ``starts``), see :func:`accumulate_bucket`."""
    W = rhs.shape[2]
    n_rows = starts.shape[0] - 1
    S = 9 if with_stencil else 0
    use_coef = coef.shape[0] == x0.shape[0] and x0.shape[0] > 0
    cpart = np.zeros(n_rows, np.float64)
    for parity in range(2):
        for r in prange(n_rows):
            if r % 2 != parity or starts[r] == starts[r + 1]:
                continue
            q0, q1 = starts[r], starts[r + 1]
            wb = np.empty(q1 - q0, w.dtype)
            for q in range(q0, q1):
                wb[q - q0] = w[sample_at(order, q)]
            la = np.empty((2, W, S + vals.shape[1]), np.float64)
            cpart[r] = accumulate_bucket(r, q0, q1, order, wb, x0, fx, fy, coef, use_coef, vals, S, la, A, rhs)
    return _sum_in_order(cpart)


@njit(cache=True, fastmath=FASTMATH)
def _stencil_point(A, u, c, i, j, H, W):
    s = 0.0
    for dy in range(-1, 2):
        ii = i + dy
        if ii < 0 or ii >= H:
            continue
        for dx in range(-1, 2):
            jj = j + dx
            if jj < 0 or jj >= W:
                continue
            s += A[3 * (dy + 1) + dx + 1, i, j] * u[c, ii, jj]
    return s


@njit(cache=True, fastmath=FASTMATH)
def _stencil_row(A, u, c, i, out):
    """Row i of the 9-point stencil ``A`` applied to channel c of ``u`` (C, H, W).

    Interior rows take the 9 products in one expression (one pass over the output row,
    vectorisable); border pixels check their neighbours (entries pointing outside are
    ignored)."""
    C, H, W = u.shape
    if 0 < i < H - 1 and W > 2:
        a0, a1, a2 = A[0, i], A[1, i], A[2, i]
        a3, a4, a5 = A[3, i], A[4, i], A[5, i]
        a6, a7, a8 = A[6, i], A[7, i], A[8, i]
        um, u0, up = u[c, i - 1], u[c, i], u[c, i + 1]
        for j in range(1, W - 1):
            out[j] = (a0[j] * um[j - 1] + a1[j] * um[j] + a2[j] * um[j + 1]
                      + a3[j] * u0[j - 1] + a4[j] * u0[j] + a5[j] * u0[j + 1]
                      + a6[j] * up[j - 1] + a7[j] * up[j] + a8[j] * up[j + 1])
        out[0] = _stencil_point(A, u, c, i, 0, H, W)
        out[W - 1] = _stencil_point(A, u, c, i, W - 1, H, W)
    else:
        for j in range(W):
            out[j] = _stencil_point(A, u, c, i, j, H, W)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _stencil_apply(A, u, out):
    """out[c] = Σ_s A[s] · shift_s(u[c]); planar (C, H, W) images, (9, H, W) stencil."""
    C, H, W = u.shape
    for i in prange(H):
        for c in range(C):
            _stencil_row(A, u, c, i, out[c, i])
    return out


@njit(parallel=True, cache=True, fastmath=FASTMATH)
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
    return _sum_in_order(parts)


def dot(a, b) -> float:
    """⟨a, b⟩ accumulated in float64 (parallel)."""
    return float(_dot(np.ascontiguousarray(a), np.ascontiguousarray(b)))


# ----------------------------------------------------------------------------- B
#: Image-formation models of :class:`Splat` (the one list of PSF names).
PSFS = ("bilinear", "footprint")


class Splat:
    """The PSF matrix ``B`` of a set of sample positions (paper §4.1, docs/explanation/method.md §4).

    Parameters
    ----------
    xy : (N, 2) float64
        Target pixel coordinates ``tau_k(x_m)`` (x = column, y = row; centre of the top-left
        pixel at (0, 0)), inside ``[0, W-1] × [0, H-1]`` (clamped otherwise).
    shape : (H, W)
        Target image shape.
    jac : (N, 2, 2) float64, optional
        ``∂tau/∂x_m`` (rows target x, y; columns source x, y), needed by ``psf="footprint"``.
    psf : {"bilinear", "footprint"}
        ``"bilinear"`` (default): the transformed PSF is a unit square centred at ``xy``
        (the paper's simplification, fig. discretization left), whose overlaps with the
        target pixels are the bilinear coefficients ``(1-fx)(1-fy), fx(1-fy), (1-fx)fy,
        fx·fy`` of the cell containing ``xy``. ``"footprint"``: the square source pixel of
        a uniformly sensitive sensor maps, under the locally linear warp, to the
        parallelogram ``P_m = tau(x_m) + J_m·[-½, ½]²`` and
        ``B_mp = area(P_m ∩ pixel p) / area(P_m)`` (paper eq. normal, fig. discretization
        right); J = I gives the bilinear coefficients again.

    Either way ``B`` is N × (H·W) with 4 non-zeros per row on a 2×2 block of pixels,
    rows summing to one, so ``Σ BᵀWB`` stays a 9-point stencil. A footprint wider or higher
    than one target pixel (a source coarser than the target along that axis) cannot be
    held by a 2×2 block: it is shrunk about its centre along that axis until its bounding
    box is 1 px (see :func:`_footprint_setup`); :attr:`shrunk_fraction` says how many
    samples were. Along an axis where the footprint fits it keeps its exact extent, and a
    uniformly coarser source (J = s·I, s ≥ 1) degrades to the bilinear model, the model
    the default already uses at every sample.

    Attributes
    ----------
    x0, y0, fx, fy : (N,) int32, int32, float64, float64
        The bilinear cell and fractions of ``xy`` (bilinear *interpolation* at ``tau``,
        whatever the PSF: the weights of docs/explanation/method.md §3 sample ``∇u`` there).
    bx0, by0 : (N,) int32
        Top-left pixel of each row's 2×2 block (``x0``, ``y0`` for the bilinear PSF).
    coef : (N, 4) float64
        Footprint coefficients (top-left, top-right, bottom-left, bottom-right); empty for
        the bilinear PSF (computed on the fly from fx, fy).
    n_shrunk, n_degenerate : int
        Footprints shrunk to fit a 2×2 block; non-finite or singular Jacobians (unit square).
    """

    def __init__(self, xy, shape, jac=None, psf="bilinear"):
        if psf not in PSFS:
            raise ValueError(f"psf must be one of {PSFS}, got {psf!r}")
        self.shape = (int(shape[0]), int(shape[1]))
        self.psf = psf
        H, W = self.shape
        xy = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2)
        self.n = xy.shape[0]
        if self.n >= 2 ** 31:
            raise ValueError(f"{self.n} samples: at most 2³¹ − 1 in one Splat (split the target)")
        self.x0, self.y0, self.fx, self.fy = _bilinear_setup(xy, H, W)
        self.n_shrunk = self.n_degenerate = 0
        if psf == "bilinear":
            self.bx0, self.by0 = self.x0, self.y0
            self.coef = np.zeros((0, 4), np.float64)
        else:
            if jac is None:
                raise ValueError("psf='footprint' needs the warp Jacobians (jac)")
            jac = np.ascontiguousarray(jac, dtype=np.float64).reshape(-1, 2, 2)
            if jac.shape[0] != self.n:
                raise ValueError(f"jac has {jac.shape[0]} rows for {self.n} samples")
            self.coef = np.empty((self.n, 4), np.float64)
            self.bx0 = np.empty(self.n, np.int32)
            self.by0 = np.empty(self.n, np.int32)
            flags = np.empty(self.n, np.int8)
            _footprint_setup(xy, jac, H, W, self.coef, self.bx0, self.by0, flags)
            counts = np.bincount(flags, minlength=3)
            self.n_shrunk, self.n_degenerate = int(counts[1]), int(counts[2])
        self.order, self.starts = bucket_by_cell(self.bx0, self.by0, max(H - 1, 1), W)

    @property
    def shrunk_fraction(self) -> float:
        """Fraction of the samples whose footprint was shrunk to fit a 2×2 block (0 for
        the bilinear PSF)."""
        return self.n_shrunk / self.n if self.n else 0.0

    def coefficients(self):
        """``(bx0, by0, coef)``: each row's block and its 4 coefficients (N, 4) (top-left,
        top-right, bottom-left, bottom-right), for either PSF."""
        if self.psf == "footprint":
            return self.bx0, self.by0, self.coef
        a, b = self.fx.astype(np.float64), self.fy.astype(np.float64)
        return self.x0, self.y0, np.stack([(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b], 1)

    def apply(self, u) -> np.ndarray:
        """``B u``: (H, W, C) image (or (H, W)) → (N, C) float64 sample values."""
        u = np.asarray(u)
        squeeze = u.ndim == 2
        if squeeze:
            u = u[..., None]
        out = _B_apply(np.ascontiguousarray(u), self.bx0, self.by0, self.fx, self.fy, self.coef)
        return out[:, 0] if squeeze else out

    def adjoint(self, vals, weight=None) -> np.ndarray:
        """``Bᵀ (w · vals)``: (N, C) → (H, W, C) float64 (splatting); (N,) → (H, W)."""
        vals = np.asarray(vals, dtype=np.float64)
        squeeze = vals.ndim == 1
        if squeeze:
            vals = vals[:, None]
        w = np.ones(self.n) if weight is None else np.ascontiguousarray(weight)
        H, W = self.shape
        rhs = np.zeros((vals.shape[1], H, W), np.float64)
        _assemble_kernel(self.bx0, self.by0, self.fx, self.fy, self.coef, self.order, self.starts,
                         w, np.ascontiguousarray(vals), np.zeros((0, 1, 1)), rhs, False)
        return rhs[0] if squeeze else np.ascontiguousarray(rhs.transpose(1, 2, 0))

    def normal(self, weight, vals, dtype=np.float64):
        """Assemble the stencil ``A = Bᵀ diag(w) B`` (9, H, W), ``b = Bᵀ (w·vals)`` (K, H, W)
        and ``c = ½ Σ w |vals|²`` so that for a planar image u (K, H, W)
        ``½ Σ_m w_m |(Bu)(m) − vals_m|² = ½⟨u, Au⟩ − ⟨b, u⟩ + c``.

        ``weight`` (N,) and ``vals`` (N, K) or (N,) may be float32 or float64 (sums are
        accumulated in float64); ``A`` and ``b`` are returned as ``dtype``."""
        w = np.ascontiguousarray(weight)
        if w.dtype not in (np.float32, np.float64):
            w = w.astype(np.float64)
        vals = np.asarray(vals)
        if vals.ndim == 1:
            vals = vals[:, None]
        vals = np.ascontiguousarray(vals)
        if vals.dtype not in (np.float32, np.float64):
            vals = vals.astype(np.float64)
        H, W = self.shape
        A = np.zeros((9, H, W), dtype)
        rhs = np.zeros((vals.shape[1], H, W), dtype)
        c = _assemble_kernel(self.bx0, self.by0, self.fx, self.fy, self.coef, self.order, self.starts,
                             w, vals, A, rhs, True)
        return A, rhs, c


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
    """``B`` as a scipy.sparse CSR matrix N × (H·W) (for tests), either PSF."""
    import scipy.sparse as sp

    H, W = splat.shape
    x0, y0, coef = splat.coefficients()
    rows = np.repeat(np.arange(splat.n), 4)
    y, x = y0.astype(np.int64), x0.astype(np.int64)
    cols = np.stack([y * W + x, y * W + x + 1, (y + 1) * W + x, (y + 1) * W + x + 1], 1).ravel()
    return sp.csr_matrix((coef.ravel(), (rows, cols)), shape=(splat.n, H * W))


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
@njit(parallel=True, cache=True, fastmath=FASTMATH)
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


@njit(parallel=True, cache=True, fastmath=FASTMATH)
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


def grad_central(u, out=None) -> np.ndarray:
    """Central-difference gradient ``D u``, replicated border: (C, H, W) → (C, 2, H, W),
    ``(Du)_x(i,j) = ½ (u(i, min(j+1,W-1)) − u(i, max(j-1,0)))`` (same for y)."""
    return grad_image(u, "central", out)


def grad_central_adj(g, out=None) -> np.ndarray:
    """Adjoint ``Dᵀ`` of :func:`grad_central`: (C, 2, H, W) → (C, H, W)."""
    return grad_image_adj(g, "central", out)
