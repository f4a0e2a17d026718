"""Pictures of a per-pixel uncertainty: a colour-mapped σ map with a scale bar,
the raw array, and sparsification plots, drawn with numpy and Pillow (already required by
imageio; no plotting library)."""

from __future__ import annotations

import logging
import os

import numpy as np

from .._runtime.atomic import atomic_path
from ..errors import VibrInputError
from ..io.images import write_encoded
from ..render.uncertainty import hole_sigma

logger = logging.getLogger(__name__)

__all__ = ["colourise", "sigma_scale", "sigma_figure", "write_sigma", "sparsification_plot", "write_sparsification_figure"]

#: viridis (matplotlib's perceptually uniform map, CC0), 9 anchors from 0 to 1
_VIRIDIS = np.array([
    [68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
    [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37]], np.float64)


def colourise(values, vmax: float, vmin: float = 0.0) -> np.ndarray:
    """(H, W) values → (H, W, 3) uint8 through viridis on ``[vmin, vmax]`` (clipped; NaN grey)."""
    v = np.asarray(values, np.float64)
    t = np.clip((v - vmin) / max(vmax - vmin, 1e-300), 0.0, 1.0)
    t = np.where(np.isnan(v), 0.0, t) * (len(_VIRIDIS) - 1)
    i = np.minimum(np.floor(t).astype(int), len(_VIRIDIS) - 2)
    f = (t - i)[..., None]
    rgb = _VIRIDIS[i] * (1 - f) + _VIRIDIS[i + 1] * f
    rgb[np.isnan(v)] = 128
    return np.round(rgb).astype(np.uint8)


def _nice_ceiling(x: float) -> float:
    """The smallest of 1, 2, 2.5, 5 × 10^k that is ≥ x."""
    if not x > 0 or not np.isfinite(x):
        return 1.0
    e = 10.0 ** np.floor(np.log10(x))
    for m in (1, 2, 2.5, 5, 10):
        if m * e >= x * (1 - 1e-9):
            return float(m * e)
    return float(10 * e)


def sigma_scale(values, scale: float = 255.0) -> float:
    """Top of the colour scale of σ maps (grey levels of ``scale``): the 99th percentile of
    the finite σ below σ_hole (:func:`vibr.render.uncertainty.hole_sigma`, the σ of pixels no
    source reaches, drawn at the top whatever the scale), rounded up to 1, 2, 2.5 or 5 × 10^k.

    Holes are left out because they would set the scale by themselves: on fountain's
    fly-through 7 % of a frame's pixels are holes, the 99th percentile of all pixels is σ_hole
    (73.6) and the σ of the pixels the sources reach (median 7, 90th percentile 18) took the
    bottom tenth of the colours."""

    v = np.asarray(values, np.float64).ravel()
    v = v[np.isfinite(v) & (v < 0.999 * hole_sigma(scale))]  # σ_hole, also as float16
    return _nice_ceiling(float(np.percentile(v, 99)) if v.size else hole_sigma(scale))


def sigma_figure(sigma, vmax: float | None = None, label: str = "sigma, grey levels") -> np.ndarray:
    """σ map (H, W) → RGB uint8 image: the colour-mapped map above a horizontal scale bar
    (0 to ``vmax``, default :func:`sigma_scale`) with the caption ``label``."""
    from PIL import Image, ImageDraw

    s = np.asarray(sigma, np.float64)
    if vmax is None:
        vmax = sigma_scale(s)
    H, W = s.shape
    bar_h = max(40, H // 12)
    img = Image.new("RGB", (W, H + bar_h), (255, 255, 255))
    img.paste(Image.fromarray(colourise(np.where(np.isfinite(s), s, vmax), vmax)), (0, 0))
    x0, x1 = 8, max(W - 8, 9)
    ramp = np.linspace(0, vmax, x1 - x0)[None].repeat(max(bar_h // 4, 4), 0)
    img.paste(Image.fromarray(colourise(ramp, vmax)), (x0, H + 2))
    d = ImageDraw.Draw(img)
    ty = H + 2 + ramp.shape[0] + 1
    n_ticks = 5 if W >= 240 else 2  # labels ~6 px per character: fewer on small maps
    for k in range(n_ticks):
        x = x0 + round(k / (n_ticks - 1) * (x1 - x0 - 1))
        d.line([(x, H + 2), (x, ty)], fill=(0, 0, 0))
        lab = f"{k / (n_ticks - 1) * vmax:g}"
        d.text((min(max(x - 3 * len(lab), 0), max(W - 6 * len(lab), 0)), ty), lab, fill=(0, 0, 0))
    lab = label
    d.text((max(W // 2 - 3 * len(lab), 0), ty + 12), lab, fill=(0, 0, 0))
    return np.asarray(img)


def write_sigma(path, sigma, vmax: float | None = None) -> None:
    """Write a σ map atomically: ``.npy`` the raw float32 array, ``.png`` the colour-mapped
    figure with its scale bar (:func:`sigma_figure`)."""

    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".npy", ".png"):
        raise VibrInputError("the uncertainty output must end in .png or .npy", path)
    with atomic_path(path) as tmp:
        if ext == ".npy":
            with open(tmp, "wb") as fh:
                np.save(fh, np.asarray(sigma, np.float32))
        else:
            write_encoded(tmp, sigma_figure(sigma, vmax), ".png")


_LINE_COLOURS = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (0, 0, 0), (214, 39, 40), (148, 103, 189)]


def sparsification_plot(path, fractions, curves: dict, title: str = "", size=(480, 360)) -> None:
    """Draw sparsification curves (dict label → values over ``fractions``; a label
    containing "oracle" is drawn dashed) into a PNG, atomically. x: fraction of pixels
    removed; y: RMSE of the rest, relative to all pixels."""
    from PIL import Image, ImageDraw

    Wd, Hd = size
    ml, mr, mt, mb = 46, 12, 22, 34
    img = Image.new("RGB", size, (255, 255, 255))
    d = ImageDraw.Draw(img)
    fr = np.asarray(fractions, np.float64)
    ymax = max(1e-9, max(float(np.nanmax(v)) for v in curves.values()))
    ymax = float(np.ceil(ymax * 1.05 * 10) / 10)
    px = lambda x: ml + x * (Wd - ml - mr)  # noqa: E731
    py = lambda y: Hd - mb - y / ymax * (Hd - mt - mb)  # noqa: E731
    d.rectangle([px(0), py(ymax), px(1), py(0)], outline=(0, 0, 0))
    for k in range(6):
        x = k / 5
        d.line([(px(x), py(0)), (px(x), py(0) + 4)], fill=(0, 0, 0))
        d.text((px(x) - 8, py(0) + 6), f"{x:.1f}", fill=(0, 0, 0))
        y = k / 5 * ymax
        d.line([(px(0) - 4, py(y)), (px(0), py(y))], fill=(0, 0, 0))
        d.text((4, py(y) - 5), f"{y:.2g}", fill=(0, 0, 0))
    d.text((px(0.3), Hd - 13), "fraction of pixels removed", fill=(0, 0, 0))
    d.text((ml, 4), (title + ": " if title else "") + "RMSE of the rest / RMSE", fill=(0, 0, 0))
    for n, (label, vals) in enumerate(curves.items()):
        col = _LINE_COLOURS[n % len(_LINE_COLOURS)]
        pts = [(px(x), py(y)) for x, y in zip(fr, vals) if np.isfinite(y)]
        if "oracle" in label:
            for a, b in list(zip(pts[:-1], pts[1:]))[::2]:
                d.line([a, b], fill=col, width=2)
        else:
            d.line(pts, fill=col, width=2)
        ly = mt + 6 + 13 * n
        d.line([(Wd - mr - 120, ly + 5), (Wd - mr - 100, ly + 5)], fill=col, width=2)
        d.text((Wd - mr - 96, ly), label, fill=(0, 0, 0))
    with atomic_path(path) as tmp:
        write_encoded(tmp, np.asarray(img), ".png")


def write_sparsification_figure(folder, results, prefix: str) -> str:
    """``FOLDER/PREFIX_sparsification.png``: the sparsification curve of every evaluated
    setting that has one (``results`` of :func:`vibr.eval.protocol.evaluate`, entry
    ``uncertainty``) and the oracle of the first; returns the path."""
    rows = [r for r in results if r.get("uncertainty")]
    curves = {f"{r['label']} (AUSE {r['uncertainty']['ause']:.3f})": r["uncertainty"]["curve"] for r in rows}
    if rows:
        curves[f"oracle ({rows[0]['label']})"] = rows[0]["uncertainty"]["oracle"]
    path = os.path.join(os.fspath(folder), f"{prefix}_sparsification.png")
    sparsification_plot(path, rows[0]["uncertainty"]["fractions"] if rows else [], curves, title=prefix,
                        size=(640, 400))
    return path
