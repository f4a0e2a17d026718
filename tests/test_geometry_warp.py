"""Warps and their analytic Jacobians (docs/explanation/method.md §2 eqs. projection, deformation, geometrie):
closed-form cases and finite-difference checks."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from _helpers import pinhole
from vibr.camera import Camera
from vibr.geometry import warp_points, warp_view


def test_parallel_translation_is_fb_over_z_with_unit_det():
    W, H, f, b, z = 40, 30, 75.0, 0.2, 3.0
    src = pinhole(f, W, H)
    tgt = pinhole(f, W, H, C=(b, 0, 0))  # target shifted by +b along x
    r = warp_view(src, tgt, np.full((H, W), z, np.float32))
    grid = src.pixel_grid()
    np.testing.assert_allclose(r["tau"][..., 0], grid[..., 0] - f * b / z, atol=1e-9)
    np.testing.assert_allclose(r["tau"][..., 1], grid[..., 1], atol=1e-9)
    np.testing.assert_allclose(r["det"], 1.0, atol=1e-12)
    np.testing.assert_allclose(r["w"], z, atol=1e-12)
    # ∂tau/∂z = (f b / z², 0): moving the plane away reduces the disparity
    np.testing.assert_allclose(r["dtau_dz"][..., 0], f * b / z**2, rtol=1e-12)
    np.testing.assert_allclose(r["dtau_dz"][..., 1], 0.0, atol=1e-12)


def test_vertical_baseline_shifts_rows():
    W, H, f, b, z = 20, 20, 50.0, 0.1, 2.0
    r = warp_view(pinhole(f, W, H), pinhole(f, W, H, C=(0, -b, 0)), np.full((H, W), z))
    np.testing.assert_allclose(r["tau"][..., 1] - np.arange(H)[:, None], f * b / z, atol=1e-9)


def test_pure_rotation_is_the_homography_whatever_the_depth():
    rng = np.random.default_rng(1)
    W, H = 50, 40
    Ks = Camera.intrinsics(60.0, W, H)
    Ku = Camera.intrinsics(70.0, W, H, cx=22.0, cy=21.0)
    Rs = Rotation.from_rotvec(rng.normal(size=3) * 0.1).as_matrix()
    Ru = Rotation.from_rotvec(rng.normal(size=3) * 0.1).as_matrix()
    C = np.array([0.3, -0.2, 0.5])
    src = Camera.from_centre(Ks, Rs, C, W, H)
    tgt = Camera.from_centre(Ku, Ru, C, W, H)
    Hm = Ku @ Ru @ Rs.T @ np.linalg.inv(Ks)
    depth = rng.uniform(0.5, 20.0, size=(H, W))
    r = warp_view(src, tgt, depth)
    g = src.pixel_grid()
    xh = np.concatenate([g, np.ones((H, W, 1))], -1) @ Hm.T
    expect = xh[..., :2] / xh[..., 2:]
    np.testing.assert_allclose(r["tau"], expect, atol=1e-9)
    np.testing.assert_allclose(r["dtau_dz"], 0.0, atol=1e-9)
    # the Jacobian is the homography's, independent of depth and its slopes
    r2 = warp_view(src, tgt, depth * 3.0)
    np.testing.assert_allclose(r2["jac"], r["jac"], atol=1e-9)


def _random_pair(rng, W=64, H=48):
    K1 = Camera.intrinsics(rng.uniform(40, 90), W, H, cx=rng.uniform(25, 35), cy=rng.uniform(20, 28))
    K2 = Camera.intrinsics(rng.uniform(40, 90), W, H)
    R1 = Rotation.from_rotvec(rng.normal(size=3) * 0.15).as_matrix()
    R2 = Rotation.from_rotvec(rng.normal(size=3) * 0.15).as_matrix()
    src = Camera.from_centre(K1, R1, rng.normal(size=3) * 0.3, W, H)
    tgt = Camera.from_centre(K2, R2, rng.normal(size=3) * 0.3, W, H)
    return src, tgt


def _smooth_depth(rng):
    """A random smooth depth function z(x, y) with its exact derivatives."""
    a, bx, by = rng.uniform(4, 6), rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02)
    A, kx, ky, ph = rng.uniform(0.1, 0.4), rng.uniform(0.02, 0.1), rng.uniform(0.02, 0.1), rng.uniform(0, 6)

    def z(x, y):
        return a + bx * x + by * y + A * np.sin(kx * x + ky * y + ph)

    def zx(x, y):
        return bx + A * kx * np.cos(kx * x + ky * y + ph)

    def zy(x, y):
        return by + A * ky * np.cos(kx * x + ky * y + ph)

    return z, zx, zy


@pytest.mark.parametrize("seed", range(5))
def test_jacobians_match_finite_differences(seed):
    rng = np.random.default_rng(seed)
    src, tgt = _random_pair(rng)
    z, zx, zy = _smooth_depth(rng)
    xy = rng.uniform([0, 0], [src.width - 1, src.height - 1], size=(200, 2))
    x, y = xy[:, 0], xy[:, 1]
    r = warp_points(src, tgt, xy, z(x, y), zx(x, y), zy(x, y))
    assert np.all(r["w"] > 0)
    h = 1e-5

    def tau_at(px, py, dz=0.0):
        return warp_points(src, tgt, np.stack([px, py], 1), z(px, py) + dz)["tau"]

    fd_x = (tau_at(x + h, y) - tau_at(x - h, y)) / (2 * h)
    fd_y = (tau_at(x, y + h) - tau_at(x, y - h)) / (2 * h)
    fd = np.stack([fd_x, fd_y], axis=-1)  # (N, 2 target, 2 source)
    rel = np.abs(fd - r["jac"]).max(axis=(1, 2)) / np.abs(r["jac"]).max(axis=(1, 2))
    assert rel.max() < 1e-4, rel.max()
    # depth Jacobian: perturb z only
    hz = 1e-6
    fdz = (tau_at(x, y, hz) - tau_at(x, y, -hz)) / (2 * hz)
    relz = np.linalg.norm(fdz - r["dtau_dz"], axis=1) / np.linalg.norm(r["dtau_dz"], axis=1)
    assert relz.max() < 1e-4, relz.max()
    # det is the determinant of the Jacobian
    np.testing.assert_allclose(r["det"], np.linalg.det(r["jac"]), rtol=1e-12)


def test_nan_depth_gives_nan_fields():
    src, tgt = _random_pair(np.random.default_rng(7))
    d = np.full(src.shape, 5.0)
    d[3, 4] = np.nan
    r = warp_view(src, tgt, d)
    assert np.isnan(r["tau"][3, 4]).all() and np.isnan(r["det"][3, 4])
    assert np.isfinite(r["tau"][3, 5]).all()
