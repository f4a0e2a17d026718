"""Geometric consistency of depth maps across views (the MVS filtering step).

A reference depth is kept when at least ``min_agree`` neighbouring depth maps see the same
surface: the reference point projected into neighbour v has depth z_v within ``rel_tol·z_v``
of the neighbour's own depth there, and the neighbour's point projected back into the
reference lands within ``px_tol`` pixels (forward-backward check, as in COLMAP's
geometric filtering, Schönberger et al. 2016 §4.3). The spread of the agreeing depths
(in the reference frame) is a second depth-uncertainty estimate, and their mean the
views' consensus (:func:`consensus_depth`).
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
    agreeing depths (scene units, NaN where none); keep (H,W) bool; mean (H,W) float64 the
    mean of the reference depth and the agreeing depths, in the reference frame (the
    reference depth where none agrees, NaN where it is unknown)."""

    n_agree: np.ndarray
    reproj: np.ndarray
    spread: np.ndarray
    keep: np.ndarray
    mean: np.ndarray


def check_consistency(depth: np.ndarray, camera: Camera, nb_depths: list[np.ndarray],
                      nb_cameras: list[Camera], *, rel_tol: float = 0.01, px_tol: float = 1.0,
                      min_agree: int = 1) -> ConsistencyResult:
    """Forward-backward consistency of ``depth`` (H×W, NaN unknown) of ``camera`` against
    the neighbours' depth maps (NaN unknown) and cameras. See the module docstring."""
    H, W = camera.shape
    if len(nb_depths) == 0:
        z = np.zeros((H, W), np.int32)
        nan = np.full((H, W), np.nan)
        return ConsistencyResult(z, nan, nan.copy(), np.zeros((H, W), bool), np.array(depth, np.float64))
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
    n, reproj, spread, mean = kern.consistency(
        f8(depth), f8(np.linalg.inv(camera.K)), f8(camera.R), f8(camera.t), D, sizes,
        Ks, Rs, ts, float(rel_tol), float(px_tol))
    return ConsistencyResult(n, reproj, spread, n >= int(min_agree), mean)


def consensus_depth(depths: list[np.ndarray], cameras: list[Camera], *, rel_tol: float,
                    n_neighbours: int = 8) -> tuple[list[np.ndarray], list[float]]:
    """The views' consensus on their depth: each pixel's depth replaced by the mean of its
    own and of the depths of its ``n_neighbours`` nearest views (by camera centre) that see
    the same point within ``rel_tol`` (:func:`check_consistency`'s depth test, without its
    round-trip bound).

    Every view is compared with the others' own estimates, never with a consensus already
    taken, so the result does not depend on the order of the views. Returns the depth maps
    (float32, NaN where unknown, as given) and each view's mean number of agreeing views
    over its known pixels.

    Examples
    --------
    >>> from vibr.synthetic import make_scene
    >>> sc = make_scene("grid", n_views=4, width=32, height=32)
    >>> out, agree = consensus_depth([v.depth for v in sc.views], [v.camera for v in sc.views], rel_tol=0.05)
    >>> float(np.nanmedian(np.abs(out[0] - sc.views[0].depth) / sc.views[0].depth)) < 1e-4  # exact depth stays
    True
    """
    if rel_tol < 0 or not np.isfinite(rel_tol):
        raise ValueError(f"rel_tol must be a finite fraction >= 0, got {rel_tol!r}")
    if len(depths) != len(cameras):
        raise ValueError(f"{len(depths)} depth maps for {len(cameras)} cameras")
    centres = np.array([c.centre for c in cameras], np.float64).reshape(-1, 3)
    out, agree = [], []
    for i, (d, cam) in enumerate(zip(depths, cameras)):
        dist = np.linalg.norm(centres - centres[i], axis=1)
        nb = [j for j in np.argsort(dist, kind="stable") if j != i][: int(n_neighbours)]
        if rel_tol == 0 or not nb:
            out.append(np.asarray(d, np.float32))
            agree.append(0.0)
            continue
        cr = check_consistency(d, cam, [depths[j] for j in nb], [cameras[j] for j in nb], rel_tol=rel_tol,
                               px_tol=np.inf)
        out.append(cr.mean.astype(np.float32))
        known = np.isfinite(d)
        agree.append(float(cr.n_agree[known].mean()) if known.any() else 0.0)
    return out, agree
