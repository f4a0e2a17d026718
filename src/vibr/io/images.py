"""Reading and writing images.

In memory an image is an H×W×3 float32 array in [0, 1] (see :mod:`vibr.camera`). Files are
read with imageio; 8-bit files map to ``q / 255`` and 16-bit files to ``q / 65535`` computed
in float32, always through :func:`from_uint`, so that an image written by :func:`write_image`
and read back is bit-for-bit the array that was written whenever it lies on that 8- or
16-bit grid (:func:`quantise16` puts resized images on the 16-bit grid).
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import VibrInputError, require_file
from .atomic import atomic_path

#: Image file extensions recognised when scanning folders.
IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".ppm", ".pgm")


def is_image_file(name) -> bool:
    return os.path.splitext(os.fspath(name))[1].lower() in IMAGE_EXTS


def from_uint(q: np.ndarray) -> np.ndarray:
    """Integer pixels → float32 in [0, 1]: ``q / (2^bits − 1)`` evaluated in float32."""
    q = np.asarray(q)
    full = np.float32(255.0 if q.dtype == np.uint8 else 65535.0)
    return q.astype(np.float32) / full


def quantise16(img: np.ndarray) -> np.ndarray:
    """Round a float image in [0, 1] to the 16-bit grid (step 1/65535 ≈ 1.5e-5).

    Resized images are put on this grid so that saving them as 16-bit PNG and loading them
    again is lossless (the rounding error is far below 8-bit photographic noise)."""
    q = np.round(np.clip(img, 0.0, 1.0) * np.float32(65535.0)).astype(np.uint16)
    return from_uint(q)


def read_image(path) -> np.ndarray:
    """Read an image file as an H×W×3 float32 array in [0, 1].

    Grey images are repeated over three channels, an alpha channel is dropped; 8-bit,
    16-bit and float files are accepted. Unreadable files raise
    :class:`~vibr.errors.VibrInputError` naming the file.
    """
    import imageio.v3 as iio

    p = require_file(path)
    try:
        a = iio.imread(p)
    except Exception as exc:  # imageio raises many types for corrupt files
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise VibrInputError(f"cannot read image ({msg})", p) from None
    a = np.asarray(a)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] not in (3, 4) or a.shape[0] == 0 or a.shape[1] == 0:
        raise VibrInputError(f"not an RGB image (array shape {a.shape})", p)
    a = a[..., :3]
    if a.dtype in (np.uint8, np.uint16):
        return np.ascontiguousarray(from_uint(a))
    if np.issubdtype(a.dtype, np.floating):
        a = a.astype(np.float32)
        if not np.all(np.isfinite(a)):
            raise VibrInputError("image has non-finite pixel values", p)
        return np.ascontiguousarray(np.clip(a, 0.0, 1.0))
    if np.issubdtype(a.dtype, np.integer):
        return np.ascontiguousarray(a.astype(np.float32) / np.float32(np.iinfo(a.dtype).max))
    raise VibrInputError(f"unsupported pixel type {a.dtype}", p)


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


def write_image(path, img: np.ndarray, bits: int | None = None) -> None:
    """Write an H×W×3 (or H×W) float image in [0, 1] atomically.

    PNG files are 8-bit when the image is exactly representable in 8 bits, else 16-bit
    (``bits`` forces one); JPEG is always 8-bit.
    """
    import imageio.v3 as iio

    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext in (".jpg", ".jpeg", ".bmp"):
        bits = 8
    q = to_uint(img, bits)
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, q, extension=ext or ".png")


# ----------------------------------------------------------------------------- resizing
def resize_image(img: np.ndarray, shape) -> np.ndarray:
    """Resize an H×W×3 image to ``shape = (h, w)`` (bilinear with Gaussian anti-aliasing,
    skimage.transform.resize), result on the 16-bit grid (:func:`quantise16`)."""
    from skimage.transform import resize

    shape = tuple(int(s) for s in shape)
    if img.shape[:2] == shape:
        return img
    out = resize(img, shape + img.shape[2:], order=1, anti_aliasing=shape[0] < img.shape[0],
                 preserve_range=True, mode="edge")
    return quantise16(out.astype(np.float32))


def resize_depth(depth: np.ndarray, shape) -> np.ndarray:
    """Nearest-neighbour resize of an H×W map to ``shape = (h, w)``.

    New pixel ``i`` takes old pixel ``floor((i + ½) H / h)``, the one containing its centre,
    so depth values are never mixed across depth edges (and NaN holes stay NaN)."""
    h, w = (int(s) for s in shape)
    H, W = depth.shape[:2]
    if (H, W) == (h, w):
        return depth
    ri = np.minimum(((np.arange(h) + 0.5) * H / h).astype(np.intp), H - 1)
    ci = np.minimum(((np.arange(w) + 0.5) * W / w).astype(np.intp), W - 1)
    return np.ascontiguousarray(depth[ri[:, None], ci[None, :]])


# ----------------------------------------------------------------------------- view building
def build_views(entries, scale: float = 1.0, desc: str = "reading images", check_size: bool = True):
    """Read the images of ``entries`` in a thread pool and build scaled :class:`View` s.

    Parameters
    ----------
    entries : list of dict
        Keys ``name``, ``path`` (image file), ``camera`` (at the file's resolution), optional
        ``depth`` (H×W float32, NaN unknown, at the file's resolution), ``sigma_z`` (scalar or
        H×W).
    scale : float
        Resize factor applied after reading: images by :func:`resize_image`, cameras by
        :meth:`Camera.scaled`, depth and sigma_z maps by :func:`resize_depth`.
    check_size : bool
        An image whose size differs from its camera's raises :class:`VibrInputError`.
    """
    from concurrent.futures import ThreadPoolExecutor

    from ..progress import progress
    from ..scene import View

    if scale <= 0 or not np.isfinite(scale):
        raise VibrInputError(f"scale must be positive, got {scale}")

    def work(e):
        img = read_image(e["path"])
        cam = e["camera"]
        if img.shape[:2] != cam.shape:
            if check_size:
                raise VibrInputError(
                    f"image is {img.shape[1]}x{img.shape[0]} but its camera says {cam.width}x{cam.height}",
                    e["path"])
        depth, sz = e.get("depth"), e.get("sigma_z")
        if scale != 1.0:
            cam = cam.scaled(scale)
            img = resize_image(img, cam.shape)
            if depth is not None:
                depth = resize_depth(depth, cam.shape)
            if sz is not None and np.ndim(sz) == 2:
                sz = resize_depth(np.asarray(sz, dtype=np.float32), cam.shape)
        return View(e["name"], img, cam, depth=depth, sigma_z=sz, path=os.fspath(e["path"]))

    n = len(entries)
    workers = min(8, max(1, n), (os.cpu_count() or 2) * 2)
    with ThreadPoolExecutor(max_workers=workers) as ex:
        views = list(progress(ex.map(work, entries), desc=desc, total=n, unit="img"))
    return views
