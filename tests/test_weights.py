"""Geometric weights W = omega / |det ∂tau/∂x| (docs/METHOD.md §3)."""

import numpy as np

from vibr.geometry.samples import Samples
from vibr.render.weights import geometric_weights, luminance_gradient


def _samples(xy, dtau, sigma_z, inv_det, shape):
    n = len(xy)
    return Samples(np.asarray(xy, float), np.zeros((n, 3), np.float32), np.zeros((n, 3, 2), np.float32),
                   np.tile(np.eye(2), (n, 1, 1)), np.asarray(inv_det, float), np.asarray(dtau, float),
                   np.asarray(sigma_z, float), np.zeros(n, np.int32), np.zeros((n, 2), np.int32),
                   np.zeros((n, 3)), shape)


def test_closed_form_on_a_ramp():
    H, W = 10, 12
    slope = 0.01  # per pixel, on [0, 1] intensities → 2.55 grey levels per pixel
    u = np.repeat((slope * np.arange(W))[None, :, None], H, 0).repeat(3, 2).astype(np.float32)
    g = luminance_gradient(u)
    np.testing.assert_allclose(g[:, 1:-1, 0], slope, rtol=1e-5)
    np.testing.assert_allclose(g[..., 1], 0, atol=1e-7)
    xy = [[5.5, 4.2], [3.0, 7.0], [8.25, 1.5]]
    dtau = [[10.0, 0.0], [0.0, 10.0], [3.0, 4.0]]
    sz = [0.05, 0.05, 0.1]
    inv_det = [1.0, 0.5, 2.0]
    S = _samples(xy, dtau, sz, inv_det, (H, W))
    w = geometric_weights(S, u, sigma_s=1.0, scale=255.0, grad_max=None)
    gx = slope * 255
    proj = np.array([10 * gx, 0.0, 3 * gx])
    want = np.array(inv_det) / (1.0 + (np.array(sz) * proj) ** 2)
    np.testing.assert_allclose(w, want, rtol=1e-5)
    # the clamp caps the gradient magnitude (grey levels per pixel)
    wc = geometric_weights(S, u, sigma_s=1.0, scale=255.0, grad_max=1.0)
    np.testing.assert_allclose(wc, np.array(inv_det) / (1.0 + (np.array(sz) * np.array([10, 0, 3])) ** 2), rtol=1e-5)
    # no depth uncertainty (SAVSR): only the deformation weight over sigma_s²
    np.testing.assert_allclose(geometric_weights(S, u, sigma_s=2.0, sigma_z=0.0), np.array(inv_det) / 4)
    np.testing.assert_allclose(geometric_weights(S, None, sigma_s=1.0), inv_det)
