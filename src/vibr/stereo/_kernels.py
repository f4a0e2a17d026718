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
@njit(parallel=True, cache=True)
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
@njit(parallel=True, cache=True)
def sweep_slab(I, mu, sd, srcs, sizes, A, b, winv, l0, radius, n_best, eps2, block,
               J, HJ, HJJ, HIJ, ok, best_c, best_l, c_minus, c_plus, prev):
    """Process a slab of fronto-parallel planes of the reference camera (streaming WTA).

    For the plane of inverse depth ``w`` (orthogonal depth ``z = 1/w``) the reference pixel
    ``x̄`` maps into source ``v`` by the plane homography

        x̃_v = K_v (R_rel + t_rel e₃ᵀ w) K_r⁻¹ x̄ = A_v x̄ + w b_v,

    ``A_v = K_v R_rel K_r⁻¹``, ``b_v = K_v t_rel`` (R_rel, t_rel: reference → source).
    Each source is resampled bilinearly (clamped at the border), the ZNCC in a
    (2r+1)² window is computed from box sums, the per-view costs ``1 − ZNCC`` are
    aggregated by the mean of the ``n_best`` lowest (occlusion robustness), and the
    running minimum over planes is kept together with the costs of its two neighbouring
    labels (for the parabolic sub-label fit). Only O(views·H·W) memory: the full cost
    volume is never stored.

    Arrays: I, mu, sd (H,W) reference grey / window mean / regularised std; srcs
    (nv,Hm,Wm) float32 source grey images (padded), sizes (nv,2) their (H,W); A (nv,3,3),
    b (nv,3); winv (d,) inverse depths of this slab, first label index ``l0``; work buffers
    J, HJ, HJJ, HIJ (nv,H,W), ok (nv,H,W) uint8; state best_c, best_l, c_minus, c_plus,
    prev (H,W) updated in place.
    """
    H, W = I.shape
    nv = srcs.shape[0]
    for di in range(winv.shape[0]):
        w = winv[di]
        lab = l0 + di
        # 1. warp every source onto the plane and take horizontal window sums
        for k in prange(nv * H):
            v = k // H
            i = k - v * H
            hv = sizes[v, 0]
            wv = sizes[v, 1]
            for j in range(W):
                px = A[v, 0, 0] * j + A[v, 0, 1] * i + A[v, 0, 2] + w * b[v, 0]
                py = A[v, 1, 0] * j + A[v, 1, 1] * i + A[v, 1, 2] + w * b[v, 1]
                pz = A[v, 2, 0] * j + A[v, 2, 1] * i + A[v, 2, 2] + w * b[v, 2]
                if pz <= 1e-12:
                    ok[v, i, j] = 0
                    J[v, i, j] = 0.0
                    continue
                x = px / pz
                y = py / pz
                inside = (x > -0.5) and (y > -0.5) and (x < wv - 0.5) and (y < hv - 0.5)
                ok[v, i, j] = 1 if inside else 0
                if x < 0.0:
                    x = 0.0
                if y < 0.0:
                    y = 0.0
                if x > wv - 1.0:
                    x = wv - 1.0
                if y > hv - 1.0:
                    y = hv - 1.0
                x0 = min(int(x), wv - 2) if wv > 1 else 0
                y0 = min(int(y), hv - 2) if hv > 1 else 0
                fx = x - x0
                fy = y - y0
                x1 = min(x0 + 1, wv - 1)
                y1 = min(y0 + 1, hv - 1)
                J[v, i, j] = ((1 - fy) * ((1 - fx) * srcs[v, y0, x0] + fx * srcs[v, y0, x1])
                              + fy * ((1 - fx) * srcs[v, y1, x0] + fx * srcs[v, y1, x1]))
            # running horizontal window sums (window clipped at the border)
            a = 0.0
            a2 = 0.0
            a3 = 0.0
            for jj in range(min(W, radius)):
                q = J[v, i, jj]
                a += q
                a2 += q * q
                a3 += q * I[i, jj]
            for j in range(W):
                jn = j + radius
                if jn < W:
                    q = J[v, i, jn]
                    a += q
                    a2 += q * q
                    a3 += q * I[i, jn]
                jo = j - radius - 1
                if jo >= 0:
                    q = J[v, i, jo]
                    a -= q
                    a2 -= q * q
                    a3 -= q * I[i, jo]
                HJ[v, i, j] = a
                HJJ[v, i, j] = a2
                HIJ[v, i, j] = a3
        # 2. vertical sums, ZNCC, robust aggregation over views, running minimum
        nblk = (H + block - 1) // block
        for blk in prange(nblk):
            costs = np.empty(nv)
            # running vertical sums of the horizontal sums, per view and column
            VJ = np.zeros((nv, W))
            VJJ = np.zeros((nv, W))
            VIJ = np.zeros((nv, W))
            ib0 = blk * block
            ib1 = min(H, ib0 + block)
            for v in range(nv):
                for ii in range(max(0, ib0 - radius - 1), min(H, ib0 + radius)):
                    for j in range(W):
                        VJ[v, j] += HJ[v, ii, j]
                        VJJ[v, j] += HJJ[v, ii, j]
                        VIJ[v, j] += HIJ[v, ii, j]
            for i in range(ib0, ib1):
                i0 = max(0, i - radius)
                i1 = min(H, i + radius + 1)
                inew = i + radius
                iold = i - radius - 1
                for v in range(nv):
                    if inew < H:
                        for j in range(W):
                            VJ[v, j] += HJ[v, inew, j]
                            VJJ[v, j] += HJJ[v, inew, j]
                            VIJ[v, j] += HIJ[v, inew, j]
                    if iold >= 0:
                        for j in range(W):
                            VJ[v, j] -= HJ[v, iold, j]
                            VJJ[v, j] -= HJJ[v, iold, j]
                            VIJ[v, j] -= HIJ[v, iold, j]
                for j in range(W):
                    n = (i1 - i0) * (min(W, j + radius + 1) - max(0, j - radius))
                    nval = 0
                    for v in range(nv):
                        if ok[v, i, j] == 0:
                            continue
                        a = VJ[v, j]
                        a2 = VJJ[v, j]
                        a3 = VIJ[v, j]
                        mJ = a / n
                        vJ = a2 / n - mJ * mJ
                        if vJ < 0.0:
                            vJ = 0.0
                        ncc = (a3 / n - mu[i, j] * mJ) / (sd[i, j] * np.sqrt(vJ + eps2))
                        costs[nval] = 1.0 - ncc
                        nval += 1
                    if nval == 0:
                        c = 2.0  # seen by no source at this depth: worst cost
                    else:
                        # partial selection sort of the n_best lowest (nv is small; no allocation)
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
                        c /= m
                    if c < best_c[i, j]:
                        best_c[i, j] = c
                        best_l[i, j] = lab
                        c_minus[i, j] = prev[i, j] if lab > 0 else np.inf
                        c_plus[i, j] = np.inf
                    elif best_l[i, j] == lab - 1:
                        c_plus[i, j] = c
                    prev[i, j] = c


@njit(parallel=True, cache=True)
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
@njit(parallel=True, cache=True)
def consistency(depth_r, Kr_inv, Rr, tr, depths, sizes, Ks, Rs, ts, rel_tol, px_tol):
    """Geometric consistency of a reference depth map with its neighbours' depth maps.

    For each reference pixel x with depth z: X = back-projection; project into neighbour
    v → (x_v, z_v); read the neighbour's depth D_v at the nearest pixel; the view agrees
    when |D_v − z_v| ≤ rel_tol · z_v and the round trip (back-project x_v with D_v,
    project into the reference) lands within ``px_tol`` pixels of x.

    Returns ``(n_agree (H,W) int32, reproj (H,W) float64 mean round-trip error of the
    agreeing views (NaN if none), spread (H,W) float64 std of the reference-frame depths
    of the agreeing round-trip points together with z)``.
    """
    H, W = depth_r.shape
    nv = depths.shape[0]
    n_agree = np.zeros((H, W), np.int32)
    reproj = np.full((H, W), np.nan)
    spread = np.full((H, W), np.nan)
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
            if cnt > 0:
                reproj[i, j] = err_sum / cnt
                m = s1 / (cnt + 1)
                var = s2 / (cnt + 1) - m * m
                spread[i, j] = np.sqrt(var) if var > 0 else 0.0
    return n_agree, reproj, spread


# --------------------------------------------------------------------------- TV-L1
@njit(parallel=True, cache=True)
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
