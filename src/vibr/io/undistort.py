"""Distorted cameras made pinhole at load (COLMAP's camera models, through pycolmap).

vibr's renderer and depth estimate assume pinhole cameras. A COLMAP model straight from the
mapper (``SIMPLE_RADIAL``, ``OPENCV``, fisheye models) and a transforms.json from
``ns-process-data`` (``OPENCV`` with ``k1, k2, p1, p2``, or ``OPENCV_FISHEYE``) describe
distorted photographs; they are undistorted as they are read, as ``colmap
image_undistorter`` would:

1. the pinhole camera is COLMAP's (``pycolmap.undistort_camera`` with its defaults: the
   same focal lengths, the size and principal point chosen so that every output pixel lies
   inside the photograph, so no blank border; a fisheye keeps the central part of its
   field of view);
2. each output pixel ``p`` is looked up in the photograph at
   ``camera.img_from_cam(pinhole.cam_from_img(p))`` (COLMAP's own distortion maths), bilinearly
   for images (:func:`_remap`, compiled; ``scipy.ndimage.map_coordinates`` to float32
   rounding), at the nearest pixel for depth and
   sigma_z maps and masks. The camera's pose is unchanged and orthogonal depth is the same
   in both cameras (the same camera frame), so depth values need no conversion.

A model that folds the image over itself inside the photograph (outside its valid range), or
for which no pinhole fits inside the photograph, is refused; one that keeps under a quarter
of it is warned about (:func:`check_lens`).

nerfstudio's ``OPENCV`` radial polynomial ``1 + k1 r² + k2 r⁴ + k3 r⁶ + k4 r⁸`` is COLMAP's
``OPENCV`` when ``k3 = k4 = 0`` and its ``FULL_OPENCV`` (numerator only) when ``k4 = 0``; a
non-zero ``k4`` has no COLMAP model and is refused, as are tangential terms with a fisheye.
Both tools put the centre of the top-left pixel at (0.5, 0.5); the pinhole's principal point
becomes vibr's by subtracting 0.5 (:mod:`vibr.io.colmap`).
"""

from __future__ import annotations

import functools
import logging
import threading
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from .._runtime.pycolmap import import_pycolmap
from ..errors import VibrInputError

logger = logging.getLogger(__name__)

#: nerfstudio camera_model → the COLMAP model of the same formula (the fisheye's θ-polynomial
#: ``θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`` is COLMAP's OPENCV_FISHEYE).
NERFSTUDIO_FISHEYE = ("OPENCV_FISHEYE", "FISHEYE")


@dataclass(frozen=True)
class Distortion:
    """A distorted camera's intrinsics: a COLMAP model name, its parameters (COLMAP's order
    and pixel convention) and the photograph's size in pixels."""

    model: str
    params: tuple
    width: int
    height: int

    def colmap_camera(self):
        pycolmap = import_pycolmap()
        cam = pycolmap.Camera.create_from_model_name(1, self.model, 1.0, self.width, self.height)
        cam.params = list(self.params)
        return cam



def summary(entries) -> str | None:
    """One line on the loader entries' distorted cameras (``scene.meta["undistorted"]``,
    shown by ``vibr info``), or None when there are none."""
    dists = [e["distortion"] for e in entries if e.get("distortion") is not None]
    if not dists:
        return None
    kinds = {}
    for d in dists:
        K, w, h = pinhole(d)
        key = f"{d.model} {d.width}x{d.height} -> pinhole {w}x{h}"
        kinds[key] = kinds.get(key, 0) + 1
    return f"{len(dists)} of {len(entries)} views undistorted at load (" + "; ".join(
        f"{n}: {k}" if len(kinds) > 1 else k for k, n in kinds.items()) + ")"


def from_nerfstudio(model: str, fx: float, fy: float, cx: float, cy: float, k: dict, width: int,
                    height: int, src: str) -> Distortion | None:
    """The :class:`Distortion` of a transforms.json frame (``k``: its k1..k4, p1, p2, absent
    ones 0), or None when it is a plain pinhole. ``cx, cy`` as written (pixel-centre 0.5)."""
    k = {n: float(k.get(n, 0.0) or 0.0) for n in ("k1", "k2", "k3", "k4", "p1", "p2")}
    if model in NERFSTUDIO_FISHEYE:
        if k["p1"] or k["p2"]:
            raise VibrInputError(f"{model} with tangential distortion (p1 {k['p1']}, p2 {k['p2']}) has no "
                                 "COLMAP model: undistort the images first", src)
        return Distortion("OPENCV_FISHEYE", (fx, fy, cx, cy, k["k1"], k["k2"], k["k3"], k["k4"]), width, height)
    if not any(k.values()):
        return None
    if k["k4"]:
        raise VibrInputError(f"radial term k4 = {k['k4']} (r^8) has no COLMAP camera model: undistort the "
                             "images first", src)
    if k["k3"]:
        return Distortion("FULL_OPENCV", (fx, fy, cx, cy, k["k1"], k["k2"], k["p1"], k["p2"], k["k3"], 0.0, 0.0, 0.0),
                          width, height)
    return Distortion("OPENCV", (fx, fy, cx, cy, k["k1"], k["k2"], k["p1"], k["p2"]), width, height)


@functools.lru_cache(maxsize=16)
def _undistorted_camera(dist: Distortion):
    pycolmap = import_pycolmap()
    return pycolmap.undistort_camera(pycolmap.UndistortCameraOptions(), dist.colmap_camera())


def pinhole(dist: Distortion) -> tuple[np.ndarray, int, int]:
    """vibr's K (top-left pixel centre at 0) and the size of the undistorted camera."""
    u = _undistorted_camera(dist)
    fx, fy = float(u.focal_length_x), float(u.focal_length_y)
    cx, cy = float(u.principal_point_x) - 0.5, float(u.principal_point_y) - 0.5
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]), int(u.width), int(u.height)


#: ``vibr`` warns when the undistorted pinhole keeps less than this fraction of the photograph.
SMALL_COVERAGE = 0.25
_WARNED: set = set()


@functools.lru_cache(maxsize=64)
def _lens_report(dist: Distortion) -> tuple[str | None, float]:
    """(problem, coverage), checked on a 65 × 65 grid of the pinhole: the problem, or None,
    of a model whose map from pinhole pixels to the photograph leaves the photograph (COLMAP
    found no pinhole inside it: its size clamped) or is not monotone along rows and columns
    (the model folds the image over itself: outside its valid range, a typing error in k1);
    and what the pinhole keeps: the smaller of the fraction of the photograph's extent it
    sees and of its pixel count."""
    _, w, h = pinhole(dist)
    gx, gy = np.meshgrid(np.linspace(0, w - 1, 65), np.linspace(0, h - 1, 65))
    src = source_coords(dist, np.stack([gx.ravel(), gy.ravel()], axis=1)).reshape(65, 65, 2)
    x, y = src[..., 0], src[..., 1]
    outside = "maps the pinhole's pixels outside the photograph (no pinhole fits inside it)"
    if not np.all(np.isfinite(src)):
        return outside, 0.0
    if np.any(np.diff(x, axis=1) <= 0) or np.any(np.diff(y, axis=0) <= 0):
        return "folds the image over itself inside the photograph (outside the model's valid range)", 0.0
    if not (x.min() > -1 and y.min() > -1 and x.max() < dist.width and y.max() < dist.height):
        return outside, 0.0
    span = np.ptp(x) * np.ptp(y) / (dist.width * dist.height)
    return None, float(min(span, w * h / (dist.width * dist.height)))


def check_lens(dist: Distortion, src: str) -> Distortion:
    """Refuse a model that folds the image, or that no pinhole fits inside; warn (once per
    camera) when the pinhole keeps little of the photograph."""
    problem, coverage = _lens_report(dist)
    if problem:
        raise VibrInputError(f"lens model {dist.model} {list(dist.params[4:])} {problem}: check the "
                             "distortion parameters", src)
    if coverage < SMALL_COVERAGE and dist not in _WARNED:
        _WARNED.add(dist)
        _, w, h = pinhole(dist)
        logger.warning(f"{src}: undistorted, the {dist.width}x{dist.height} photograph becomes a {w}x{h} "
                       f"pinhole that keeps {100 * coverage:.0f} % of its extent or pixels: check the "
                       f"distortion parameters {list(dist.params[4:])}")
    return dist


def source_coords(dist: Distortion, xy: np.ndarray) -> np.ndarray:
    """(N, 2) pixels of the undistorted (pinhole) camera, vibr's convention → (N, 2) (x, y)
    of the same rays in the photograph, in array coordinates (top-left pixel centre 0)."""
    rays = _undistorted_camera(dist).cam_from_img(np.asarray(xy, np.float64).reshape(-1, 2) + 0.5)
    src = dist.colmap_camera().img_from_cam(np.concatenate([rays, np.ones((len(rays), 1))], axis=1))
    return src - 0.5


_LOOKUP_LOCK = threading.Lock()  # the loader's threads share one map per camera


def _lookup(dist: Distortion) -> np.ndarray:
    with _LOOKUP_LOCK:
        return _lookup_cached(dist)


@functools.lru_cache(maxsize=4)
def _lookup_cached(dist: Distortion) -> np.ndarray:
    """(2, H, W) float32: the photograph's (row, column) for each undistorted pixel, made
    in bands of rows (pycolmap's float64 arrays of a whole 12-Mpixel photo took 1 GB)."""
    _, w, h = pinhole(dist)
    out = np.empty((2, h, w), np.float32)
    xx = np.arange(w, dtype=np.float64)
    for y0 in range(0, h, 256):
        y1 = min(h, y0 + 256)
        yy, xs = np.meshgrid(np.arange(y0, y1, dtype=np.float64), xx, indexing="ij")
        src = source_coords(dist, np.stack([xs.ravel(), yy.ravel()], axis=1))
        out[:, y0:y1] = src[:, ::-1].T.reshape(2, y1 - y0, w)
    return out


def undistort_array(a: np.ndarray, dist: Distortion, *, nearest: bool = False) -> np.ndarray:
    """An H×W or H×W×C float array of the photograph resampled onto the pinhole camera
    (float32): bilinear, or the nearest pixel (``nearest``, for depth: no depth across an
    edge); positions beyond the border take the border's values (``scipy.ndimage``'s
    ``map_coordinates(..., mode="nearest")``, which the tests compare it with)."""
    coords = _lookup(dist)
    a = np.ascontiguousarray(a, dtype=np.float32)
    out = _remap(a.reshape(a.shape[0], a.shape[1], -1), coords[0], coords[1], bool(nearest))
    return out.reshape(coords.shape[1:] + a.shape[2:])


@njit(parallel=True, cache=True)
def _remap(a, ys, xs, nearest):  # pragma: no cover - compiled
    """``out[i, j] = a(ys[i, j], xs[i, j])``, bilinear or nearest, coordinates clamped to
    the array; the weights in float64. A compiled loop: ``map_coordinates`` holds the GIL
    and took 0.8 s a 12-Mpixel photograph."""
    H, W, C = a.shape
    h, w = ys.shape
    out = np.empty((h, w, C), np.float32)
    for i in prange(h):
        for j in range(w):
            y = min(max(np.float64(ys[i, j]), 0.0), H - 1.0)
            x = min(max(np.float64(xs[i, j]), 0.0), W - 1.0)
            if nearest:
                yi = min(int(np.floor(y + 0.5)), H - 1)
                xi = min(int(np.floor(x + 0.5)), W - 1)
                for c in range(C):
                    out[i, j, c] = a[yi, xi, c]
                continue
            y0 = int(np.floor(y))
            x0 = int(np.floor(x))
            y1 = min(y0 + 1, H - 1)
            x1 = min(x0 + 1, W - 1)
            fy = y - y0
            fx = x - x0
            for c in range(C):
                top = (1.0 - fx) * a[y0, x0, c] + fx * a[y0, x1, c]
                bot = (1.0 - fx) * a[y1, x0, c] + fx * a[y1, x1, c]
                out[i, j, c] = (1.0 - fy) * top + fy * bot
    return out
