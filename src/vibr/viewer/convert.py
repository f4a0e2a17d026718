"""viser's camera ↔ vibr's :class:`~vibr.camera.Camera` (the one place this lives).

viser reports a browser's viewport camera as ``wxyz`` (the unit quaternion of the
camera-to-world rotation ``R_wc``), ``position`` (the camera centre ``C`` in world
coordinates), ``fov`` (the *vertical* field of view, radians) and the canvas aspect
(width / height). Its cameras use OpenCV axes (x right, y down, z forward; see viser's
``CameraHandle.wxyz`` and ``add_camera_frustum``), as vibr does (:mod:`vibr.camera`), so no
axis flip is needed: ``R = R_wcᵀ``, ``t = −R C``. The browser draws the scene (and the
background image the viewer sends) with the pinhole of three.js's PerspectiveCamera: square
pixels, principal point at the image centre, ``f = (H / 2) / tan(fov / 2)`` pixels for an
image ``H`` pixels high; with vibr's pixel convention (the centre of the top-left pixel at
(0, 0)) the principal point is ``((W − 1) / 2, (H − 1) / 2)``.
"""

from __future__ import annotations

import math

import numpy as np

from ..camera import Camera
from ..errors import VibrInputError

__all__ = ["camera_from_viser", "viser_pose_from_camera", "image_size", "quat_to_matrix",
           "matrix_to_quat"]


def quat_to_matrix(wxyz) -> np.ndarray:
    """Rotation matrix of a quaternion ``(w, x, y, z)`` (normalised first)."""
    q = np.asarray(wxyz, dtype=np.float64).reshape(4)
    n = np.linalg.norm(q)
    if not np.isfinite(n) or n < 1e-12:
        raise VibrInputError(f"camera quaternion {q.tolist()} is not a rotation")
    w, x, y, z = q / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quat(R) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` with ``w ≥ 0`` of a rotation matrix (Shepperd's
    method: the largest of the four squared components is taken first, for stability)."""
    R = np.asarray(R, dtype=np.float64).reshape(3, 3)
    tr = np.trace(R)
    d = np.array([tr, R[0, 0], R[1, 1], R[2, 2]])
    i = int(np.argmax(d))
    if i == 0:
        w = 0.5 * math.sqrt(max(1.0 + tr, 0.0))
        q = [w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)]
    elif i == 1:
        x = 0.5 * math.sqrt(max(1.0 + 2 * R[0, 0] - tr, 0.0))
        q = [(R[2, 1] - R[1, 2]) / (4 * x), x, (R[0, 1] + R[1, 0]) / (4 * x), (R[0, 2] + R[2, 0]) / (4 * x)]
    elif i == 2:
        y = 0.5 * math.sqrt(max(1.0 + 2 * R[1, 1] - tr, 0.0))
        q = [(R[0, 2] - R[2, 0]) / (4 * y), (R[0, 1] + R[1, 0]) / (4 * y), y, (R[1, 2] + R[2, 1]) / (4 * y)]
    else:
        z = 0.5 * math.sqrt(max(1.0 + 2 * R[2, 2] - tr, 0.0))
        q = [(R[1, 0] - R[0, 1]) / (4 * z), (R[0, 2] + R[2, 0]) / (4 * z), (R[1, 2] + R[2, 1]) / (4 * z), z]
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def image_size(aspect: float, long_side: int) -> tuple[int, int]:
    """``(width, height)`` of an image of ``aspect`` = width / height whose longer side is
    ``long_side`` pixels (the other rounded, at least 1)."""
    a = float(aspect)
    if not (a > 0 and math.isfinite(a)):
        raise VibrInputError(f"canvas aspect must be positive, got {aspect!r}")
    L = int(long_side)
    if L < 1:
        raise VibrInputError(f"image size must be at least 1 pixel, got {long_side!r}")
    if a >= 1:
        return L, max(1, int(round(L / a)))
    return max(1, int(round(L * a))), L


def camera_from_viser(wxyz, position, fov_y: float, aspect: float, long_side: int) -> Camera:
    """The vibr camera of a viser viewport, for an image of long side ``long_side`` px.

    ``R = R_wcᵀ`` (``R_wc`` the rotation of ``wxyz``), ``C = position``,
    ``K = [[f, 0, (W−1)/2], [0, f, (H−1)/2], [0, 0, 1]]`` with ``f = (H/2) / tan(fov_y/2)``
    and ``(W, H) = image_size(aspect, long_side)`` (module docstring). The horizontal field
    of view of the result is then the browser's (``W/H`` = the canvas aspect, up to rounding).
    """
    fov = float(fov_y)
    if not (0.0 < fov < math.pi):
        raise VibrInputError(f"vertical field of view must be in (0, pi) radians, got {fov_y!r}")
    C = np.asarray(position, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(C)):
        raise VibrInputError(f"camera position {C.tolist()} is not finite")
    W, H = image_size(aspect, long_side)
    f = (H / 2.0) / math.tan(fov / 2.0)
    K = Camera.intrinsics(f, W, H)
    return Camera.from_centre(K, quat_to_matrix(wxyz).T, C, W, H)


def viser_pose_from_camera(camera: Camera) -> tuple[np.ndarray, np.ndarray, float, float]:
    """``(wxyz, position, fov_y, aspect)`` of a vibr camera, for viser (frustums, moving the
    viewport): the inverse of :func:`camera_from_viser` for a centred square-pixel camera;
    otherwise the vertical fov of ``K[1, 1]`` and the image's aspect."""
    wxyz = matrix_to_quat(camera.R.T)
    fov = 2.0 * math.atan((camera.height / 2.0) / float(camera.K[1, 1]))
    return wxyz, camera.centre.copy(), fov, camera.width / camera.height
