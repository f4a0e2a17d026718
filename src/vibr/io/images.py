"""Reading and writing images.

In memory an image is an H×W×3 float32 array in [0, 1] (see :mod:`vibr.camera`). Files are
read with imageio; 8-bit files map to ``q / 255`` and 16-bit files to ``q / 65535`` computed
in float32, always through :func:`from_uint`, so that an image written by :func:`write_image`
and read back is bit-for-bit the array that was written whenever it lies on that 8- or
16-bit grid (:func:`quantise16` puts resized images on the 16-bit grid).
"""

from __future__ import annotations

import contextlib
import contextvars
import logging
import os
import struct
import warnings
import zlib

import numpy as np
from numba import njit

from .._runtime.atomic import atomic_path
from .._runtime.memory import check_memory
from ..errors import VibrInputError, require_file
from ..geometry.resample import from_uint, resize_depth, resize_image, resize_mask
from ..progress import progress
from ..scene import (
    View,
    check_image,  # NaN, or 0..255 as floats: refused, not clipped to white
)
from .undistort import undistort_array

logger = logging.getLogger(__name__)

#: Set by :func:`headers_only`: :func:`build_views` then reads image headers, not pixels.
_HEADERS_ONLY = contextvars.ContextVar("vibr_headers_only", default=False)

#: The smallest image side vibr loads, after ``--scale``: the depth estimate's gradients and
#: the solver's stencils need a few pixels (DSSIM needs 11 + 2·border: see vibr.metrics).
MIN_SIDE = 8

#: Image file extensions recognised when scanning folders.
IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".ppm", ".pgm", ".webp")


def is_image_file(name) -> bool:
    return os.path.splitext(os.fspath(name))[1].lower() in IMAGE_EXTS


# ----------------------------------------------------------------------------- 16-bit PNG
# Pillow reads 16-bit RGB PNGs as 8-bit and cannot write them, so vibr has its own small
# codec for 16-bit PNGs (8-bit ones go through imageio/Pillow).
_PNG_SIG = b"\x89PNG\r\n\x1a\n"
_PNG_CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}  # colour type -> samples per pixel


def _png_chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)


def encode_png16(q: np.ndarray, level: int = 3) -> bytes:
    """PNG bytes of an H×W or H×W×3 uint16 array (filter 0 on every row, zlib ``level``)."""
    q = np.asarray(q, dtype=np.uint16)
    h, w = q.shape[:2]
    ctype = 0 if q.ndim == 2 else 2
    rows = np.ascontiguousarray(q.astype(">u2")).view(np.uint8).reshape(h, -1)
    raw = np.concatenate([np.zeros((h, 1), np.uint8), rows], axis=1).tobytes()
    ihdr = struct.pack(">IIBBBBB", w, h, 16, ctype, 0, 0, 0)
    return _PNG_SIG + _png_chunk(b"IHDR", ihdr) + _png_chunk(b"IDAT", zlib.compress(raw, level)) + _png_chunk(b"IEND", b"")


@njit(cache=True)
def _png_unfilter(data, h, stride, bpp):  # pragma: no cover - compiled
    """Undo PNG row filters (None, Sub, Up, Average, Paeth); rows depend on the previous one,
    so this runs row by row (sequential by nature)."""
    out = np.zeros((h, stride), np.uint8)
    ok = True
    for i in range(h):
        f = data[i * (stride + 1)]
        base = i * (stride + 1) + 1
        for j in range(stride):
            x = np.int32(data[base + j])
            a = np.int32(out[i, j - bpp]) if j >= bpp else 0
            b = np.int32(out[i - 1, j]) if i > 0 else 0
            c = np.int32(out[i - 1, j - bpp]) if (i > 0 and j >= bpp) else 0
            if f == 0:
                v = x
            elif f == 1:
                v = x + a
            elif f == 2:
                v = x + b
            elif f == 3:
                v = x + (a + b) // 2
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                if pa <= pb and pa <= pc:
                    v = x + a
                elif pb <= pc:
                    v = x + b
                else:
                    v = x + c
            else:
                ok = False
                v = x
            out[i, j] = v & 255
    return out, ok


def png_bit_depth(path) -> int | None:
    """Bit depth from a PNG header, None if the file is not a PNG."""
    with open(path, "rb") as f:
        head = f.read(29)
    if len(head) < 29 or head[:8] != _PNG_SIG or head[12:16] != b"IHDR":
        return None
    return head[24]


def decode_png16(path) -> np.ndarray:
    """Decode a 16-bit PNG (grey, grey+alpha, RGB, RGBA; not interlaced) → H×W[×C] uint16."""
    p = os.fspath(path)
    with open(p, "rb") as f:
        data = f.read()
    pos, idat, hdr = 8, [], None
    try:
        while pos + 8 <= len(data):
            n, tag = struct.unpack(">I4s", data[pos:pos + 8])
            body = data[pos + 8:pos + 8 + n]
            if len(body) != n:
                raise ValueError("truncated chunk")
            if tag == b"IHDR":
                hdr = struct.unpack(">IIBBBBB", body)
            elif tag == b"IDAT":
                idat.append(body)
            elif tag == b"IEND":
                break
            pos += 12 + n
        if hdr is None:
            raise ValueError("no IHDR chunk")
        w, h, depth, ctype, _, _, interlace = hdr
        if depth != 16 or ctype not in _PNG_CHANNELS or interlace:
            raise ValueError(f"unsupported 16-bit PNG (colour type {ctype}, interlace {interlace})")
        ch = _PNG_CHANNELS[ctype]
        raw = np.frombuffer(zlib.decompress(b"".join(idat)), np.uint8)
    except (ValueError, struct.error, zlib.error) as exc:
        raise VibrInputError(f"cannot read image (bad PNG: {exc})", p) from None
    stride = w * ch * 2
    if raw.size < h * (stride + 1):
        raise VibrInputError("cannot read image (PNG data truncated)", p)
    rows = raw[: h * (stride + 1)].reshape(h, stride + 1)
    if np.all(rows[:, 0] == 0):
        px = np.ascontiguousarray(rows[:, 1:])  # fast path: no filters (vibr's own files)
    else:
        px, ok = _png_unfilter(raw, h, stride, ch * 2)
        if not ok:
            raise VibrInputError("cannot read image (bad PNG filter type)", p)
    a = px.view(">u2").reshape(h, w, ch).astype(np.uint16)
    return a[..., 0] if ch == 1 else a


#: Pillow modes that are not RGB channels: converted to RGB when read (CMYK JPEGs from print
#: workflows read as C, M, Y otherwise; grey with alpha has two channels).
_CONVERT_MODES = {"CMYK", "YCbCr", "LAB", "HSV", "LA", "La", "PA"}


def _colour_mode(path) -> str | None:
    """The file's Pillow mode from its header, or None (not a Pillow format)."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            return im.mode
    except Exception:  # noqa: BLE001 - imageio reads it, or names the problem
        return None


def _require_content(path) -> str:
    """:func:`vibr.errors.require_file`, and a file of 0 bytes said to be empty (imageio
    said it found no backend for it)."""
    p = require_file(path)
    if os.path.getsize(p) == 0:
        raise VibrInputError("the image file is empty (0 bytes)", p)
    return p


#: The last chunk of every complete PNG file (length 0, type IEND, its CRC).
_PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"


def _warn_truncated_png(p: str) -> None:
    """Warn about a PNG file whose pixels decoded but which lacks its closing IEND chunk: it
    was cut short (a copy interrupted), and what follows the pixels (their checksum) is lost."""
    try:
        with open(p, "rb") as f:
            if f.read(8) != _PNG_SIG:
                return
            f.seek(-len(_PNG_END), os.SEEK_END)
            end = f.read()
    except OSError:
        return
    if end != _PNG_END:
        logger.warning(f"{p}: the PNG file is truncated (it does not end with its IEND chunk); its pixels "
                       "decoded in full, but check the file (an interrupted copy?)")


def read_image(path) -> np.ndarray:
    """Read an image file as an H×W×3 float32 array in [0, 1].

    Grey images are repeated over three channels, an alpha channel is dropped; 8-bit,
    16-bit and float files are accepted. Unreadable files raise
    :class:`~vibr.errors.VibrInputError` naming the file.
    """
    import imageio.v3 as iio

    p = _require_content(path)
    if png_bit_depth(p) == 16:
        a = decode_png16(p)
    else:
        try:
            with warnings.catch_warnings():  # imageio's legacy plugins warn while probing bad files
                warnings.simplefilter("ignore")
                mode = _colour_mode(p)
                a = iio.imread(p, extension=os.path.splitext(p)[1].lower() or None,
                               **({"mode": "RGB"} if mode in _CONVERT_MODES else {}))
        except Exception as exc:  # imageio raises many types for corrupt files
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise VibrInputError(f"cannot read image ({msg})", p) from None
    a = np.asarray(a)
    if a.ndim == 3 and a.shape[2] in (1, 2):  # grey, grey + alpha (16-bit PNG)
        a = a[..., 0]
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] not in (3, 4) or a.shape[0] == 0 or a.shape[1] == 0:
        raise VibrInputError(f"not an RGB image (array shape {a.shape})", p)
    _warn_truncated_png(p)
    a = a[..., :3]
    if a.dtype in (np.uint8, np.uint16):
        return np.ascontiguousarray(from_uint(a))
    if np.issubdtype(a.dtype, np.floating):
        return np.clip(check_image(a, p), 0.0, 1.0)
    if np.issubdtype(a.dtype, np.integer):
        return np.ascontiguousarray(a.astype(np.float32) / np.float32(np.iinfo(a.dtype).max))
    raise VibrInputError(f"unsupported pixel type {a.dtype}", p)


def image_size(path) -> tuple[int, int]:
    """(width, height) of an image file from its header; unreadable files raise
    :class:`VibrInputError` naming the file."""
    import imageio.v3 as iio

    p = _require_content(path)
    try:
        with warnings.catch_warnings():  # imageio's legacy plugins warn while probing bad files
            warnings.simplefilter("ignore")
            shape = iio.improps(p, extension=os.path.splitext(p)[1].lower() or None).shape
    except Exception as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise VibrInputError(f"cannot read image ({msg})", p) from None
    if len(shape) < 2 or shape[0] == 0 or shape[1] == 0:
        raise VibrInputError(f"not an image (array shape {shape})", p)
    return int(shape[1]), int(shape[0])


def image_bits(img: np.ndarray) -> int:
    """8 if ``img`` is exactly representable as 8-bit (``from_uint(round(255 img)) == img``),
    else 16."""
    img = np.asarray(img, dtype=np.float32)
    q8 = np.round(np.clip(img, 0, 1) * np.float32(255.0)).astype(np.uint8)
    return 8 if np.array_equal(from_uint(q8), img) else 16


def to_uint(img: np.ndarray, bits: int | None = None) -> np.ndarray:
    """Float image in [0, 1] → uint8 / uint16 (``bits`` None: the smallest exact one, else 16)."""
    img = np.asarray(img, dtype=np.float32)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    bits = image_bits(img) if bits is None else bits
    full = np.float32(255.0 if bits == 8 else 65535.0)
    q = np.round(np.clip(np.nan_to_num(img), 0, 1) * full)
    return q.astype(np.uint8 if bits == 8 else np.uint16)


#: Image formats :func:`write_image` writes (PNG and TIFF in 8 or 16 bits, the others 8).
WRITE_EXTS = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".webp", ".ppm")
_EIGHT_BIT_EXTS = (".jpg", ".jpeg", ".bmp", ".webp", ".ppm")
#: Pillow's defaults (75 for JPEG, 80 for WebP) lose more than a render's own error; 95 as
#: image tools write them (measured in docs/reference/errors-and-limits.md, "Image files").
_LOSSY_QUALITY = {".jpg": {"quality": 95}, ".jpeg": {"quality": 95}, ".webp": {"quality": 95}}


def check_image_ext(path, bits: int | None = None) -> str:
    """The lower-case extension of an image file to write (``""``: PNG), one of
    :data:`WRITE_EXTS`; another (``out.npy``, written as a TIFF under that name) is refused,
    and so are 16 ``bits`` in a format of 8."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext and ext not in WRITE_EXTS:
        raise VibrInputError(f"{ext} is not an image format vibr writes ({', '.join(WRITE_EXTS)})", path)
    if bits == 16 and ext in _EIGHT_BIT_EXTS:  # asked for, not silently dropped
        raise VibrInputError(f"{ext} holds 8 bits per channel: 16 need .png or .tif", path)
    return ext


def write_encoded(path, q: np.ndarray, extension: str, **kw) -> None:
    """Write the array ``q`` to ``path`` in the format of ``extension`` (imageio's writer
    options ``kw``), encoded in memory first: a file imageio opens itself and cannot close
    (a full disk) is closed again by imageio's finaliser, which printed a traceback after
    vibr's one-line error."""
    import imageio.v3 as iio

    data = iio.imwrite("<bytes>", q, extension=extension, **kw)
    with open(path, "wb") as f:
        f.write(data)


def write_image(path, img: np.ndarray, bits: int | None = None, text: dict | None = None) -> None:
    """Write an H×W×3 (or H×W) float image in [0, 1] atomically.

    PNG files are 8-bit when the image is exactly representable in 8 bits, else 16-bit
    (``bits`` = 8 or 16 forces one: a rendered view is 8-bit unless asked); JPEG, BMP, WebP
    and PPM are always 8-bit (``bits=16`` is refused for them), JPEG and WebP at quality 95.
    ``text``: key → value strings stored in an 8-bit PNG's text chunks (:func:`read_png_text`
    reads them back).
    """
    if bits not in (None, 8, 16):
        raise VibrInputError(f"bit depth must be 8 or 16, got {bits}", path)
    path = os.fspath(path)
    ext = check_image_ext(path, bits)
    if ext in _EIGHT_BIT_EXTS:
        bits = 8
    q = to_uint(img, bits)
    if text and (q.dtype != np.uint8 or ext not in (".png", "")):
        raise VibrInputError("text chunks are written to 8-bit PNG files only", path)
    with atomic_path(path) as tmp:
        if q.dtype == np.uint16 and ext in (".png", ""):
            with open(tmp, "wb") as f:
                f.write(encode_png16(q))
        else:
            # zlib level 2: ~6x faster than Pillow's default for ~10% larger files.
            kw = {"compress_level": 2} if ext in (".png", "") else _LOSSY_QUALITY.get(ext, {})
            if text:
                from PIL.PngImagePlugin import PngInfo

                kw["pnginfo"] = info = PngInfo()
                for k, v in text.items():
                    info.add_text(str(k), str(v))
            write_encoded(tmp, q, ext or ".png", **kw)


def read_png_text(path) -> dict:
    """The text chunks of a PNG file (key → value), without decoding its pixels; {} when
    the file is missing or not a PNG that Pillow can open."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            return dict(getattr(im, "text", {}) or {})
    except (OSError, UnidentifiedImageError, ValueError):
        return {}


def read_mask(path, shape, what: str = "its image") -> np.ndarray:
    """A validity mask file (nerfstudio's ``mask_path``: non-zero = use the pixel, 0 =
    ignore it) as an H×W bool array of ``shape``; a mask of the image's aspect at another
    resolution is resized (nearest pixel), another aspect is an error naming the file."""
    m = read_image(path).max(axis=2) > 0
    (h, w), (H, W) = m.shape, tuple(int(s) for s in shape)
    if (h, w) != (H, W):
        if abs(w * H - h * W) > max(w, W):
            raise VibrInputError(f"mask is {w}x{h}, {what} is {W}x{H} (another aspect)", path)
        m = resize_depth(m, (H, W))
    if not m.any():
        raise VibrInputError("mask excludes every pixel (0 everywhere; non-zero marks the pixels to use)", path)
    return m


# ----------------------------------------------------------------------------- view building
def build_views(entries, scale: float = 1.0, desc: str = "reading images", check_size: bool = True):
    """Read the images of ``entries`` in a thread pool and build scaled :class:`View` s.

    Parameters
    ----------
    entries : list of dict
        Keys ``name``, ``path`` (image file), ``camera`` (at the file's resolution), optional
        ``depth`` (H×W float32, NaN unknown, at the file's resolution), ``sigma_z`` (scalar or
        H×W), ``mask`` (H×W bool, True where the photograph is to be used, at the file's
        resolution), ``distortion`` (a :class:`vibr.io.undistort.Distortion` of the file's camera:
        ``camera`` is then its pinhole, and the image and maps are undistorted onto it
        before the scale).
    scale : float
        Resize factor applied after reading: images by :func:`resize_image`, cameras by
        :meth:`Camera.scaled`, depth and sigma_z maps by :func:`resize_depth`.
    check_size : bool
        An image whose size differs from its camera's raises :class:`VibrInputError`.
    """
    from concurrent.futures import ThreadPoolExecutor


    if scale <= 0 or not np.isfinite(scale):
        raise VibrInputError(f"scale must be positive, got {scale}")
    headers = _HEADERS_ONLY.get()
    if not headers:

        # float32 RGB + decoding, at the requested scale: checked from the sizes the files
        # declare (their cameras, compared with each header below) before any image is read
        npx = sum(e["camera"].width * e["camera"].height for e in entries) * max(1.0, scale * scale)
        at = f" at scale {scale:g}" if scale != 1.0 else ""
        check_memory(16.0 * npx, f"loading {len(entries)} images{at} ({npx / 1e6:.0f} Mpixels)",
                     "load fewer views (--only), a smaller --scale, or resize the images first",
                     entries[0]["path"] if entries else None)

    def work(e):
        cam, dist = e["camera"], e.get("distortion")
        fw, fh = (dist.width, dist.height) if dist is not None else (cam.width, cam.height)
        w, h = image_size(e["path"])  # the header, before decoding
        if headers:
            img, size = None, (h, w)
        else:
            if check_size and (w, h) != (fw, fh):  # no decoding of a lying image
                raise VibrInputError(f"image is {w}x{h} but its camera says {fw}x{fh}", e["path"])
            img = read_image(e["path"])
            size = img.shape[:2]
        if size != (fh, fw):
            if check_size:
                raise VibrInputError(f"image is {size[1]}x{size[0]} but its camera says {fw}x{fh}", e["path"])
        depth, sz, mask = e.get("depth"), e.get("sigma_z"), e.get("mask")
        if dist is not None:
            img, depth, sz, mask, size = _undistorted(img, depth, sz, mask, dist, cam)
        if scale != 1.0:
            cam = cam.scaled(scale)
        _check_side(size, cam, scale, e["path"])
        if scale != 1.0:
            img = None if img is None else resize_image(img, cam.shape)
            if depth is not None:
                depth = resize_depth(depth, cam.shape)
            if sz is not None and np.ndim(sz) == 2:
                sz = resize_depth(np.asarray(sz, dtype=np.float32), cam.shape)
            mask = None if mask is None else resize_mask(mask, cam.shape)
        return View(e["name"], img, cam, depth=depth, sigma_z=sz, path=os.fspath(e["path"]), mask=mask)

    n = len(entries)
    workers = min(8, max(1, n), (os.cpu_count() or 2) * 2)
    with ThreadPoolExecutor(max_workers=workers) as ex:
        views = list(progress(ex.map(work, entries), desc=desc, total=n, unit="img"))
    return views


def _undistorted(img, depth, sz, mask, dist, cam):
    """A distorted view's arrays resampled onto its pinhole ``cam`` (:mod:`vibr.io.undistort`)."""

    img = None if img is None else undistort_array(img, dist)
    depth = None if depth is None else undistort_array(depth, dist, nearest=True)
    if sz is not None and np.ndim(sz) == 2:
        sz = undistort_array(np.asarray(sz, np.float32), dist, nearest=True)
    if mask is not None:
        mask = undistort_array(np.asarray(mask, np.float32), dist, nearest=True) > 0.5
    return img, depth, sz, mask, cam.shape


def _check_side(size, cam, scale, path) -> None:
    """A view smaller than :data:`MIN_SIDE` pixels a side (after ``scale``) is refused at
    load, before any work (it would fail later, deep in the depth estimate or the metrics)."""
    if min(cam.width, cam.height) >= MIN_SIDE:
        return
    at = f" at scale {scale:g}" if scale != 1.0 else ""
    raise VibrInputError(
        f"image of {size[1]}x{size[0]} is {cam.width}x{cam.height}{at}: vibr needs at least "
        f"{MIN_SIDE} pixels a side" + (" (use a larger --scale)" if scale < 1.0 else ""), path)


@contextlib.contextmanager
def headers_only():
    """Within this block, scenes load without their pixels: :func:`build_views` (every
    loader's image reader) reads each image's size from its header and leaves
    ``View.image`` None; cameras, depth and metadata load as usual (``vibr info``)."""
    token = _HEADERS_ONLY.set(True)
    try:
        yield
    finally:
        _HEADERS_ONLY.reset(token)


