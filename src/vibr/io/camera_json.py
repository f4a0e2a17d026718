"""Bare target cameras as JSON (the :meth:`Camera.to_dict` format) and shared camera helpers.

A camera file is ``{"K": [[...]*3], "R": [[...]*3], "t": [...], "width": W, "height": H}``
in vibr's conventions (:mod:`vibr.camera`: ``x̃ = K (R X + t)``, centre of the top-left pixel
at (0, 0)).
"""

from __future__ import annotations

import json
import os

import numpy as np

from .._runtime.atomic import atomic_path
from ..camera import Camera
from ..errors import VibrInputError, require_file

#: Largest |R Rᵀ − I| accepted from a file (text files round to ~6 digits); such matrices
#: are snapped to the nearest rotation. Anything worse is reported as not a rotation.
ROTATION_TOL = 1e-4


def as_rotation(R, source=None, what: str = "R") -> np.ndarray:
    """Check a 3×3 matrix read from a file and return the nearest rotation.

    Matrices within :data:`ROTATION_TOL` of orthonormal (rounded text values) are snapped to
    ``U Vᵀ`` of their SVD; others, or reflections (det < 0), raise :class:`VibrInputError`.
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise VibrInputError(f"{what} must be a finite 3x3 matrix", source)
    err = float(np.abs(R @ R.T - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if err > ROTATION_TOL or det < 0:
        raise VibrInputError(f"{what} is not a rotation matrix (|R Rᵀ - I| = {err:.2g}, det = {det:.3g})", source)
    if err == 0.0:
        return R
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def as_scaled_rotation(M, source=None, what: str = "R") -> tuple[np.ndarray, float]:
    """A 3×3 matrix that is a rotation times a uniform scale ``s > 0`` → ``(R, s)``.

    A camera-to-world matrix from 3-D software carries the camera object's scale
    (Blender's ``matrix_world`` of a scaled camera); it scales the rays' directions, not
    their lines, so the rotation is the camera. Shear, non-uniform scale and reflections
    raise :class:`VibrInputError` (:func:`as_rotation`'s tolerance, relative to ``s``)."""
    M = np.asarray(M, dtype=np.float64)
    if M.shape != (3, 3) or not np.all(np.isfinite(M)):
        raise VibrInputError(f"{what} must be a finite 3x3 matrix", source)
    det = float(np.linalg.det(M))
    if not det > 0:
        return as_rotation(M, source, what), 1.0  # its error names the reflection or singularity
    s = det ** (1.0 / 3.0)
    sv = np.linalg.svd(M, compute_uv=False)
    if np.abs(sv / s - 1.0).max() > ROTATION_TOL:
        raise VibrInputError(f"{what} is not a rotation matrix, nor one with a uniform scale (singular values "
                             f"{sv[0]:.4g}, {sv[1]:.4g}, {sv[2]:.4g}: shear or a scale that differs by axis)",
                             source)
    return as_rotation(M / s, source, what), s


def parse_json(path) -> object:
    """Load a JSON file; syntax errors become one-line :class:`VibrInputError` s. A UTF-8
    byte-order mark (what Windows editors write) is accepted."""
    p = require_file(path)
    try:
        with open(p, encoding="utf-8-sig") as f:
            return json.load(f)
    except json.JSONDecodeError as exc:
        raise VibrInputError(f"malformed JSON: {exc.msg} at line {exc.lineno} column {exc.colno}", p) from None
    except UnicodeDecodeError:
        raise VibrInputError("malformed JSON: not UTF-8 text", p) from None


def read_camera_json(path) -> Camera:
    """Read a bare camera written by :func:`write_camera_json` (``Camera.to_dict`` format)."""
    p = os.fspath(path)
    d = parse_json(p)
    if not isinstance(d, dict):
        raise VibrInputError("a camera file must hold a JSON object with K, R, t, width, height", p)
    for k in ("K", "R", "t", "width", "height"):
        if k not in d:
            raise VibrInputError(f"camera is missing key {k!r}", p)
    try:
        R = as_rotation(np.asarray(d["R"], dtype=np.float64).reshape(3, 3), p)
        return Camera(d["K"], R, d["t"], d["width"], d["height"], p)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, VibrInputError):
            raise
        raise VibrInputError(f"bad camera values ({exc})", p) from None


def write_camera_json(path, camera: Camera) -> None:
    """Write ``camera.to_dict()`` as JSON, atomically (floats written exactly, by repr)."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(camera.to_dict(), f, indent=2)
            f.write("\n")
