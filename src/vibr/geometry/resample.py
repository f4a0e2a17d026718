"""The one image resampling of vibr: images, masks, depth maps, views and scenes resized.

Reduction averages boxes of source pixels (no aliasing); enlargement is a cubic B-spline;
depth, sigma_z and masks are resized by nearest neighbour (a depth edge must not be
blurred into depths that exist nowhere). Loaders (``vibr.io``), the renderer (sources
finer than the target) and depth estimation (at a fraction of the images' size) all use
these functions, so an image is resized the same way wherever it is.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..camera import Camera


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



# ----------------------------------------------------------------------------- resizing
@njit(parallel=True, cache=True)
def _block_mean(img, k):  # pragma: no cover - compiled
    """Mean over k×k blocks of an H×W×C float32 image (H, W multiples of k): a box filter
    whose output pixel centres map as x' = (x + ½)/k − ½."""
    H, W, C = img.shape
    h, w = H // k, W // k
    out = np.empty((h, w, C), np.float32)
    inv = 1.0 / (k * k)
    for i in prange(h):
        for j in range(w):
            for c in range(C):
                acc = 0.0
                for a in range(k):
                    for b in range(k):
                        acc += img[i * k + a, j * k + b, c]
                out[i, j, c] = acc * inv
    return out


def resize_image(img: np.ndarray, shape, *, box: bool = True, mode: str = "edge",
                 quantise: bool = True, order: int = 1) -> np.ndarray:
    """Resize an H×W(×C) image to ``shape = (h, w)`` with anti-aliasing (the one image
    resize of vibr: scene loading and depth estimation).

    With ``box``, large reductions first average k×k blocks (k the largest of 16, 8, 4, 2
    with ``k ≤ 1/s`` that divides H and W: a box filter, fast); skimage.transform.resize
    (spline ``order``: 1 bilinear, 3 bicubic; Gaussian anti-aliasing when shrinking, border
    ``mode``) does the rest. Both map pixel centres as ``x' = s (x + ½) − ½``, the mapping of
    :meth:`Camera.scaled`. With ``quantise`` the result is on the 16-bit grid
    (:func:`quantise16`), as a loaded image is; float32 in any case.
    """
    from skimage.transform import resize

    shape = tuple(int(v) for v in shape)
    H, W = img.shape[:2]
    if (H, W) == shape:
        return img
    if order == 3 and shape[0] >= H and shape[1] >= W:
        img = _spline_enlarge(img, shape)
        return quantise16(img) if quantise else img
    inv = min(H / shape[0], W / shape[1])
    for k in (16, 8, 4, 2) if box else ():
        if k <= inv + 1e-9 and H % k == 0 and W % k == 0:
            grey = img.ndim == 2
            img = _block_mean(np.ascontiguousarray(img[..., None] if grey else img, dtype=np.float32), k)
            img = img[..., 0] if grey else img
            break
    if img.shape[:2] != shape:
        img = resize(img.astype(np.float32), shape + img.shape[2:], order=order,
                     anti_aliasing=shape[0] < img.shape[0] or shape[1] < img.shape[1],
                     preserve_range=True, mode=mode)
    img = np.asarray(img, dtype=np.float32)
    return quantise16(img) if quantise else img


def _centres(n_out: int, n_in: int):
    """Each output pixel's centre in input pixels, ``x = (i + ½) n_in / n_out − ½`` (the mapping
    of :func:`resize_image` and :meth:`Camera.scaled`): the input pixel at or before it and the
    fraction past that pixel."""
    x = (np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5
    i0 = np.floor(x).astype(np.intp)
    return i0, x - i0


def _neighbours(n_out: int, n_in: int):
    """The two input pixels on either side of each output pixel's centre (clamped)."""
    i0, _ = _centres(n_out, n_in)
    return np.clip(i0, 0, n_in - 1), np.clip(i0 + 1, 0, n_in - 1)


def _bspline_rows(n_out: int, n_in: int):
    """The cubic B-spline's weights of output samples at ``x = (i + ½) n_in / n_out − ½`` (the
    pixel-centre mapping of :func:`resize_image`) as an ``n_out × n_in`` sparse matrix, four
    coefficients a row, indices clamped at the border."""
    from scipy import sparse

    i0, t = _centres(n_out, n_in)
    w = np.stack([(1 - t) ** 3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3], axis=1) / 6.0
    cols = np.clip(i0[:, None] + np.arange(-1, 3)[None, :], 0, n_in - 1)
    return sparse.csr_matrix((w.ravel(), (np.repeat(np.arange(n_out), 4), cols.ravel())), shape=(n_out, n_in))


def _spline_enlarge(img: np.ndarray, shape) -> np.ndarray:
    """Cubic-spline interpolation of an H×W(×C) image onto a larger ``shape``, separable: the
    spline's coefficients (scipy's recursive prefilter along each axis, border "nearest"),
    then four of them per output sample and axis (sparse products; skimage's resize with
    ``order=3`` interpolates across the colour channels as well, 4³ taps a sample: timings in
    docs/explanation/renderer.md, "Sources coarser than the target")."""
    from scipy.ndimage import spline_filter1d

    (h, w), (H, W) = img.shape[:2], shape
    c = spline_filter1d(np.asarray(img, np.float64), 3, axis=0, mode="nearest")
    c = spline_filter1d(c, 3, axis=1, mode="nearest").reshape(h, w, -1)
    n = c.shape[2]
    t = (_bspline_rows(H, h) @ c.reshape(h, w * n)).reshape(H, w, n)
    t = _bspline_rows(W, w) @ t.transpose(1, 0, 2).reshape(w, H * n)
    return np.ascontiguousarray(t.reshape(W, H, n).transpose(1, 0, 2).reshape((H, W) + img.shape[2:]), np.float32)


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


def resize_mask(mask: np.ndarray, shape) -> np.ndarray:
    """A validity mask resized to ``shape``: a new pixel is valid only where every old
    pixel under it is (the area average of :func:`resize_image` at 1), so no masked-out
    colour leaks into a kept pixel."""
    m = np.asarray(mask, bool)
    shape = tuple(int(s) for s in shape)
    if m.shape == shape:
        return m
    if shape[0] >= m.shape[0] and shape[1] >= m.shape[1]:  # enlarged: the 2×2 pixels under each
        (y0, y1), (x0, x1) = (_neighbours(n, k) for n, k in zip(shape, m.shape))
        return m[y0][:, x0] & m[y0][:, x1] & m[y1][:, x0] & m[y1][:, x1]
    a = resize_image(np.repeat(m[..., None].astype(np.float32), 3, axis=2), shape)[..., 0]
    return a >= np.float32(1.0 - 1e-6)


def scaled_view(v, s: float):
    """One view resized by ``s`` as :func:`vibr.io.load_scene` does with ``scale``: the image
    by :func:`resize_image`, the camera by :meth:`vibr.camera.Camera.scaled`, depth, sigma_z
    and fallback maps by nearest neighbour (:func:`resize_depth`), the mask by
    :func:`resize_mask`. ``s = 1``: the view."""
    if s == 1.0:
        return v
    cam = v.camera.scaled(s)
    sz = v.sigma_z
    if sz is not None and np.ndim(sz) > 0:
        sz = resize_depth(np.asarray(sz, np.float32), cam.shape)
    fb = None if v.fallback is None else resize_depth(v.fallback, cam.shape)
    return v.replace(camera=cam, image=resize_image(v.image, cam.shape),
                     depth=None if v.depth is None else resize_depth(v.depth, cam.shape), sigma_z=sz,
                     fallback=fb, mask=None if v.mask is None else resize_mask(v.mask, cam.shape))


def scaled_scene(scene, s: float):
    """Every view of ``scene`` resized by ``s`` (:func:`scaled_view`). ``s = 1``: the scene."""
    if s == 1.0:
        return scene
    views = [scaled_view(v, s) for v in scene.views]
    meta = dict(scene.meta)
    if meta.get("missing_views"):  # a light field's absent positions (vibr.io.hci)
        meta["missing_views"] = {n: Camera.from_dict(d).scaled(s).to_dict() for n, d in meta["missing_views"].items()}
    return scene.replace(views=views, meta=meta)

