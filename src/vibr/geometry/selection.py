"""Choosing the source views that matter for a target.

For a scene with many views, rendering from all of them costs time linear in the number of
views while only the few that see the target's surfaces from nearby directions contribute
(ULR, Buehler et al. 2001, §3: views are ranked by angular and resolution penalties). vibr
ranks source views by

    penalty_k = mean over target-visible points X of  angle_k(X) + beta * max(0, 1 - d_u(X)/d_k(X))

where ``angle_k(X)`` is the angle (radians) between the rays from the target centre and from
source k to X, ``d`` are distances to X (the resolution term: a source farther than the target
sees X at lower resolution), and only points that project inside source k with positive depth
count; views seeing less than ``min_overlap`` of the points are ranked last. The points X are
a subsample of the sources' depth maps that project inside the target (or the scene's sparse
points, or a plane through the scene when no geometry is known).
"""

from __future__ import annotations

import numpy as np

from ..camera import Camera, axes_meeting_point
from ..scene import Scene


def depth_points(view, n_points: int) -> np.ndarray:
    """About ``n_points`` world points of ``view``'s depth map: the known depths of a
    regular stride (``sqrt(H·W / n_points)`` pixels) backprojected; (0, 3) without depth."""
    if view.depth is None:
        return np.zeros((0, 3))
    h, w = view.shape
    step = max(1, int(np.sqrt(h * w / n_points)))
    z = view.depth[::step, ::step]
    yy, xx = np.mgrid[0:h:step, 0:w:step]
    ok = np.isfinite(z)
    return view.camera.backproject(np.stack([xx[ok], yy[ok]], -1).astype(float), z[ok])


def target_points(sources: Scene, target: Camera, max_points: int = 1024) -> np.ndarray:
    """(N, 3) world points the target camera sees, from the sources' geometry.

    Uses a strided subsample of every source depth map, keeps those in front of the target
    and inside its image. Falls back to the scene's sparse points, then (a scene with no
    geometry at all) to a plane perpendicular to the target's axis through the point where
    the cameras' axes meet (:func:`vibr.camera.axes_meeting_point`), or at 4× the mean
    target–source distance when they do not meet (parallel rigs).
    """
    pts = []
    per_view = max(64, max_points // max(1, len(sources)))
    for v in sources.views:
        p = depth_points(v, per_view)
        if len(p):
            pts.append(p)
    if not pts and sources.points is not None and len(sources.points):
        pts = [np.asarray(sources.points, dtype=np.float64)]
    if pts:
        P = np.concatenate(pts)
        P = P[target.sees(P)[2]]
        if len(P):
            if len(P) > max_points:
                P = P[np.random.default_rng(0).choice(len(P), max_points, replace=False)]
            return P
    # No geometry: a fronto-parallel plane in the target, through the point the cameras'
    # axes meet when they converge on an object (a ring), else at 4× the mean distance
    # between the target and the sources (parallel rigs: far enough for the angle term).
    X = axes_meeting_point([target] + [v.camera for v in sources.views])
    z = float((X - target.centre) @ target.optical_axis) if X is not None else 0.0
    if z <= 0:
        dist = np.mean([np.linalg.norm(v.camera.centre - target.centre) for v in sources.views])
        z = 4.0 * dist if dist > 0 else 1.0
    g = target.pixel_grid()[:: max(1, target.height // 16), :: max(1, target.width // 16)].reshape(-1, 2)
    return target.backproject(g, np.full(len(g), z))


def rank_views(sources: Scene, target: Camera, *, beta: float = 1.0, min_overlap: float = 0.05,
               points: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rank source views for a target, best first.

    Returns ``(order, penalty, overlap)``: indices into ``sources.views`` sorted by increasing
    penalty (views with overlap below ``min_overlap`` last), and each view's penalty
    (radians-equivalent, see the module docstring) and overlap fraction in [0, 1].
    """
    X = target_points(sources, target) if points is None else points
    to_u = X - target.centre
    d_u = np.linalg.norm(to_u, axis=1)
    n = len(sources)
    penalty = np.full(n, np.inf)
    overlap = np.zeros(n)
    for k, v in enumerate(sources.views):
        cam = v.camera
        seen = cam.sees(X)[2]
        overlap[k] = seen.mean() if len(X) else 0.0
        if not np.any(seen):
            continue
        to_k = X[seen] - cam.centre
        d_k = np.linalg.norm(to_k, axis=1)
        cosang = np.einsum("ij,ij->i", to_u[seen], to_k) / np.maximum(d_u[seen] * d_k, 1e-300)
        ang = np.arccos(np.clip(cosang, -1.0, 1.0))
        res = np.maximum(0.0, 1.0 - d_u[seen] / np.maximum(d_k, 1e-300))
        penalty[k] = float(np.mean(ang + beta * res))
    key = np.where(overlap >= min_overlap, penalty, np.inf)
    order = np.lexsort((penalty, -overlap, key))  # by key, ties by overlap then penalty
    return order, penalty, overlap


def select_views(sources: Scene, target: Camera, k: int, **kw) -> list[int]:
    """Indices of the ``k`` best source views for ``target`` (all views when ``k`` ≥ their
    number), in the scene's original order. See :func:`rank_views`."""
    if k is None or k >= len(sources):
        return list(range(len(sources)))
    order, _, overlap = rank_views(sources, target, **kw)
    chosen = [int(i) for i in order[:k]]
    return sorted(chosen)
