"""Visibility (paper §5.5, docs/explanation/method.md §2): target z-buffer by quad splatting, and the
per-sample visibility test.

1. **Z-buffer.** Every source pixel m of every source view is a small 3D surface element:
   the four corners ``(x ± ½, y ± ½)`` with depth ``z + z_x dx + z_y dy`` (the pixel's
   tangent plane), back-projected and projected into the target. The projected quad is
   rasterised as two triangles; at every target pixel centre inside, the depth is
   interpolated perspective-correctly (``1/w`` is affine in screen space on a planar
   triangle) and the per-pixel minimum is kept. Parallel and deterministic: each thread
   owns a strip of source rows and its own buffer; buffers are min-reduced at the end
   (min is order independent, so the result does not depend on scheduling).
2. **Visibility.** A sample that lands inside the target at ``tau`` with target depth
   ``w`` is visible iff ``w_p ≤ (1 + vis_threshold) · z_u(p)`` where ``p`` is the nearest
   target pixel and ``w_p`` is the sample's depth carried from ``tau`` to ``p`` along its
   own surface element (first order: ``w_p = w + ∇_x w · (∂tau/∂x)⁻¹ (p − tau)``), so
   that the test compares depths at the same point and a slanted surface does not occlude
   itself.

Threshold: relative, default :data:`DEFAULT_VIS_THRESHOLD` = 0.02. Reasoning: a
correct sample differs from the z-buffer at its pixel by (a) the second-order error of the
tangent-plane quads (≪ 1e-3 z at ½ pixel) and (b) disagreement between views about the
same surface, i.e. depth noise; the z-buffer keeps the *minimum* over the overlapping
quads of all views and the slopes of a noisy map are noisy too, so the margin must be
several times the relative noise. A truly occluded sample is behind by the gap between
two surfaces, typically well above 2 % of the depth. Measured on the synthetic arc scene
(``_synthetic_agreement`` in ``tests/test_geometry_visibility.py``, 128², agreement with
exact ray casting on source pixels > 1 px from a depth edge):

===========  =======  =======  =======  =======  =======
noise / thr  0.002    0.005    0.01     0.02     0.05
===========  =======  =======  =======  =======  =======
exact depth  0.9909   0.9948   0.9955   0.9955   0.9955
0.3 % noise  0.5027   0.7532   0.9496   0.9945   0.9955
1 % noise    0.3783   0.4538   0.5821   0.7934   0.9844
===========  =======  =======  =======  =======  =======

(per-pixel independent Gaussian noise, ``vibr.synthetic.degrade_depth``; real estimated
depth is spatially correlated and less harsh). With noisier depth raise the threshold
to about 5× its relative noise.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from .warp import _warp_one

__all__ = ["splat_zbuffer", "splat_mesh", "new_zbuffers", "reduce_zbuffers", "visibility_mask",
           "DEFAULT_VIS_THRESHOLD", "DEFAULT_MAX_QUAD_PX",
           "OUTSIDE", "BEHIND", "UNKNOWN", "OCCLUDED", "VISIBLE"]

DEFAULT_VIS_THRESHOLD = 0.02
#: A projected quad whose bounding box is larger than this (pixels, per side) is not
#: rasterised: it can only come from a surface element seen edge-on or very close to the
#: target camera, where one source pixel would smear over a large area of the z-buffer.
DEFAULT_MAX_QUAD_PX = 32
#: Affine splatting enlarges each quad by this much (source pixels, per side).
QUAD_MARGIN = 0.01

# sample states returned by visibility_mask
UNKNOWN = 0    # depth unknown (NaN)
BEHIND = 1     # at or behind the target camera's plane
OUTSIDE = 2    # lands outside the target image
OCCLUDED = 3   # behind the z-buffer by more than the threshold
VISIBLE = 4


#: The warps' kernels divide by IEEE rules (numba's "numpy" error model): each divisor is
#: tested before or after its division (w > 0, |det| > 0, area ≠ 0), so a zero gives an
#: infinity the test rejects, where Python's model added a zero test and an exception path
#: to every division (docs/explanation/renderer.md, "Speed round 6").
_DIVISION = "numpy"


@njit(cache=True, inline="always")
def _raster_tri(buf, ax, ay, aw, bx, by, bw, cx, cy, cw, Hu, Wu):
    # signed area (twice)
    area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    if abs(area) < 1e-12:
        return
    inv_area = 1.0 / area
    xmin = min(ax, min(bx, cx))
    xmax = max(ax, max(bx, cx))
    ymin = min(ay, min(by, cy))
    ymax = max(ay, max(by, cy))
    i0 = max(int(np.ceil(ymin)), 0)
    i1 = min(int(np.floor(ymax)), Hu - 1)
    j0 = max(int(np.ceil(xmin)), 0)
    j1 = min(int(np.floor(xmax)), Wu - 1)
    eps = -1e-9
    for i in range(i0, i1 + 1):
        py = float(i)
        for j in range(j0, j1 + 1):
            px = float(j)
            l0 = ((bx - px) * (cy - py) - (by - py) * (cx - px)) * inv_area
            l1 = ((cx - px) * (ay - py) - (cy - py) * (ax - px)) * inv_area
            l2 = 1.0 - l0 - l1
            if l0 >= eps and l1 >= eps and l2 >= eps:
                d = 1.0 / (l0 / aw + l1 / bw + l2 / cw)
                if d < buf[i, j]:
                    buf[i, j] = d


@njit(parallel=True, cache=True, error_model=_DIVISION)
def _splat_kernel(z, zx, zy, M, c, bufs, max_quad):
    H, W = z.shape
    nb, Hu, Wu = bufs.shape
    for b in prange(nb):
        buf = bufs[b]
        r0 = (H * b) // nb
        r1 = (H * (b + 1)) // nb
        cu = np.empty(4)
        cv = np.empty(4)
        cw = np.empty(4)
        for i in range(r0, r1):
            for j in range(W):
                zc = z[i, j]
                if not (zc == zc):
                    continue
                gx = zx[i, j]
                gy = zy[i, j]
                ok = True
                for k in range(4):
                    dx = -0.5 if (k == 0 or k == 3) else 0.5
                    dy = -0.5 if k < 2 else 0.5
                    zk = zc + gx * dx + gy * dy
                    x = j + dx
                    y = i + dy
                    q0 = M[0, 0] * x + M[0, 1] * y + M[0, 2]
                    q1 = M[1, 0] * x + M[1, 1] * y + M[1, 2]
                    q2 = M[2, 0] * x + M[2, 1] * y + M[2, 2]
                    w = zk * q2 + c[2]
                    if zk <= 0.0 or w <= 1e-12:
                        ok = False
                        break
                    cu[k] = (zk * q0 + c[0]) / w
                    cv[k] = (zk * q1 + c[1]) / w
                    cw[k] = w
                if not ok:
                    continue
                umin = min(min(cu[0], cu[1]), min(cu[2], cu[3]))
                umax = max(max(cu[0], cu[1]), max(cu[2], cu[3]))
                vmin = min(min(cv[0], cv[1]), min(cv[2], cv[3]))
                vmax = max(max(cv[0], cv[1]), max(cv[2], cv[3]))
                if umax < 0 or vmax < 0 or umin > Wu - 1 or vmin > Hu - 1:
                    continue
                if umax - umin > max_quad or vmax - vmin > max_quad:
                    continue
                # quick reject: no pixel centre in the bounding box
                if np.floor(umax) < np.ceil(umin) or np.floor(vmax) < np.ceil(vmin):
                    continue
                _raster_tri(buf, cu[0], cv[0], cw[0], cu[1], cv[1], cw[1],
                            cu[2], cv[2], cw[2], Hu, Wu)
                _raster_tri(buf, cu[0], cv[0], cw[0], cu[2], cv[2], cw[2],
                            cu[3], cv[3], cw[3], Hu, Wu)


@njit(parallel=True, cache=True, error_model=_DIVISION)
def _splat_affine_kernel(z, zx, zy, M, c, bufs, max_quad, half):
    H, W = z.shape
    nb, Hu, Wu = bufs.shape
    for b in prange(nb):
        buf = bufs[b]
        wk = np.empty(10)
        # interleaved rows: both threads get foreground and background alike (balance)
        for i in range(b, H, nb):
            y = float(i)
            for j in range(W):
                zc = z[i, j]
                if not (zc == zc):
                    continue
                x = float(j)
                w = _warp_one(x, y, zc, zx[i, j], zy[i, j], M, c, wk)
                if not (w > 1e-12):
                    continue
                u = wk[0]
                v = wk[1]
                j00 = wk[3]
                j01 = wk[4]
                j10 = wk[5]
                j11 = wk[6]
                ex = half * (abs(j00) + abs(j01))
                ey = half * (abs(j10) + abs(j11))
                if u + ex < 0 or v + ey < 0 or u - ex > Wu - 1 or v - ey > Hu - 1:
                    continue
                if 2 * ex > max_quad or 2 * ey > max_quad:
                    continue
                c0 = max(int(np.ceil(u - ex)), 0)
                c1 = min(int(np.floor(u + ex)), Wu - 1)
                rr0 = max(int(np.ceil(v - ey)), 0)
                rr1 = min(int(np.floor(v + ey)), Hu - 1)
                if c1 < c0 or rr1 < rr0:
                    continue
                det = wk[9]
                if abs(det) < 1e-9:
                    continue
                idet = 1.0 / det
                q2 = M[2, 0] * x + M[2, 1] * y + M[2, 2]
                gwx = zc * M[2, 0] + q2 * zx[i, j]
                gwy = zc * M[2, 1] + q2 * zy[i, j]
                for pi in range(rr0, rr1 + 1):
                    dv = pi - v
                    for pj in range(c0, c1 + 1):
                        du = pj - u
                        sx = (j11 * du - j01 * dv) * idet
                        sy = (-j10 * du + j00 * dv) * idet
                        if abs(sx) <= half and abs(sy) <= half:
                            d = w + gwx * sx + gwy * sy
                            if d < buf[pi, pj]:
                                buf[pi, pj] = d


@njit(parallel=True, cache=True, error_model=_DIVISION)
def _splat_mesh_kernel(z, M, c, bufs, max_quad, edge_rel):
    H, W = z.shape
    nb, Hu, Wu = bufs.shape
    for b in prange(nb):
        buf = bufs[b]
        cu = np.empty(4)
        cv = np.empty(4)
        cw = np.empty(4)
        for i in range(b, H - 1, nb):
            for j in range(W - 1):
                # cell corners in order (i,j) (i,j+1) (i+1,j+1) (i+1,j)
                ok = True
                zmin = np.inf
                zmax = -np.inf
                for k in range(4):
                    di = 0 if k < 2 else 1
                    dj = 1 if (k == 1 or k == 2) else 0
                    zk = z[i + di, j + dj]
                    if not (zk == zk):
                        ok = False
                        break
                    zmin = min(zmin, zk)
                    zmax = max(zmax, zk)
                    x = float(j + dj)
                    y = float(i + di)
                    q0 = M[0, 0] * x + M[0, 1] * y + M[0, 2]
                    q1 = M[1, 0] * x + M[1, 1] * y + M[1, 2]
                    q2 = M[2, 0] * x + M[2, 1] * y + M[2, 2]
                    w = zk * q2 + c[2]
                    if w <= 1e-12:
                        ok = False
                        break
                    cu[k] = (zk * q0 + c[0]) / w
                    cv[k] = (zk * q1 + c[1]) / w
                    cw[k] = w
                if not ok or zmax - zmin > edge_rel * zmin:
                    continue  # unknown corner or a depth edge: do not bridge it
                umin = min(min(cu[0], cu[1]), min(cu[2], cu[3]))
                umax = max(max(cu[0], cu[1]), max(cu[2], cu[3]))
                vmin = min(min(cv[0], cv[1]), min(cv[2], cv[3]))
                vmax = max(max(cv[0], cv[1]), max(cv[2], cv[3]))
                if umax < 0 or vmax < 0 or umin > Wu - 1 or vmin > Hu - 1:
                    continue
                if umax - umin > max_quad or vmax - vmin > max_quad:
                    continue
                _raster_tri(buf, cu[0], cv[0], cw[0], cu[1], cv[1], cw[1],
                            cu[2], cv[2], cw[2], Hu, Wu)
                _raster_tri(buf, cu[0], cv[0], cw[0], cu[2], cv[2], cw[2],
                            cu[3], cv[3], cw[3], Hu, Wu)


def splat_mesh(bufs, M, c, z, edge_rel: float = 0.02, max_quad_px: int = DEFAULT_MAX_QUAD_PX) -> None:
    """Splat a depth map as a triangle mesh through its pixel centres (in place).

    Each cell of four neighbouring pixel centres, with their depths, is cut along its
    ``(i, j)–(i+1, j+1)`` diagonal into two planar 3D triangles, rasterised with
    perspective-correct depth. Cells with an unknown corner or whose depths spread by more
    than ``edge_rel · z`` (a depth edge) are not drawn. On a planar triangle ``1/z`` is
    affine in the image of *any* pinhole camera, so for a light field (where disparity is
    affine in ``1/z``) the transferred depth is exactly the piecewise-linear interpolation
    of the source disparity: this is what :func:`vibr.geometry.ensure_source_depth` uses.
    The target z-buffer of the renderer uses per-pixel quads (:func:`splat_zbuffer`).
    """
    _splat_mesh_kernel(np.ascontiguousarray(z, dtype=np.float64), M, c, bufs,
                       float(max_quad_px), float(edge_rel))


@njit(parallel=True, cache=True)
def _reduce_kernel(bufs, out):
    nb, Hu, Wu = bufs.shape
    for i in prange(Hu):
        for j in range(Wu):
            m = bufs[0, i, j]
            for b in range(1, nb):
                if bufs[b, i, j] < m:
                    m = bufs[b, i, j]
            out[i, j] = m


def new_zbuffers(shape, n: int | None = None) -> np.ndarray:
    """``n`` (default: numba's thread count) per-thread z-buffers of ``shape``, float64,
    filled with +inf."""
    n = numba.get_num_threads() if n is None else int(n)
    return np.full((max(n, 1),) + tuple(shape), np.inf)


def splat_zbuffer(bufs, M, c, z, zx, zy, max_quad_px: int = DEFAULT_MAX_QUAD_PX,
                  mode: str = "affine") -> None:
    """Splat one source view's surface quads into per-thread z-buffers (in place).

    ``mode="projective"`` projects the quad's four corners ``(x ± ½, y ± ½)`` with depth
    ``z + z_x dx + z_y dy`` and rasterises two triangles with perspective-correct depth.
    ``mode="affine"`` (default, about 2× faster) uses the same quad to first order: a
    target pixel centre ``p`` is inside iff its source offset ``s = (∂tau/∂x_m)⁻¹ (p − tau)``
    has ``|s_x|, |s_y| ≤ ½ + QUAD_MARGIN`` and gets depth ``w + ∇_x w · s``. Over a
    half-pixel quad the two differ by second-order terms (measured in the tests). The
    small margin closes the hairline cracks between neighbouring pixels' tangent-plane
    quads (they share corners only to first order) that would otherwise let background
    samples count as visible through a foreground surface.

    Parameters
    ----------
    bufs : (T, Hu, Wu) float64, from :func:`new_zbuffers`.
    M, c : warp constants of the view (:func:`vibr.geometry.warp.warp_constants`).
    z, zx, zy : (H, W) float64 depth (NaN unknown) and slopes, scene units (per pixel).
    """
    z = np.ascontiguousarray(z, dtype=np.float64)
    zx = np.ascontiguousarray(zx, dtype=np.float64)
    zy = np.ascontiguousarray(zy, dtype=np.float64)
    if mode == "affine":
        _splat_affine_kernel(z, zx, zy, M, c, bufs, float(max_quad_px), 0.5 + QUAD_MARGIN)
    elif mode == "projective":
        _splat_kernel(z, zx, zy, M, c, bufs, float(max_quad_px))
    else:
        raise ValueError(f"splat mode must be 'affine' or 'projective', got {mode!r}")


def reduce_zbuffers(bufs) -> np.ndarray:
    """Min over the per-thread buffers: the target depth map z_u, (Hu, Wu) float64,
    +inf where nothing was splatted."""
    out = np.empty(bufs.shape[1:])
    _reduce_kernel(bufs, out)
    return out


@njit(parallel=True, cache=True, error_model=_DIVISION)
def _visibility_kernel(z, zx, zy, M, c, zbuf, thr, state, counts):
    H, W = z.shape
    Hu, Wu = zbuf.shape
    for i in prange(H):
        buf = np.empty(10)
        for t in range(5):
            counts[i, t] = 0
        for j in range(W):
            zc = z[i, j]
            if not (zc == zc):
                state[i, j] = UNKNOWN
                counts[i, UNKNOWN] += 1
                continue
            w = _warp_one(float(j), float(i), zc, zx[i, j], zy[i, j], M, c, buf)
            if not (w > 1e-12):
                state[i, j] = BEHIND
                counts[i, BEHIND] += 1
                continue
            u = buf[0]
            v = buf[1]
            if not (u >= 0.0 and v >= 0.0 and u <= Wu - 1 and v <= Hu - 1):
                state[i, j] = OUTSIDE
                counts[i, OUTSIDE] += 1
                continue
            pu = int(np.floor(u + 0.5))
            pv = int(np.floor(v + 0.5))
            if pu > Wu - 1:
                pu = Wu - 1
            if pv > Hu - 1:
                pv = Hu - 1
            zu = zbuf[pv, pu]
            # carry w from tau to the pixel centre along the sample's surface element:
            # δx_src = J⁻¹ (p − tau); w_p = w + ∂w/∂x_src · δx_src.
            det = buf[9]
            wp = w
            if abs(det) > 1e-6:
                du = pu - u
                dv = pv - v
                sx = (buf[6] * du - buf[4] * dv) / det
                sy = (-buf[5] * du + buf[3] * dv) / det
                if sx * sx + sy * sy <= 4.0:
                    x = float(j)
                    y = float(i)
                    q2 = M[2, 0] * x + M[2, 1] * y + M[2, 2]
                    gwx = zc * M[2, 0] + q2 * zx[i, j]
                    gwy = zc * M[2, 1] + q2 * zy[i, j]
                    wp = w + gwx * sx + gwy * sy
            if wp <= (1.0 + thr) * zu:
                state[i, j] = VISIBLE
                counts[i, VISIBLE] += 1
            else:
                state[i, j] = OCCLUDED
                counts[i, OCCLUDED] += 1


def visibility_mask(M, c, z, zx, zy, zbuf, vis_threshold: float = DEFAULT_VIS_THRESHOLD,
                    return_counts: bool = False):
    """State of every source pixel of one view: (H, W) uint8, one of UNKNOWN, BEHIND,
    OUTSIDE, OCCLUDED, VISIBLE (module constants). See the module docstring for the test.
    With ``return_counts``, also the (H, 5) int64 number of pixels of each state per row."""
    z = np.ascontiguousarray(z, dtype=np.float64)
    state = np.empty(z.shape, np.uint8)
    counts = np.empty((z.shape[0], 5), np.int64)
    with np.errstate(all="ignore"):
        _visibility_kernel(z, np.ascontiguousarray(zx, dtype=np.float64),
                           np.ascontiguousarray(zy, dtype=np.float64), M, c,
                           np.ascontiguousarray(zbuf, dtype=np.float64), float(vis_threshold),
                           state, counts)
    return (state, counts) if return_counts else state
