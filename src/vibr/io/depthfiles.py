"""Depth map files: PFM, NPY, 16-bit PNG, COLMAP ``.bin``.

In memory depth is an H×W float32 array of *orthogonal* depth in scene units with NaN where
unknown (:mod:`vibr.scene`). In files ``0`` marks unknown depth; NaN, ±inf and negative values
are errors (:func:`vibr.scene.depth_from_file_values`).

Formats
-------
* **PFM** (``.pfm``): header ``Pf`` (1 channel) or ``PF`` (3 channels, first used), ``W H``,
  then a scale whose sign gives the byte order (negative = little endian); rows are stored
  **bottom-up**.
* **NPY** (``.npy``): an H×W (or H×W×1) float array.
* **PNG** (``.png``): 16-bit grey; depth = value × ``scale`` (default 1e-3, the nerfstudio /
  Kinect convention of millimetres → metres).
* **COLMAP** (``.bin``, e.g. ``NAME.geometric.bin``): an ASCII header ``width&height&channels&``
  followed by float32 values in column-major (Fortran) order of a W×H×C array, i.e. x fastest.
"""

from __future__ import annotations

import logging
import os

import numpy as np

from .._runtime.atomic import atomic_path
from ..errors import VibrInputError, require_file
from ..geometry.resample import resize_depth
from ..scene import depth_from_file_values
from .images import write_encoded

logger = logging.getLogger(__name__)

DEPTH_EXTS = (".pfm", ".npy", ".png", ".bin")


# ----------------------------------------------------------------------------- PFM
def read_pfm(path) -> np.ndarray:
    """Raw values of a PFM file, top row first: H×W (``Pf``) or H×W×3 (``PF``) float32.

    Rows are stored bottom-up in the file and flipped here; both byte orders are read.
    """
    p = require_file(path)
    with open(p, "rb") as f:
        data = f.read()
    try:
        # Header: three whitespace-separated tokens after the magic, then one whitespace byte.
        tokens, pos = [], 0
        while len(tokens) < 4:
            while pos < len(data) and data[pos : pos + 1].isspace():
                pos += 1
            start = pos
            while pos < len(data) and not data[pos : pos + 1].isspace():
                pos += 1
            tokens.append(data[start:pos].decode("ascii"))
        pos += 1
        magic, w, h, sc = tokens[0], int(tokens[1]), int(tokens[2]), float(tokens[3])
    except (ValueError, UnicodeDecodeError):
        raise VibrInputError("not a PFM file (bad header)", p) from None
    if magic not in ("Pf", "PF") or w <= 0 or h <= 0 or sc == 0:
        raise VibrInputError(f"not a PFM file (header {' '.join(tokens)!r})", p)
    ch = 3 if magic == "PF" else 1
    n = w * h * ch
    dtype = np.dtype("<f4" if sc < 0 else ">f4")
    if len(data) - pos < 4 * n:
        raise VibrInputError(f"PFM file is truncated ({len(data) - pos} bytes of data, {4 * n} expected)", p)
    a = np.frombuffer(data, dtype=dtype, count=n, offset=pos).astype(np.float32)
    a = a.reshape((h, w, ch) if ch == 3 else (h, w))
    return np.ascontiguousarray(a[::-1])


def write_pfm(path, values: np.ndarray, little_endian: bool = True) -> None:
    """Write an H×W float array as a grey PFM (rows bottom-up), atomically."""
    a = np.asarray(values, dtype=np.float32)
    if a.ndim != 2:
        raise ValueError(f"write_pfm needs an H×W array, got {a.shape}")
    h, w = a.shape
    dt = "<f4" if little_endian else ">f4"
    header = f"Pf\n{w} {h}\n{-1.0 if little_endian else 1.0}\n".encode("ascii")
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(header)
            f.write(np.ascontiguousarray(a[::-1]).astype(dt).tobytes())


# ----------------------------------------------------------------------------- COLMAP
def read_colmap_bin(path) -> np.ndarray:
    """Raw values of a COLMAP dense ``.bin`` array: H×W (one channel) or H×W×C float32."""
    p = require_file(path)
    with open(p, "rb") as f:
        data = f.read()
    parts, pos = [], 0
    for _ in range(3):
        amp = data.find(b"&", pos)
        if amp < 0 or amp - pos > 20:
            raise VibrInputError("not a COLMAP array file (header 'width&height&channels&' missing)", p)
        parts.append(data[pos:amp])
        pos = amp + 1
    try:
        w, h, c = (int(x.decode("ascii")) for x in parts)
    except (ValueError, UnicodeDecodeError):
        raise VibrInputError("not a COLMAP array file (bad header)", p) from None
    n = w * h * c
    if w <= 0 or h <= 0 or c <= 0 or len(data) - pos < 4 * n:
        raise VibrInputError(f"COLMAP array file is truncated or has a bad size {w}x{h}x{c}", p)
    a = np.frombuffer(data, dtype="<f4", count=n, offset=pos)
    # Column-major W×H×C == row-major C×H×W.
    a = a.reshape(c, h, w).transpose(1, 2, 0)
    return np.ascontiguousarray(a[..., 0] if c == 1 else a, dtype=np.float32)


def write_colmap_bin(path, values: np.ndarray) -> None:
    """Write an H×W (or H×W×C) float array in COLMAP's dense ``.bin`` format, atomically."""
    a = np.asarray(values, dtype=np.float32)
    if a.ndim == 2:
        a = a[..., None]
    h, w, c = a.shape
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(f"{w}&{h}&{c}&".encode("ascii"))
            f.write(np.ascontiguousarray(a.transpose(2, 0, 1)).astype("<f4").tobytes())


# ----------------------------------------------------------------------------- generic
def read_depth_values(path, scale: float | None = None) -> np.ndarray:
    """Raw depth values of a file (0 = unknown), multiplied by ``scale``; float64 H×W."""
    import imageio.v3 as iio

    p = require_file(path)
    ext = os.path.splitext(p)[1].lower()
    if ext == ".pfm":
        a = read_pfm(p)
    elif ext == ".bin":
        a = read_colmap_bin(p)
    elif ext == ".npy":
        with open(p, "rb") as fh:
            if fh.read(6) != b"\x93NUMPY":  # else numpy's message is about pickles
                raise VibrInputError("not a .npy file (no NumPy header)", p)
        try:
            a = np.load(p, allow_pickle=False)
        except Exception as exc:
            raise VibrInputError(f"cannot read .npy depth ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})", p) from None
        if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
            raise VibrInputError(f"depth array has type {a.dtype}", p)
    elif ext == ".png":
        try:
            a = iio.imread(p)
        except Exception as exc:
            raise VibrInputError(f"cannot read depth image ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})", p) from None
        if a.ndim != 2 or a.dtype != np.uint16:
            raise VibrInputError(f"a PNG depth map must be 16-bit grey, got {a.dtype} shape {a.shape}", p)
        scale = 1e-3 if scale is None else scale
    else:
        raise VibrInputError(f"unknown depth file type {ext!r} (use {', '.join(DEPTH_EXTS)})", p)
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim != 2:
        raise VibrInputError(f"depth must be a single-channel H×W array, got shape {a.shape}", p)
    if scale is not None:
        a = a * float(scale)
    return a


def fit_depth(depth: np.ndarray, shape, path=None, what: str = "the view") -> np.ndarray:
    """A depth map of the view's aspect at another resolution (a full-size map for a view
    loaded at ``--scale``, COLMAP's dense maps at its ``max_image_size``) resized to
    ``shape`` = (H, W) by nearest neighbour, which never mixes depths across an edge. Another
    aspect is an error naming ``path`` (the map is of another image)."""

    (h, w), (H, W) = depth.shape[:2], tuple(shape)
    if (h, w) == (H, W):
        return depth
    if abs(w * H - h * W) > max(w, W):  # aspects differ by more than a pixel's rounding
        raise VibrInputError(f"depth is {w}x{h}, {what} is {W}x{H} (another aspect)", path)
    return resize_depth(depth, (H, W))


def check_depth_content(depth: np.ndarray, path, what: str = "depth") -> None:
    """Say so when a depth map loads but is unlikely to be what was meant: a warning when it
    is unknown (0) everywhere (the view then gives the render nothing), a note (the log's
    info level) when it has one value at every known pixel (a placeholder? a plane facing
    the camera has it too). A map of another ``what`` (a σ_z map) is only checked for the first."""
    known = np.isfinite(depth)
    if not known.any():
        logger.warning(f"{os.fspath(path)}: the {what} is all zero (unknown at every pixel): this view gives "
                       "the render no samples")
    elif what == "depth" and known.sum() > 1:
        v = depth[known]
        if v.min() == v.max():
            # a note, not a warning: a plane facing the camera has it too
            logger.info(f"{os.fspath(path)}: the depth is {float(v[0]):g} at every known pixel (constant: "
                        "a placeholder rather than a measurement?)")


def read_depth(path, scale: float | None = None, shape=None, what: str = "depth") -> np.ndarray:
    """Read an orthogonal depth map: H×W float32, NaN where unknown (0 in the file).

    Parameters
    ----------
    path : str or Path
        ``.pfm``, ``.npy``, ``.png`` (16-bit) or COLMAP ``.bin``.
    scale : float, optional
        Multiplies the stored values (scene units per file unit); default 1, or 1e-3 for PNG.
    shape : (H, W), optional
        Expected shape (the image's); a mismatch raises :class:`VibrInputError`.

    what : str
        What the file holds, in messages (``"sigma_z"``): :func:`check_depth_content` warns
        about a map that is unknown everywhere (or, for depth, constant).

    NaN, inf and negative values in the file raise :class:`VibrInputError`.
    """
    a = read_depth_values(path, scale)
    d = depth_from_file_values(a, a.shape if shape is None else tuple(shape), os.fspath(path))
    check_depth_content(d, path, what)
    return d


def write_depth(path, depth: np.ndarray, scale: float | None = None) -> None:
    """Write an H×W depth map (NaN = unknown, stored as 0), atomically, format by extension.

    ``.npy`` and ``.pfm`` store float32 values; ``.bin`` COLMAP's format; ``.png`` stores
    ``round(depth / scale)`` as 16-bit (default scale 1e-3; values must fit in 0..65535).
    """
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    d = np.asarray(depth, dtype=np.float32)
    if d.ndim == 3 and d.shape[2] == 1:
        d = d[..., 0]
    if d.ndim != 2:
        raise ValueError(f"depth must be H×W, got {d.shape}")
    d = np.where(np.isfinite(d), d, np.float32(0))
    if ext == ".npy":
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.save(f, d)
    elif ext == ".pfm":
        write_pfm(path, d)
    elif ext == ".bin":
        write_colmap_bin(path, d)
    elif ext == ".png":
        scale = 1e-3 if scale is None else float(scale)
        q = np.round(d.astype(np.float64) / scale)
        if q.max(initial=0) > 65535:
            raise ValueError(f"depth {d.max():.4g} does not fit a 16-bit PNG with scale {scale}")
        with atomic_path(path) as tmp:
            write_encoded(tmp, q.astype(np.uint16), ".png")
    else:
        raise ValueError(f"unknown depth file type {ext!r}")
