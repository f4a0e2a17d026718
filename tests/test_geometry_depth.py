"""Depth preparation: radial → orthogonal (eq. orth) and its derivative, disparity →
depth, edge-aware slopes, joint bilateral hole filling."""

import numpy as np
import pytest

from vibr.camera import Camera
from vibr.errors import VibrInputError
from vibr.geometry import (
    depth_derivatives,
    disparity_to_depth,
    fill_depth_holes,
    radial_to_orthogonal,
    radial_to_orthogonal_derivatives,
)


def test_radial_to_orthogonal_matches_camera_geometry():
    W, H = 30, 20
    K = Camera.intrinsics(40.0, W, H, cx=12.0, cy=9.5)
    cam = Camera(K, np.eye(3), np.zeros(3), W, H)
    rng = np.random.default_rng(0)
    z_true = rng.uniform(1, 5, size=(H, W))
    X = cam.backproject(cam.pixel_grid(), z_true)
    h = np.linalg.norm(X, axis=-1)  # radial distance from the centre (at the origin)
    h[2, 3] = np.nan
    z = radial_to_orthogonal(h, K)
    assert np.isnan(z[2, 3])
    ok = np.isfinite(z)
    np.testing.assert_allclose(z[ok], z_true[ok], rtol=1e-6)


def test_radial_derivative_conversion_matches_finite_differences():
    W, H = 30, 20
    K = Camera.intrinsics(40.0, W, H)
    y, x = np.mgrid[0:H, 0:W].astype(float)
    hfun = lambda x, y: 3 + 0.05 * x - 0.03 * y + 0.2 * np.sin(0.1 * x * y / 10)  # noqa: E731
    hx = lambda x, y: 0.05 + 0.2 * np.cos(0.1 * x * y / 10) * 0.01 * y  # noqa: E731
    hy = lambda x, y: -0.03 + 0.2 * np.cos(0.1 * x * y / 10) * 0.01 * x  # noqa: E731
    zx, zy = radial_to_orthogonal_derivatives(hfun(x, y), hx(x, y), hy(x, y), K)
    Kinv = np.linalg.inv(K)

    def zfun(x, y):
        r = np.stack([x, y, np.ones_like(x)], -1) @ Kinv.T
        return hfun(x, y) / np.linalg.norm(r, axis=-1)

    e = 1e-5
    fdx = (zfun(x + e, y) - zfun(x - e, y)) / (2 * e)
    fdy = (zfun(x, y + e) - zfun(x, y - e)) / (2 * e)
    np.testing.assert_allclose(zx, fdx, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(zy, fdy, rtol=1e-5, atol=1e-9)


def test_disparity_to_depth():
    d = np.array([[1.0, 2.0], [0.0, np.nan]])
    z = disparity_to_depth(d, focal_px=100.0, baseline=0.5)
    np.testing.assert_allclose(z[0], [50.0, 25.0], rtol=1e-6)
    assert np.isnan(z[1, 0]) and np.isnan(z[1, 1])  # d = 0 is at infinity: unknown, not 0
    # with a focus plane Z0 (HCI): d = 0 is Z0, negative d is farther
    z0 = disparity_to_depth(np.array([0.0, -1.0, 1.0]), 1000.0, 0.01, z0=4.0)
    np.testing.assert_allclose(z0, [4.0, 1 / (-0.1 + 0.25), 1 / (0.1 + 0.25)], rtol=1e-6)
    with pytest.raises(VibrInputError):
        disparity_to_depth(d, 0.0, 1.0, source="x.pfm")


def test_slopes_exact_on_a_plane_and_one_sided_at_edges():
    H, W = 12, 16
    y, x = np.mgrid[0:H, 0:W].astype(float)
    z = 2.0 + 0.01 * x + 0.02 * y
    zx, zy = depth_derivatives(z)
    np.testing.assert_allclose(zx, 0.01, atol=1e-12)
    np.testing.assert_allclose(zy, 0.02, atol=1e-12)
    # a step of +1 at column 8: both sides of the edge keep their own surface's slope
    z2 = z.copy()
    z2[:, 8:] += 1.0
    zx2, _ = depth_derivatives(z2)
    np.testing.assert_allclose(zx2, 0.01, atol=1e-12)  # a central difference would give 0.51
    # unknown depth: NaN slopes there, one-sided next to it, never a jump to 0
    z3 = z.copy()
    z3[5, 5] = np.nan
    zx3, zy3 = depth_derivatives(z3)
    assert np.isnan(zx3[5, 5]) and np.isnan(zy3[5, 5])
    np.testing.assert_allclose(zx3[5, 4], 0.01, atol=1e-12)
    np.testing.assert_allclose(zx3[5, 6], 0.01, atol=1e-12)
    # isolated known pixel: slope 0
    z4 = np.full((3, 3), np.nan)
    z4[1, 1] = 3.0
    zx4, zy4 = depth_derivatives(z4)
    assert zx4[1, 1] == 0 and zy4[1, 1] == 0


def test_joint_bilateral_fill_follows_the_image():
    H, W = 40, 40
    img = np.zeros((H, W, 3), np.float32)
    img[:, 20:] = 1.0  # two regions: dark left (near, z = 1), bright right (far, z = 3)
    depth = np.where(np.arange(W)[None, :] < 20, 1.0, 3.0) * np.ones((H, 1))
    holes = np.zeros((H, W), bool)
    holes[10:30, 15:25] = True  # a hole straddling the colour edge
    d = depth.copy()
    d[holes] = np.nan
    filled, was = fill_depth_holes(d, img, sigma_color=0.1)
    assert np.array_equal(was, holes)
    np.testing.assert_allclose(filled[~holes], depth[~holes])  # known depth untouched
    np.testing.assert_allclose(filled[holes], depth[holes], atol=1e-3)  # no mixing across the edge
    # without the guide, depth is mixed across the edge near it
    filled_nog, _ = fill_depth_holes(d, None)
    assert np.abs(filled_nog[holes] - depth[holes]).max() > 0.2


def test_fill_leaves_unreachable_pixels_unknown():
    d = np.full((30, 30), np.nan)
    d[0, 0] = 2.0
    out, was = fill_depth_holes(d, np.zeros((30, 30, 3)), radius=2, max_passes=2)
    assert np.isnan(out[29, 29]) and not was[29, 29]
    assert out[2, 2] == pytest.approx(2.0)
    assert np.all(out[np.isfinite(out)] > 0)
