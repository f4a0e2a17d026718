"""Photographs turned on the spot: recognised from COLMAP's matches and calibrated as such.

COLMAP's incremental mapper gives every image a translation and triangulates points from the
baseline. Photographs taken from one point (a panorama from a tripod, a video panned on the
spot) have no baseline: on a synthetic pan the mapper either invented one (20 frames spread
over 11 scene units, a focal length of 386 px for a true 307 px) or registered 9–11 of 20 frames
without a single point (docs/explanation/calibration.md, "Turned on the spot").

**The rotation-only model.** Every observation ``x_ij`` of track ``j`` in image ``i`` is the
image of a direction ``d_j``::

    x_ij = π_c(R_i d_j)                                                     (1)

``π_c`` the camera's projection with its distortion (COLMAP's model, principal point held),
``R_i`` the image's rotation (world → camera; the first image's is held: the gauge). For
given rotations and intrinsics the best direction is, to first order, the normalised sum of
the observations' rays ``R_iᵀ π_c⁻¹(x_ij)``; eliminating ``d_j`` so (variable projection,
Golub & Pereyra 1973) leaves ``3(n − 1)`` rotation parameters and each camera's focal length
and distortion, fitted by Levenberg–Marquardt on a Huber cost (:func:`robust_lm`). With one
axis of turn the focal length is still determined: a turn by θ maps a point ``x`` pixels from
the centre to ``f tan(atan(x/f) + θ)``, which depends on ``f``.

**From the matches, not the mapper** (:func:`fit_one_centre`). The tracks are the connected
sets of COLMAP's verified matches (:func:`tracks_from_matches`); the focal length to start
from makes the pairs' ``K⁻¹ H K`` nearest to rotations (:func:`focal_from_homographies`), the
starting rotations are chained along the pairs with the most inliers
(:func:`chain_rotations`), and tracks the start cannot explain (wrong matches join the
tracks of two points) are left out of the fit.

**Which model** (:func:`prefer_one_centre`). Only where at least
:data:`MIN_HOMOGRAPHY_SHARE` of the verified pairs are related by a homography by COLMAP's
own two-view classification is the model fitted; COLMAP's mapper runs anyway, and one centre
is taken when the mapper's model explains its points no better (within
:data:`MAX_MAPPER_RATIO`), or when the mapper registered fewer photos and one centre explains
the matches within :data:`MAX_HOMOGRAPHY_RATIO` times the pairs' own homographies.

:func:`rotation_only_reconstruction` builds the COLMAP model: every image at the origin with
its fitted rotation, the fitted intrinsics, the tracks' directions at unit distance. vibr
recognises such a scene as sharing a centre (:func:`vibr.camera.shared_centre`); its renders
need no depth (docs/explanation/renderer.md, "Rotation-only captures").
"""

from __future__ import annotations

import copy
import logging
from dataclasses import dataclass, replace

import numpy as np

from .._runtime.pycolmap import import_pycolmap

__all__ = [
    "MAX_REPROJECTION_PX",
    "MAX_HOMOGRAPHY_RATIO",
    "MAX_MAPPER_RATIO",
    "MAX_TRACKS",
    "COARSE_TRACKS",
    "MIN_TRACKS",
    "START_ERROR_FACTOR",
    "MIN_HOMOGRAPHY_SHARE",
    "PLAUSIBLE_FOCAL",
    "Choice",
    "Matches",
    "OneCentre",
    "RotationFit",
    "Tracks",
    "chain_rotations",
    "with_focal_scaled",
    "fit_one_centre",
    "focal_from_homographies",
    "focal_note",
    "fit_rotation_only",
    "homography_error",
    "huber_cost",
    "point_error",
    "prefer_one_centre",
    "read_matches",
    "robust_lm",
    "rotation_only_reconstruction",
    "tracks_from_matches",
]

logger = logging.getLogger(__name__)

#: The share of verified image pairs COLMAP classifies as related by a homography from which
#: the rotation-only model is fitted at all (on a synthetic pan 69 of 69; on a walk along an
#: arc 17 of 69, on fountain-P11 12 of 52, on the temple ring 2 of 33).
MIN_HOMOGRAPHY_SHARE = 0.5
#: One centre is taken when its points' median error is at most this many times that of
#: the mapper's model (which has a centre per photo and a depth per point more to fit with).
MAX_MAPPER_RATIO = 1.25
#: ... or, where the mapper registered fewer photos, when it explains the matches within this
#: many times the median error of the pairs' own homographies.
MAX_HOMOGRAPHY_RATIO = 2.0
#: Tracks the fit uses at most (a seeded sample: the fit's time grows with images × tracks),
#: after a first fit on ``COARSE_TRACKS`` of them.
MAX_TRACKS = 3000
COARSE_TRACKS = 500
#: Fewer tracks than this that the model explains: no model of one centre.
MIN_TRACKS = 20
#: Focal lengths, in units of the image's longer side, that a camera plausibly has (the
#: range :func:`focal_from_homographies` searches from COLMAP's prior of 1.2).
PLAUSIBLE_FOCAL = (0.3, 4.8)
#: Before the first fit, tracks with an observation further than this many times the median
#: track's largest error (or :data:`MAX_REPROJECTION_PX`) from the starting model are left out.
START_ERROR_FACTOR = 5.0
#: Observations further than this from their track's direction are left out of the model
#: (COLMAP's own filter after triangulation).
MAX_REPROJECTION_PX = 4.0


# ---------------------------------------------------------------------------- the matches
@dataclass
class Matches:
    """What a COLMAP database holds after matching, as arrays.

    ``image_ids``, ``names``, ``camera_of_image`` (index into ``cameras``, pycolmap Camera
    objects with their prior intrinsics), ``keypoints`` one (N_i, 2) array per image (COLMAP's
    pixel convention), and per verified pair: ``pairs`` (P, 2) image indices, ``inliers``
    one (k, 2) array of keypoint indices each, ``H`` (P, 3, 3) with ``x_j ~ H x_i``, and
    ``homography`` (P,) whether COLMAP classified the pair as related by one.
    """

    image_ids: np.ndarray
    names: list
    camera_of_image: np.ndarray
    cameras: list
    keypoints: list
    pairs: np.ndarray
    inliers: list
    H: np.ndarray
    homography: np.ndarray

    @property
    def n_images(self) -> int:
        return len(self.image_ids)


def read_matches(database) -> Matches:
    """The images, keypoints and verified pairs of a COLMAP database."""
    pycolmap = import_pycolmap()
    C = pycolmap.TwoViewGeometryConfiguration
    homography = {int(C.PLANAR_OR_PANORAMIC), int(C.PANORAMIC)}
    db = pycolmap.Database.open(str(database))
    try:
        images = sorted(db.read_all_images(), key=lambda im: im.image_id)
        cams = sorted(db.read_all_cameras(), key=lambda c: c.camera_id)
        keypoints = [np.asarray(db.read_keypoints(im.image_id), np.float64)[:, :2] for im in images]
        pair_ids, geoms = db.read_two_view_geometries()
    finally:
        db.close()
    index = {im.image_id: k for k, im in enumerate(images)}
    cam_index = {c.camera_id: k for k, c in enumerate(cams)}
    pairs, inliers, H, hom = [], [], [], []
    for pid, g in zip(pair_ids, geoms):
        m = np.asarray(g.inlier_matches, np.int64).reshape(-1, 2)
        if len(m) == 0:
            continue
        a, b = pycolmap.pair_id_to_image_pair(int(pid))
        pairs.append((index[a], index[b]))
        inliers.append(m)
        H.append(np.asarray(g.H, np.float64))
        hom.append(int(g.config) in homography)
    return Matches(
        image_ids=np.array([im.image_id for im in images]),
        names=[im.name for im in images],
        camera_of_image=np.array([cam_index[im.camera_id] for im in images], dtype=np.int64),
        cameras=cams,
        keypoints=keypoints,
        pairs=np.array(pairs, np.int64).reshape(-1, 2),
        inliers=inliers,
        H=np.array(H).reshape(-1, 3, 3),
        homography=np.array(hom, bool),
    )


@dataclass
class Tracks:
    """Observations of tracks as flat arrays: ``image`` (index into the images), ``keypoint``
    (index into that image's keypoints), ``track`` (0 … n_tracks − 1) and ``xy`` (k, 2)."""

    image: np.ndarray
    keypoint: np.ndarray
    track: np.ndarray
    xy: np.ndarray

    @property
    def n_tracks(self) -> int:
        return int(self.track.max()) + 1 if len(self.track) else 0

    def subset(self, tracks: np.ndarray) -> Tracks:
        """The observations of ``tracks`` (sorted ids), renumbered 0 … len − 1."""
        keep = np.isin(self.track, tracks)
        return Tracks(self.image[keep], self.keypoint[keep], np.searchsorted(tracks, self.track[keep]),
                      self.xy[keep])


def tracks_from_matches(m: Matches, images: np.ndarray | None = None) -> Tracks:
    """The tracks of the verified matches between ``images`` (indices; all by default): the
    connected components of the graph whose nodes are keypoints and whose edges are inlier
    matches. A component that holds two keypoints of one image is left out (a wrong match
    joined two tracks)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    use = np.ones(m.n_images, bool) if images is None else np.isin(np.arange(m.n_images), images)
    offset = np.concatenate([[0], np.cumsum([len(k) for k in m.keypoints])])
    rows, cols = [], []
    for (i, j), inl in zip(m.pairs, m.inliers):
        if use[i] and use[j]:
            rows.append(offset[i] + inl[:, 0])
            cols.append(offset[j] + inl[:, 1])
    n = int(offset[-1])
    if not rows:
        return Tracks(*(np.zeros(0, np.int64),) * 3, np.zeros((0, 2)))
    r, c = np.concatenate(rows), np.concatenate(cols)
    _, label = connected_components(coo_matrix((np.ones(len(r)), (r, c)), shape=(n, n)), directed=False)
    node = np.unique(np.concatenate([r, c]))  # keypoints that are matched at all
    image = np.searchsorted(offset, node, side="right") - 1
    lab = label[node]
    # a component with two keypoints of one image: a wrong match somewhere; drop it
    size = np.bincount(lab, minlength=n)
    distinct = np.bincount(np.unique(lab * m.n_images + image) // m.n_images, minlength=n)
    good = (size[lab] == distinct[lab]) & (size[lab] >= 2)
    node, image, lab = node[good], image[good], lab[good]
    _, track = np.unique(lab, return_inverse=True)
    keypoint = node - offset[image]
    xy = np.concatenate(m.keypoints)[node].reshape(-1, 2)
    order = np.lexsort((image, track))
    return Tracks(image[order], keypoint[order], track[order].astype(np.int64), xy[order])


def _calibration(cam) -> np.ndarray:
    f = cam.focal_length_x, cam.focal_length_y
    return np.array([[f[0], 0.0, cam.principal_point_x], [0.0, f[1], cam.principal_point_y], [0.0, 0.0, 1.0]])


def focal_from_homographies(m: Matches, scales=np.geomspace(0.25, 4.0, 49)) -> float:
    """The factor of the cameras' prior focal lengths that makes the homography pairs' ``K⁻¹
    H K`` nearest to rotations: the median over the pairs of ``‖MᵀM − I‖`` (``M`` scaled to
    determinant 1), least over ``scales``; 1 where no pair is related by a homography."""
    hom = np.flatnonzero(m.homography)
    if len(hom) == 0:
        return 1.0
    Ks = np.array([_calibration(c) for c in m.cameras])  # (c, 3, 3)
    f = np.asarray(scales, np.float64)[:, None, None, None]
    K = Ks[None] * (1.0 + (f - 1.0) * np.diag([1.0, 1.0, 0.0]))  # (g, c, 3, 3): fx, fy scaled
    Ki = K[:, m.camera_of_image[m.pairs[hom, 0]]]  # (g, p, 3, 3)
    Kj = K[:, m.camera_of_image[m.pairs[hom, 1]]]
    M = np.linalg.solve(Kj, m.H[hom][None] @ Ki)
    M /= np.cbrt(np.linalg.det(M))[..., None, None]
    dev = np.linalg.norm(M.transpose(0, 1, 3, 2) @ M - np.eye(3), axis=(2, 3))
    return float(np.asarray(scales)[np.argmin(np.median(dev, axis=1))])


def with_focal_scaled(m: Matches, factor: float) -> Matches:
    """``m`` with every camera's focal length(s) multiplied by ``factor``."""
    params = []
    for c in m.cameras:
        p = np.array(c.params, np.float64)
        p[list(c.focal_length_idxs())] *= factor
        params.append(p)
    return _with_params(m, params)


def _with_params(m: Matches, params: list) -> Matches:
    """``m`` with its cameras' parameters replaced (copies: ``m``'s cameras unchanged)."""
    cams = []
    for c, p in zip(m.cameras, params):
        c = copy.copy(c)
        c.params = p
        cams.append(c)
    return replace(m, cameras=cams)


def chain_rotations(m: Matches) -> tuple[np.ndarray, np.ndarray]:
    """Starting rotations (n, 3, 3) chained from the pairs' homographies along a spanning
    tree of the pairs with the most inliers, and the images of the largest connected part
    of the pair graph (indices; the others are left without a rotation, the identity)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

    n = m.n_images
    R = np.repeat(np.eye(3)[None], n, axis=0)
    if len(m.pairs) == 0:
        return R, np.zeros(0, np.int64)
    w = 1.0 / np.array([len(k) for k in m.inliers], np.float64)  # most inliers = lightest edge
    g = coo_matrix((w, (m.pairs[:, 0], m.pairs[:, 1])), shape=(n, n)).tocsr()
    _, label = connected_components(g, directed=False)
    part = np.flatnonzero(label == np.bincount(label).argmax())
    tree = minimum_spanning_tree(g)
    tree = tree + tree.T
    order, pred = breadth_first_order(tree, int(part[0]), directed=False)
    pair_of = {(int(i), int(j)): p for p, (i, j) in enumerate(m.pairs)}
    for j in order[1:]:
        i = int(pred[j])
        if (i, int(j)) in pair_of:
            Rji = _rotation_from_homography(m, pair_of[(i, int(j))], i, int(j))
        else:
            Rji = _rotation_from_homography(m, pair_of[(int(j), i)], int(j), i).T
        R[j] = Rji @ R[i]
    return R, np.sort(part)


def _rotation_from_homography(m: Matches, p: int, i: int, j: int) -> np.ndarray:
    """``R_j R_iᵀ``: the rotation nearest to ``K_j⁻¹ H K_i`` (``H`` maps image i to j)."""
    Ki = _calibration(m.cameras[m.camera_of_image[i]])
    Kj = _calibration(m.cameras[m.camera_of_image[j]])
    M = np.linalg.solve(Kj, m.H[p] @ Ki)
    U, _, Vt = np.linalg.svd(M)
    Rji = U @ Vt
    return Rji if np.linalg.det(Rji) > 0 else -Rji


def homography_error(m: Matches) -> float:
    """Median distance (px) of each inlier of a homography-related pair from its partner
    mapped by the pair's homography: how well 8 free parameters a pair explain the matches."""
    errs = []
    for p in np.flatnonzero(m.homography):
        i, j = m.pairs[p]
        x = m.keypoints[i][m.inliers[p][:, 0]]
        y = m.keypoints[j][m.inliers[p][:, 1]]
        h = np.c_[x, np.ones(len(x))] @ m.H[p].T
        errs.append(np.linalg.norm(h[:, :2] / h[:, 2:] - y, axis=1))
    return float(np.median(np.concatenate(errs))) if errs else float("nan")


# ---------------------------------------------------------------------------- the fit
@dataclass
class RotationFit:
    """The rotation-only model fitted to tracks (equation (1)): ``rotations`` (n, 3, 3) world
    → camera (of every image; meaningful for ``images``), ``params`` one array of COLMAP
    camera parameters per camera, ``median_px`` the median error of the fitted observations,
    ``iterations`` those of the least-squares fit."""

    rotations: np.ndarray
    params: list
    images: np.ndarray
    median_px: float
    iterations: int


class _Model:
    """Equation (1) with the directions eliminated, over the free parameters ``x``: the
    rotation vectors of ``images[1:]`` (relative to ``R0``), then each camera's focal
    length(s) and distortion parameters."""

    def __init__(self, tracks: Tracks, camera_of_image: np.ndarray, cameras: list, R0: np.ndarray,
                 images: np.ndarray):
        self.t = tracks
        self.cameras = [copy.copy(c) for c in cameras]  # their params are set per evaluation
        self.free = [np.concatenate([c.focal_length_idxs(), c.extra_params_idxs()]).astype(int) for c in cameras]
        self.params0 = [np.array(c.params, dtype=np.float64) for c in cameras]
        self.cam_of_obs = camera_of_image[tracks.image]
        self.R0, self.images = R0, images

    def x0(self) -> np.ndarray:
        return np.concatenate([np.zeros(3 * (len(self.images) - 1))]
                              + [p[f] for p, f in zip(self.params0, self.free)])

    def unpack(self, x):
        """Rotations (n, 3, 3), rotation vectors (n, 3) and camera parameters of ``x``."""
        from scipy.spatial.transform import Rotation

        w = np.zeros((len(self.R0), 3))
        w[self.images[1:]] = x[: 3 * (len(self.images) - 1)].reshape(-1, 3)
        R = Rotation.from_rotvec(w).as_matrix() @ self.R0
        params, o = [], 3 * (len(self.images) - 1)
        for p0, f in zip(self.params0, self.free):
            p = p0.copy()
            p[f] = x[o:o + len(f)]
            params.append(p)
            o += len(f)
        return R, w, params

    def world_rays(self, R, params) -> np.ndarray:
        """Each observation's unit ray in world axes, ``R_iᵀ π_c⁻¹(x)`` normalised."""
        ray = np.ones((len(self.t.xy), 3))
        for c, cam in enumerate(self.cameras):
            sel = self.cam_of_obs == c
            cam.params = params[c]
            ray[sel, :2] = cam.cam_from_img(self.t.xy[sel])
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        return np.einsum("kji,kj->ki", R[self.t.image], ray)

    def track_sums(self, world) -> np.ndarray:
        n = self.t.n_tracks
        return np.stack([np.bincount(self.t.track, world[:, a], minlength=n) for a in range(3)], axis=1)

    def directions(self, R, params) -> np.ndarray:
        """Each track's direction: the normalised sum of its observations' unit rays."""
        s = self.track_sums(self.world_rays(R, params))
        return s / np.maximum(np.linalg.norm(s, axis=1, keepdims=True), 1e-300)

    def project(self, params, Xc) -> np.ndarray:
        out = np.empty((len(Xc), 2))
        for c, cam in enumerate(self.cameras):
            sel = self.cam_of_obs == c
            cam.params = params[c]
            out[sel] = cam.img_from_cam(Xc[sel])
        return out

    def errors(self, R, params, d) -> np.ndarray:
        """(k, 2) projection of each observation's direction minus the observation."""
        return self.project(params, np.einsum("kij,kj->ki", R[self.t.image], d[self.t.track])) - self.t.xy

    def residuals(self, x) -> np.ndarray:
        R, _, params = self.unpack(x)
        r = self.errors(R, params, self.directions(R, params))
        return np.nan_to_num(r, nan=1e3, posinf=1e3, neginf=-1e3).ravel()  # behind a camera: an outlier

    def jacobian(self, x) -> np.ndarray:
        """∂residuals/∂x (2k × len(x), dense): the rotations' columns in closed form, through
        the projection and through the tracks' directions; the intrinsics' by forward
        differences (a handful of columns)."""
        t = self.t
        R, w, params = self.unpack(x)
        world = self.world_rays(R, params)
        s = self.track_sums(world)
        norm = np.maximum(np.linalg.norm(s, axis=1), 1e-300)
        d = s / norm[:, None]
        Xc = np.einsum("kij,kj->ki", R[t.image], d[t.track])
        P = self._projection_jacobian(params, Xc)  # (k, 2, 3)
        Jl = _left_jacobian(w)  # (n, 3, 3)
        col = np.full(len(R), -1)
        col[self.images[1:]] = np.arange(len(self.images) - 1)
        J = np.zeros((2 * len(t.xy), len(x)))
        rows = np.arange(len(t.xy))
        # through the projection: X_c = exp(w_i) R0_i d → ∂X_c/∂w_i = −[X_c]× J_l(w_i)
        free = col[t.image] >= 0
        direct = -(P @ _skew(Xc) @ Jl[t.image])
        _scatter(J, rows[free], col[t.image[free]], direct[free])
        # through the direction: the ray of observation k' moves with w_j (j its image) as
        # ∂(R_jᵀu)/∂w_j = [R_jᵀu]× R0_jᵀ J_l(w_j)ᵀ; d = s/|s| moves as (I − d dᵀ)/|s|
        D = (np.eye(3)[None] - np.einsum("ta,tb->tab", d, d)) / norm[:, None, None]
        Q = P @ R[t.image] @ D[t.track]  # (k, 2, 3)
        G = _skew(world) @ self.R0[t.image].transpose(0, 2, 1) @ Jl[t.image].transpose(0, 2, 1)
        k_idx, kp_idx = _track_pairs(t.track)
        keep = col[t.image[kp_idx]] >= 0
        k_idx, kp_idx = k_idx[keep], kp_idx[keep]
        _scatter(J, k_idx, col[t.image[kp_idx]], Q[k_idx] @ G[kp_idx])
        # the intrinsics: forward differences of the whole residual
        r0 = self.residuals(x)
        for c in range(3 * (len(self.images) - 1), len(x)):
            h = 1e-6 * max(1.0, abs(x[c]))
            xh = x.copy()
            xh[c] += h
            J[:, c] = (self.residuals(xh) - r0) / h
        J[~np.isfinite(J)] = 0.0
        J[np.repeat(np.abs(r0[0::2]) >= 1e3, 2)] = 0.0  # an outlier behind a camera moves nothing
        return J

    def _projection_jacobian(self, params, Xc) -> np.ndarray:
        """∂π_c/∂X_c (k, 2, 3) by central differences of the camera model."""
        h = 1e-6 * np.maximum(np.abs(Xc).max(axis=1, keepdims=True), 1e-12)
        P = np.empty((len(Xc), 2, 3))
        for a in range(3):
            e = np.zeros(3)
            e[a] = 1.0
            P[:, :, a] = (self.project(params, Xc + h * e) - self.project(params, Xc - h * e)) / (2 * h)
        return P


def _skew(v) -> np.ndarray:
    """[v]× for each row of v (k, 3) → (k, 3, 3)."""
    z = np.zeros(len(v))
    return np.stack([z, -v[:, 2], v[:, 1], v[:, 2], z, -v[:, 0], -v[:, 1], v[:, 0], z], axis=1).reshape(-1, 3, 3)


def _left_jacobian(w) -> np.ndarray:
    """SO(3)'s left Jacobian J_l(w) (n, 3, 3): exp(w + ε) ≈ exp(J_l(w) ε) exp(w)."""
    th = np.linalg.norm(w, axis=1)
    small = th < 1e-8
    ths = np.where(small, 1.0, th)
    a = np.where(small, 0.5, (1 - np.cos(ths)) / ths**2)
    b = np.where(small, 1.0 / 6.0, (ths - np.sin(ths)) / ths**3)
    K = _skew(w)
    return np.eye(3)[None] + a[:, None, None] * K + b[:, None, None] * (K @ K)


def _track_pairs(track: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every ordered pair (k, k') of observations of one track (``track`` sorted)."""
    n = np.bincount(track)
    start = np.concatenate([[0], np.cumsum(n)[:-1]])
    rep = n[track]
    k = np.repeat(np.arange(len(track)), rep)
    pos = np.arange(len(k)) - np.repeat(np.cumsum(rep) - rep, rep)
    return k, start[track[k]] + pos


def _scatter(J, obs, block, val) -> None:
    """Add (m, 2, 3) blocks at rows 2·obs, 2·obs + 1 and columns 3·block … 3·block + 2 (each
    (obs, block) at most once)."""
    r = (2 * obs[:, None] + np.arange(2))[:, :, None]
    c = (3 * block[:, None] + np.arange(3))[:, None, :]
    J[np.broadcast_to(r, val.shape), np.broadcast_to(c, val.shape)] += val


def fit_rotation_only(tracks: Tracks, m: Matches, R0: np.ndarray, images: np.ndarray,
                      max_iter: int = 50) -> RotationFit:
    """Fit equation (1) to ``tracks`` of ``images`` (``m``'s cameras, not changed, give the
    model and the starting intrinsics; ``R0`` the starting rotations): :func:`robust_lm`
    with a Huber loss of scale 1 px."""
    model = _Model(tracks, m.camera_of_image, m.cameras, R0, images)
    x, history = robust_lm(model.residuals, model.jacobian, model.x0(), max_iter=max_iter)
    R, _, params = model.unpack(x)
    err = np.linalg.norm(model.errors(R, params, model.directions(R, params)), axis=1)
    return RotationFit(R, params, images, float(np.median(np.nan_to_num(err, nan=np.inf))), len(history) - 1)


def huber_cost(r: np.ndarray, delta: float = 1.0) -> float:
    """Σ_k ρ(e_k) over the observations' errors ``e_k = ‖(r_2k, r_2k+1)‖``, with Huber's
    ``ρ(e) = e²/2`` for ``e ≤ δ`` and ``δ(e − δ/2)`` beyond."""
    e = np.hypot(r[0::2], r[1::2])
    return float(np.sum(np.where(e <= delta, 0.5 * e**2, delta * (e - 0.5 * delta))))


def robust_lm(fun, jac, x0, delta: float = 1.0, max_iter: int = 50, tol: float = 1e-10):
    """Levenberg–Marquardt on the Huber cost of :func:`huber_cost` (iteratively reweighted:
    each step solves ``(JᵀWJ + μ diag JᵀWJ) Δ = −JᵀW r`` with the weights ``w_k = min(1,
    δ/e_k)`` of the observations, Marquardt 1963; Holland & Welsch 1977). A step is taken only
    where it lowers the cost, so the cost never rises. Returns ``x`` and the cost after each
    iteration (the first: at ``x0``)."""
    x = np.asarray(x0, np.float64).copy()
    r = fun(x)
    history = [huber_cost(r, delta)]
    mu = 1e-3
    for _ in range(max_iter):
        J = jac(x)
        e = np.hypot(r[0::2], r[1::2])
        w = np.repeat(np.where(e <= delta, 1.0, delta / np.maximum(e, 1e-300)), 2)
        A = J.T @ (w[:, None] * J)
        g = J.T @ (w * r)
        diag = np.maximum(np.diag(A), 1e-12)
        while mu < 1e12:
            try:
                step = np.linalg.solve(A + mu * np.diag(diag), -g)
            except np.linalg.LinAlgError:
                mu *= 10
                continue
            r_new = fun(x + step)
            cost = huber_cost(r_new, delta)
            if cost < history[-1]:
                break
            mu *= 10
        else:
            break  # no step lowers the cost: a minimum
        x, r = x + step, r_new
        mu = max(mu / 10, 1e-9)
        history.append(cost)
        if history[-2] - cost <= tol * history[-2]:
            break
    return x, history


# ---------------------------------------------------------------------------- the test and its model
@dataclass
class OneCentre:
    """The model of one centre fitted to a database's matches (:func:`fit_one_centre`).

    ``homography_pairs`` of ``pairs`` related by a homography (COLMAP's classification), the
    median error of those pairs' own homographies ``homography_px``; ``fit`` and
    ``reconstruction`` (a pycolmap Reconstruction) None where the gate stopped the fit.
    """

    matches: Matches
    homography_pairs: int
    pairs: int
    homography_px: float
    fit: RotationFit | None = None
    reconstruction: object | None = None


def fit_one_centre(database, seed: int = 0, force: bool = False) -> OneCentre:
    """Read a COLMAP database's matches and, when at least :data:`MIN_HOMOGRAPHY_SHARE` of
    its verified pairs are related by homographies (or ``force``), fit the rotation-only
    model to them (at most :data:`MAX_TRACKS` tracks, a sample seeded by ``seed``) and build
    its reconstruction (:func:`rotation_only_reconstruction`)."""
    m = read_matches(database)
    one = OneCentre(m, int(m.homography.sum()), len(m.pairs), homography_error(m))
    if not force and (one.pairs == 0 or one.homography_pairs < MIN_HOMOGRAPHY_SHARE * one.pairs):
        return one
    m = with_focal_scaled(m, focal_from_homographies(m))
    R0, images = chain_rotations(m)
    tracks = tracks_from_matches(m, images)
    if len(images) < 2 or tracks.n_tracks == 0:
        return one
    rng = np.random.default_rng(seed)
    # wrong matches join tracks of different points, whose directions no rotation explains:
    # the fit uses the tracks each of whose observations its starting model explains
    err = _track_errors(tracks, m, R0, images)
    good = np.flatnonzero(err <= max(MAX_REPROJECTION_PX, START_ERROR_FACTOR * np.median(err)))
    if len(good) < MIN_TRACKS:
        return one
    coarse = fit_rotation_only(tracks.subset(np.sort(rng.permutation(good)[:COARSE_TRACKS])), m, R0, images)
    m_fit = _with_params(m, coarse.params)
    good = np.flatnonzero(_track_errors(tracks, m_fit, coarse.rotations, images) <= MAX_REPROJECTION_PX)
    if len(good) < MIN_TRACKS:
        return one
    one.fit = fit_rotation_only(tracks.subset(np.sort(rng.permutation(good)[:MAX_TRACKS])), m_fit,
                                coarse.rotations, images)
    one.fit.iterations += coarse.iterations
    one.reconstruction = rotation_only_reconstruction(m, one.fit)
    return one


def _track_errors(tracks: Tracks, m: Matches, R: np.ndarray, images: np.ndarray) -> np.ndarray:
    """Each track's largest observation error (px) under rotations ``R`` and ``m``'s cameras."""
    model = _Model(tracks, m.camera_of_image, m.cameras, R, images)
    params = [np.array(c.params, np.float64) for c in m.cameras]
    e = np.linalg.norm(model.errors(R, params, model.directions(R, params)), axis=1)
    out = np.zeros(tracks.n_tracks)
    np.maximum.at(out, tracks.track, np.nan_to_num(e, nan=np.inf))
    return out


def focal_note(one: OneCentre) -> str | None:
    """A warning where a fitted focal length is outside :data:`PLAUSIBLE_FOCAL` times its
    image's longer side (a flat scene filmed while moving sideways fits one centre with an
    ever longer focal length), else None."""
    if one.fit is None:
        return None
    for c in _with_params(one.matches, one.fit.params).cameras:
        ratio = c.mean_focal_length() / max(c.width, c.height)
        if not PLAUSIBLE_FOCAL[0] <= ratio <= PLAUSIBLE_FOCAL[1]:
            return (f"one centre's focal length {c.mean_focal_length():.0f} px is {ratio:.2g}x the image's longer "
                    "side: a flat scene filmed while moving also looks turned on the spot")
    return None


def point_error(rec) -> float:
    """Median over a reconstruction's points of their mean reprojection error (px)."""
    e = [p.error for p in rec.points3D.values()]
    return float(np.median(e)) if e else float("inf")


@dataclass
class Choice:
    """:func:`prefer_one_centre`'s verdict, why, and the figures it compared: photos
    registered and the points' median error (px), by one centre and by the mapper."""

    one_centre: bool
    why: str
    registered: tuple = (0, 0)
    points_px: tuple = (float("nan"), float("nan"))


def prefer_one_centre(one: OneCentre, mapper) -> Choice:
    """Whether the model of one centre is taken rather than ``mapper`` (COLMAP's largest
    model, or None): when the mapper's model, with a centre for every photo and a depth for
    every point, explains its points no better than one centre does within a factor
    :data:`MAX_MAPPER_RATIO`; or when the mapper registered fewer photos and one centre
    explains the matches within :data:`MAX_HOMOGRAPHY_RATIO` times the pairs' own
    homographies."""
    if one.reconstruction is None:
        return Choice(False, "the pairs are not related by homographies" if one.fit is None else "no model")
    n1, e1 = one.reconstruction.num_reg_images(), point_error(one.reconstruction)
    n0, e0 = (mapper.num_reg_images(), point_error(mapper)) if mapper is not None else (0, float("inf"))
    seen = dict(registered=(n1, n0), points_px=(e1, e0))
    if n0 >= n1:
        if e1 <= MAX_MAPPER_RATIO * e0:
            return Choice(True, f"the mapper's centres explain the points no better ({e0:.3f} px against "
                                f"{e1:.3f} px)", **seen)
        return Choice(False, f"the mapper's centres explain the points better ({e0:.3f} px against {e1:.3f} px)",
                      **seen)
    if one.fit.median_px <= MAX_HOMOGRAPHY_RATIO * one.homography_px:
        return Choice(True, f"the mapper registered {n0} photos, one centre {n1}, explaining the matches to "
                            f"{one.fit.median_px:.3f} px (the pairs' homographies: {one.homography_px:.3f} px)",
                      **seen)
    return Choice(False, f"one centre explains the matches to {one.fit.median_px:.3f} px, the pairs' "
                         f"homographies to {one.homography_px:.3f} px", **seen)


def rotation_only_reconstruction(m: Matches, fit: RotationFit):
    """A pycolmap Reconstruction of the fitted model: ``fit.images`` at the origin with their
    rotations, the cameras with the fitted parameters, and every track of the matches
    between those images that the model explains (each observation within
    :data:`MAX_REPROJECTION_PX`) as a point at unit distance along its direction."""
    pycolmap = import_pycolmap()
    m = _with_params(m, fit.params)
    tracks = tracks_from_matches(m, fit.images)
    tracks = tracks.subset(np.flatnonzero(_track_errors(tracks, m, fit.rotations, fit.images) <= MAX_REPROJECTION_PX))
    d = _Model(tracks, m.camera_of_image, m.cameras, fit.rotations, fit.images).directions(fit.rotations, fit.params)

    rec = pycolmap.Reconstruction()
    for cam in m.cameras:
        rec.add_camera_with_trivial_rig(cam)
    for i in fit.images:
        im = pycolmap.Image(name=m.names[i], keypoints=m.keypoints[i], image_id=int(m.image_ids[i]),
                            camera_id=int(m.cameras[m.camera_of_image[i]].camera_id))
        rec.add_image_with_trivial_frame(im, pycolmap.Rigid3d(pycolmap.Rotation3d(fit.rotations[i]), np.zeros(3)))
    ids = m.image_ids[tracks.image]
    starts = np.searchsorted(tracks.track, np.arange(tracks.n_tracks + 1))
    for t in range(tracks.n_tracks):  # one COLMAP point a track (thousands, not pixels)
        sl = slice(starts[t], starts[t + 1])
        elements = [pycolmap.TrackElement(int(a), int(b)) for a, b in zip(ids[sl], tracks.keypoint[sl])]
        rec.add_point3D(d[t], pycolmap.Track(elements))
    rec.update_point_3d_errors()
    return rec
