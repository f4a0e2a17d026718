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


def _sinusoid(omega, amplitude=0.25, shape=(40, 64)):
    x = np.arange(shape[1])
    return np.broadcast_to(0.5 + amplitude * np.cos(omega * x), shape)[..., None].repeat(3, axis=2)


def test_laplacian_energy_of_a_sinusoid():
    from vibr.metrics import laplacian_energy

    # 64 columns counted (border 1, stencil 1): whole periods, where the mean of (a (2 cos ω − 2) cos ωx)² = 2 a² (1 − cos ω)²
    for omega, a in ((2 * np.pi / 8, 0.25), (2 * np.pi / 4, 0.1)):
        assert laplacian_energy(_sinusoid(omega, a, (40, 68)), border=1) == pytest.approx(
            2 * a * a * (1 - np.cos(omega)) ** 2, rel=1e-9)
    assert laplacian_energy(_sinusoid(np.pi, 0.3, (40, 68)), border=1) == pytest.approx(16 * 0.3 ** 2)  # ±a
    ramp = np.broadcast_to(np.linspace(0, 1, 64), (40, 64))
    assert laplacian_energy(ramp) == pytest.approx(0.0, abs=1e-20)


def test_sharpness_ratio():
    from scipy.ndimage import gaussian_filter

    from vibr.metrics import METRICS, sharpness, view_metrics

    ref = _sinusoid(2 * np.pi / 8, 0.25, (40, 68))
    assert sharpness(ref, ref) == pytest.approx(1.0)
    assert sharpness(0.5 + 0.5 * (ref - 0.5), ref) == pytest.approx(0.25)  # contrast halved
    # a coarser texture in place of the photo's: ((1 − cos ω₁) / (1 − cos ω₂))²
    coarse = _sinusoid(2 * np.pi / 16, 0.25, (40, 68))
    want = ((1 - np.cos(2 * np.pi / 16)) / (1 - np.cos(2 * np.pi / 8))) ** 2
    assert sharpness(coarse, ref, border=1) == pytest.approx(want, rel=1e-6)
    # blur lowers it, more blur lowers it more; noise raises it above 1
    rng = np.random.default_rng(1)
    photo = gaussian_filter(rng.random((48, 48, 3)), (1, 1, 0))
    s1, s2 = (sharpness(gaussian_filter(photo, (s, s, 0)), photo, border=2) for s in (0.7, 1.5))
    assert 0 < s2 < s1 < 1
    assert sharpness(photo + 0.05 * rng.standard_normal(photo.shape), photo, border=2) > 1.5
    # only the masked pixels count: noise outside the mask changes nothing
    mask = np.zeros((48, 48), bool)
    mask[10:30, 10:30] = True
    noisy = photo.copy()
    noisy[35:] += 0.2 * rng.standard_normal(noisy[35:].shape)
    assert sharpness(noisy, photo, mask) == pytest.approx(1.0)
    assert sharpness(noisy, photo) > 1.2
    assert np.isnan(sharpness(ref * 0 + 0.5, ref * 0 + 0.5))  # a flat photograph has no high frequency
    assert "sharpness" in METRICS and view_metrics(noisy, photo, mask)["sharpness"] == pytest.approx(1.0)
    with pytest.raises(VibrInputError, match="sharpness"):
        sharpness(photo[:10], photo)
