"""Plane-sweep MVS: homographies, the sweep on exact synthetic scenes, consistency, API."""

from __future__ import annotations

import numpy as np
import pytest

from vibr.camera import Camera
from vibr.errors import VibrInputError
from vibr.stereo import (check_consistency, estimate_depth, plane_homographies, plane_sweep,
                         select_neighbours, upsample_depth)


def _cams():
    K = Camera.intrinsics(120.0, 96, 80)
    ref = Camera.look_at([0, 0, 0], [0, 0, 5], [0, -1, 0], K, 96, 80)
    src = Camera.look_at([0.4, 0.1, 0.2], [0.1, 0, 5], [0, -1, 0], K, 96, 80)
    return ref, src


def test_plane_homography_closed_form():
    """A point of the fronto-parallel plane z maps by (A + w b e3ᵀ) exactly where the
    source camera projects it."""
    ref, src = _cams()
    A, b = plane_homographies(ref, [src])
    rng = np.random.default_rng(0)
    xy = rng.uniform([0, 0], [95, 79], (20, 2))
    for z in (2.0, 5.0, 13.0):
        X = ref.backproject(xy, np.full(20, z))
        want = src.project(X)[0]
        p = np.c_[xy, np.ones(20)] @ A[0].T + b[0] / z
        np.testing.assert_allclose(p[:, :2] / p[:, 2:], want, atol=1e-9)


def _textured_plane_views(z_of, cams, seed=0):
    """Render views of a textured surface z = z_of(X, Y) (world = reference frame) by
    inverse warping a random texture defined on the world XY plane (ray marching the
    height field is avoided: the surface is a plane, intersected in closed form)."""
    from scipy.ndimage import gaussian_filter, map_coordinates
    tex = gaussian_filter(np.random.default_rng(seed).random((400, 400)), 1.2)
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    n, d = z_of  # plane n·X = d
    n = np.asarray(n, float)
    out = []
    for c in cams:
        g = c.pixel_grid().reshape(-1, 2)
        dirs = c.pixel_rays(g) @ c.R
        C = c.centre
        lam = (d - C @ n) / (dirs @ n)
        X = C + lam[:, None] * dirs
        u, v = X[:, 0] * 60 + 200, X[:, 1] * 60 + 200
        img = map_coordinates(tex, [v, u], order=3, mode="reflect").reshape(c.shape)
        depth = (X @ c.R.T + c.t)[:, 2].reshape(c.shape)
        out.append((np.repeat(img[..., None], 3, 2).astype(np.float32), depth))
    return out


def test_plane_sweep_slanted_plane_within_1pct():
    ref, src = _cams()
    K = ref.K
    src2 = Camera.look_at([-0.4, -0.1, 0.1], [-0.1, 0, 5], [0, -1, 0], K, 96, 80)
    cams = [ref, src, src2]
    views = _textured_plane_views(((0.15, 0.0, 1.0), 4.0), cams)
    res = plane_sweep(views[0][0], ref, [v[0] for v in views[1:]], cams[1:], (2.5, 8.0),
                      n_planes=160, radius=3)
    gt = views[0][1]
    rel = np.abs(res.depth - gt) / gt
    inner = (slice(4, -4), slice(4, -4))
    assert res.confident[inner].mean() > 0.9
    assert np.mean(rel[inner][res.confident[inner]] < 0.01) >= 0.95
    # sigma_z is positive and finite, bigger where the cost minimum is flatter
    assert np.all(np.isfinite(res.sigma_z)) and np.all(res.sigma_z > 0)


def test_plane_sweep_memory_bound():
    ref, src = _cams()
    img = np.zeros((80, 96, 3), np.float32)
    with pytest.raises(ValueError, match="exceeds"):
        plane_sweep(img, ref, [img], [src], (1, 10), mem_bytes=1e3)


def test_consistency_keeps_consistent_and_rejects_wrong():
    ref, src = _cams()
    # exact depths of a fronto-parallel plane Z_ref = 5 in both views
    X = ref.backproject(ref.pixel_grid().reshape(-1, 2), np.full(96 * 80, 5.0))
    g = src.pixel_grid().reshape(-1, 2)
    dirs = src.pixel_rays(g) @ src.R
    lam = (5.0 - src.centre[2]) / dirs[:, 2]
    d_src = (lam[:, None] * dirs + src.centre) @ src.R.T + src.t
    d_src = d_src[:, 2].reshape(80, 96)
    d_ref = np.full((80, 96), 5.0)
    r = check_consistency(d_ref, ref, [d_src], [src], rel_tol=0.01, px_tol=1.0)
    seen = src.project(X)[0]
    inside = ((seen[:, 0] > 0.5) & (seen[:, 0] < 94.5) & (seen[:, 1] > 0.5) & (seen[:, 1] < 78.5)).reshape(80, 96)
    assert r.keep[inside].mean() > 0.99
    assert np.nanmax(r.reproj[r.keep]) < 0.8
    r2 = check_consistency(d_ref * 1.05, ref, [d_src], [src], rel_tol=0.01, px_tol=1.0)
    assert r2.keep.mean() < 0.01


def test_upsample_depth_constant_and_nan():
    K = Camera.intrinsics(100.0, 64, 48)
    hi = Camera(K, np.eye(3), np.zeros(3), 64, 48)
    lo = hi.scaled(0.5)
    d = np.full(lo.shape, 3.0, np.float32)
    d[0:4, 0:4] = np.nan
    up = upsample_depth(d, lo, hi)
    assert up.shape == hi.shape
    assert np.allclose(up[np.isfinite(up)], 3.0)
    assert np.isnan(up[0, 0]) and np.isfinite(up[-1, -1])


def test_select_neighbours_nearest_first():
    K = Camera.intrinsics(100.0, 64, 48)
    cams = [Camera.from_centre(K, np.eye(3), [x, 0, 0], 64, 48) for x in (0, 3, 1, 2)]
    assert select_neighbours(cams, 0, [0, 1, 2, 3], 2) == [2, 3]


def test_estimate_depth_excluded_views_never_used():
    from vibr.synthetic import make_scene

    s = make_scene("free", n_views=4, width=64, height=48, seed=1)
    e = estimate_depth(s, views=[0], exclude=[1], n_planes=32, method="mvs")
    info = e.meta["depth_estimation"]["views"]
    for st in info.values():
        assert "view_001" not in st["neighbours"]
    assert "view_001" not in info
    assert e[0].depth.shape == s[0].depth.shape and e[0].sigma_z.shape == s[0].depth.shape
    assert np.all(np.isfinite(e[0].sigma_z))
    with pytest.raises(VibrInputError, match="excluded"):
        estimate_depth(s, views=[1], exclude=[1])


def test_default_depth_range_covers_a_wide_baseline_ring(temple_dir):
    """The temple ring's neighbours are ~22° apart: the half-image parallax limit alone put
    the sweep's near end at 1.17 while the temple lies around 0.5–0.6 from the cameras. The
    range must contain the depth where the ring's axes meet."""
    from vibr.camera import axes_meeting_point
    from vibr.io import load_scene
    from vibr.stereo.api import default_depth_range, select_neighbours

    sc = load_scene(temple_dir, scale=0.5)
    cams = [v.camera for v in sc.views]
    ref = 0
    nb = select_neighbours(cams, ref, list(range(1, len(cams))), 4)
    near, far = default_depth_range(sc, ref, cams, {i: v.image for i, v in enumerate(sc.views)}, nb)
    X = axes_meeting_point([cams[ref]] + [cams[j] for j in nb])
    z_c = float((X - cams[ref].centre) @ cams[ref].optical_axis)
    assert 0.45 < z_c < 0.7
    assert near < 0.9 * z_c and far > 1.1 * z_c
