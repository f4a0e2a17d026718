"""Image quality metrics, optionally restricted to a mask: PSNR, SSIM and DSSIM; and the
metrics of a predicted per-pixel uncertainty: sparsification curves, AUSE, Spearman's rho.

The metrics of a rendered view (:func:`view_metrics`, what ``vibr render`` and ``vibr eval``
report) are a registry users extend: :class:`Metric`, :func:`register_metric`,
:data:`METRICS` (docs/how-to/extend/add-a-metric.md).

docs/explanation/method.md §8: PSNR over the three channels, SSIM of Wang et al. (2004) with a
Gaussian window of sigma 1.5, and the paper's DSSIM = 10⁴ · (1 − SSIM); all with an
optional border excluded and, for rendered views, only over the reconstructed pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .errors import VibrInputError

__all__ = ["psnr", "ssim", "dssim", "mse", "view_metrics", "METRIC_BORDER", "Metric", "METRICS", "register_metric",
           "unregister_metric", "get_metric", "checkerboard_energy", "laplacian_energy", "sharpness",
           "speckle_density", "pixel_error", "sparsification", "ause", "spearman", "uncertainty_metrics"]


def _prepare(img, ref, mask, border, what):
    """Check shapes; crop ``border`` pixels on each side; return float64 arrays and a
    boolean mask (H'×W')."""
    a = np.asarray(img)
    b = np.asarray(ref)
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (1, 3)):
        raise VibrInputError(f"{what}: image must be H×W or H×W×3, got shape {a.shape}")
    if a.shape != b.shape:
        raise VibrInputError(f"{what}: image has shape {a.shape} but the reference has {b.shape}")
    border = int(border)
    if border < 0:
        raise VibrInputError(f"{what}: border must be >= 0, got {border}")
    H, W = a.shape[:2]
    if 2 * border >= H or 2 * border >= W:
        raise VibrInputError(f"{what}: border {border} leaves nothing of a {W}x{H} image")
    if mask is None:
        m = np.ones((H, W), dtype=bool)
    else:
        m = np.asarray(mask)
        if m.ndim == 3 and m.shape[2] == 1:
            m = m[..., 0]
        if m.shape != (H, W):
            raise VibrInputError(f"{what}: mask has shape {m.shape} but the image is {(H, W)}")
        m = m.astype(bool)
    sl = (slice(border, H - border), slice(border, W - border))
    return (a[sl].astype(np.float64), b[sl].astype(np.float64), m[sl])


def mse(img, ref, mask=None, border: int = 0) -> float:
    """Mean squared error over all channels of the masked pixels (after cropping
    ``border`` pixels on each side)."""
    a, b, m = _prepare(img, ref, mask, border, "mse")
    if not m.any():
        raise VibrInputError("mse: the mask selects no pixel")
    d = (a - b)[m]
    if not np.all(np.isfinite(d)):
        raise VibrInputError("mse: the images have non-finite values inside the mask")
    return float(np.mean(d * d))


def psnr(img, ref, mask=None, border: int = 0, data_range: float = 1.0) -> float:
    """Peak signal-to-noise ratio (dB).

    ``PSNR = 10 log10(data_range² / MSE)`` with the MSE over the three channels of the
    pixels selected by ``mask`` (H×W bool; all pixels if None) after excluding ``border``
    pixels on each side. Identical images give ``inf``.

    Parameters
    ----------
    img, ref : (H, W, 3) or (H, W) arrays, same shape (float in [0, data_range])
    mask : (H, W) bool, optional
    border : int
        Pixels excluded on each side (the paper's evaluation uses 2).

    Examples
    --------
    >>> ref = np.zeros((4, 4, 3))
    >>> round(psnr(ref + 0.1, ref), 6)
    20.0
    """
    e = mse(img, ref, mask, border)
    if e == 0.0:
        return float("inf")
    return float(10.0 * np.log10(data_range**2 / e))


#: The side of SSIM's Gaussian window (sigma 1.5): 2 * int(3.5 * 1.5 + 0.5) + 1.
SSIM_WINDOW = 11


def ssim(img, ref, mask=None, border: int = 0) -> float:
    """Mean structural similarity (Wang et al. 2004), Gaussian window sigma 1.5.

    The SSIM map is scikit-image's ``structural_similarity(img, ref,
    gaussian_weights=True, sigma=1.5, use_sample_covariance=False, channel_axis=-1,
    data_range=1.0, full=True)`` on the images with ``border`` pixels cropped on each
    side; it is averaged over the channels and then over the masked pixels. As in
    scikit-image, the 5 pixels nearest the (cropped) image edge are left out of the mean
    (their 11×11 window reaches into padding), so that without a mask the value equals
    scikit-image's mean SSIM. Pixels outside the mask still enter the windows of masked
    pixels near the mask's edge.
    """
    from skimage.metrics import structural_similarity

    a, b, m = _prepare(img, ref, mask, border, "ssim")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise VibrInputError("ssim: the images have non-finite values")
    H, W = a.shape[:2]
    pad = SSIM_WINDOW // 2
    if H < SSIM_WINDOW or W < SSIM_WINDOW:
        raise VibrInputError(f"ssim: image of {W}x{H} (after border) is smaller than the 11×11 window")
    _, S = structural_similarity(
        a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
        channel_axis=-1 if a.ndim == 3 else None, data_range=1.0, full=True,
    )
    if S.ndim == 3:
        S = S.mean(axis=2)
    inner = np.zeros_like(m)
    inner[pad : H - pad, pad : W - pad] = True
    sel = m & inner
    if not sel.any():
        raise VibrInputError("ssim: the mask selects no pixel away from the image edge")
    return float(S[sel].mean())


def dssim(img, ref, mask=None, border: int = 0) -> float:
    """DSSIM as the paper defines it: ``10⁴ · (1 − SSIM)`` (see :func:`ssim`)."""
    return 1e4 * (1.0 - ssim(img, ref, mask, border))


@dataclass(frozen=True)
class Metric:
    """A metric of a rendered view against its photograph (:func:`view_metrics`).

    Attributes
    ----------
    name : str
        The key in reports (``res.metrics``, ``vibr eval --json``).
    function : callable
        ``function(img, ref, mask=None, border=0) -> float``: ``img`` and ``ref`` H×W×3 (or
        H×W) floats in [0, 1], ``mask`` H×W bool (the pixels measured; None: all) and
        ``border`` pixels left out at each edge.
    higher_is_better : bool
    summary : str
        One line: what it measures.
    heading : str
        Its column's heading in ``vibr eval``'s table; empty: no column.
    width : int
        That column's width, in characters.
    fmt : str
        Format of a value in that column (``".2f"``).
    min_side : int
        The smallest side, less the border on each edge, the metric is defined on (SSIM's
        window); on a smaller image :func:`view_metrics` gives NaN. 0: no limit.
    derive : callable, optional
        ``derive(values) -> float`` from the metrics registered before it (DSSIM from SSIM,
        not a second SSIM); then :attr:`function` is not called by :func:`view_metrics`.
    """

    name: str
    function: Callable[..., float]
    higher_is_better: bool
    summary: str
    heading: str = ""
    width: int = 8
    fmt: str = ".4g"
    min_side: int = 0
    derive: Callable[[dict], float] | None = None


#: The metrics of a rendered view by name, in the order reports list them.
METRICS: dict[str, Metric] = {}


def register_metric(metric: Metric) -> Metric:
    """Add ``metric`` to :data:`METRICS` (replacing a metric of the same name); returns it."""
    if not isinstance(metric, Metric):
        raise TypeError(f"register_metric takes a Metric, got {type(metric).__name__}")
    METRICS[metric.name] = metric
    return metric


def unregister_metric(name: str) -> Metric:
    """Remove the metric ``name`` from :data:`METRICS` (tests, a plugin's teardown); returns it."""
    metric = get_metric(name)
    del METRICS[name]
    return metric


def get_metric(name: str) -> Metric:
    """The registered :class:`Metric` named ``name``."""
    try:
        return METRICS[name]
    except (KeyError, TypeError):
        raise VibrInputError(f"unknown metric {name!r} (choose from {', '.join(METRICS)})") from None


register_metric(Metric("psnr", psnr, True, "peak signal-to-noise ratio (dB) over the three channels",
                       heading="PSNR dB", width=8, fmt=".2f"))
def psnr_all(img, ref, mask=None, border: int = 0) -> float:
    """PSNR over every pixel (``border`` excluded), whatever ``mask`` says: what the holes of a
    render cost, beside :func:`psnr` over the reconstructed pixels."""
    return psnr(img, ref, border=border)


register_metric(Metric("psnr_all", psnr_all, True, "PSNR (dB) over all pixels, the holes included",
                       heading="all px dB", width=9, fmt=".2f"))
register_metric(Metric("ssim", ssim, True, "mean structural similarity (Wang et al. 2004), Gaussian window sigma 1.5",
                       min_side=SSIM_WINDOW))
register_metric(Metric("dssim", dssim, False, "the paper's DSSIM = 10^4 (1 - SSIM)", heading="DSSIM", width=7,
                       fmt=".1f", min_side=SSIM_WINDOW, derive=lambda values: 1e4 * (1.0 - values["ssim"])))


def _grey_mask(img, mask, border, shrink):
    """Grey image (channel mean) and the pixels counted: ``mask`` minus ``border`` pixels,
    eroded by ``shrink`` (the stencil's reach)."""
    from scipy.ndimage import binary_erosion

    g = np.asarray(img, np.float64)
    g = g.mean(axis=2) if g.ndim == 3 else g
    H, W = g.shape
    m = np.ones((H, W), bool) if mask is None else np.asarray(mask, bool).copy()
    if border:
        m[:border] = m[-border:] = False
        m[:, :border] = m[:, -border:] = False
    if shrink:
        m = binary_erosion(m, np.ones((2 * shrink + 1,) * 2, bool), border_value=0)
    return g, m


def checkerboard_energy(img, mask=None, border: int = 0) -> float:
    """Energy at the Nyquist frequency (checkerboard) of the grey image g:
    ``mean |g(i,j) − g(i+1,j) − g(i,j+1) + g(i+1,j+1)|`` over the 2×2 blocks whose top-left
    pixel is counted (``mask``, ``border`` excluded). A pure checkerboard of amplitude a
    gives 4a; a linear ramp gives 0."""
    g, m = _grey_mask(img, mask, border, 1)
    d = np.abs(g[:-1, :-1] - g[1:, :-1] - g[:-1, 1:] + g[1:, 1:])
    m = m[:-1, :-1]
    return float(d[m].mean()) if m.any() else float("nan")


def laplacian_energy(img, mask=None, border: int = 0) -> float:
    """High-frequency energy of the grey image g: the mean of the squared 4-neighbour
    Laplacian ``g(i−1,j) + g(i+1,j) + g(i,j−1) + g(i,j+1) − 4 g(i,j)`` over the counted pixels
    (``mask``, ``border`` excluded, eroded by one pixel: the stencil stays inside). A
    sinusoid of amplitude a and frequency 0 < ω < π (radians per pixel) along x gives
    ``2 a² (1 − cos ω)²`` over whole periods; a linear ramp gives 0."""
    g, m = _grey_mask(img, mask, border, 1)
    lap = np.zeros_like(g)
    lap[1:-1, 1:-1] = g[:-2, 1:-1] + g[2:, 1:-1] + g[1:-1, :-2] + g[1:-1, 2:] - 4.0 * g[1:-1, 1:-1]
    return float(np.mean(lap[m] ** 2)) if m.any() else float("nan")


def sharpness(img, ref, mask=None, border: int = 0) -> float:
    """How sharp a render is against its photograph: :func:`laplacian_energy` of ``img`` over
    that of ``ref``, on the same pixels. 1: as much fine texture as the photograph; below 1:
    blurred (a contrast halved gives 0.25); above 1: more high frequencies than the photograph
    (noise, seams, aliasing). NaN when the photograph has no high frequency there."""
    _prepare(img, ref, mask, border, "sharpness")  # same shapes, a valid mask and border
    e_ref = laplacian_energy(ref, mask, border)
    return laplacian_energy(img, mask, border) / e_ref if e_ref > 0 else float("nan")


register_metric(Metric("sharpness", sharpness, True,
                       "high-frequency energy (squared Laplacian) of the render over the photograph's: 1 as "
                       "sharp, below 1 blurred, above 1 noisier", fmt=".3f"))


def speckle_density(img, mask=None, border: int = 0, threshold: float = 0.1) -> float:
    """Isolated outlier pixels per 10,000: pixels of the grey image (intensities in [0, 1])
    that differ from the median of their 3×3 neighbourhood by more than ``threshold``
    (compare a render with its reference photo, which has its own)."""
    from scipy.ndimage import median_filter

    g, m = _grey_mask(img, mask, border, 1)
    spk = np.abs(g - median_filter(g, size=3, mode="nearest")) > threshold
    return float(1e4 * spk[m].mean()) if m.any() else float("nan")


#: Pixels at each image edge left out of the metrics of a rendered view, by ``vibr render``
#: and ``vibr eval`` alike (as the authors' evaluator): edge pixels see the fewest samples.
METRIC_BORDER = 2


def view_metrics(img, ref, mask=None, border: int = METRIC_BORDER) -> dict:
    """The metrics of a rendered view against the held-out photograph, by the one rule of
    ``vibr render`` and ``vibr eval``: every registered metric (:data:`METRICS`, in order:
    ``psnr``, ``ssim``, ``dssim = 10⁴ · (1 − SSIM)`` and ``sharpness``, then any a user registered) over the
    pixels of ``mask`` (the reconstructed pixels) with ``border`` pixels at each edge
    excluded. A metric with a ``min_side`` (``ssim`` and ``dssim``) is NaN for an image too
    small for it (:func:`check_measurable`): the PSNR of a tiny render is still worth
    reporting."""
    out = {}
    for m in METRICS.values():
        if m.min_side and not _measurable(np.shape(img), border, m.min_side):
            out[m.name] = float("nan")
        elif m.derive is not None:
            out[m.name] = m.derive(out)
        else:
            out[m.name] = m.function(img, ref, mask, border)
    return out


def _measurable(shape, border: int, side: int = SSIM_WINDOW) -> bool:
    """Whether ``side`` (SSIM's window) fits in an image of ``shape`` less ``border`` on each edge."""
    return min(shape[:2]) >= side + 2 * int(border)


def check_measurable(shape, border: int = METRIC_BORDER, source=None) -> None:
    """Refuse, before any work, to measure a view of ``shape`` (H, W, ...) on which DSSIM
    is undefined: its side, less the ``border`` on each edge, under SSIM's window."""
    if not _measurable(shape, border):
        H, W = shape[:2]
        need = SSIM_WINDOW + 2 * int(border)
        raise VibrInputError(f"the held-out view is {W}x{H}: DSSIM needs at least {need} pixels a side "
                             f"({SSIM_WINDOW}-px window, {int(border)}-px border; use a larger --scale"
                             f"{' or a smaller --border' if border else ''})", source)


# ----------------------------------------------------------------------------- uncertainty
def pixel_error(img, ref, scale: float = 255.0) -> np.ndarray:
    """Per-pixel error (H, W) float64: the RMS over channels of ``img − ref``, times
    ``scale`` (grey levels of 255 by default)."""
    a = np.asarray(img, np.float64)
    b = np.asarray(ref, np.float64)
    if a.shape != b.shape:
        raise VibrInputError(f"pixel_error: image has shape {a.shape} but the reference has {b.shape}")
    d = (a - b) * float(scale)
    return np.sqrt((d * d).mean(-1)) if d.ndim == 3 else np.abs(d)


def _select(sigma, error, mask, border, what):
    s = np.asarray(sigma, np.float64)
    e = np.asarray(error, np.float64)
    if s.shape != e.shape:
        raise VibrInputError(f"{what}: sigma has shape {s.shape} but the error has {e.shape}")
    m = np.ones(s.shape, bool) if mask is None else np.asarray(mask, bool)
    if m.shape != s.shape:
        raise VibrInputError(f"{what}: mask has shape {m.shape} but sigma has {s.shape}")
    if border and s.ndim == 2:
        m = m.copy()
        b = int(border)
        m[:b] = m[-b:] = False
        m[:, :b] = m[:, -b:] = False
    s, e = s[m].ravel(), e[m].ravel()
    if not np.all(np.isfinite(e)):
        raise VibrInputError(f"{what}: the error has non-finite values")
    if np.any(np.isnan(s)):
        raise VibrInputError(f"{what}: sigma has NaN values")
    if s.size == 0:
        raise VibrInputError(f"{what}: the mask selects no pixel")
    return s, e


def _removal_curve(key, e2, fractions):
    """RMSE of the pixels left after removing the fraction f with the largest ``key``, at each
    f of ``fractions``. Pixels with equal keys are removed together in expectation (each
    one removes the mean squared error of its tie group), i.e. the expected curve over random
    tie-breaking."""
    order = np.argsort(-key, kind="stable")
    k = key[order]
    e2s = e2[order]
    # tie groups: replace each squared error by its group's mean
    start = np.r_[0, np.flatnonzero(k[1:] != k[:-1]) + 1]
    sums = np.add.reduceat(e2s, start)
    cnt = np.diff(np.r_[start, k.size])
    e2s = np.repeat(sums / cnt, cnt)
    n = e2s.size
    tail = np.r_[np.cumsum(e2s[::-1])[::-1], 0.0]  # tail[i] = Σ e2s[i:]
    out = np.empty(len(fractions))
    for j, f in enumerate(fractions):
        r = f * n  # pixels removed (fractional: linear inside a pixel)
        i = min(int(np.floor(r)), n - 1)
        rest = tail[i] - (r - i) * e2s[i]
        out[j] = np.sqrt(max(rest, 0.0) / max(n - r, 1e-12))
    return out


def sparsification(sigma, error, mask=None, border: int = 0, n_points: int = 50,
                   normalise: bool = True) -> dict:
    """Sparsification curve of a predicted uncertainty and its oracle (Ilg et al. 2018,
    "Uncertainty estimates and multi-hypotheses networks for optical flow", ECCV).

    Pixels are removed in decreasing order of ``sigma``; ``curve[j]`` is the RMSE of the
    ``error`` of the pixels left after removing the fraction ``fractions[j]``
    (``fractions = j / n_points``, j = 0..n_points−1). The ``oracle`` removes them in
    decreasing order of the error itself (the best any predictor can do). Ties in ``sigma``
    are removed together in expectation (the expected curve over random tie-breaking), so a
    constant ``sigma`` gives the flat curve of a random order. With ``normalise`` both curves
    are divided by the RMSE of all selected pixels (they start at 1).

    Parameters
    ----------
    sigma, error : (H, W) arrays
        Predicted uncertainty (any monotone scale; ``inf`` allowed) and the true per-pixel
        error (e.g. :func:`pixel_error`).
    mask : (H, W) bool, optional
    border : int
        Pixels excluded on each side.

    Returns
    -------
    dict with ``fractions``, ``curve``, ``oracle`` (lists of float) and ``rmse`` (all pixels).
    """
    s, e = _select(sigma, error, mask, border, "sparsification")
    e2 = e * e
    fr = np.arange(int(n_points)) / float(n_points)
    curve = _removal_curve(s, e2, fr)
    oracle = _removal_curve(e, e2, fr)
    rmse = float(np.sqrt(e2.mean()))
    if normalise and rmse > 0:
        curve, oracle = curve / rmse, oracle / rmse
    return {"fractions": fr.tolist(), "curve": curve.tolist(), "oracle": oracle.tolist(), "rmse": rmse}


def ause(sigma=None, error=None, mask=None, border: int = 0, n_points: int = 50, *, curves=None) -> float:
    """Area Under the Sparsification Error: ``mean_j (curve[j] − oracle[j])`` over the removed
    fractions ``j / n_points`` (the rectangle rule over [0, 1) of :func:`sparsification`'s
    normalised curves; lower is better, 0 for a predictor ordering the pixels as their
    error). ``curves`` reuses the output of :func:`sparsification`."""
    c = curves if curves is not None else sparsification(sigma, error, mask, border, n_points)
    return float(np.mean(np.asarray(c["curve"]) - np.asarray(c["oracle"])))


def spearman(sigma, error, mask=None, border: int = 0) -> float:
    """Spearman's rank correlation between the predicted ``sigma`` and the ``error`` over the
    selected pixels (scipy.stats.spearmanr, average ranks for ties); NaN when either is
    constant."""
    from scipy.stats import spearmanr

    s, e = _select(sigma, error, mask, border, "spearman")
    s = np.where(np.isinf(s), np.finfo(np.float64).max, s)  # inf ranks last, as it should
    if s.size < 2 or np.all(s == s[0]) or np.all(e == e[0]):
        return float("nan")
    return float(spearmanr(s, e).statistic)


def uncertainty_metrics(sigma, img, ref, mask=None, border: int = 0, scale: float = 255.0,
                        n_points: int = 50) -> dict:
    """AUSE, Spearman's rho and the sparsification curves of ``sigma`` against the per-pixel
    error of ``img`` w.r.t. ``ref`` (:func:`pixel_error`, grey levels of ``scale``)."""
    err = pixel_error(img, ref, scale)
    c = sparsification(sigma, err, mask, border, n_points)
    return {"ause": ause(curves=c), "spearman": spearman(sigma, err, mask, border), **c}
