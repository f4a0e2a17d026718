"""What the viewer draws besides the rendered view: points, frustum sizes, thumbnails, up.

Pure array code (no viser): the app (:mod:`vibr.viewer.app`) sends the results.
"""

from __future__ import annotations

import numpy as np

from ..camera import shared_centre
from ..errors import VibrInputError
from ..paths.camera_path import scene_up
from ..scene import Scene

__all__ = ["point_cloud", "scene_scale", "frustum_size", "world_up", "thumbnail", "points_in_view",
           "display_origin"]


def point_cloud(scene: Scene, max_points: int = 300_000, seed: int = 0,
                origin=None) -> tuple[np.ndarray, np.ndarray]:
    """World points and their colours from the views' depth maps, at most ``max_points``.

    Every view contributes pixels on a regular grid of stride
    ``s = ceil(sqrt(N_pixels / max_points))`` (all views together), back-projected with their
    depth (``X = C + depth · Rᵀ K⁻¹ x̄``, :meth:`vibr.camera.Camera.backproject`); a random
    subset of ``max_points`` is kept when the grid gives more. Views without depth add
    nothing, nor do the pixels of a view's fallback proxy (:attr:`vibr.scene.View.fallback`);
    when no view has depth the scene's sparse points (grey) are used. With ``origin``
    (:func:`display_origin`) the points are relative to it, subtracted before the cast.

    Returns
    -------
    points : (N, 3) float32
    colours : (N, 3) uint8
    """
    o = np.zeros(3) if origin is None else np.asarray(origin, np.float64)
    views = [v for v in scene.views if v.depth is not None]
    if not views:
        if scene.points is not None and len(scene.points):
            P = (np.asarray(scene.points, dtype=np.float64) - o).astype(np.float32)
            P = _subsample(P, max_points, seed)
            return P, np.full(P.shape, 160, np.uint8)
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8)
    n_pix = sum(v.shape[0] * v.shape[1] for v in views)
    step = max(1, int(np.ceil(np.sqrt(n_pix / max(1, max_points)))))
    pts, cols = [], []
    for v in views:
        h, w = v.shape
        z = v.depth[::step, ::step]
        yy, xx = np.mgrid[0:h:step, 0:w:step]
        ok = np.isfinite(z) & (z > 0)
        if v.fallback is not None:  # the fallback proxy's plane is not a surface of the scene
            ok &= ~v.fallback[::step, ::step]
        if v.mask is not None:
            ok &= v.mask[::step, ::step]
        if not np.any(ok):
            continue
        xy = np.stack([xx[ok], yy[ok]], -1).astype(np.float64)
        pts.append((v.camera.backproject(xy, z[ok]) - o).astype(np.float32))
        cols.append(np.clip(v.image[::step, ::step][ok] * 255 + 0.5, 0, 255).astype(np.uint8))
    if not pts:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8)
    P, C = np.concatenate(pts), np.concatenate(cols)
    if len(P) > max_points:
        keep = np.random.default_rng(seed).choice(len(P), max_points, replace=False)
        P, C = P[keep], C[keep]
    return P, C


def _subsample(P: np.ndarray, n: int, seed: int) -> np.ndarray:
    if len(P) <= n:
        return P
    return P[np.random.default_rng(seed).choice(len(P), n, replace=False)]


def scene_scale(scene: Scene, points: np.ndarray | None = None) -> float:
    """A length for drawing (frustum size, point size): the median distance from the cameras
    to the points when there are points, else the median distance between camera centres,
    else 1."""
    C = np.array([v.camera.centre for v in scene.views])
    if points is not None and len(points):
        sample = _subsample(np.asarray(points, np.float64), 2000, 0)
        d = np.linalg.norm(sample[None, :, :] - C[:, None, :], axis=2)
        s = float(np.median(d))
        if s > 0:
            return s
    if len(C) > 1:
        d = np.linalg.norm(C[:, None] - C[None], axis=2)[np.triu_indices(len(C), 1)]
        s = float(np.median(d))
        if s > 0 and shared_centre([v.camera for v in scene.views]) is None:
            return s
    return 1.0


def display_origin(scene: Scene, max_ratio: float = 100.0) -> np.ndarray:
    """The world point the viewer sends positions relative to: the cameras' mean centre when
    it lies more than ``max_ratio`` scene scales (:func:`scene_scale`) from the world origin,
    else the origin itself.

    The browser draws in float32 (7 significant digits): a scene in georeferenced
    coordinates, 5·10⁵ units from the origin, would have its points and frustums rounded to
    0.03 units and shaking by as much as the camera moves. Relative to its own centre it is
    drawn as precisely as any other; the viewer adds the origin back to the browser's
    camera before rendering (:class:`vibr.viewer.Viewer`)."""
    C = np.array([v.camera.centre for v in scene.views], np.float64)
    m = C.mean(axis=0)
    return m if float(np.linalg.norm(m)) > max_ratio * scene_scale(scene) else np.zeros(3)


def frustum_size(scene: Scene, scale: float) -> float:
    """Depth (scene units) at which to draw the input cameras' frustums: 6 % of the scene
    ``scale``, at most half the median distance from a camera to its nearest neighbour (so
    that neighbouring frustums do not overlap: a light-field grid has a small baseline)."""
    C = np.array([v.camera.centre for v in scene.views])
    size = 0.06 * scale
    if len(C) > 1:
        d = np.linalg.norm(C[:, None] - C[None], axis=2)
        np.fill_diagonal(d, np.inf)
        nn = float(np.median(d.min(axis=1)))
        if nn > 0 and shared_centre([v.camera for v in scene.views]) is None:  # not a rotation-only capture
            size = min(size, 0.5 * nn)
    return size


def world_up(scene: Scene) -> np.ndarray:
    """World "up" as camera paths take it (:func:`vibr.paths.camera_path.scene_up`: the mean of the
    cameras' image-up directions, or the normal of a ring of cameras, which stays right when
    the photographs are rolled); ``(0, -1, 0)`` when the cameras have none."""

    try:
        return scene_up([v.camera for v in scene.views])
    except VibrInputError:
        return np.array([0.0, -1.0, 0.0])


def thumbnail(image: np.ndarray, long_side: int = 160) -> np.ndarray:
    """uint8 copy of an H×W×3 [0, 1] image whose longer side is at most ``long_side``
    (area-averaged by an integer factor, then strided)."""
    h, w = image.shape[:2]
    f = max(1, int(np.ceil(max(h, w) / long_side)))
    hh, ww = (h // f) * f, (w // f) * f
    small = image[:hh, :ww].reshape(hh // f, f, ww // f, f, 3).mean(axis=(1, 3))
    return np.clip(small * 255 + 0.5, 0, 255).astype(np.uint8)


def points_in_view(points: np.ndarray, camera) -> np.ndarray:
    """The rows of ``points`` (N, 3) in front of ``camera`` and inside its image."""
    if len(points) == 0:
        return points
    return points[camera.sees(points)[2]]
