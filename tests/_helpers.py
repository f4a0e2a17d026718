"""Plain helpers shared by the tests (fixtures are in conftest.py)."""

from __future__ import annotations

import numpy as np

from vibr.camera import Camera


def pinhole(f, W, H, R=np.eye(3), C=(0, 0, 0), cx=None, cy=None) -> Camera:
    """A ``W`` × ``H`` pinhole camera of focal length ``f`` (pixels) at centre ``C``, rotation
    ``R`` (world to camera), principal point ``(cx, cy)`` (the image centre by default)."""
    return Camera.from_centre(Camera.intrinsics(f, W, H, cx=cx, cy=cy), R, np.asarray(C, float), W, H)


def rot_about(ax: int, angle: float) -> np.ndarray:
    """The rotation by ``angle`` radians about coordinate axis ``ax`` (0: x, 1: y, 2: z)."""
    c, s = np.cos(angle), np.sin(angle)
    R = np.eye(3)
    i, j = [(1, 2), (0, 2), (0, 1)][ax]
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def rodrigues(axis, deg: float) -> np.ndarray:
    """The rotation by ``deg`` degrees about ``axis`` (any length; Rodrigues' formula)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    th = np.radians(deg)
    Kx = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(th) * Kx + (1 - np.cos(th)) * Kx @ Kx


def rot2d(t: float) -> np.ndarray:
    """The 2 × 2 rotation by ``t`` radians."""
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
