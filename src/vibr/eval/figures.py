"""Comparison figures: reference, each method, error maps, and zoomed crops where methods
differ most. Plain PNGs assembled with numpy (no plotting dependency)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._runtime.atomic import atomic_path

# A perceptually ordered dark-to-bright map (approximating 'inferno') for error images.
_ANCHORS = np.array([[0, 0, 4], [40, 11, 84], [101, 21, 110], [159, 42, 99], [212, 72, 66],
                     [245, 125, 21], [250, 193, 39], [252, 255, 164]], float) / 255.0


def colormap(x: np.ndarray) -> np.ndarray:
    """Map values in [0, 1] (clipped) to H×W×3 float32 colours."""
    x = np.clip(np.asarray(x, float), 0, 1) * (len(_ANCHORS) - 1)
    i = np.minimum(x.astype(int), len(_ANCHORS) - 2)
    f = (x - i)[..., None]
    return ((1 - f) * _ANCHORS[i] + f * _ANCHORS[i + 1]).astype(np.float32)


def error_map(img: np.ndarray, ref: np.ndarray, max_err: float = 0.1) -> np.ndarray:
    """Colour-coded per-pixel RGB error ‖img − ref‖/√3, saturating at ``max_err``."""
    e = np.sqrt(np.mean((np.asarray(img, float) - ref) ** 2, axis=-1))
    return colormap(e / max_err)


def most_different_window(images: list[np.ndarray], size: int, mask=None) -> tuple[int, int]:
    """Top-left (row, col) of the size×size window where the images disagree most
    (sum over the window of the per-pixel variance across images; only pixels of ``mask``
    count when it is given, so that the crop shows evaluated pixels)."""
    from scipy.ndimage import uniform_filter

    stack = np.stack([np.asarray(i, float).mean(-1) for i in images])
    var = stack.var(axis=0)
    if mask is not None:
        var = np.where(np.asarray(mask, bool), var, 0.0)
    score = uniform_filter(var, size, mode="constant")
    h, w = var.shape
    half = size // 2
    score = score[half : h - size + half + 1, half : w - size + half + 1]
    r, c = np.unravel_index(np.argmax(score), score.shape)
    return int(r), int(c)


def downscale_image(a: np.ndarray, f: int) -> np.ndarray:
    """Box-average an H×W×C image by the integer factor ``f`` (edges cropped to a multiple)."""
    f = int(f)
    if f <= 1:
        return a
    H, W = a.shape[0] // f * f, a.shape[1] // f * f
    a = np.asarray(a[:H, :W], np.float32)
    return a.reshape(H // f, f, W // f, f, -1).mean(axis=(1, 3))


def label_panel(img: np.ndarray, text: str, height: int = 14) -> np.ndarray:
    """``img`` with a white strip above it carrying ``text`` (Pillow's default font), so a
    figure's panels say what they show."""
    from PIL import Image, ImageDraw

    strip = Image.new("RGB", (img.shape[1], height), (255, 255, 255))
    ImageDraw.Draw(strip).text((2, 1), text, fill=(0, 0, 0))
    return np.concatenate([np.asarray(strip, np.float32) / 255.0, np.asarray(img, np.float32)], axis=0)


def _write_png(path: Path, img: np.ndarray) -> None:
    """An 8-bit PNG at full zlib compression (figures are kept in docs), written atomically."""
    from PIL import Image


    q = (np.clip(np.asarray(img, np.float32), 0, 1) * 255 + 0.5).astype(np.uint8)
    with atomic_path(path) as tmp:
        Image.fromarray(q).save(tmp, format="PNG", compress_level=9)


def write_figures(folder, ref: np.ndarray, images: dict[str, np.ndarray], mask=None,
                  prefix: str = "view", max_err: float = 0.1, downscale: int = 1) -> dict:
    """Write ``PREFIX_compare.png`` (top row: reference and each method; bottom row: the mask
    and each method's error map) and ``PREFIX_crops.png`` (the same images cropped to the
    window where methods differ most, magnified ×4). ``downscale`` reduces the side-by-side
    figure by an integer factor (the crops stay at full resolution). Returns the file names
    and the column order."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    names = list(images)
    top = [ref] + [np.clip(images[n], 0, 1) for n in names]
    m = np.ones(ref.shape[:2], bool) if mask is None else np.asarray(mask, bool)
    bottom = [np.repeat(m[..., None].astype(np.float32), 3, -1)] + [error_map(images[n], ref, max_err) for n in names]
    labelled = lambda ims, texts: [label_panel(i, t) for i, t in zip(ims, texts)]  # noqa: E731
    top_l = labelled(top, ["reference"] + names)
    bottom_l = labelled(bottom, ["evaluated pixels"] + [f"error {n} (max {max_err:g})" for n in names])
    sep = np.ones((top_l[0].shape[0], 4, 3), np.float32)
    row = lambda ims: np.concatenate(sum(([i, sep] for i in ims), [])[:-1], axis=1)  # noqa: E731
    grid = np.concatenate([row(top_l), np.ones((4, row(top_l).shape[1], 3), np.float32), row(bottom_l)], axis=0)
    compare = folder / f"{prefix}_compare.png"
    _write_png(compare, downscale_image(grid, downscale))

    size = max(16, min(ref.shape[:2]) // 6)
    r, c = most_different_window(top[1:] if len(top) > 2 else top, size, m)
    crop = lambda a: np.kron(a[r : r + size, c : c + size], np.ones((4, 4, 1), np.float32))  # noqa: E731
    crops_l = [label_panel(crop(i), t) for i, t in zip(top, ["reference"] + names)]
    sepc = np.ones((crops_l[0].shape[0], 4, 3), np.float32)
    crops = np.concatenate(sum(([c_, sepc] for c_ in crops_l), [])[:-1], axis=1)
    crops_path = folder / f"{prefix}_crops.png"
    _write_png(crops_path, crops)
    return {"compare": str(compare), "crops": str(crops_path), "columns": ["reference"] + names,
            "crop_window": {"row": r, "col": c, "size": size}, "error_saturation": max_err,
            "downscale": int(max(1, downscale))}


def write_evaluation_figures(evaluation, folder, *, labels=None, prefix: str | None = None,
                             downscale: int = 1) -> dict:
    """:func:`write_figures` of a :class:`vibr.eval.protocol.Evaluation`: the reference, the
    renders of the settings ``labels`` (default all, in the evaluation's order) and the
    evaluated pixels. ``prefix`` defaults to the evaluation's (``TARGET_DEPTH``). Returns
    the figures' entry of a report (file names, columns, crop window)."""
    images = evaluation.images
    shown = list(images) if labels is None else [k for k in labels if k in images]
    return write_figures(folder, evaluation.reference, {k: images[k] for k in shown}, evaluation.mask,
                         prefix=prefix or evaluation.prefix, downscale=downscale)
