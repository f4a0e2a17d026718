"""What the viewer draws besides the rendered view (points, frustum sizes, thumbnails, up),
and how its camera moves (bounds, drag gains).

Pure array code (no viser): the app (:mod:`vibr.viewer.app`) sends the results.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import shared_centre
from ..errors import VibrInputError
from ..paths.camera_path import scene_up
from ..scene import Scene
from .convert import matrix_to_quat

__all__ = ["point_cloud", "scene_scale", "frustum_size", "world_up", "thumbnail", "points_in_view",
           "display_origin", "CameraBounds", "DragGains", "camera_bounds", "drag_gains", "clamp_to_bounds",
           "clamp_turn", "govern_move", "look_at_wxyz", "ROOM"]


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


# ------------------------------------------------------------------ camera governor
#: How far the viewer's camera may go from the cameras' mean centre, in multiples of the
#: capture's spread (:class:`CameraBounds`): the renders degrade quickly outside the captured
#: region (holes, then nothing), and a user cannot tell the scene from the method there.
ROOM = 1.5
#: The least spread, as a fraction of the scene depth, given to a capture whose cameras share
#: one centre (a panorama) or to a single view: a little sway is allowed, not more.
MIN_SPREAD = 0.01


@dataclass(frozen=True)
class CameraBounds:
    """Where the viewer's camera may go and at what scale it moves (display coordinates).

    centre : (3,) the input cameras' mean centre
    spread : the capture's extent, the largest distance of a camera centre from ``centre``
        (at least :data:`MIN_SPREAD` × ``depth``)
    depth : the scene's depth, the median distance from the cameras to the scene's points
        (:func:`scene_scale`)
    target : (3,) the scene's centre, the median of its points (else ``depth`` ahead of the
        cameras)
    max_turn : the camera's view may turn at most this far (radians) from ``target``: the
        input cameras' least half vertical field of view, so the scene's centre stays in
        the picture
    room : the camera is kept within ``room × spread`` of ``centre`` (:data:`ROOM`)
    """

    centre: np.ndarray
    spread: float
    depth: float
    target: np.ndarray
    max_turn: float
    room: float = ROOM

    @property
    def radius(self) -> float:
        return self.room * self.spread


@dataclass(frozen=True)
class DragGains:
    """Factors from the browser's own camera moves to the viewer's (:func:`drag_gains`).

    orbit : the view turns by ``orbit`` × the browser's orbit angle
    pivot : about a point ``pivot`` ahead of the camera (scene units)
    pan : the camera moves by ``pan`` × the browser's pan
    dolly : and by ``dolly`` × the change of the browser's distance to its look-at point
    """

    orbit: float
    pivot: float
    pan: float
    dolly: float


def camera_bounds(scene: Scene, points: np.ndarray | None = None, origin=None) -> CameraBounds:
    """The :class:`CameraBounds` of ``scene``: its cameras' mean centre and spread, its depth
    (:func:`scene_scale` of ``points``, world coordinates) and centre, with ``centre`` and
    ``target`` relative to ``origin`` (:func:`display_origin`)."""
    C = np.array([v.camera.centre for v in scene.views], np.float64)
    c = C.mean(axis=0)
    depth = scene_scale(scene, points)
    spread = float(np.max(np.linalg.norm(C - c, axis=1))) if len(C) > 1 else 0.0
    if shared_centre([v.camera for v in scene.views]) is not None:
        spread = 0.0
    spread = max(spread, MIN_SPREAD * depth)
    o = np.zeros(3) if origin is None else np.asarray(origin, np.float64)
    if points is not None and len(points):
        target = np.median(_subsample(np.asarray(points, np.float64), 20_000, 0), axis=0)
    else:
        axis = np.mean([v.camera.optical_axis for v in scene.views], axis=0)
        target = c + depth * axis / max(float(np.linalg.norm(axis)), 1e-12)
    max_turn = min(float(np.arctan2(0.5 * v.camera.height, v.camera.K[1, 1])) for v in scene.views)
    return CameraBounds(c - o, spread, depth, target - o, max_turn)


def drag_gains(bounds: CameraBounds, fov: float) -> DragGains:
    """The gains that make the browser's camera moves fit the scene (``fov``: vertical, radians).

    viser's orbit controls turn the camera by 2π per canvas height dragged, about a look-at
    point the viewer keeps at the scene's depth, whatever the scene: a drag of a few pixels
    carried the camera out of a small-baseline capture. Here

    * a drag of the canvas height moves the camera across the capture (2 × spread): it
      travels ``spread / π`` per radian of the browser's orbit;
    * the view turns so that the scene at ``depth`` moves as far as the cursor:
      ``orbit = tan(fov/2) / π + (spread / π) / depth``, about a point ``pivot`` ahead that
      gives that travel;
    * a pan of the canvas height (the browser: ``2 depth tan(fov/2)``) and a dolly from the
      look-at point to the camera (``depth``) move the camera across the capture too.

    Every gain is at most 1 (a wide capture keeps the browser's own moves).
    """
    t = float(np.tan(0.5 * fov))
    travel = bounds.spread / np.pi
    orbit = min(1.0, t / np.pi + travel / bounds.depth)
    return DragGains(orbit=orbit, pivot=travel / orbit, pan=min(1.0, bounds.spread / (bounds.depth * t)),
                     dolly=min(1.0, 2.0 * bounds.spread / bounds.depth))


def clamp_to_bounds(position, bounds: CameraBounds) -> tuple[np.ndarray, bool]:
    """``position`` moved back onto the ball of :attr:`CameraBounds.radius` about the centre
    when outside it; and whether it was."""
    p = np.asarray(position, np.float64)
    d = p - bounds.centre
    n = float(np.linalg.norm(d))
    if n <= bounds.radius:
        return p, False
    return bounds.centre + d * (bounds.radius / n), True


def clamp_turn(position, forward, bounds: CameraBounds) -> tuple[np.ndarray, bool]:
    """``forward`` turned back towards the scene's centre (:attr:`CameraBounds.target`) when
    it points more than :attr:`CameraBounds.max_turn` away from it, seen from ``position``;
    and whether it was."""
    f = np.asarray(forward, np.float64)
    to = bounds.target - np.asarray(position, np.float64)
    n = float(np.linalg.norm(to))
    if n == 0:
        return f, False
    to = to / n
    angle = float(np.arccos(np.clip(f @ to, -1.0, 1.0)))
    if angle <= bounds.max_turn:
        return f, False
    axis = np.cross(to, f)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:  # turned right round: any axis across the view
        axis = np.cross(to, np.eye(3)[int(np.argmin(np.abs(to)))])
        s = float(np.linalg.norm(axis))
    return _rotate(to, axis / s, bounds.max_turn), True


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation of ``v`` by ``angle`` about the unit ``axis``."""
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * float(axis @ v) * (1.0 - c)


def govern_move(raw_before, raw_after, position, forward, gains: DragGains,
                bounds: CameraBounds) -> tuple[np.ndarray, np.ndarray, bool]:
    """The viewer's camera after one move of the browser's camera, scaled by ``gains``.

    ``raw_before`` and ``raw_after`` are the browser's (position, look-at) before and after
    the move; ``position`` and unit ``forward`` the viewer's camera before it. The browser's
    move splits as its orbit controls make it: a pan (the look-at point moves, the camera
    with it), an orbit (the camera turns about the look-at point) and a dolly (its distance
    to it changes). Returns the new position (kept in ``bounds``, :func:`clamp_to_bounds`),
    the new forward direction (kept towards the scene, :func:`clamp_turn`), and whether
    either was held back.
    """
    P0, L0 = (np.asarray(x, np.float64) for x in raw_before)
    P1, L1 = (np.asarray(x, np.float64) for x in raw_after)
    p = np.asarray(position, np.float64)
    f = np.asarray(forward, np.float64)
    v0, v1 = P0 - L0, P1 - L1
    n0, n1 = float(np.linalg.norm(v0)), float(np.linalg.norm(v1))
    if n0 > 0 and n1 > 0:
        u0, u1 = v0 / n0, v1 / n1
        axis = np.cross(u0, u1)
        s = float(np.linalg.norm(axis))
        if s > 1e-12:
            angle = gains.orbit * float(np.arctan2(s, u0 @ u1))
            axis = axis / s
            pivot = p + gains.pivot * f
            p = pivot + _rotate(p - pivot, axis, angle)
            f = _rotate(f, axis, angle)
            f = f / np.linalg.norm(f)
    p = p + gains.pan * (L1 - L0) + gains.dolly * (n0 - n1) * f
    p, clamped = clamp_to_bounds(p, bounds)
    f, turned = clamp_turn(p, f, bounds)
    return p, f / np.linalg.norm(f), clamped or turned


def look_at_wxyz(position, look_at, up) -> np.ndarray:
    """The camera-to-world rotation (w, x, y, z) of a camera at ``position`` looking at
    ``look_at`` with no roll about the world ``up``, in OpenCV axes (x right, y down, z
    forward), as viser's orbit controls pose it."""
    z = np.asarray(look_at, np.float64) - np.asarray(position, np.float64)
    z = z / np.linalg.norm(z)
    u = np.asarray(up, np.float64)
    y = -(u - (u @ z) * z)
    n = float(np.linalg.norm(y))
    if n < 1e-9:  # looking straight along up: any roll
        a = np.zeros(3)
        a[np.argmin(np.abs(z))] = 1.0
        y = a - (a @ z) * z
        n = float(np.linalg.norm(y))
    y = y / n
    x = np.cross(y, z)
    return matrix_to_quat(np.stack([x, y, z], axis=1))
