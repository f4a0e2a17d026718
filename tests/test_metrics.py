"""Tests of vibr.metrics against known values and scikit-image."""

from __future__ import annotations

import numpy as np
import pytest
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from vibr import VibrInputError
from vibr.metrics import dssim, mse, psnr, ssim


@pytest.fixture(scope="module")
def pair():
    rng = np.random.default_rng(0)
    from scipy.ndimage import gaussian_filter

    ref = gaussian_filter(rng.random((48, 64, 3)), (2, 2, 0)).astype(np.float32)
    ref = (ref - ref.min()) / (ref.max() - ref.min())
    img = np.clip(ref + 0.05 * rng.standard_normal(ref.shape), 0, 1).astype(np.float32)
    return img, ref


def test_identical(pair):
    _, ref = pair
    assert psnr(ref, ref) == np.inf
    assert ssim(ref, ref) == pytest.approx(1.0)
    assert dssim(ref, ref) == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("e", [0.1, 0.01, 0.003])
def test_uniform_offset(pair, e):
    _, ref = pair
    ref = 0.5 * ref  # room for the offset
    assert psnr(ref + e, ref) == pytest.approx(-20 * np.log10(e), abs=1e-3)
    assert psnr(ref + e, ref, data_range=2.0) == pytest.approx(-20 * np.log10(e / 2), abs=1e-3)
    assert mse(ref - e, ref) == pytest.approx(e * e, rel=1e-4)


def test_agrees_with_skimage(pair):
    img, ref = pair
    want_p = peak_signal_noise_ratio(ref.astype(np.float64), img.astype(np.float64), data_range=1.0)
    assert psnr(img, ref) == pytest.approx(want_p, rel=1e-9)
    want_s = structural_similarity(img.astype(np.float64), ref.astype(np.float64), gaussian_weights=True,
                                   sigma=1.5, use_sample_covariance=False, channel_axis=-1, data_range=1.0)
    got = ssim(img, ref)
    assert got == pytest.approx(want_s, abs=1e-9)
    assert 0.3 < got < 0.99
    assert dssim(img, ref) == pytest.approx(1e4 * (1 - got))


def test_greyscale(pair):
    img, ref = pair
    g, r = img[..., 0], ref[..., 0]
    want = structural_similarity(g.astype(np.float64), r.astype(np.float64), gaussian_weights=True, sigma=1.5,
                                 use_sample_covariance=False, data_range=1.0)
    assert ssim(g, r) == pytest.approx(want, abs=1e-9)
    assert psnr(g, r) == pytest.approx(peak_signal_noise_ratio(r, g, data_range=1.0), rel=1e-6)


def test_mask_restricts(pair):
    _, ref = pair
    img = ref.copy()
    img[:, 40:] = 1.0 - img[:, 40:]  # corrupt the right part
    mask = np.zeros(ref.shape[:2], bool)
    mask[:, :30] = True  # left part, > 5 px from the corruption (SSIM window radius)
    assert psnr(img, ref, mask=mask) == np.inf
    assert ssim(img, ref, mask=mask) == pytest.approx(1.0)
    assert psnr(img, ref) < 20
    assert ssim(img, ref) < 0.9
    # the masked PSNR is the PSNR of the selected pixels alone
    mask2 = ~mask
    sel = mask2
    want = 10 * np.log10(1 / np.mean((img[sel].astype(np.float64) - ref[sel]) ** 2))
    assert psnr(img, ref, mask=mask2) == pytest.approx(want, rel=1e-9)


def test_border(pair):
    _, ref = pair
    img = ref.copy()
    img[:2] = 0.0
    img[:, -2:] = 1.0
    assert psnr(img, ref) < np.inf
    assert psnr(img, ref, border=2) == np.inf
    assert ssim(img, ref, border=2) == pytest.approx(1.0)
    assert ssim(img, ref) < 1.0


def test_errors(pair):
    img, ref = pair
    with pytest.raises(VibrInputError, match="shape"):
        psnr(img[:-1], ref)
    with pytest.raises(VibrInputError, match="shape"):
        ssim(img, ref[..., :2])
    with pytest.raises(VibrInputError, match="mask"):
        psnr(img, ref, mask=np.ones((10, 10), bool))
    with pytest.raises(VibrInputError, match="no pixel"):
        psnr(img, ref, mask=np.zeros(ref.shape[:2], bool))
    with pytest.raises(VibrInputError, match="border"):
        dssim(img, ref, border=40)
    with pytest.raises(VibrInputError, match="window"):
        ssim(img[:8, :8], ref[:8, :8])
