"""Camera paths: nerfstudio's ``camera_path.json`` in and out, and path generators.

A fly-through is a list of cameras rendered one after another into a video. vibr reads and
writes paths in the schema of nerfstudio (``nerfstudio/cameras/camera_paths.py``,
``get_path_from_json``; written by the viewer's render panel), so that a path drawn in
nerfstudio's viewer renders in vibr and a vibr path renders in ``ns-render camera-path``
(both through the model's ``dataparser_transforms.json``: nerfstudio works in a normalised
frame, :func:`read_camera_path` and :func:`write_camera_path` map to and from it)::

    {"camera_type": "perspective", "render_width": W, "render_height": H,
     "seconds": S, "fps": F,
     "camera_path": [{"camera_to_world": [16 numbers, 4x4 row-major],
                      "fov": vertical field of view in degrees, "aspect": W / H,
                      "fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy}, ...]}

``camera_to_world`` uses **OpenGL camera axes** (x right, y up, looking down −z), vibr uses
OpenCV axes (x right, y down, looking down +z): the flip ``diag(1, −1, −1)`` of the camera
axes lives in :func:`camera_from_c2w_opengl` / :func:`c2w_opengl_from_camera` and nowhere
else. The focal length is nerfstudio's ``f = (H / 2) / tan(fov / 2)`` (fx = fy), the
principal point the image centre (``W/2, H/2`` with nerfstudio's pixel centres at half
integers, ``(W − 1)/2, (H − 1)/2`` in vibr's), unless the frame carries vibr's optional
``fl_x``, ``fl_y``, ``cx``, ``cy`` (:data:`FRAME_INTRINSICS`: transforms.json's names and pixel
convention), written for a camera that is not such a pinhole (a frame at a photograph's
camera has the photograph's intrinsics). docs/explanation/flythrough.md has the details, the
``dataparser_transforms.json`` mapping and the sources.

Generators (:func:`interpolate`, :func:`orbit`, :func:`spiral`) return a :class:`CameraPath`.
"""

from __future__ import annotations

import json
import logging
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._runtime.atomic import atomic_path
from ..camera import Camera, axes_meeting_point, image_side, shared_centre
from ..errors import VibrInputError
from ..geometry.selection import depth_points
from ..io.camera_json import ROTATION_TOL, as_rotation, as_scaled_rotation, parse_json
from ..io.transforms import find_transforms
from ..stereo.lightfield import grid_positions

logger = logging.getLogger(__name__)

__all__ = ["CameraPath", "read_camera_path", "write_camera_path", "camera_from_c2w_opengl",
           "c2w_opengl_from_camera", "read_dataparser_transforms", "interpolate", "orbit", "spiral",
           "scene_centre", "scene_up", "scene_points", "scene_processing_transform", "LEGACY_COLMAP_APPLIED",
           "frame_count", "key_intrinsics", "FRAME_INTRINSICS", "ROLL_MODES", "orient_keys", "turns_text", "grid_loop", "smooth_keys"]

#: How :func:`interpolate` orients its key cameras about their optical axes (``roll=``;
#: ``vibr path interpolate --roll``). orbit and spiral look at the scene with its up, as "level".
ROLL_MODES = {
    "snap": "turn each key camera by the quarter turns that bring its image's up nearest the scene's up "
            "(photographs taken rolled by 90 degrees or upside down pass upright; a hand-held tilt is kept)",
    "level": "as snap, then roll each key camera to the scene's up exactly (a level horizon)",
    "keep": "the cameras' own orientations",
}

#: A camera looking within this angle (degrees) of the scene's up or down has no roll to
#: correct: its image's up says nothing about the world's (a nadir photograph).
ROLL_UNDEFINED_DEG = 15.0

#: A frame's own intrinsics, optional keys vibr adds to nerfstudio's frame (which its readers
#: ignore): focal lengths and principal point in pixels with transforms.json's names and pixel
#: convention (the top-left pixel's centre at (0.5, 0.5): vibr's ``cx = cx_file − 0.5``).
#: Written only for a camera that is not the centred square-pixel pinhole of its ``fov``; a
#: frame without them is that pinhole.
FRAME_INTRINSICS = ("fl_x", "fl_y", "cx", "cy")

#: OpenGL camera axes (x right, y up, z backward) <-> OpenCV (x right, y down, z forward).
_GL_CV = np.diag([1.0, -1.0, -1.0])


@dataclass
class CameraPath:
    """A camera path: the cameras of the frames, in order, and the video timing.

    Attributes
    ----------
    cameras : list of Camera
    fps : float
        Frames per second of the video.
    seconds : float
        Duration (nerfstudio's ``seconds``); ``len(cameras) / fps`` for vibr's paths.
    width, height : int
        Frame size (every camera has it).
    meta : dict
        What made the path (kind, key views); written under ``"vibr"`` in the JSON file.
    """

    cameras: list
    fps: float = 24.0
    seconds: float | None = None
    width: int | None = None
    height: int | None = None
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        if not self.cameras:
            raise VibrInputError("a camera path needs at least one frame")
        c0 = self.cameras[0]
        self.width = int(self.width or c0.width)
        self.height = int(self.height or c0.height)
        if not (self.fps > 0 and math.isfinite(self.fps)):
            raise VibrInputError(f"fps must be positive and finite, got {self.fps}")
        if self.seconds is None:
            self.seconds = len(self.cameras) / float(self.fps)

    def __len__(self) -> int:
        return len(self.cameras)


# ----------------------------------------------------------------------------- conversions
def focal_from_fov(fov_deg: float, height: int) -> float:
    """nerfstudio's ``three_js_perspective_camera_focal_length``: ``(H/2) / tan(fov/2)``."""
    return (height / 2.0) / math.tan(math.radians(fov_deg) / 2.0)


def fov_from_focal(f: float, height: int) -> float:
    """Vertical field of view (degrees) of focal length ``f`` px for an image ``height`` px high."""
    return math.degrees(2.0 * math.atan((height / 2.0) / f))


def camera_from_c2w_opengl(c2w_4x4, fov_deg_vertical: float, width: int, height: int,
                           source=None) -> Camera:
    """A vibr camera from a camera-to-world matrix in OpenGL axes and a vertical fov.

    ``R_c2w(OpenCV) = R_c2w(OpenGL) · diag(1, −1, −1)``, ``R = R_c2wᵀ``, ``C = c2w[:3, 3]``;
    ``K`` has ``fx = fy = (H/2) / tan(fov/2)`` and the principal point at the image centre.
    The rotation block must be a rotation, or one times a uniform scale (a scaled camera
    object; the scale is dropped), within 1e-4 (snapped to the nearest rotation:
    :func:`vibr.io.camera_json.as_scaled_rotation`), and the last row ``[0, 0, 0, 1]``:
    anything else raises :class:`VibrInputError`.
    """
    try:
        M = np.asarray(c2w_4x4, dtype=np.float64).reshape(4, 4)
    except (TypeError, ValueError):
        raise VibrInputError("camera_to_world must hold 16 numbers", source) from None
    if not np.all(np.isfinite(M)):
        raise VibrInputError("camera_to_world has non-finite entries", source)
    if np.abs(M[3] - [0, 0, 0, 1]).max() > 1e-6:
        raise VibrInputError(f"camera_to_world's last row is {M[3].tolist()}, not [0, 0, 0, 1]", source)

    Rgl, _ = as_scaled_rotation(M[:3, :3], source, "camera_to_world's rotation")
    try:
        fov = float(fov_deg_vertical)
    except (TypeError, ValueError):
        raise VibrInputError(f"fov must be a number, got {fov_deg_vertical!r}", source) from None
    if not (0.0 < fov < 180.0):
        raise VibrInputError(f"fov must be in (0, 180) degrees, got {fov:g}", source)
    w, h = int(width), int(height)
    K = Camera.intrinsics(focal_from_fov(fov, h), w, h)
    R = (Rgl @ _GL_CV).T
    return Camera.from_centre(K, R, M[:3, 3], w, h, source)


def c2w_opengl_from_camera(camera: Camera) -> np.ndarray:
    """The (4, 4) camera-to-world matrix of ``camera`` in OpenGL axes (x right, y up,
    looking down −z): ``[[Rᵀ · diag(1, −1, −1), C], [0, 0, 0, 1]]``."""
    M = np.eye(4)
    M[:3, :3] = camera.R.T @ _GL_CV
    M[:3, 3] = camera.centre
    return M


def _frame_intrinsics(cam: Camera, tol: float = 1e-9) -> dict:
    """A frame's :data:`FRAME_INTRINSICS` for ``cam``, or {} when its ``fov`` alone says its K
    (a centred square-pixel pinhole, within ``tol`` of its focal length). A skewed K has no
    such keys: its skew is dropped with a warning."""
    K = cam.K
    f = max(float(K[1, 1]), 1.0)
    if abs(K[0, 1]) > tol * f:
        logger.warning("camera %r has a skewed K (%s): the camera_path frame drops its skew", cam,
                       np.array2string(K, precision=2))
    cx, cy = (cam.width - 1) / 2, (cam.height - 1) / 2
    if max(abs(K[0, 2] - cx), abs(K[1, 2] - cy), abs(K[0, 0] - K[1, 1])) <= tol * f:
        return {}
    return {"fl_x": float(K[0, 0]), "fl_y": float(K[1, 1]), "cx": float(K[0, 2]) + 0.5, "cy": float(K[1, 2]) + 0.5}


def _read_frame_intrinsics(fr: dict, fov: float, w: int, h: int, where) -> np.ndarray | None:
    """The K of a frame that carries :data:`FRAME_INTRINSICS` (any of them; ``fl_y`` defaults
    to the ``fov``'s focal, ``fl_x`` to ``fl_y``, ``cx, cy`` to the image centre), else None.
    ``fl_y`` and ``fov`` must agree: a file edited in one of them would otherwise mean two
    cameras."""
    if not any(k in fr for k in FRAME_INTRINSICS):
        return None
    vals = {}
    for k in FRAME_INTRINSICS:
        if k in fr:
            try:
                vals[k] = float(fr[k])
            except (TypeError, ValueError):
                raise VibrInputError(f"{k!r} must be a number, got {fr[k]!r}", where) from None
            if not math.isfinite(vals[k]) or (k.startswith("fl") and vals[k] <= 0):
                raise VibrInputError(f"{k!r} must be {'positive and ' if k.startswith('fl') else ''}finite, "
                                     f"got {fr[k]!r}", where)
    f_fov = focal_from_fov(fov, h)
    fy = vals.get("fl_y", f_fov)
    if abs(fy - f_fov) > 1e-6 * fy:
        raise VibrInputError(f"'fl_y' {fy:g} px and 'fov' {fov:g} degrees ({f_fov:g} px) disagree: correct or "
                             "remove one of them", where)
    fx = vals.get("fl_x", fy)
    return Camera.intrinsics(fx, w, h, fy=fy, cx=vals.get("cx", w / 2.0) - 0.5, cy=vals.get("cy", h / 2.0) - 0.5)


# ----------------------------------------------------------------------------- files
def write_camera_path(path, cameras, *, fps: float = 24.0, seconds: float | None = None,
                      meta: dict | None = None, dataparser_transforms=None, applied_transform=None,
                      applied_scale: float = 1.0) -> None:
    """Write cameras (a list or a :class:`CameraPath`) as nerfstudio's ``camera_path.json``,
    atomically. Every camera must have the same size; ``seconds`` defaults to
    ``len(cameras) / fps``. Floats are written by ``repr`` (exact round trip).

    With ``dataparser_transforms`` (nerfstudio's ``dataparser_transforms.json``, and the
    scene's ``applied_transform`` / ``applied_scale``: :func:`scene_processing_transform`)
    the cameras are written in nerfstudio's normalised frame, the one ``ns-render`` renders
    in; :func:`read_camera_path` with the same arguments reads them back.

    A camera that is not a centred square-pixel pinhole (a frame at a photograph's camera)
    gets its ``fl_x``, ``fl_y``, ``cx``, ``cy`` (:data:`FRAME_INTRINSICS`) beside its ``fov``
    (``ns-render`` keeps only the ``fov``); a skewed K loses its skew, with a warning."""
    if isinstance(cameras, CameraPath):
        fps = cameras.fps
        seconds = cameras.seconds if seconds is None else seconds
        meta = dict(cameras.meta, **(meta or {}))
        cameras = cameras.cameras
    cams = list(cameras)
    if not cams:
        raise VibrInputError("no cameras to write", path)
    w, h = cams[0].width, cams[0].height
    if any((c.width, c.height) != (w, h) for c in cams):
        raise VibrInputError("every camera of a path must have the same size", path)
    seconds = len(cams) / float(fps) if seconds is None else float(seconds)
    to_file = _frame_map(dataparser_transforms, applied_transform, applied_scale, path, _normalise)
    frames = []
    for c in cams:
        frames.append({"camera_to_world": to_file(c2w_opengl_from_camera(c)).ravel().tolist(),
                       "fov": fov_from_focal(float(c.K[1, 1]), h), "aspect": w / h, **_frame_intrinsics(c)})
    if dataparser_transforms is not None:
        meta = dict(meta or {}, frame=f"nerfstudio's normalised frame ({os.fspath(dataparser_transforms)})")
    data = {"camera_type": "perspective", "render_width": int(w), "render_height": int(h),
            "seconds": seconds, "fps": float(fps), "camera_path": frames}
    if meta:
        data["vibr"] = meta
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(data, f, indent=1)
            f.write("\n")


def read_dataparser_transforms(path) -> tuple[np.ndarray, float]:
    """nerfstudio's ``dataparser_transforms.json``: ``(T, scale)`` with ``T`` the 3×4
    ``transform`` and ``scale`` such that a world point of the data maps to the
    normalised frame as ``x_n = scale · (T[:, :3] x + T[:, 3])``."""

    p = os.fspath(path)
    d = parse_json(p)
    if not isinstance(d, dict) or "transform" not in d or "scale" not in d:
        raise VibrInputError("a dataparser_transforms.json holds 'transform' (3x4) and 'scale'", p)
    try:
        T = np.asarray(d["transform"], dtype=np.float64).reshape(3, 4)
        s = float(d["scale"])
    except (TypeError, ValueError):
        raise VibrInputError("'transform' must be 3x4 numbers and 'scale' a number", p) from None
    if not (np.all(np.isfinite(T)) and math.isfinite(s) and s > 0):
        raise VibrInputError("'transform' must be finite and 'scale' positive", p)
    T[:, :3] = as_rotation(T[:, :3], p, "'transform' (its 3x3 part)")
    return T, s


def _frame_map(dataparser_transforms, applied_transform, applied_scale, where, fn):
    """``M -> fn(M, T, s / applied_scale, applied)`` for a dataparser_transforms.json, else
    the identity (the path is in the data's own frame)."""
    if not (math.isfinite(applied_scale) and applied_scale > 0):
        raise VibrInputError(f"applied_scale must be positive, got {applied_scale!r}", where)
    if dataparser_transforms is None:
        return lambda M: M
    T, s = read_dataparser_transforms(dataparser_transforms)
    applied = None if applied_transform is None else np.asarray(applied_transform, np.float64).reshape(3, 4)
    return lambda M: fn(M, T, s / applied_scale, applied)


def _unnormalise(M: np.ndarray, T: np.ndarray, s: float, applied: np.ndarray | None) -> np.ndarray:
    """Map a camera-to-world from nerfstudio's normalised frame back to the data's frame:
    ``x = T_R⁻¹ (x_n / s − T_t)`` (then ``applied`` when the scene's transforms.json
    records one: nerfstudio's dataparser transform includes it)."""
    A = np.eye(4)
    A[:3, :3] = T[:, :3].T
    A[:3, 3] = -T[:, :3].T @ T[:, 3]
    out = M.copy()
    out[:3, 3] = out[:3, 3] / s
    out = A @ out
    if applied is not None:
        B = np.eye(4)
        B[:3, :] = applied
        out = B @ out
    return out


def _normalise(M: np.ndarray, T: np.ndarray, s: float, applied: np.ndarray | None) -> np.ndarray:
    """The inverse of :func:`_unnormalise`: a camera-to-world of the data's frame in
    nerfstudio's normalised frame, ``x_n = s (T_R x + T_t)`` after undoing ``applied``."""
    out = np.asarray(M, np.float64).copy()
    if applied is not None:
        B = np.eye(4)
        B[:3, :] = applied
        out = np.linalg.solve(B, out)
    T4 = np.eye(4)
    T4[:3, :] = T
    out = T4 @ out
    out[:3, 3] = out[:3, 3] * s
    return out


def read_camera_path(path, *, dataparser_transforms=None, applied_transform=None,
                     applied_scale: float = 1.0) -> CameraPath:
    """Read nerfstudio's ``camera_path.json`` (written by its viewer or by vibr).

    Parameters
    ----------
    path : path-like
    dataparser_transforms : path-like, optional
        nerfstudio's ``dataparser_transforms.json``: the path lives in nerfstudio's
        normalised world frame and is mapped back to the data's frame.
    applied_transform : (3, 4) array, optional
        The ``applied_transform`` of the scene's transforms.json, if any (nerfstudio folds
        it into the dataparser transform); only used with ``dataparser_transforms``.
    applied_scale : float
        The ``applied_scale`` of the scene's transforms.json (default 1): nerfstudio folds it
        into the dataparser scale, while the file's poses already carry it.
        :func:`scene_processing_transform` reads both.

    Returns
    -------
    CameraPath
        ``fps`` is the file's ``fps`` when present, else ``frames / seconds`` (what
        ``ns-render`` uses).

    Raises
    ------
    VibrInputError
        Not JSON, no ``camera_path`` or an empty one, a size that is not positive, a
        camera type other than perspective, a non-rigid matrix, a fov outside (0, 180),
        intrinsics (:data:`FRAME_INTRINSICS`) that are not finite numbers, a focal length
        that is not positive or an ``fl_y`` that disagrees with the ``fov``.

    A frame with ``fl_x``, ``fl_y``, ``cx``, ``cy`` has that K; one without them (every file
    of nerfstudio's) the centred square-pixel pinhole of its ``fov``.
    """

    p = os.fspath(path)
    d = parse_json(p)
    if not isinstance(d, dict):
        raise VibrInputError("a camera path file holds a JSON object (nerfstudio camera_path.json)", p)
    if "camera_path" not in d:
        raise VibrInputError("no 'camera_path' list (not a nerfstudio camera_path.json?)", p)
    frames = d["camera_path"]
    if not isinstance(frames, list) or not frames:
        raise VibrInputError("'camera_path' has no frames", p)
    if len(frames) > MAX_FRAMES:  # before any camera is built: it would fill the memory
        raise VibrInputError(f"'camera_path' has {len(frames)} frames, more than the {MAX_FRAMES} vibr reads "
                             "(and 'vibr path' makes)", p)
    ctype = str(d.get("camera_type", "perspective")).lower()
    if ctype != "perspective":
        raise VibrInputError(f"camera_type {ctype!r} is not supported (only 'perspective')", p)
    try:
        w, h = image_side(d["render_width"], "render_width", p), image_side(d["render_height"], "render_height", p)
    except KeyError as exc:
        raise VibrInputError(f"missing {exc.args[0]!r}", p) from None
    if w <= 0 or h <= 0:
        raise VibrInputError(f"render size must be positive, got {w}x{h}", p)
    from_file = _frame_map(dataparser_transforms, applied_transform, applied_scale, p, _unnormalise)
    cams, scaled = [], []
    for i, fr in enumerate(frames):
        where = f"{p}: camera_path[{i}]"
        if not isinstance(fr, dict) or "camera_to_world" not in fr or "fov" not in fr:
            raise VibrInputError("each frame needs 'camera_to_world' and 'fov'", where)
        try:
            M = np.asarray(fr["camera_to_world"], dtype=np.float64)
        except (TypeError, ValueError):
            raise VibrInputError("camera_to_world must hold 16 numbers", where) from None
        if M.size != 16:
            raise VibrInputError(f"camera_to_world must hold 16 numbers, got {M.size}", where)
        M = M.reshape(4, 4)
        if np.all(np.isfinite(M)):
            s = abs(float(np.linalg.det(M[:3, :3]))) ** (1.0 / 3.0)
            if abs(s - 1.0) > ROTATION_TOL:  # the file's own matrix, before any dataparser scale
                scaled.append((i, s))
            M = from_file(M)
        cam = camera_from_c2w_opengl(M, fr["fov"], w, h, source=where)
        K = _read_frame_intrinsics(fr, float(fr["fov"]), w, h, where)
        cams.append(cam if K is None else Camera(K, cam.R, cam.t, w, h, where))
    if scaled:  # usable (the rotation is the camera), but not what a viewer or 'vibr path' writes
        ss = [s for _, s in scaled]
        logger.warning(f"{p}: the camera_to_world rotations of {len(scaled)} of {len(frames)} frames carry a "
                       f"scale ({min(ss):.4g}..{max(ss):.4g}, first camera_path[{scaled[0][0]}]), not a rigid "
                       "motion; vibr uses their rotation")
    seconds = d.get("seconds")
    fps = d.get("fps")
    try:
        seconds = None if seconds is None else float(seconds)
        fps = None if fps is None else float(fps)
    except (TypeError, ValueError):
        raise VibrInputError("'seconds' and 'fps' must be numbers", p) from None
    if fps is None or not (fps > 0 and math.isfinite(fps)):
        if seconds is None or not (seconds > 0 and math.isfinite(seconds)):
            raise VibrInputError("needs a positive 'fps' or 'seconds'", p)
        fps = len(cams) / seconds
    meta = d.get("vibr") if isinstance(d.get("vibr"), dict) else {}
    return CameraPath(cams, fps, seconds, w, h, dict(meta, file=p))


# ----------------------------------------------------------------------------- scene geometry
def scene_up(cameras, centre=None) -> np.ndarray:
    """World "up" of a set of cameras.

    The mean of the cameras' −y axes (image up), normalised, with cameras rolled by quarter
    turns counted by their axis nearest that mean (:func:`_quarter_turn_mean`) — unless the camera centres
    spread in a plane in two directions (a ring or a wide arc: singular values of the
    centres ``s₂ < 0.1 s₁`` and ``s₁ > 0.3 s₀``) and the cameras look across that plane (mean
    ``|n · axis| < 0.5``; a light-field grid looks along it): then the plane's normal, which stays right
    when the photographs are rolled (templeSparseRing's are, by ±90°); its sign agrees with
    the mean −y when that is clear (|cos| > 0.3), else puts the cameras above ``centre``.
    """
    cams = list(cameras)
    u = -np.mean([c.R[1] for c in cams], axis=0)
    C = np.array([c.centre for c in cams])
    if len(C) >= 3:
        _, S, Vt = np.linalg.svd(C - C.mean(0), full_matrices=False)
        n = Vt[2]
        looks_along = float(np.mean([abs(n @ c.optical_axis) for c in cams]))
        # a ring or arc looks across its plane; a planar grid of parallel cameras (a light
        # field) looks along its normal, which is then no "up"
        if S[0] > 0 and S[1] > 0.3 * S[0] and S[2] < 0.1 * S[1] and looks_along < 0.5:
            nu = np.linalg.norm(u)
            if nu > 1e-9 and abs(n @ u) / nu > 0.3:
                return n if n @ u > 0 else -n
            X = axes_meeting_point(cams) if centre is None else np.asarray(centre, np.float64)
            if X is not None:
                return n if np.mean((C - X) @ n) >= 0 else -n
            return n
    n = np.linalg.norm(u)
    if n < 1e-9:
        raise VibrInputError("the cameras' up directions cancel out: no common up")
    return _quarter_turn_mean(cams, u / n)


def _quarter_turn_mean(cams, u: np.ndarray, rounds: int = 3) -> np.ndarray:
    """The mean image up of cameras some of which are rolled by quarter turns (portrait
    photographs stored sideways among landscape ones): each camera's up taken as whichever
    of its ±x, ±y axes is nearest the current estimate, averaged again. The plain mean of
    −y leans towards the rolled ones (3 of 6 turned by 90°: 45°, where a quarter turn is
    ambiguous); for cameras taken upright it is the plain mean, unchanged."""
    for _ in range(rounds):
        ups = []
        for c in cams:
            cand = np.array([-c.R[1], -c.R[0], c.R[1], c.R[0]])
            ups.append(cand[int(np.argmax(cand @ u))])
        v = np.mean(ups, axis=0)
        nv = np.linalg.norm(v)
        if nv < 1e-9 or np.allclose(v / nv, u, rtol=0, atol=1e-15):
            break
        u = v / nv
    return u


def scene_centre(cameras, points: np.ndarray | None = None) -> np.ndarray:
    """What the cameras look at: the point nearest to all optical axes (least squares,
    :func:`vibr.camera.axes_meeting_point`); for parallel rigs, the median of ``points``
    (e.g. from depth maps) if given, else a point on the mean axis at 4× the cameras' spread."""
    X = axes_meeting_point(cameras)
    if X is not None:
        return X
    C = np.array([c.centre for c in cameras])
    a = np.mean([c.optical_axis for c in cameras], axis=0)
    a /= np.linalg.norm(a)
    if points is not None and len(points):
        d = np.median((np.asarray(points) - C.mean(0)) @ a)
        if d > 0:
            return C.mean(0) + d * a
    spread = max(float(np.linalg.norm(C.max(0) - C.min(0))), 1e-6)
    return C.mean(0) + 4.0 * spread * a


def scene_points(scene, max_points: int = 4096) -> np.ndarray | None:
    """World points of the scene: a strided subsample of its views' depth maps, else its
    sparse points, else None (used where the cameras' axes do not meet)."""

    per_view = max(64, max_points // max(1, len(scene)))
    pts = [depth_points(v, per_view) for v in scene.views if v.depth is not None]
    if pts:
        return np.concatenate(pts)
    if scene.points is not None and len(scene.points):
        return np.asarray(scene.points, np.float64)
    return None


#: The most frames a generated path has: 100 000 frames are 69 minutes at 24 fps.
MAX_FRAMES = 100_000


def frame_count(n_frames, seconds, fps) -> int:
    """The number of frames of a path: ``n_frames``, or ``seconds × fps`` rounded; checked
    (at least one, at most :data:`MAX_FRAMES`)."""
    if not (math.isfinite(float(fps)) and float(fps) > 0):
        raise VibrInputError(f"fps must be positive and finite, got {fps}")
    if n_frames is None:
        if seconds is None:
            raise VibrInputError("give the number of frames or the duration in seconds")
        if not (math.isfinite(float(seconds)) and float(seconds) > 0):
            raise VibrInputError(f"the duration must be positive and finite (seconds), got {seconds}")
        n_frames = int(round(float(seconds) * float(fps)))
    n = int(n_frames)
    if n < 1:
        raise VibrInputError(f"a path needs at least one frame, got {n}")
    if n > MAX_FRAMES:  # a typo (--seconds 1e9), not a video: it would fill the memory
        raise VibrInputError(f"a path of {n} frames ({n / float(fps) / 3600:.3g} hours at {float(fps):g} fps) "
                             f"is more than the {MAX_FRAMES} frames vibr path makes")
    return n


def _output_size(cameras, width, height, scale):
    w = cameras[0].width if width is None else image_side(width, "width", None)
    h = cameras[0].height if height is None else image_side(height, "height", None)
    if width is None and height is None and scale != 1.0:
        w, h = max(1, round(w * scale)), max(1, round(h * scale))
    if w <= 0 or h <= 0:
        raise VibrInputError(f"frame size must be positive, got {w}x{h}")
    return w, h


def _cameras_of(scene, views=None):
    if views is None:
        return [v.camera for v in scene.views], scene.names
    idx = [scene.index(k) for k in views]
    return [scene.views[i].camera for i in idx], [scene.views[i].name for i in idx]


def _look_at(eye, target, up, f_rel, w, h) -> Camera:
    K = Camera.intrinsics(f_rel * h, w, h)
    return Camera.look_at(eye, target, up, K, w, h)


def _vertical_focal(cam: Camera, w: int, h: int) -> float:
    """Focal length relative to the image height (fy / H: what a resize keeps) for a frame of
    w×h; relative to the photograph's width when its orientation is not the frame's (a
    portrait photograph in a landscape path): then the focal in pixels is kept, where fy / H
    would zoom out by the aspect ratio at that key (4:3: 1.33×) and back in after it."""
    other = (cam.width > cam.height and h > w) or (cam.height > cam.width and w > h)
    return float(cam.K[1, 1]) / (cam.width if other else cam.height)


def key_intrinsics(cam: Camera, w: int, h: int) -> np.ndarray:
    """The (3, 3) K of a w×h frame at the key camera ``cam``: its photograph's K brought to
    the frame, so that the frame at the key is the photograph resized.

    The image is scaled about its centre (``x' + ½ − w/2 = s_x (x + ½ − W/2)``, likewise y):
    by ``s_x = w/W``, ``s_y = h/H`` when the photograph has the frame's shape (up to a pixel
    of rounding: what :meth:`Camera.scaled` gives), else by one ``s = h/L`` on both axes,
    ``L`` the reference length of :func:`_vertical_focal` (its height, or its width for a
    photograph of the other orientation than the frame): its field of view kept vertically
    and its pixels square, the principal point's offset from the centre scaled alike."""
    W, H = cam.width, cam.height
    other = (W > H and h > w) or (H > W and w > h)
    if not other and abs(W * h / H - w) <= 1.0:
        sx, sy = w / W, h / H
    else:
        sx = sy = h / (W if other else H)
    S = np.array([[sx, 0.0, 0.5 * (w - sx * W) + 0.5 * sx - 0.5],
                  [0.0, sy, 0.5 * (h - sy * H) + 0.5 * sy - 0.5],
                  [0.0, 0.0, 1.0]])
    return S @ cam.K


def _intrinsics_along(t, keys, ts, bc) -> np.ndarray:
    """(len(ts), 3, 3) K at the path parameters ``ts`` from the keys' K (n, 3, 3) at the
    knots ``t``: cubic splines (boundary ``bc``, as the positions) of ``log fx``, ``log fy``
    (a zoom's steps alike in and out), the skew over fy and the principal point. At a knot
    a frame has its key's K exactly; an entry every key shares is kept as it is (a path
    through centred pinholes stays one)."""
    from scipy.interpolate import CubicSpline

    raw = np.stack([keys[:, 0, 0], keys[:, 1, 1], keys[:, 0, 1], keys[:, 0, 2], keys[:, 1, 2]], axis=1)
    tr = np.column_stack([np.log(raw[:, 0]), np.log(raw[:, 1]), raw[:, 2] / raw[:, 1], raw[:, 3], raw[:, 4]])
    v = CubicSpline(t, tr, bc_type=bc)(ts)
    fy = np.exp(v[:, 1])
    out = np.column_stack([np.exp(v[:, 0]), fy, v[:, 2] * fy, v[:, 3], v[:, 4]])
    const = np.all(raw == raw[0], axis=0)
    out[:, const] = raw[0, const]
    at_key = np.searchsorted(t, ts)
    hit = (at_key < len(t)) & (t[np.minimum(at_key, len(t) - 1)] == ts)
    out[hit] = raw[at_key[hit]]
    K = np.zeros((len(ts), 3, 3))
    K[:, 0, 0], K[:, 1, 1], K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = out.T
    K[:, 2, 2] = 1.0
    return K


# ----------------------------------------------------------------------------- generators
def _check_not_one_centre(scene, what: str) -> None:
    """An orbit or a spiral moves the camera; from a rotation-only capture (every camera at
    one centre) it would look from where no photograph did."""
    if shared_centre([v.camera for v in scene.views], scene.points) is not None:
        raise VibrInputError(f"the cameras share one centre (a rotation-only capture): {what} would move the camera "
                             f"where no photograph looked from; 'interpolate' turns between the views")


def order_by_proximity(cameras) -> list[int]:
    """A visiting order of cameras: start at the camera farthest from the centroid of the
    centres (an end of the sequence), then always the nearest camera not yet visited. Cameras
    that share one centre (:func:`vibr.camera.shared_centre`) are ordered by their optical
    axes instead (the points those axes reach at unit distance)."""
    C = np.array([c.centre for c in cameras])
    if shared_centre(cameras) is not None:
        C = np.array([c.optical_axis for c in cameras])
    left = list(range(len(C)))
    cur = int(np.argmax(np.linalg.norm(C - C.mean(0), axis=1)))
    order = [cur]
    left.remove(cur)
    while left:
        d = np.linalg.norm(C[left] - C[cur], axis=1)
        cur = left[int(np.argmin(d))]
        order.append(cur)
        left.remove(cur)
    return order


def _key_steps(cams, X):
    """``‖C_i − C_{i−1}‖ + r · angle(R_{i−1}, R_i)`` between consecutive cameras, ``r`` their
    mean distance to ``X``."""
    from scipy.spatial.transform import Rotation

    C = np.array([c.centre for c in cams])
    rots = Rotation.from_matrix(np.array([c.R.T for c in cams]))
    # cameras turning on one spot look at nothing in particular: a radian counts as a unit
    r = 1.0 if shared_centre(cams) is not None else float(np.mean(np.linalg.norm(C - X, axis=1)))
    return np.linalg.norm(np.diff(C, axis=0), axis=1) + r * (rots[:-1].inv() * rots[1:]).magnitude(), r


def _check_roll(roll: str) -> None:
    if roll not in ROLL_MODES:
        raise VibrInputError(f"roll must be one of {', '.join(ROLL_MODES)}, got {roll!r}")


def _quarter_turns(cam: Camera, up: np.ndarray) -> int | None:
    """The quarter turns k (0–3, :meth:`Camera.turned`) after which the camera's image up
    (its −y axis) is nearest to ``up``; None when it looks within
    :data:`ROLL_UNDEFINED_DEG` of ±up."""
    R = cam.R
    if math.hypot(R[0] @ up, R[1] @ up) < math.sin(math.radians(ROLL_UNDEFINED_DEG)):  # up's projection
        return None
    # image up after k turns: -y, then -x, +y, +x of the original camera
    return int(np.argmax(np.array([-R[1], -R[0], R[1], R[0]]) @ up))


def _levelled(cam: Camera, up: np.ndarray) -> Camera:
    """The camera rolled about its optical axis until its image up lies in the plane of
    that axis and ``up`` (same K, size and centre)."""
    z = cam.R[2]
    x = np.cross(-up, z)
    x /= np.linalg.norm(x)
    return Camera.from_centre(cam.K, np.stack([x, np.cross(z, x), z]), cam.centre, cam.width, cam.height,
                              cam.source)


def orient_keys(cameras, roll: str, up) -> tuple[list, list]:
    """Key cameras oriented for a path by ``roll`` (:data:`ROLL_MODES`) about their optical
    axes, the world's ``up`` given (:func:`scene_up`). Returns the cameras and the quarter
    turns given to each (0 for those kept, with "keep", or looking along ±up).

    A path through cameras whose photographs were taken rolled (templeSparseRing's by ±90°,
    half of them upside down relative to the others; a phone held in portrait) spins the
    video by up to 180° between two neighbours; "snap" turns such a key by whole quarter
    turns (the frame at the key is its photograph, turned), "level" also removes the rest
    of the roll (the frame at the key is the photograph turned by a few degrees too)."""
    _check_roll(roll)
    cams = list(cameras)
    if roll == "keep":
        return cams, [0] * len(cams)
    up = np.asarray(up, np.float64)
    out, turns = [], []
    for c in cams:
        k = _quarter_turns(c, up)
        if k is None or (k and c.K[0, 1] != 0):  # nadir; a skewed K has no quarter turn
            out.append(c)
            turns.append(0)
            continue
        c = c.turned(k)
        out.append(_levelled(c, up) if roll == "level" else c)
        turns.append(k)
    return out, turns


def _oriented(cams, roll, X):
    """:func:`orient_keys` with the scene's up; with no common up, "snap" keeps the cameras."""
    _check_roll(roll)
    if roll == "keep":
        return cams
    try:
        up = scene_up(cams, X)
    except VibrInputError:
        if roll == "level":
            raise VibrInputError("roll 'level' needs the scene's up, and the cameras' up directions cancel out; "
                                 "use roll 'keep'") from None
        logger.debug("interpolate: no common up, the cameras' own orientations kept")
        return cams
    out, turns = orient_keys(cams, roll, up)
    if any(turns):
        logger.info("interpolate: %d of %d key cameras turned to the scene's up (clockwise: %s; roll 'keep' "
                    "leaves them as photographed)", sum(1 for k in turns if k), len(cams), turns_text(turns))
    return out


def turns_text(turns) -> str:
    """``"5 by 90°, 11 by 270°"``: how many cameras :func:`orient_keys` turned by each angle."""
    by = {90 * k: sum(1 for j in turns if j == k) for k in (1, 2, 3)}
    return ", ".join(f"{n} by {a}°" for a, n in by.items() if n)


def _distinct_keys(cams, names, X):
    """The key cameras without those whose pose is the one before's (the spline needs
    increasing knots), with a warning naming them; returns ``(cams, names, steps)``."""
    step, r = _key_steps(cams, X)
    same = np.flatnonzero(step <= 1e-12 * max(r, 1.0)) + 1
    if len(same):
        logger.warning("interpolate: %s left out: the same pose as the view before",
                       ", ".join(f"{names[k]} (after {names[k - 1]})" for k in same))
        keep = np.setdiff1d(np.arange(len(cams)), same)
        cams, names = [cams[k] for k in keep], [names[k] for k in keep]
        if len(cams) < 2:
            raise VibrInputError(f"views {', '.join(names)}: all of the same pose, nothing to interpolate")
        step, r = _key_steps(cams, X)
    return cams, names, step


def interpolate(scene, views=None, *, order: str | None = None, n_frames: int | None = None,
                seconds: float | None = None, fps: float = 24.0, width: int | None = None,
                height: int | None = None, scale: float = 1.0, roll: str = "snap",
                smooth: float = 0.0) -> CameraPath:
    """A C²-smooth path through the scene's cameras (all, or ``views`` in that order).

    Knots ``t_i`` are the cumulative length ``Σ ‖C_i − C_{i−1}‖ + r · angle(R_{i−1}, R_i)``
    (``r``: the cameras' mean distance to :func:`scene_centre`, so turning on the spot
    counts as the motion of what is looked at). Positions: a natural cubic spline
    (``scipy.interpolate.CubicSpline``, C² with zero end curvature); orientations:
    ``scipy.spatial.transform.RotationSpline`` (rotation vectors between consecutive keys
    cubic in t, angular rate and acceleration continuous: C²); the intrinsics: each key's
    photograph's K brought to the frame (:func:`key_intrinsics`: focal lengths and
    principal point, scaled with the image height, or the width for a photograph of the
    other orientation than the frame), their log focal lengths and principal points by
    the same cubic splines (:func:`_intrinsics_along`), so that a frame at a key camera
    is its photograph, resized. Frames are ``n_frames`` equal steps of t from the first key
    to the last, so a key camera is never repeated.

    Parameters
    ----------
    scene : Scene
    views : sequence of view names / indices, optional
    order : {"given", "proximity"}, optional
        Keep the given (or the scene's) order, or reorder by :func:`order_by_proximity`.
        Default: ``"given"`` when ``views`` are named or the scene is a video's frames
        (``scene.meta["capture"] == "video"``: time order), else ``"proximity"`` (a scene's
        file order need not follow its cameras: templeSparseRing's jumps across the ring,
        and a path in that order goes through the temple).
    n_frames : int, or ``seconds`` × ``fps``
    width, height : int, optional
        Frame size (default: the first key camera's, times ``scale``: W×H swapped when
        ``roll`` turned it by a quarter turn).
    roll : {"snap", "level", "keep"}
        How the key cameras are oriented about their optical axes (:data:`ROLL_MODES`,
        :func:`orient_keys`), the world's up from :func:`scene_up`; with "snap", photographs
        taken rolled by 90° or upside down make no spin in the video.
    smooth : float
        σ (in keys) of a Gaussian smoothing of the key cameras along the path before the
        splines (:func:`smooth_keys`): the hand's sway between the frames of a hand-held
        video, which the splines would otherwise follow. 0 (the default): the path passes
        through the cameras.

    Examples
    --------
    >>> from vibr.synthetic import make_scene
    >>> path = interpolate(make_scene("arc", width=32, height=32), n_frames=10)
    >>> len(path.cameras), path.cameras[0].shape
    (10, (32, 32))
    """
    from scipy.interpolate import CubicSpline
    from scipy.spatial.transform import Rotation, RotationSpline

    cams, names, closed = _path_keys(scene, views, order)
    n = frame_count(n_frames, seconds, fps)
    X = scene_centre(cams, scene_points(scene))
    cams = _oriented(cams, roll, X)
    w, h = _output_size(cams, width, height, scale)
    if smooth and closed:  # the loop's last key is its first again
        cams = smooth_keys(cams[:-1], smooth, closed=True)
        cams = cams + cams[:1]
    elif smooth:
        cams = smooth_keys(cams, smooth)
    cams, names, step = _distinct_keys(cams, names, X)
    t = np.concatenate([[0.0], np.cumsum(step)])
    C = np.array([c.centre for c in cams])
    rots = Rotation.from_matrix(np.array([c.R.T for c in cams]))  # camera-to-world
    bc = "periodic" if closed else "natural"
    pos = CubicSpline(t, C, bc_type=bc)
    rot = RotationSpline(t, rots)
    # a closed loop does not end on its first frame again: the video loops without a repeat
    ts = np.linspace(t[0], t[-1], n, endpoint=not closed) if n > 1 else t[:1]
    Rc2w = rot(ts).as_matrix()
    P = pos(ts)
    Ks = _intrinsics_along(t, np.array([key_intrinsics(c, w, h) for c in cams]), ts, bc)
    out = [Camera.from_centre(K, Ri.T, Ci, w, h) for Ri, Ci, K in zip(Rc2w, P, Ks)]
    return CameraPath(out, float(fps), None, w, h,
                      {"kind": "interpolate", "views": names, "knots": t.tolist(), "roll": roll, "closed": closed,
                       "smooth": float(smooth)})


def smooth_keys(cameras, sigma: float, closed: bool = False) -> list:
    """Key cameras smoothed along their sequence: a Gaussian low-pass of the trajectory, the
    first step of video stabilisation (Grundmann, Kwatra & Essa, "Auto-directed video
    stabilization with robust L1 optimal camera paths", CVPR 2011, fit a smooth path to the
    shaky one; a Gaussian is the simplest such fit).

    Key ``i`` gets ``C̃_i = Σ_j g_j C_{i+j} / Σ_j g_j``, ``g_j = exp(−j²/2σ²)``, ``|j| ≤ ⌈3σ⌉``;
    its orientation the weighted chordal mean of the rotations (``Rotation.mean``) and its
    focal length the weighted mean, the intrinsics otherwise kept. An open sequence is
    extended past its ends by point reflection (``C_{−j} = 2C_0 − C_j``, ``R_{−j} =
    R_0 R_jᵀ R_0``), so the end keys stay where they are and a steady motion is left as it
    is; a ``closed`` one wraps round.

    Parameters
    ----------
    cameras : list of Camera (at least 2)
    sigma : float
        Width of the Gaussian in keys (> 0; for a hand-held video's frames, 1–3).
    closed : bool
        The sequence is a loop (its last key is followed by its first).
    """
    from scipy.spatial.transform import Rotation

    if not (np.isfinite(sigma) and sigma > 0):
        raise VibrInputError(f"smooth must be a positive number of keys, got {sigma}")
    n = len(cameras)
    m = min(int(np.ceil(3 * sigma)), n - 1)
    g = np.exp(-np.arange(-m, m + 1) ** 2 / (2.0 * sigma ** 2))
    C = np.array([c.centre for c in cameras])
    R = Rotation.from_matrix(np.array([c.R.T for c in cameras]))  # camera-to-world
    f = np.array([c.K[1, 1] for c in cameras])
    out = []
    for i in range(n):
        Cs, Rs, fs = _window(C, R, f, i, m, closed)
        c = cameras[i]
        K = c.K.copy()
        K[0, 0] *= float(g @ fs) / g.sum() / K[1, 1]
        K[1, 1] = float(g @ fs) / g.sum()
        Rc2w = Rs.mean(weights=g).as_matrix()
        out.append(Camera.from_centre(K, Rc2w.T, g @ Cs / g.sum(), c.width, c.height))
    return out


def _window(C, R, f, i: int, m: int, closed: bool):
    """The keys ``i − m … i + m`` (centres, rotations, focal lengths): wrapped round when
    ``closed``, else reflected through the end keys."""
    from scipy.spatial.transform import Rotation

    n = len(C)
    idx = np.arange(i - m, i + m + 1)
    if closed:
        k = idx % n
        return C[k], R[k], f[k]
    Cs, Rm, fs = np.empty((len(idx), 3)), [], np.empty(len(idx))
    for a, j in enumerate(idx):
        e = 0 if j < 0 else n - 1 if j >= n else None  # the end key reflected through
        if e is None:
            Cs[a], fs[a] = C[j], f[j]
            Rm.append(R[j].as_matrix())
        else:
            r = 2 * e - j  # mirror index, inside since m ≤ n − 1
            Cs[a], fs[a] = 2 * C[e] - C[r], 2 * f[e] - f[r]
            Rm.append((R[e] * R[r].inv() * R[e]).as_matrix())
    return Cs, Rotation.from_matrix(np.array(Rm)), fs


def _path_keys(scene, views, order) -> tuple[list, list, bool]:
    """The key cameras of :func:`interpolate`, their names, and whether they close a loop."""
    cams, names = _cameras_of(scene, views)
    if views is None and order is None:
        loop = grid_loop(scene)
        if loop is not None:
            logger.info("interpolate: a light field's grid: a loop through %d views round its border "
                        "(order 'proximity': through all %d, row by row)", len(loop), len(cams))
            return [cams[i] for i in loop] + [cams[loop[0]]], [names[i] for i in loop] + [names[loop[0]]], True
    if order is None and views is None and scene.meta.get("capture") == "video":
        logger.info("interpolate: the frames of a video: in time order (--order proximity reorders them)")
        order = "given"
    order = ("given" if views is not None else "proximity") if order is None else order
    if order not in ("given", "proximity"):
        raise VibrInputError(f"order must be 'given' or 'proximity', got {order!r}")
    if order == "proximity":
        idx = order_by_proximity(cams)
        cams, names = [cams[i] for i in idx], [names[i] for i in idx]
    if len(cams) < 2:
        raise VibrInputError("interpolate needs at least two cameras")
    return cams, names, False


def grid_loop(scene) -> list[int] | None:
    """Views round the border of a light field's grid: at its corners and the middles of its
    sides (or the border views nearest to them where positions are missing), clockwise
    from the top-left; None when the scene is no grid of at least 3×3 positions with 4 such
    views.

    A path through all the views of a grid in proximity order scans them row by row, the
    camera going back and forth at every view (cotton: 81 keys, the direction reversed at
    each); round the border it circles the grid once, showing the parallax all round."""
    if scene.grid is None and not scene.meta.get("grid_pos"):
        return None

    pos = grid_positions(scene)
    at = {rc: i for i, rc in pos.items()}
    rows = sorted({r for r, _ in pos.values()})
    cols = sorted({c for _, c in pos.values()})
    r0, r1, c0, c1 = rows[0], rows[-1], cols[0], cols[-1]
    if r1 - r0 < 2 or c1 - c0 < 2:
        return None
    rm, cm = (r0 + r1) / 2, (c0 + c1) / 2
    # the corners and the middles of the sides, clockwise: a periodic spline through them is
    # a rounded loop (through all the border views it turned by 90° within a frame or two at
    # each corner)
    marks = [(r0, c0), (r0, cm), (r0, c1), (rm, c1), (r1, c1), (r1, cm), (r1, c0), (rm, c0)]
    border = [rc for rc in at if rc[0] in (r0, r1) or rc[1] in (c0, c1)]
    loop = []
    for m in marks:
        rc = min(border, key=lambda p: (p[0] - m[0]) ** 2 + (p[1] - m[1]) ** 2)
        if at[rc] not in loop:
            loop.append(at[rc])
    return loop if len(loop) >= 4 else None


def _upright_framing(cams, up, width, height, scale):
    """Frame size and focal (``fy / H``, the cameras' mean) of the photographs turned upright
    (:func:`orient_keys`, "snap"): the framing of an orbit or a spiral, which look with the
    scene's up — portrait for photographs taken rolled by 90° (templeSparseRing's)."""
    upright, _ = orient_keys(cams, "snap", up)
    w, h = _output_size(upright, width, height, scale)
    return w, h, float(np.mean([_vertical_focal(c, w, h) for c in upright]))


def _angles_in_plane(V, e1, e2):
    return np.arctan2(V @ e2, V @ e1)


def orbit(scene, *, n_frames: int | None = None, seconds: float | None = None, fps: float = 24.0,
          width: int | None = None, height: int | None = None, scale: float = 1.0,
          full: bool | None = None, radius_scale: float = 1.0) -> CameraPath:
    """An elliptical orbit around :func:`scene_centre`, looking at it.

    The orbit lies in the plane perpendicular to "up" (:func:`scene_up`) at the cameras'
    mean height above the centre. Its semi-axes are ``√2 ×`` the standard deviation of the
    cameras' horizontal offsets along their two principal directions when the cameras
    surround the centre (the largest angular gap between them is under 180°: a ring, for
    which this is the ring's radius) — ``full`` orbit —, and a circle at their mean
    horizontal distance swept back and forth over the arc they cover otherwise
    (``θ(s) = θ_mid + ½ span · sin 2πs``: nothing is rendered from where no camera looked;
    ``full=True`` forces a full turn). Focal length: the cameras' mean ``fy / H``, and the
    frame size the first camera's, both of the photographs turned upright
    (:func:`_upright_framing`).
    """
    cams = [v.camera for v in scene.views]
    _check_not_one_centre(scene, "an orbit")
    n = frame_count(n_frames, seconds, fps)
    X = scene_centre(cams, scene_points(scene))
    up = scene_up(cams, X)
    w, h, f_rel = _upright_framing(cams, up, width, height, scale)
    C = np.array([c.centre for c in cams]) - X
    height_ = float(np.mean(C @ up))
    V = C - np.outer(C @ up, up)
    if np.max(np.linalg.norm(V, axis=1)) < 1e-9:
        raise VibrInputError("the cameras are all straight above the centre: no orbit plane")
    # in-plane basis: principal directions of the horizontal offsets
    _, _, Wt = np.linalg.svd(V - 0.0, full_matrices=False)
    e1 = Wt[0] - (Wt[0] @ up) * up
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    th = np.sort(_angles_in_plane(V, e1, e2))
    gaps = np.diff(np.concatenate([th, [th[0] + 2 * np.pi]]))
    surround = len(th) > 2 and float(gaps.max()) < np.pi
    full = surround if full is None else bool(full)
    s = np.arange(n) / n
    if full:
        if surround:
            a = math.sqrt(2.0) * float(np.std(V @ e1)) * radius_scale
            b = math.sqrt(2.0) * float(np.std(V @ e2)) * radius_scale
        else:
            a = b = float(np.mean(np.linalg.norm(V, axis=1))) * radius_scale
        start = float(_angles_in_plane(V[:1], e1, e2)[0])
        ang = start + 2 * np.pi * s
        rad_a, rad_b = a, b
    else:
        k = int(np.argmax(gaps))
        lo = th[(k + 1) % len(th)]
        span = 2 * np.pi - float(gaps[k])
        mid = lo + span / 2
        ang = mid + 0.5 * span * np.sin(2 * np.pi * s)
        rad_a = rad_b = float(np.mean(np.linalg.norm(V, axis=1))) * radius_scale
    out = []
    for t in ang:
        eye = X + height_ * up + rad_a * math.cos(t) * e1 + rad_b * math.sin(t) * e2
        out.append(_look_at(eye, X, up, f_rel, w, h))
    return CameraPath(out, float(fps), None, w, h,
                      {"kind": "orbit", "centre": X.tolist(), "up": up.tolist(), "full": full})


def spiral(scene, *, n_frames: int | None = None, seconds: float | None = None, fps: float = 24.0,
           width: int | None = None, height: int | None = None, scale: float = 1.0,
           rots: float = 2.0, zrate: float = 0.5, radius_scale: float = 1.0) -> CameraPath:
    """A forward-facing spiral around the mean camera, looking at :func:`scene_centre`
    (LLFF, Mildenhall et al. 2019, ``render_path_spiral``). When the cameras surround the
    centre (their mean centre is nearer to it than half their distance: a ring), around the
    first view, with radii a tenth of its distance to the centre.

    Mean camera: the mean centre and the mean rotation (``Rotation.mean``). In its axes
    the eye moves on ``(r_x cos θ, −r_y sin θ, −r_z sin(zrate θ))``, ``θ`` over ``rots``
    turns, with ``r`` the 90th percentile of the cameras' absolute offsets from the mean
    camera along each axis (LLFF's radii) times ``radius_scale``.
    """
    from scipy.spatial.transform import Rotation

    cams = [v.camera for v in scene.views]
    _check_not_one_centre(scene, "a spiral")
    n = frame_count(n_frames, seconds, fps)
    X = scene_centre(cams, scene_points(scene))
    up = scene_up(cams, X)
    w, h, f_rel = _upright_framing(cams, up, width, height, scale)
    C = np.array([c.centre for c in cams])
    Cm = C.mean(0)
    dist = float(np.mean(np.linalg.norm(C - X, axis=1)))
    if np.linalg.norm(Cm - X) < 0.5 * dist:
        # the cameras surround the centre (a ring): their mean camera is inside the object;
        # spiral around the first view instead, radii a tenth of its distance to the centre
        Cm = C[0]
        Rm = Camera.look_at(Cm, X, up, np.eye(3), 1, 1).R
        rad = np.full(3, 0.1 * float(np.linalg.norm(Cm - X))) * radius_scale
    else:
        Rm = Rotation.from_matrix(np.array([c.R for c in cams])).mean().as_matrix()  # world-to-camera
        off = (C - Cm) @ Rm.T
        rad = np.percentile(np.abs(off), 90, axis=0) * radius_scale
    if not np.any(rad > 0):
        raise VibrInputError("the cameras share one centre: no spiral radius")
    out = []
    for th in np.linspace(0.0, 2 * np.pi * rots, n, endpoint=False):
        local = np.array([math.cos(th), -math.sin(th), -math.sin(th * zrate)]) * rad
        eye = Cm + Rm.T @ local
        out.append(_look_at(eye, X, up, f_rel, w, h))
    return CameraPath(out, float(fps), None, w, h,
                      {"kind": "spiral", "centre": X.tolist(), "radii": rad.tolist()})


#: The ``applied_transform`` nerfstudio assumes for a transforms.json that has none but a
#: ``colmap/sparse/0`` folder beside it: what ns-process-data applied to COLMAP's poses
#: before it recorded the transform (nerfstudio_dataparser.py).
LEGACY_COLMAP_APPLIED = ((0.0, 1.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, -1.0, 0.0))


def scene_processing_transform(scene_path) -> tuple[np.ndarray | None, float]:
    """``(applied_transform, applied_scale)`` of a transforms.json scene, as nerfstudio's
    data parser reads them: the 3×4 ``applied_transform`` (else
    :data:`LEGACY_COLMAP_APPLIED` when a ``colmap/sparse/0`` folder lies beside the file,
    else None) and ``applied_scale`` (default 1). ``(None, 1.0)`` for another format.

    nerfstudio composes both into its dataparser transform and scale, so a path in its
    normalised frame maps back to the frame *before* them; vibr reads the transforms.json
    poses as they are, so :func:`read_camera_path` applies them again.

    Raises
    ------
    VibrInputError
        A transforms.json whose ``applied_transform`` is not 3×4 finite numbers or whose
        ``applied_scale`` is not a positive number (the path would land elsewhere).
    """

    tj = find_transforms(scene_path)
    if tj is None:  # not a transforms.json scene
        return None, 1.0
    d = parse_json(tj)
    d = d if isinstance(d, dict) else {}
    A = d.get("applied_transform")
    if A is None and (Path(tj).parent / "colmap" / "sparse" / "0").is_dir():
        A = LEGACY_COLMAP_APPLIED
    try:
        A = None if A is None else np.asarray(A, np.float64).reshape(3, 4)
        scale = float(d.get("applied_scale", 1.0))
    except (TypeError, ValueError):
        raise VibrInputError("'applied_transform' must be 3x4 numbers and 'applied_scale' a number", tj) from None
    if (A is not None and not np.all(np.isfinite(A))) or not (math.isfinite(scale) and scale > 0):
        raise VibrInputError("'applied_transform' must be finite and 'applied_scale' positive", tj)
    return A, scale
