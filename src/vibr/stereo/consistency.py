"""Geometric consistency of depth maps across views (the MVS filtering step).

A reference depth is kept when at least ``min_agree`` neighbouring depth maps see the same
surface: the reference point projected into neighbour v has depth z_v within ``rel_tol·z_v``
of the neighbour's own depth there, and the neighbour's point projected back into the
reference lands within ``px_tol`` pixels (forward-backward check, as in COLMAP's
geometric filtering, Schönberger et al. 2016 §4.3). The spread of the agreeing depths
(in the reference frame) is a second depth-uncertainty estimate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import Camera
from . import _kernels as kern


@dataclass
class ConsistencyResult:
    """n_agree (H,W) int32 agreeing neighbours; reproj (H,W) float64 mean round-trip
    error in reference pixels (NaN where none agrees); spread (H,W) float64 std of the
    agreeing depths (scene units, NaN where none); keep (H,W) bool."""

    n_agree: np.ndarray
    reproj: np.ndarray
    spread: np.ndarray
    keep: np.ndarray


def check_consistency(depth: np.ndarray, camera: Camera, nb_depths: list[np.ndarray],
                      nb_cameras: list[Camera], *, rel_tol: float = 0.01, px_tol: float = 1.0,
                      min_agree: int = 1) -> ConsistencyResult:
    """Forward-backward consistency of ``depth`` (H×W, NaN unknown) of ``camera`` against
    the neighbours' depth maps (NaN unknown) and cameras. See the module docstring."""
    H, W = camera.shape
    if len(nb_depths) == 0:
        z = np.zeros((H, W), np.int32)
        nan = np.full((H, W), np.nan)
        return ConsistencyResult(z, nan, nan.copy(), np.zeros((H, W), bool))
    Hm = max(d.shape[0] for d in nb_depths)
    Wm = max(d.shape[1] for d in nb_depths)
    D = np.full((len(nb_depths), Hm, Wm), np.nan)
    sizes = np.zeros((len(nb_depths), 2), np.int64)
    for v, d in enumerate(nb_depths):
        D[v, : d.shape[0], : d.shape[1]] = d
        sizes[v] = d.shape
    # writable C-ordered float64 copies: a transposed or read-only rotation would compile the kernel again
    f8 = lambda a: np.array(a, np.float64, order="C")  # noqa: E731
    Ks, Rs, ts = (f8(np.stack([getattr(c, a) for c in nb_cameras])) for a in ("K", "R", "t"))
    n, reproj, spread = kern.consistency(
        f8(depth), f8(np.linalg.inv(camera.K)), f8(camera.R), f8(camera.t), D, sizes,
        Ks, Rs, ts, float(rel_tol), float(px_tol))
    return ConsistencyResult(n, reproj, spread, n >= int(min_agree))
