"""Compiled kernels of the depth estimators (numba, parallel over rows).

Nothing here knows about :class:`~vibr.scene.Scene`; the callers in
:mod:`vibr.stereo.planesweep`, :mod:`vibr.stereo.consistency` and
:mod:`vibr.stereo.lightfield` prepare plain arrays.

Pixel convention: pixel (row i, col j) has centre (x, y) = (j, i) (see :mod:`vibr.camera`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


# --------------------------------------------------------------------------- windows
@njit(parallel=True, cache=True, nogil=True)
def box_mean_std(img, radius, eps2):
    """Mean and regularised standard deviation of ``img`` (H×W) in (2r+1)² windows.

    The window is clipped at the image border. Returns ``(mu, sd)`` (H×W float64) with
    ``sd = sqrt(var + eps2)`` (``eps2`` regularises ZNCC in flat regions).
    """
    H, W = img.shape
    hs = np.empty((H, W))
    hs2 = np.empty((H, W))
    for i in prange(H):
        for j in range(W):
            a = 0.0
            a2 = 0.0
            for jj in range(max(0, j - radius), min(W, j + radius + 1)):
                v = img[i, jj]
                a += v
                a2 += v * v
            hs[i, j] = a
            hs2[i, j] = a2
    mu = np.empty((H, W))
    sd = np.empty((H, W))
    for i in prange(H):
        i0 = max(0, i - radius)
        i1 = min(H, i + radius + 1)
        for j in range(W):
            n = (i1 - i0) * (min(W, j + radius + 1) - max(0, j - radius))
            a = 0.0
            a2 = 0.0
            for ii in range(i0, i1):
                a += hs[ii, j]
                a2 += hs2[ii, j]
            m = a / n
            var = a2 / n - m * m
            if var < 0.0:
                var = 0.0
            mu[i, j] = m
            sd[i, j] = np.sqrt(var + eps2)
    return mu, sd


# --------------------------------------------------------------------------- plane sweep
@njit(cache=True, inline="always")
def _bilinear_clamped(srcs, v, x, y, wv, hv):
    """Bilinear sample of view ``v`` of the zero-padded stack ``srcs`` at (x, y), the
    coordinates clamped to its own ``hv × wv`` image (edge pixels extend outwards)."""
    x = min(max(x, 0.0), wv - 1.0)
    y = min(max(y, 0.0), hv - 1.0)
    x0 = min(int(x), wv - 2) if wv > 1 else 0
    y0 = min(int(y), hv - 2) if hv > 1 else 0
    fx = x - x0
    fy = y - y0
    x1 = min(x0 + 1, wv - 1)
    y1 = min(y0 + 1, hv - 1)
    return ((1 - fy) * ((1 - fx) * srcs[v, y0, x0] + fx * srcs[v, y0, x1])
            + fy * ((1 - fx) * srcs[v, y1, x0] + fx * srcs[v, y1, x1]))


@njit(cache=True, inline="always")
def _bilinear_inside(flat, wst, x, y):
    """:func:`_bilinear_clamped` for a point known to lie in [0, wv−1) × [0, hv−1) of a
    view: the same value, without the clamping. ``flat`` is the view's padded image as one
    row-major 1-d array of row stride ``wst``; the index is unsigned, so no load pays
    numba's negative-index test."""
    x0 = int(x)
    y0 = int(y)
    fx = x - x0
    fy = y - y0
    p = np.uint64(y0 * wst + x0)
    one = np.uint64(1)
    row = np.uint64(wst)
    return ((1 - fy) * ((1 - fx) * flat[p] + fx * flat[p + one])
            + fy * ((1 - fx) * flat[p + row] + fx * flat[p + row + one]))


@njit(cache=True, inline="always")
def _mean_lowest(costs, nval, n_best):
    """Mean of the ``min(n_best, nval)`` lowest of ``costs[:nval]`` (partially sorted in
    place, the lowest first); 2 (the worst cost) when ``nval`` is 0."""
    if nval == 0:
        return 2.0
    m = min(n_best, nval)
    c = 0.0
    for q in range(m):
        kmin = q
        for r in range(q + 1, nval):
            if costs[r] < costs[kmin]:
                kmin = r
        tmp = costs[q]
        costs[q] = costs[kmin]
        costs[kmin] = tmp
        c += costs[q]
    return c / m


@njit(cache=True, inline="always")
def _mean_two_lowest(C, OK, r, j, nv, n_best):
    """:func:`_mean_lowest` for ``n_best`` ≤ 2 of the views ``v`` with ``OK[v, r, j]``,
    from ``C[v, r, j]``, in one pass of min/max: the same sums, without the selection
    sort's data-dependent branches (they mispredict at every plane of the sweep)."""
    m1 = np.inf
    m2 = np.inf
    nval = 0
    for v in range(nv):
        if OK[v, r, j] != 0:
            cv = np.float64(C[v, r, j])
            m2 = min(m2, max(m1, cv))
            m1 = min(m1, cv)
            nval += 1
    if nval == 0:
        return 2.0
    if n_best == 1 or nval == 1:
        return m1
    return (m1 + m2) / 2


@njit(cache=True, inline="always")
def _warp_band_hsums(I, srcs, valid, A, b, v, w, hv, wv, h0, h1, ib0, ib1, radius, OK, Jrow, HJ, HJJ, HIJ):
    """Step 1 of :func:`sweep_slab` for view ``v`` and plane ``w``: warp the rows
    ``h0..h1`` (the band and its halo) by the plane homography, bilinearly (clamped), mark
    the band's samples that land inside the source in ``OK``, and store the running
    horizontal window sums of J, J² and I·J (window clipped at the border) in HJ, HJJ, HIJ."""
    W = I.shape[1]
    masked = valid.shape[0] > 0
    for ii in range(h0, h1):
        inband = ii >= ib0 and ii < ib1
        px = A[v, 0, 1] * ii + A[v, 0, 2] + w * b[v, 0]
        py = A[v, 1, 1] * ii + A[v, 1, 2] + w * b[v, 1]
        pz = A[v, 2, 1] * ii + A[v, 2, 2] + w * b[v, 2]
        # affine along the row (A[v, 2, 0] = 0: parallel cameras, light fields): the same
        # 1/qz for the whole row, one division per row instead of one per pixel
        affine = A[v, 2, 0] == 0.0 and pz > 1e-12
        iz_row = 1.0 / pz if affine else 0.0
        for j in range(W):
            qx = px + A[v, 0, 0] * j
            qy = py + A[v, 1, 0] * j
            if affine:
                iz = iz_row
            else:
                qz = pz + A[v, 2, 0] * j
                if qz <= 1e-12:
                    if inband:
                        OK[v, ii - ib0, j] = 0
                    Jrow[j] = 0.0
                    continue
                iz = 1.0 / qz
            x = qx * iz
            y = qy * iz
            if inband:
                inside = (x > -0.5) and (y > -0.5) and (x < wv - 0.5) and (y < hv - 0.5)
                if masked and inside and valid[v, int(y + 0.5), int(x + 0.5)] == 0:
                    inside = False  # lands on a masked pixel of the source: as if outside
                OK[v, ii - ib0, j] = 1 if inside else 0
            Jrow[j] = _bilinear_clamped(srcs, v, x, y, wv, hv)
        # running horizontal window sums (window clipped at the border)
        a = 0.0
        a2 = 0.0
        a3 = 0.0
        for jj in range(min(W, radius)):
            q = Jrow[jj]
            a += q
            a2 += q * q
            a3 += q * I[ii, jj]
        r = ii - h0
        for j in range(W):
            jn = j + radius
            if jn < W:
                q = Jrow[jn]
                a += q
                a2 += q * q
                a3 += q * I[ii, jn]
            jo = j - radius - 1
            if jo >= 0:
                q = Jrow[jo]
                a -= q
                a2 -= q * q
                a3 -= q * I[ii, jo]
            HJ[r, j] = a
            HJJ[r, j] = a2
            HIJ[r, j] = a3


@njit(cache=True, inline="always")
def _band_zncc(mu, sd, v, h0, ib0, ib1, radius, eps2, inv_cols, HJ, HJJ, HIJ, VJ, VJJ, VIJ, C):
    """Step 2 of :func:`sweep_slab`: running vertical sums of the horizontal sums and the
    cost ``1 − ZNCC`` of view ``v`` on the band's rows ``ib0..ib1``, into ``C[v]``."""
    H, W = mu.shape
    VJ[:] = 0.0
    VJJ[:] = 0.0
    VIJ[:] = 0.0
    for ii in range(max(0, ib0 - radius - 1), min(H, ib0 + radius)):
        if ii < h0:
            continue
        for j in range(W):
            VJ[j] += HJ[ii - h0, j]
            VJJ[j] += HJJ[ii - h0, j]
            VIJ[j] += HIJ[ii - h0, j]
    for i in range(ib0, ib1):
        i0 = max(0, i - radius)
        i1 = min(H, i + radius + 1)
        inew = i + radius
        iold = i - radius - 1
        if inew < H:
            for j in range(W):
                VJ[j] += HJ[inew - h0, j]
                VJJ[j] += HJJ[inew - h0, j]
                VIJ[j] += HIJ[inew - h0, j]
        if iold >= h0:
            for j in range(W):
                VJ[j] -= HJ[iold - h0, j]
                VJJ[j] -= HJJ[iold - h0, j]
                VIJ[j] -= HIJ[iold - h0, j]
        rn = 1.0 / (i1 - i0)
        for j in range(W):
            inv_n = rn * inv_cols[j]
            mJ = VJ[j] * inv_n
            vJ = VJJ[j] * inv_n - mJ * mJ
            if vJ < 0.0:
                vJ = 0.0
            ncc = (VIJ[j] * inv_n - mu[i, j] * mJ) / (sd[i, j] * np.sqrt(vJ + eps2))
            C[v, i - ib0, j] = 1.0 - ncc


@njit(cache=True, inline="always")
def _aggregate_band(C, OK, costs, nv, n_best, ib0, ib1, lab, best_c, best_l, c_minus, c_plus, prev):
    """Step 3 of :func:`sweep_slab`: the robust aggregation over views (mean of the
    ``n_best`` lowest costs) on the band and the running minimum over planes, with the
    costs of the winner's two neighbouring labels."""
    W = best_c.shape[1]
    for i in range(ib0, ib1):
        for j in range(W):
            if n_best <= 2:
                c = _mean_two_lowest(C, OK, i - ib0, j, nv, n_best)
            else:
                nval = 0
                for v in range(nv):
                    if OK[v, i - ib0, j] != 0:
                        costs[nval] = C[v, i - ib0, j]
                        nval += 1
                c = _mean_lowest(costs, nval, n_best)
            if c < best_c[i, j]:
                best_c[i, j] = c
                best_l[i, j] = lab
                c_minus[i, j] = prev[i, j] if lab > 0 else np.inf
                c_plus[i, j] = np.inf
            elif best_l[i, j] == lab - 1:
                c_plus[i, j] = c
            prev[i, j] = c


@njit(parallel=True, cache=True, nogil=True)
def sweep_slab(I, mu, sd, srcs, sizes, valid, A, b, winv, l0, radius, n_best, eps2, block,
               best_c, best_l, c_minus, c_plus, prev):
    """Process a slab of fronto-parallel planes of the reference camera (streaming WTA).

    For the plane of inverse depth ``w`` (orthogonal depth ``z = 1/w``) the reference pixel
    ``x̄`` maps into source ``v`` by the plane homography

        x̃_v = K_v (R_rel + t_rel e₃ᵀ w) K_r⁻¹ x̄ = A_v x̄ + w b_v,

    ``A_v = K_v R_rel K_r⁻¹``, ``b_v = K_v t_rel`` (R_rel, t_rel: reference → source).
    Each source is resampled bilinearly (clamped at the border), the ZNCC in a
    (2r+1)² window is computed from running box sums, the per-view costs ``1 − ZNCC`` are
    aggregated by the mean of the ``n_best`` lowest (occlusion robustness), and the
    running minimum over planes is kept together with the costs of its two neighbouring
    labels (for the parabolic sub-label fit). The full cost volume is never stored.

    One parallel region per slab: each task owns a band of ``block`` reference rows and
    runs every plane of the slab on it, warping the ``radius`` rows above and below the
    band again (instead of a second parallel region per plane and image-sized
    intermediate arrays: the work stays in the task's cache-sized buffers).

    Arrays: I, mu, sd (H,W) reference grey / window mean / regularised std; srcs
    (nv,Hm,Wm) float32 source grey images (padded), sizes (nv,2) their (H,W); valid
    (nv,Hm,Wm) uint8, 0 at the sources' masked pixels (a view whose sample lands on one
    counts as not seeing the pixel), or (0,1,1) for no masks; A (nv,3,3),
    b (nv,3); winv (d,) inverse depths of this slab, first label index ``l0``; state
    best_c, best_l, c_minus, c_plus, prev (H,W) updated in place.
    """
    H, W = I.shape
    nv = srcs.shape[0]
    nblk = (H + block - 1) // block
    inv_cols = np.empty(W)  # 1 / window width of each column (clipped at the border)
    for j in range(W):
        inv_cols[j] = 1.0 / (min(W, j + radius + 1) - max(0, j - radius))
    for blk in prange(nblk):
        ib0 = blk * block
        ib1 = min(H, ib0 + block)
        h0 = max(0, ib0 - radius)
        h1 = min(H, ib1 + radius)
        nb_ = ib1 - ib0
        HJ = np.empty((h1 - h0, W), np.float32)
        HJJ = np.empty((h1 - h0, W), np.float32)
        HIJ = np.empty((h1 - h0, W), np.float32)
        C = np.empty((nv, nb_, W), np.float32)
        OK = np.empty((nv, nb_, W), np.uint8)
        Jrow = np.empty(W, np.float32)
        VJ = np.empty(W)
        VJJ = np.empty(W)
        VIJ = np.empty(W)
        costs = np.empty(max(nv, 1))
        for di in range(winv.shape[0]):
            w = winv[di]
            for v in range(nv):
                _warp_band_hsums(I, srcs, valid, A, b, v, w, sizes[v, 0], sizes[v, 1], h0, h1, ib0, ib1,
                                 radius, OK, Jrow, HJ, HJJ, HIJ)
                _band_zncc(mu, sd, v, h0, ib0, ib1, radius, eps2, inv_cols, HJ, HJJ, HIJ,
                           VJ, VJJ, VIJ, C)
            _aggregate_band(C, OK, costs, nv, n_best, ib0, ib1, l0 + di, best_c, best_l, c_minus,
                            c_plus, prev)


@njit(parallel=True, cache=True, nogil=True)
def subpixel(best_c, best_l, c_minus, c_plus):
    """Parabolic sub-label refinement around the winning label.

    Fits ``c(l) ≈ c₀ + a (l − l*)²`` through the costs at ``l−1, l, l+1``; returns
    ``(label (H,W) float64, curvature a (H,W) float64)``, ``a = 0`` where a neighbour is
    missing (label at the end of the range) or the fit is not convex.
    """
    H, W = best_c.shape
    lab = np.empty((H, W))
    curv = np.zeros((H, W))
    for i in prange(H):
        for j in range(W):
            l = float(best_l[i, j])
            cm = c_minus[i, j]
            cp = c_plus[i, j]
            c0 = best_c[i, j]
            if np.isfinite(cm) and np.isfinite(cp):
                den = cm - 2.0 * c0 + cp
                if den > 1e-12:
                    off = 0.5 * (cm - cp) / den
                    if off > 0.5:
                        off = 0.5
                    if off < -0.5:
                        off = -0.5
                    l += off
                    curv[i, j] = 0.5 * den
            lab[i, j] = l
    return lab, curv


# --------------------------------------------------------------------------- consistency
@njit(parallel=True, cache=True, nogil=True)
def consistency(depth_r, Kr_inv, Rr, tr, depths, sizes, Ks, Rs, ts, rel_tol, px_tol):
    """Geometric consistency of a reference depth map with its neighbours' depth maps.

    For each reference pixel x with depth z: X = back-projection; project into neighbour
    v → (x_v, z_v); read the neighbour's depth D_v at the nearest pixel; the view agrees
    when |D_v − z_v| ≤ rel_tol · z_v and the round trip (back-project x_v with D_v,
    project into the reference) lands within ``px_tol`` pixels of x.

    Returns ``(n_agree (H,W) int32, reproj (H,W) float64 mean round-trip error of the
    agreeing views (NaN if none), spread (H,W) float64 std of the reference-frame depths
    of the agreeing round-trip points together with z, mean (H,W) float64 their mean (z
    where none agrees, NaN where z is unknown))``.
    """
    H, W = depth_r.shape
    nv = depths.shape[0]
    n_agree = np.zeros((H, W), np.int32)
    reproj = np.full((H, W), np.nan)
    spread = np.full((H, W), np.nan)
    mean = np.full((H, W), np.nan)
    for i in prange(H):
        for j in range(W):
            z = depth_r[i, j]
            if not np.isfinite(z):
                continue
            # camera-frame point then world point X = Rrᵀ (Xc − tr)
            cx = z * (Kr_inv[0, 0] * j + Kr_inv[0, 1] * i + Kr_inv[0, 2])
            cy = z * (Kr_inv[1, 0] * j + Kr_inv[1, 1] * i + Kr_inv[1, 2])
            cz = z * (Kr_inv[2, 0] * j + Kr_inv[2, 1] * i + Kr_inv[2, 2])
            dx = cx - tr[0]
            dy = cy - tr[1]
            dz = cz - tr[2]
            X0 = Rr[0, 0] * dx + Rr[1, 0] * dy + Rr[2, 0] * dz
            X1 = Rr[0, 1] * dx + Rr[1, 1] * dy + Rr[2, 1] * dz
            X2 = Rr[0, 2] * dx + Rr[1, 2] * dy + Rr[2, 2] * dz
            cnt = 0
            err_sum = 0.0
            s1 = z
            s2 = z * z
            for v in range(nv):
                yv0 = Rs[v, 0, 0] * X0 + Rs[v, 0, 1] * X1 + Rs[v, 0, 2] * X2 + ts[v, 0]
                yv1 = Rs[v, 1, 0] * X0 + Rs[v, 1, 1] * X1 + Rs[v, 1, 2] * X2 + ts[v, 1]
                yv2 = Rs[v, 2, 0] * X0 + Rs[v, 2, 1] * X1 + Rs[v, 2, 2] * X2 + ts[v, 2]
                if yv2 <= 0:
                    continue
                u = (Ks[v, 0, 0] * yv0 + Ks[v, 0, 1] * yv1 + Ks[v, 0, 2] * yv2) / yv2
                w = (Ks[v, 1, 1] * yv1 + Ks[v, 1, 2] * yv2) / yv2
                ju = int(np.floor(u + 0.5))
                iw = int(np.floor(w + 0.5))
                if ju < 0 or iw < 0 or ju >= sizes[v, 1] or iw >= sizes[v, 0]:
                    continue
                Dv = depths[v, iw, ju]
                if not np.isfinite(Dv):
                    continue
                if abs(Dv - yv2) > rel_tol * yv2:
                    continue
                # round trip: back-project (u, w) with Dv from view v, project into ref
                ry = (w - Ks[v, 1, 2]) / Ks[v, 1, 1]
                rx = (u - Ks[v, 0, 2] - Ks[v, 0, 1] * ry) / Ks[v, 0, 0]
                q0 = rx * Dv - ts[v, 0]
                q1 = ry * Dv - ts[v, 1]
                q2 = Dv - ts[v, 2]
                Y0 = Rs[v, 0, 0] * q0 + Rs[v, 1, 0] * q1 + Rs[v, 2, 0] * q2
                Y1 = Rs[v, 0, 1] * q0 + Rs[v, 1, 1] * q1 + Rs[v, 2, 1] * q2
                Y2 = Rs[v, 0, 2] * q0 + Rs[v, 1, 2] * q1 + Rs[v, 2, 2] * q2
                c0 = Rr[0, 0] * Y0 + Rr[0, 1] * Y1 + Rr[0, 2] * Y2 + tr[0]
                c1 = Rr[1, 0] * Y0 + Rr[1, 1] * Y1 + Rr[1, 2] * Y2 + tr[1]
                c2 = Rr[2, 0] * Y0 + Rr[2, 1] * Y1 + Rr[2, 2] * Y2 + tr[2]
                if c2 <= 0:
                    continue
                # K_r from its inverse is not at hand: compare in normalised coordinates
                # scaled by the focal length f_r = 1 / Kr_inv[0,0].
                xr = c0 / c2
                yr = c1 / c2
                ex = (xr - (Kr_inv[0, 0] * j + Kr_inv[0, 1] * i + Kr_inv[0, 2])) / Kr_inv[0, 0]
                ey = (yr - (Kr_inv[1, 1] * i + Kr_inv[1, 2])) / Kr_inv[1, 1]
                e = np.sqrt(ex * ex + ey * ey)
                if e > px_tol:
                    continue
                cnt += 1
                err_sum += e
                s1 += c2
                s2 += c2 * c2
            n_agree[i, j] = cnt
            m = s1 / (cnt + 1)
            mean[i, j] = m
            if cnt > 0:
                reproj[i, j] = err_sum / cnt
                var = s2 / (cnt + 1) - m * m
                spread[i, j] = np.sqrt(var) if var > 0 else 0.0
    return n_agree, reproj, spread, mean


# --------------------------------------------------------------------------- TV-L1
@njit(parallel=True, cache=True, nogil=True)
def tv_l1(f, conf, g, lam, n_iter):
    """Weighted TV-L1 smoothing (primal-dual, Chambolle & Pock 2011, Alg. 1):

        min_u  Σ g(x) |∇u(x)|  +  lam Σ conf(x) |u(x) − f(x)|

    f (H,W) the local estimate, conf (H,W) ≥ 0 its confidence (0 where unknown), g (H,W)
    edge weights in (0, 1] (small across image edges so that depth edges stay sharp).
    Step sizes tau = sigma = 1/sqrt(8). Returns u (H,W) float64.
    """
    H, W = f.shape
    tau = 1.0 / np.sqrt(8.0)
    sig = tau
    u = f.copy()
    ub = f.copy()
    px = np.zeros((H, W))
    py = np.zeros((H, W))
    for _ in range(n_iter):
        for i in prange(H):
            for j in range(W):
                gx = ub[i, j + 1] - ub[i, j] if j + 1 < W else 0.0
                gy = ub[i + 1, j] - ub[i, j] if i + 1 < H else 0.0
                qx = px[i, j] + sig * gx
                qy = py[i, j] + sig * gy
                nrm = np.sqrt(qx * qx + qy * qy) / g[i, j]
                if nrm > 1.0:
                    qx /= nrm
                    qy /= nrm
                px[i, j] = qx
                py[i, j] = qy
        for i in prange(H):
            for j in range(W):
                div = px[i, j] if j + 1 < W else 0.0
                if j > 0:
                    div -= px[i, j - 1]
                div += py[i, j] if i + 1 < H else 0.0
                if i > 0:
                    div -= py[i - 1, j]
                uo = u[i, j]
                v = uo + tau * div
                t = tau * lam * conf[i, j]
                d = v - f[i, j]
                if d > t:
                    v -= t
                elif d < -t:
                    v += t
                else:
                    v = f[i, j]
                u[i, j] = v
                ub[i, j] = 2.0 * v - uo
    return u


# --------------------------------------------------------------------------- slanted-plane refinement
@njit(cache=True, inline="always")
def _hash01(k):
    """Deterministic uniform number in [0, 1) from an integer key (splitmix64 finaliser):
    the refinement's random proposals do not depend on the thread schedule."""
    x = np.uint64(k)
    x ^= x >> np.uint64(33)
    x *= np.uint64(0xFF51AFD7ED558CCD)
    x ^= x >> np.uint64(33)
    x *= np.uint64(0xC4CEB9FE1A85EC53)
    x ^= x >> np.uint64(33)
    return float(x >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(parallel=True, cache=True, nogil=True)
def support_weights(I, offs, sigma_c, sigma_s, guide):
    """Adaptive-support (bilateral) window weights of the reference image (Yoon & Kweon
    2006; the bilateral NCC of Schönberger et al. 2016 §4.2):
    ``ω_q = exp(−‖G_q − G_p‖²/(2σ_c² C) − |q − p|²/(2σ_s²))`` for the window offsets ``offs``
    (n,2) (dy, dx), 0 outside the image, normalised to sum 1 per pixel. ``guide`` G
    (H,W,C) is the image the weights look at (the colour image, C = 3: two surfaces of
    equal luma but different hue are told apart; ``I[..., None]`` for grey); ``‖·‖²/C``
    is the mean squared channel difference, so σ_c is in grey levels either way. Pixels of the
    window that do not look like the centre (another surface across a depth edge) count
    little, so the matching window does not straddle an occlusion boundary.

    Returns ``(wts (H,W,n) float32, wI (H,W,n) float32, sd (H,W))``: the weights, the
    weighted centred reference samples ``ω_q (I_q − μ)`` (μ the weighted window mean; the
    weighted covariance with any J is then ``Σ wI_q J_q``), and the weighted standard
    deviation (without regulariser) of ``I`` in the window.
    """
    H, W = I.shape
    n = offs.shape[0]
    wts = np.zeros((H, W, n), np.float32)
    wI = np.zeros((H, W, n), np.float32)
    sd = np.empty((H, W))
    nc = guide.shape[2]
    ic = 0.5 / (sigma_c * sigma_c * nc)
    isp = 0.5 / (sigma_s * sigma_s)
    for i in prange(H):
        for j in range(W):
            tot = 0.0
            for k in range(n):
                qi = i + offs[k, 0]
                qj = j + offs[k, 1]
                if qi < 0 or qj < 0 or qi >= H or qj >= W:
                    continue
                d2 = 0.0
                for ch in range(nc):
                    d = guide[qi, qj, ch] - guide[i, j, ch]
                    d2 += d * d
                r2 = offs[k, 0] * offs[k, 0] + offs[k, 1] * offs[k, 1]
                wk = np.exp(-d2 * ic - r2 * isp)
                wts[i, j, k] = wk
                tot += wk
            m = 0.0
            m2 = 0.0
            for k in range(n):
                wk = wts[i, j, k] / tot
                wts[i, j, k] = wk
                if wk > 0.0:
                    v = I[i + offs[k, 0], j + offs[k, 1]]
                    m += wk * v
                    m2 += wk * v * v
            for k in range(n):
                if wts[i, j, k] > 0.0:
                    wI[i, j, k] = wts[i, j, k] * (I[i + offs[k, 0], j + offs[k, 1]] - m)
            var = m2 - m * m
            sd[i, j] = np.sqrt(var) if var > 0.0 else 0.0
    return wts, wI, sd


@njit(cache=True, fastmath=True, inline="always")
def _window_sums_inside(wts_ij, wI_ij, offf, flat, wst, cx, cy, cz, ex0, ex1, ex2, ey0, ey1, ey2):
    """The weighted window sums ``(Σ ω J, Σ ω J², Σ wI J)`` of :func:`_plane_cost` for a
    window whose samples all land inside the source (no clamping, no test per sample);
    ``wts_ij``, ``wI_ij`` the pixel's window weights, ``offf`` the offsets as floats,
    ``flat``, ``wst`` the source as :func:`_bilinear_inside` reads it."""
    sJ = 0.0
    sJJ = 0.0
    sIJ = 0.0
    if ex2 == 0.0 and ey2 == 0.0:
        # affine homography (parallel cameras: light fields): every sample has the
        # centre's 1/pz, computed once (the same numbers, one division per view instead
        # of one per sample)
        iz = 1.0 / cz
        for k in range(offf.shape[0]):
            dy = offf[k, 0]
            dx = offf[k, 1]
            q = _bilinear_inside(flat, wst, (cx + dx * ex0 + dy * ey0) * iz, (cy + dx * ex1 + dy * ey1) * iz)
            wq = wts_ij[k] * q
            sJ += wq
            sJJ += wq * q
            sIJ += wI_ij[k] * q
    else:
        for k in range(offf.shape[0]):
            dy = offf[k, 0]
            dx = offf[k, 1]
            iz = 1.0 / (cz + dx * ex2 + dy * ey2)
            q = _bilinear_inside(flat, wst, (cx + dx * ex0 + dy * ey0) * iz, (cy + dx * ex1 + dy * ey1) * iz)
            wq = wts_ij[k] * q
            sJ += wq
            sJJ += wq * q
            sIJ += wI_ij[k] * q
    return sJ, sJJ, sIJ


@njit(cache=True)
def _cost_setup(offs, srcs):
    """What every :func:`_plane_cost` of one kernel call shares: the window offsets as
    floats, the window's radius, and the sources as float64 rows (``flat``, (n, Hmax·Wmax)).
    Why float64 and flat: the window sums read four source pixels per sample, and
    converting each from float32 and indexing a 3-d array were a large share of the
    innermost loop (the same values, so the same costs; docs/explanation/depth.md, "The plane cost's
    reads")."""
    nv = srcs.shape[0]
    offf = offs.astype(np.float64)
    rwin = 0
    for k in range(offs.shape[0]):
        rwin = max(rwin, abs(offs[k, 0]), abs(offs[k, 1]))
    flat = np.ascontiguousarray(srcs).reshape(nv, -1).astype(np.float64)
    return offf, rwin, flat


@njit(cache=True, fastmath=True)
def _plane_cost(i, j, w, gx, gy, wts, wI, sdI, offs, offf, rwin, srcs, flat, sizes, valid, A, b, n_best, eps2,
                costs, lam1):
    """Aggregated cost ``1 − ZNCC`` (weighted window, mean of the ``n_best`` best views) of
    the plane ``w(x', y') = w + gx (x' − j) + gy (y' − i)`` (inverse depth, affine in the
    reference pixel: the image of any 3D plane) at reference pixel (i, j). A view counts
    when the centre lands inside it; 2 when none does or the plane is behind a camera.

    ``wts``, ``wI``, ``sdI``: the window weights, weighted centred reference samples and
    weighted reference std of :func:`support_weights` for the window offsets ``offs``;
    ``srcs``, ``sizes``, ``valid``, ``A``, ``b`` as in :func:`sweep_slab`; ``costs`` (≥ nv,) scratch.
    The ZNCC is ``Σ wI J / (√(sdI² + eps2) √(var_w(J) + eps2))``, J sampled bilinearly
    (clamped) at the plane's image of each window pixel. ``offf``, ``rwin``, ``flat``:
    :func:`_cost_setup` of ``offs``, ``srcs``."""
    nv = srcs.shape[0]
    nwin = offs.shape[0]
    wst = srcs.shape[2]
    masked = valid.shape[0] > 0
    nval = 0
    sI = np.sqrt(sdI[i, j] * sdI[i, j] + eps2)
    wts_ij = wts[i, j]
    wI_ij = wI[i, j]
    for v in range(nv):
        hv = sizes[v, 0]
        wv = sizes[v, 1]
        # homogeneous image of the centre, and its increments per window column / row
        cx = A[v, 0, 0] * j + A[v, 0, 1] * i + A[v, 0, 2] + w * b[v, 0]
        cy = A[v, 1, 0] * j + A[v, 1, 1] * i + A[v, 1, 2] + w * b[v, 1]
        cz = A[v, 2, 0] * j + A[v, 2, 1] * i + A[v, 2, 2] + w * b[v, 2]
        if cz <= 1e-12:
            continue
        xc = cx / cz
        yc = cy / cz
        if not ((xc > -0.5) and (yc > -0.5) and (xc < wv - 0.5) and (yc < hv - 0.5)):
            continue
        if masked and valid[v, int(yc + 0.5), int(xc + 0.5)] == 0:
            continue  # the centre lands on a masked pixel of the source
        ex0 = A[v, 0, 0] + gx * b[v, 0]
        ex1 = A[v, 1, 0] + gx * b[v, 1]
        ex2 = A[v, 2, 0] + gx * b[v, 2]
        ey0 = A[v, 0, 1] + gy * b[v, 0]
        ey1 = A[v, 1, 1] + gy * b[v, 1]
        ey2 = A[v, 2, 1] + gy * b[v, 2]
        sJ = 0.0
        sJJ = 0.0
        sIJ = 0.0
        bad = False
        # Fast path: when the window's four corners land in front of the camera and inside
        # [0, wv−1) × [0, hv−1), so do all its samples (pz is affine in the offset and the
        # homography maps the square onto a convex quadrilateral): no clamping, no test
        # per sample, the same numbers as the clamped sampler.
        inside = True
        for cyi in range(2):
            for cxi in range(2):
                ody = rwin if cyi else -rwin
                odx = rwin if cxi else -rwin
                pz = cz + odx * ex2 + ody * ey2
                if pz <= 1e-12:
                    inside = False
                    break
                x = (cx + odx * ex0 + ody * ey0) / pz
                y = (cy + odx * ex1 + ody * ey1) / pz
                # (a margin at the far edges: under fastmath a sample's x·(1/pz) may round
                # differently from the corner's x/pz, and must not reach column wv − 1)
                if not (x >= 0.0 and y >= 0.0 and x < wv - 1.0 - 1e-6 and y < hv - 1.0 - 1e-6):
                    inside = False
                    break
            if not inside:
                break
        if inside:
            sJ, sJJ, sIJ = _window_sums_inside(wts_ij, wI_ij, offf, flat[v], wst, cx, cy, cz, ex0, ex1,
                                               ex2, ey0, ey1, ey2)
            vJ = sJJ - sJ * sJ
            if vJ < 0.0:
                vJ = 0.0
            costs[nval] = 1.0 - sIJ / (sI * np.sqrt(vJ + eps2))
            nval += 1
            continue
        for k in range(nwin):
            wk = wts_ij[k]
            if wk == 0.0:
                continue
            dy = offs[k, 0]
            dx = offs[k, 1]
            pz = cz + dx * ex2 + dy * ey2
            if pz <= 1e-12:
                bad = True
                break
            iz = 1.0 / pz
            x = (cx + dx * ex0 + dy * ey0) * iz
            y = (cy + dx * ex1 + dy * ey1) * iz
            q = _bilinear_clamped(srcs, v, x, y, wv, hv)
            wq = wk * q
            sJ += wq
            sJJ += wq * q
            sIJ += wI_ij[k] * q
        if bad:
            continue
        vJ = sJJ - sJ * sJ
        if vJ < 0.0:
            vJ = 0.0
        ncc = sIJ / (sI * np.sqrt(vJ + eps2))
        costs[nval] = 1.0 - ncc
        nval += 1
    if nval == 0:
        return 2.0
    c = _mean_lowest(costs, nval, n_best)
    m = min(n_best, nval)
    if lam1 >= 0.0 and m > 1 and costs[0] + lam1 < c:
        c = costs[0] + lam1
    return c


@njit(parallel=True, cache=True, nogil=True)
def plane_costs(wts, wI, sdI, offs, srcs, sizes, valid, A, b, n_best, eps2, w, gx, gy, lam1):
    """:func:`_plane_cost` of every pixel's plane (w, gx, gy) (H,W) → (H,W) float64."""
    H, W = w.shape
    out = np.empty((H, W))
    nv = srcs.shape[0]
    offf, rwin, flat = _cost_setup(offs, srcs)
    for i in prange(H):
        costs = np.empty(max(nv, 1))
        for j in range(W):
            out[i, j] = _plane_cost(i, j, w[i, j], gx[i, j], gy[i, j], wts, wI, sdI, offs, offf, rwin,
                                    srcs, flat, sizes, valid, A, b, n_best, eps2, costs, lam1)
    return out


@njit(cache=True, inline="always")
def _try_plane(i, j, qi, qj, w, gx, gy, cost, wts, wI, sdI, offs, offf, rwin, srcs, flat, sizes, valid, A, b,
               n_best, eps2, costs, wmin, wmax, lam1, ver, seen, memo):
    """Propagation: pixel (i, j) tries the plane of pixel (qi, qj), extended to it; returns
    1 when it evaluated the cost, else 0.

    ``ver`` (H,W) counts the changes of each pixel's plane; ``seen`` (H,W) holds, for this
    direction of propagation, ``ver[qi, qj]`` when (i, j) last tried that neighbour's plane.
    With ``memo``, a neighbour that has not changed since is not tried again: its plane,
    extended to (i, j), is the same candidate with the same cost, which lost then against
    a cost that can only have fallen since (the result is exactly that of trying it)."""
    vq = ver[qi, qj]
    if memo and seen[i, j] == vq:
        return 0
    seen[i, j] = vq
    cw = w[qi, qj] + gx[qi, qj] * (j - qj) + gy[qi, qj] * (i - qi)
    if cw < wmin or cw > wmax:
        return 0
    # the pixel may already carry this very plane (it spread here in an earlier sweep):
    # the cost would be the same, so it could not win
    if cw == w[i, j] and gx[qi, qj] == gx[i, j] and gy[qi, qj] == gy[i, j]:
        return 0
    c = _plane_cost(i, j, cw, gx[qi, qj], gy[qi, qj], wts, wI, sdI, offs, offf, rwin, srcs, flat, sizes,
                    valid, A, b, n_best, eps2, costs, lam1)
    if c < cost[i, j]:
        cost[i, j] = c
        w[i, j] = cw
        gx[i, j] = gx[qi, qj]
        gy[i, j] = gy[qi, qj]
        ver[i, j] += 1
    return 1


@njit(parallel=True, cache=True, nogil=True)
def patchmatch_refine(wts, wI, sdI, offs, srcs, sizes, valid, A, b, n_best, eps2,
                      w, gx, gy, cost, n_iter, dw, dn, Kinv, wmin, wmax, seed, lam1,
                      r_first=0, memo=True, r_last=4):
    """Slanted-plane PatchMatch refinement (Bleyer et al. 2011) of per-pixel planes
    ``(w, gx, gy)`` (inverse depth at the pixel and its derivatives along x and y, per
    pixel), in place, with their costs ``cost`` (:func:`_plane_cost`).

    Each iteration runs four propagation sweeps, each parallel over the lines it does not
    follow (rows left→right and right→left, columns top→bottom and bottom→top): a pixel
    tries its predecessor's plane extended to it (``w_q + gx_q Δx + gy_q Δy``), so a good
    plane can cross the whole image in one sweep. Then every pixel tries four random
    perturbations of its plane: w and the normal together, w only, the normal only
    (ranges ``dw·2^-it`` in w and a slope ``dn·2^-it``, converted to pixel units by the
    focal length), and a random normal within 80° of the viewing ray at the same w. A
    candidate replaces the plane when its cost is lower; ``w`` stays in [wmin, wmax].
    Random numbers come from a hash of (seed, iteration, pixel): deterministic.

    ``r_first``, ``r_last``: the random candidates tried are those numbered r_first to
    r_last − 1 in the order above (r_first 1 leaves out the joint perturbation of w and the
    normal; r_last 2 the two candidates that change the normal alone).
    ``memo``: a propagation candidate whose source pixel has not changed since this pixel
    last tried it, in the same direction, is skipped (:func:`_try_plane`; the same planes
    and costs as without, fewer propagation evaluations from the second iteration on;
    docs/explanation/depth.md gives the count on fountain). Returns the number of plane costs evaluated.
    """
    H, W = w.shape
    nv = srcs.shape[0]
    inv_f = Kinv[0, 0]
    ver = np.zeros((H, W), np.int32)
    seen = np.full((4, H, W), -1, np.int32)
    offf, rwin, flat = _cost_setup(offs, srcs)
    n_eval = np.zeros(max(H, W), np.int64)
    for it in range(n_iter):
        scale = 0.5 ** it
        for i in prange(H):
            costs = np.empty(max(nv, 1))
            ne = 0
            for j in range(1, W):
                ne += _try_plane(i, j, i, j - 1, w, gx, gy, cost, wts, wI, sdI, offs, offf, rwin, srcs,
                                 flat, sizes, valid, A, b, n_best, eps2, costs, wmin, wmax, lam1, ver, seen[0], memo)
            for j in range(W - 2, -1, -1):
                ne += _try_plane(i, j, i, j + 1, w, gx, gy, cost, wts, wI, sdI, offs, offf, rwin, srcs,
                                 flat, sizes, valid, A, b, n_best, eps2, costs, wmin, wmax, lam1, ver, seen[1], memo)
            n_eval[i] += ne
        for j in prange(W):
            costs = np.empty(max(nv, 1))
            ne = 0
            for i in range(1, H):
                ne += _try_plane(i, j, i - 1, j, w, gx, gy, cost, wts, wI, sdI, offs, offf, rwin, srcs,
                                 flat, sizes, valid, A, b, n_best, eps2, costs, wmin, wmax, lam1, ver, seen[2], memo)
            for i in range(H - 2, -1, -1):
                ne += _try_plane(i, j, i + 1, j, w, gx, gy, cost, wts, wI, sdI, offs, offf, rwin, srcs,
                                 flat, sizes, valid, A, b, n_best, eps2, costs, wmin, wmax, lam1, ver, seen[3], memo)
            n_eval[j] += ne
        for i in prange(H):
            costs = np.empty(max(nv, 1))
            for j in range(W):
                bw = w[i, j]
                bx = gx[i, j]
                by = gy[i, j]
                bc = cost[i, j]
                # viewing ray r = K⁻¹ x̄ of the pixel
                r0 = Kinv[0, 0] * j + Kinv[0, 1] * i + Kinv[0, 2]
                r1 = Kinv[1, 0] * j + Kinv[1, 1] * i + Kinv[1, 2]
                r2 = Kinv[2, 0] * j + Kinv[2, 1] * i + Kinv[2, 2]
                rn = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
                key = ((seed * 64 + it) * H + i) * W + j
                for r in range(r_first, r_last):
                    u1 = 2.0 * _hash01(key * 16 + 3 * r) - 1.0
                    u2 = 2.0 * _hash01(key * 16 + 3 * r + 1) - 1.0
                    u3 = 2.0 * _hash01(key * 16 + 3 * r + 2) - 1.0
                    if r < 3:
                        cw = bw + (u1 * dw * scale if r != 2 else 0.0)
                        sn = dn * scale * bw * inv_f
                        cx = bx + (u2 * sn if r != 1 else 0.0)
                        cy = by + (u3 * sn if r != 1 else 0.0)
                    else:
                        # random normal n (uniform direction: u in the unit ball), within
                        # 80° of the ray: the plane n·X = d has w(x') = n·K⁻¹x̄'/d with
                        # d = n·r/w, so gx = w n·K⁻¹e₁/(n·r), gy = w n·K⁻¹e₂/(n·r)
                        nn = np.sqrt(u1 * u1 + u2 * u2 + u3 * u3)
                        if nn < 1e-6 or nn > 1.0:
                            continue
                        nr = u1 * r0 + u2 * r1 + u3 * r2
                        if abs(nr) < 0.17 * rn * nn:
                            continue
                        cw = bw
                        cx = bw * (u1 * Kinv[0, 0] + u2 * Kinv[1, 0] + u3 * Kinv[2, 0]) / nr
                        cy = bw * (u1 * Kinv[0, 1] + u2 * Kinv[1, 1] + u3 * Kinv[2, 1]) / nr
                    if cw < wmin or cw > wmax:
                        continue
                    c = _plane_cost(i, j, cw, cx, cy, wts, wI, sdI, offs, offf, rwin,
                                    srcs, flat, sizes, valid, A, b, n_best, eps2, costs, lam1)
                    n_eval[i] += 1
                    if c < bc:
                        bc = c
                        bw = cw
                        bx = cx
                        by = cy
                if bc < cost[i, j]:
                    w[i, j] = bw
                    gx[i, j] = bx
                    gy[i, j] = by
                    cost[i, j] = bc
                    ver[i, j] += 1
    return n_eval.sum()


# --------------------------------------------------------------------------- plane-vote median
@njit(cache=True)
def _stable_order(vals, m, order):
    """``order[:m]``: the indices of ``vals[:m]`` in ascending order, ties in index order
    (a stable argsort), from each value's rank. Why ranks: the m² comparisons have no
    data-dependent branch and run in vectors, where an insertion sort of a few dozen votes
    mispredicted at every step (docs/explanation/depth.md, "The median's sort")."""
    for a in range(m):
        v = vals[a]
        r = 0
        for b in range(m):
            r += (vals[b] < v) | ((vals[b] == v) & (b < a))
        order[r] = a


@njit(parallel=True, cache=True, nogil=True)
def plane_median(w, gx, gy, known, guide, offs, sigma_c, sigma_s):
    """Joint weighted median of per-pixel planes in inverse depth (Ma et al. 2013's
    weighted median filter for stereo, with plane votes).

    Every known pixel q of the window ``offs`` (n,2) (dy, dx) around p votes for its plane
    extended to p, ``w_q + gx_q (x_p − x_q) + gy_q (y_p − y_q)``, with the weight
    ``exp(−‖G_p − G_q‖²/(2σ_c² C) − |p − q|²/(2σ_s²))`` (G the (H,W,C) colour guide, the
    bilateral weights of :func:`support_weights`); p takes the weighted median of the votes
    and the slopes of the plane that cast it: the first vote, in ascending order (ties in
    window order), at which the running sum of the weights reaches half their total. Pixels
    with no known voter keep their plane; a vote that is not finite does not count.
    Returns the filtered ``(w, gx, gy)``, (H,W) float64 each.
    """
    H, W = w.shape
    n = offs.shape[0]
    nc = guide.shape[2]
    ic = 0.5 / (sigma_c * sigma_c * nc)
    ws = np.empty(n)
    for k in range(n):
        ws[k] = np.exp(-(offs[k, 0] * offs[k, 0] + offs[k, 1] * offs[k, 1]) * (0.5 / (sigma_s * sigma_s)))
    out = w.copy()
    ox = gx.copy()
    oy = gy.copy()
    for i in prange(H):
        vals = np.empty(n)
        wts = np.empty(n)
        src = np.empty(n, np.int64)
        order = np.empty(n, np.int64)
        for j in range(W):
            m = 0
            tot = 0.0
            for k in range(n):
                qi = i + offs[k, 0]
                qj = j + offs[k, 1]
                if qi < 0 or qj < 0 or qi >= H or qj >= W or not known[qi, qj]:
                    continue
                d2 = 0.0
                for ch in range(nc):
                    t = guide[i, j, ch] - guide[qi, qj, ch]
                    d2 += t * t
                v = w[qi, qj] - gx[qi, qj] * offs[k, 1] - gy[qi, qj] * offs[k, 0]
                if not np.isfinite(v):  # no vote (the ranks need a total order)
                    continue
                wk = ws[k] * np.exp(-d2 * ic)
                vals[m] = v
                wts[m] = wk
                src[m] = qi * W + qj
                tot += wk
                m += 1
            if m == 0 or tot <= 0.0:
                continue
            _stable_order(vals, m, order)
            acc = 0.0
            half = 0.5 * tot
            for r in range(m):
                k = order[r]
                acc += wts[k]
                if acc >= half:
                    out[i, j] = vals[k]
                    q = src[k]
                    ox[i, j] = gx[q // W, q % W]
                    oy[i, j] = gy[q // W, q % W]
                    break
    return out, ox, oy
