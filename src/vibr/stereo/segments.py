"""Planar completion of a depth map by colour segments (the segment-based stereo prior).

Local matching leaves two kinds of textured pixels wrong or unknown that no window can
decide: a flat surface next to a textured one (its pixels match at either depth, so the
foreground's depth "fattens" into it, or the cost is flat and the pixel is unknown), and
points that too few partners see (occluded, or outside their frames). Segment-based
stereo (Tao, Sawhney & Kumar 2001; Klaus, Sormann & Karner 2006) adds the prior that
reaches past the window: a region of uniform colour is one surface, approximately planar.
Here:

1. the reference image is cut into colour segments (Felzenszwalb & Huttenlocher 2004,
   :func:`skimage.segmentation.felzenszwalb`), at half size for speed;
2. in each segment, a plane in inverse depth ``w(x, y) = a x + b y + c`` (exactly the
   image of a 3D plane, see :func:`vibr.stereo.planesweep.refine_planes`) is fitted to the
   known depths by RANSAC with the consistency check's tolerance (``|w − w_plane| ≤
   rel_tol · w``) and refitted to its inliers by least squares;
3. where at least ``min_inliers`` of the segment's known depths lie on the plane, its
   unknown pixels take the plane's depth (within the depth range).

The caller (:func:`vibr.stereo.estimate_depth`) then runs the colour-guided weighted
median of the planes again (:func:`~vibr.stereo.planesweep.median_planes`): a band of
fattened pixels beside a textured object now has voters of its own colour carrying the
background's plane, and is outvoted.

Pixel coordinates: the centre of the top-left pixel is (0, 0), x to the right, y down.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from skimage.segmentation import felzenszwalb


@dataclass
class SegmentFill:
    """Result of :func:`fill_segment_planes`.

    depth : (H, W) float32, the input depth with the filled pixels set (NaN: still unknown).
    gx, gy : (H, W) float64, slopes of the inverse-depth plane of each filled pixel
        (per pixel of x and y; 0 elsewhere).
    filled : (H, W) bool, pixels that were unknown and now carry their segment's plane.
    rel_rms : (H, W) float64, RMS relative residual of the segment plane's inliers at the
        filled pixels (0 elsewhere): a scale for their uncertainty.
    n_segments, n_planes : segments, and segments whose plane was accepted.
    """

    depth: np.ndarray
    gx: np.ndarray
    gy: np.ndarray
    filled: np.ndarray
    rel_rms: np.ndarray
    n_segments: int
    n_planes: int


def segment_image(image: np.ndarray, shape: tuple[int, int] | None = None, *,
                  scale: float | None = None, min_size: int | None = None) -> np.ndarray:
    """Colour segments of an image (Felzenszwalb & Huttenlocher 2004), as labels on ``shape``.

    Parameters
    ----------
    image : (h, w, 3) or (h, w) float array in [0, 1], the image to segment (pass a reduced
        copy for speed: the segmentation's cost is linear in its pixels).
    shape : (H, W) of the label map to return (nearest-neighbour upsampling by the resize
        mapping ``x_small = s (x + ½) − ½``); default the image's own shape.
    scale, min_size : Felzenszwalb's ``k`` (a larger ``k`` gives larger segments) and the
        smallest segment. Defaults grow with the segmented image's area, ``k = h·w / 500``
        and ``min_size = h·w / 4000``: a segment is a fraction of the image whatever its
        resolution (``k`` acts through ``k / |C|``, ``|C|`` a component's size in pixels).

    Returns
    -------
    (H, W) int64 labels, 0 … n−1.
    """
    h, w = image.shape[:2]
    k = float(scale) if scale is not None else h * w / 500.0
    m = int(min_size) if min_size is not None else max(4, h * w // 4000)
    lab = felzenszwalb(np.asarray(image, np.float64), scale=k, sigma=0.5, min_size=m)
    if shape is None or tuple(shape) == (h, w):
        return lab
    H, W = shape
    iy = np.clip(np.floor((np.arange(H) + 0.5) * h / H).astype(np.int64), 0, h - 1)
    ix = np.clip(np.floor((np.arange(W) + 0.5) * w / W).astype(np.int64), 0, w - 1)
    return lab[iy][:, ix]


def fit_inverse_depth_plane(x: np.ndarray, y: np.ndarray, w: np.ndarray, *, rel_tol: float,
                            rng: np.random.Generator, n_hyp: int = 128, n_score: int = 2000
                            ) -> tuple[np.ndarray, np.ndarray] | None:
    """RANSAC fit of ``w = a x + b y + c`` with inliers ``|w − w_plane| ≤ rel_tol · w``.

    ``n_hyp`` minimal (3-point) hypotheses are scored on at most ``n_score`` of the points;
    the best is refitted by least squares to all its inliers, and the inliers recomputed.
    Returns ``(p, inliers)`` with ``p = (a, b, c)``, or None when every sample is degenerate.
    """
    n = len(w)
    A = np.stack([x, y, np.ones(n)], 1)
    idx = rng.integers(0, n, size=(n_hyp, 3))
    M = A[idx]
    ok = np.abs(np.linalg.det(M)) > 1e-6
    if not ok.any():
        return None
    P = np.linalg.solve(M[ok], w[idx[ok]][..., None])[..., 0]
    sub = rng.choice(n, n_score, replace=False) if n > n_score else np.arange(n)
    score = (np.abs(A[sub] @ P.T - w[sub, None]) <= rel_tol * w[sub, None]).sum(0)
    p = P[int(np.argmax(score))]
    for _ in range(2):  # refit on the inliers, then the refit's inliers
        inl = np.abs(A @ p - w) <= rel_tol * w
        if inl.sum() < 3:
            break
        p = np.linalg.lstsq(A[inl], w[inl], rcond=None)[0]
    return p, np.abs(A @ p - w) <= rel_tol * w


def fill_segment_planes(depth: np.ndarray, labels: np.ndarray, *, rel_tol: float = 0.01,
                        min_inliers: float = 0.5, min_known: int = 30, depth_range=None,
                        seed: int = 0) -> SegmentFill:
    """Fill the unknown pixels of each colour segment with the segment's plane.

    Parameters
    ----------
    depth : (H, W) orthogonal depth, NaN unknown.
    labels : (H, W) int segment labels (:func:`segment_image`).
    rel_tol : inlier tolerance of the plane fit, relative (the consistency check's: a
        known depth within it of the plane is the same surface).
    min_inliers : fraction of the segment's known depths that must lie on its plane (a
        majority: the segment is one planar surface, and its known depths say where).
    min_known : known pixels a segment needs to be fitted.
    depth_range : (near, far): filled depths outside it are left unknown (default: no bound
        beyond a positive depth).
    seed : RANSAC seed (the result is deterministic).

    Returns
    -------
    SegmentFill
    """
    depth = np.asarray(depth, np.float32)
    H, W = depth.shape
    rng = np.random.default_rng(seed)
    lab = np.asarray(labels).ravel()
    order = np.argsort(lab, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(lab[order]) != 0])
    groups = np.split(order, starts[1:])
    d = depth.ravel()
    known = np.isfinite(d)
    out = d.copy()
    gx, gy, rms = np.zeros(H * W), np.zeros(H * W), np.zeros(H * W)
    filled = np.zeros(H * W, bool)
    near, far = (0.0, np.inf) if depth_range is None else (float(depth_range[0]), float(depth_range[1]))
    n_planes = 0
    for g in groups:
        kg = g[known[g]]
        if len(kg) < min_known or len(kg) == len(g):
            continue
        fit = fit_inverse_depth_plane((kg % W).astype(np.float64), (kg // W).astype(np.float64),
                                      1.0 / d[kg].astype(np.float64), rel_tol=rel_tol, rng=rng)
        if fit is None:
            continue
        p, inl = fit
        if inl.mean() < min_inliers:
            continue
        n_planes += 1
        ug = g[~known[g]]
        wp = p[0] * (ug % W) + p[1] * (ug // W) + p[2]
        with np.errstate(divide="ignore"):
            z = np.where(wp > 0, 1.0 / wp, np.inf)
        ok = (z >= near) & (z <= far) & np.isfinite(z)
        ug, z = ug[ok], z[ok]
        out[ug] = z
        filled[ug] = True
        gx[ug], gy[ug] = p[0], p[1]
        wk = 1.0 / d[kg[inl]].astype(np.float64)
        wfit = p[0] * (kg[inl] % W) + p[1] * (kg[inl] // W) + p[2]
        rms[ug] = np.sqrt(np.mean(((wk - wfit) / wk) ** 2))
    return SegmentFill(out.reshape(H, W).astype(np.float32), gx.reshape(H, W), gy.reshape(H, W),
                       filled.reshape(H, W), rms.reshape(H, W), len(groups), n_planes)
