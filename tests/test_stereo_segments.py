"""Segment-plane completion: the RANSAC plane fit, the fill, the segmentation, the pipeline."""

from __future__ import annotations

import numpy as np
import pytest

from vibr.camera import Camera
from vibr.stereo import estimate_depth
from vibr.stereo.segments import fill_segment_planes, fit_inverse_depth_plane, segment_image


def _plane_depth(H=60, W=80):
    """Exact depth of a slanted 3D plane n·X = 1 seen by a camera: its inverse depth is
    affine in the pixel, w = n·K⁻¹x̄ (closed form)."""
    K = Camera.intrinsics(90.0, W, H)
    n = np.array([0.02, -0.03, 0.25])  # plane n·X = 1: depth 4 on the axis
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.linalg.inv(K) @ np.stack([xx.ravel(), yy.ravel(), np.ones(H * W)])
    w = (n @ rays).reshape(H, W)
    return (1.0 / w).astype(np.float32), w


def test_fit_inverse_depth_plane_recovers_the_plane_among_outliers():
    rng = np.random.default_rng(3)
    n = 500
    x, y = rng.uniform(0, 100, n), rng.uniform(0, 80, n)
    p_true = np.array([1e-4, -2e-4, 0.25])
    w = p_true[0] * x + p_true[1] * y + p_true[2]
    bad = rng.random(n) < 0.4  # 40 % of the points on another surface
    w[bad] *= rng.uniform(1.1, 2.0, bad.sum())
    p, inl = fit_inverse_depth_plane(x, y, w, rel_tol=0.01, rng=np.random.default_rng(0))
    assert np.allclose(p, p_true, rtol=1e-9, atol=1e-12)
    assert np.array_equal(inl, ~bad)


def test_fill_segment_planes_fills_a_planar_segment_exactly():
    depth, w = _plane_depth()
    H, W = depth.shape
    labels = np.zeros((H, W), np.int64)
    labels[:, W // 2:] = 1
    d = depth.copy()
    d[10:30, 5:30] = np.nan  # a hole in segment 0, all of whose known depths are planar
    d[20:50, 50:75] = np.nan  # a hole in segment 1, whose known depths are half wrong
    rows = np.arange(H)[:, None] % 2 == 0
    d[:, W // 2:] = np.where(rows & np.isfinite(d[:, W // 2:]), d[:, W // 2:] * 1.5, d[:, W // 2:])
    out = fill_segment_planes(d, labels, rel_tol=0.01, min_inliers=0.6)
    hole0 = np.zeros((H, W), bool)
    hole0[10:30, 5:30] = True
    assert np.array_equal(out.filled, hole0)  # segment 1 has no 60 % majority: left unknown
    assert np.allclose(out.depth[hole0], depth[hole0], rtol=1e-5)
    # the slopes are those of the inverse-depth plane (finite differences of the exact w)
    assert np.allclose(out.gx[hole0], (w[:, 1:] - w[:, :-1]).mean(), rtol=1e-4)
    assert np.allclose(out.gy[hole0], (w[1:] - w[:-1]).mean(), rtol=1e-4)
    known = np.isfinite(d)
    assert np.array_equal(out.depth[known], d[known])  # known depths are never changed
    assert out.n_segments == 2 and out.n_planes == 1
    # with a bare majority required, segment 1's hole gets one of its two planes
    assert fill_segment_planes(d, labels, min_inliers=0.4).filled[20:50, 50:75].all()
    # a depth range that excludes the plane fills nothing
    none = fill_segment_planes(d, labels, depth_range=(10.0, 20.0))
    assert not none.filled.any()


def test_segment_image_separates_colours_and_upsamples():
    img = np.zeros((40, 60, 3), np.float32)
    img[:, 30:] = [0.9, 0.2, 0.1]
    img[:, :30] = [0.1, 0.3, 0.8]
    lab = segment_image(img)
    assert lab.shape == (40, 60)
    # no segment crosses the colour edge (the blur may leave slivers along it)
    assert not set(np.unique(lab[:, :30])) & set(np.unique(lab[:, 30:]))
    assert len(np.unique(lab[:, :28])) == 1 and len(np.unique(lab[:, 32:])) == 1
    up = segment_image(img, (80, 120))
    assert up.shape == (80, 120)
    assert np.array_equal(up[::2, ::2], lab)


@pytest.mark.slow
def test_estimate_depth_segment_fill_recovers_pixels():
    """On a hand-held scene, the fill turns unknown pixels into known ones, most of them
    right, and the second median does not lower the share of right pixels."""
    from vibr.synthetic import make_scene

    s = make_scene("handheld", width=256, height=204, seed=1)
    kw = dict(views=[0, 1, 2, 3, 4, 5, 6], n_planes=48)
    a = estimate_depth(s, **kw)  # the default leaves unknown pixels unknown
    b = estimate_depth(s, fill_segments=True, **kw)
    gt = s[0].depth
    da, db = a[0].depth, b[0].depth
    st = b.meta["depth_estimation"]["views"]["view_000"]
    assert st["filled"] > 0 and "filled" not in a.meta["depth_estimation"]["views"]["view_000"]
    assert st["kept"] == a.meta["depth_estimation"]["views"]["view_000"]["kept"]
    with np.errstate(invalid="ignore"):
        ra = np.abs(da - gt) / gt < 0.01
        rb = np.abs(db - gt) / gt < 0.01
    assert np.isfinite(db).sum() > np.isfinite(da).sum()
    newly = np.isfinite(db) & ~np.isfinite(da)
    assert rb[newly].mean() > 0.5
    assert rb.sum() > 1.02 * ra.sum()

