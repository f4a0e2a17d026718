"""Light-field depth: EPI structure tensor (local), refined by a fine plane sweep over the
grid and a confidence-weighted TV-L1.

Geometry. The views of a light-field grid are parallel (possibly shift-lens) cameras; a
point at inverse depth ``w = 1/z`` seen at x in the reference appears at ``x − s·d`` in the
view ``s`` grid steps to the right (and ``y − s·d`` for ``s`` steps down), with the
disparity ``d`` (pixels per grid step) affine in w: ``d = −(a + b w)`` where ``a + b w`` is
the pixel shift towards the next column (for HCI: ``d = f·B·(1/z − 1/z₀)``). ``a`` and ``b``
are read off the cameras (:func:`disparity_model`), so depth and disparity convert exactly.

Local estimate (Wanner & Goldluecke 2012, §3.1). On the epipolar-plane image
``I(s, x)`` of the reference row, a scene point traces the line ``x + s d = const``, so
``I_s = d I_x``. With the structure tensor ``J = G_σ * [[I_x², I_x I_s], [I_x I_s, I_s²]]``
the line direction gives ``d = tan φ``, ``φ = ½ atan2(2 J_xs, J_xx − J_ss)``, and the
coherence ``c = sqrt((J_xx − J_ss)² + 4 J_xs²) / (J_xx + J_ss)`` ∈ [0, 1] is the confidence.
The horizontal (row) and vertical (column) EPIs are both used; each pixel keeps the more
coherent one.

Refinement (this module's default): a plane sweep over the grid neighbours with planes
``step`` px of disparity apart (:func:`vibr.stereo.planesweep.plane_sweep`, exact for
parallel cameras), in the disparity range of the coherent local estimates, the
slanted-plane refinement (:func:`~vibr.stereo.planesweep.refine_planes`; optionally the
weighted median of its planes, :func:`~vibr.stereo.planesweep.median_planes`),
followed by the weighted TV-L1 of :func:`vibr.stereo._kernels.tv_l1` (edge-aware weights from the image).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import gaussian_filter, sobel

from ..camera import Camera
from ..errors import VibrInputError
from ..scene import Scene
from . import _kernels as kern
from .partners import _resized, default_depth_range, upsample_sweep
from .planesweep import median_planes, plane_sweep, refine_planes, to_grey

#: Default spacing of the sweep's planes as parallax on the nearest view swept, in pixels
#: (``step`` of :func:`lightfield_depth`; the measurements behind it: docs/explanation/depth.md, "Light
#: fields", step 2).
PARALLAX_STEP = 0.1


#: What :func:`lightfield_depth` does after the local estimate (``LightFieldOptions.refine``):
#: nothing, the plane sweep, or the sweep and the TV-L1.
REFINE_MODES = ("st", "sweep", "sweep+tv")


#: Image scale of the light-field estimate's coarse level (sweep and first refinement
#: iteration; :func:`lightfield_depth`'s ``pm_coarse_scale``): measured in docs/explanation/depth.md
#: ("Coarse to fine").
COARSE_SCALE = 0.5
#: The light-field views' consensus tolerance (relative depth; ``LightFieldOptions.consensus_tol``),
#: chosen on procedural light fields by ``benchmarks/quality/lightfield_consensus.py``
#: (docs/explanation/depth.md, "The views' consensus").
CONSENSUS_TOL = 0.35


def disparity_model(ref: Camera, right: Camera) -> tuple[float, float]:
    """``(a, b)`` with ``d = −(a + b w)``: disparity in pixels per grid step of a point of
    inverse depth ``w`` in ``ref``, ``right`` being the next view of the same grid row.
    Measured at the image centre (exact for parallel cameras: the shift is uniform)."""
    x = np.array([(ref.width - 1) / 2, (ref.height - 1) / 2])
    ray = ref.pixel_rays(x)
    p_inf = right.project(ref.camera_to_world(ray * 1e9))[0][0]
    p_1 = right.project(ref.camera_to_world(ray * 1.0))[0][0]
    a = p_inf - x[0]
    b = p_1 - p_inf
    return float(a), float(b)


def grid_positions(scene: Scene) -> dict[int, tuple[int, int]]:
    """View index → (row, col) from ``scene.meta["grid_pos"]`` or ``scene.grid``."""
    gp = scene.meta.get("grid_pos")
    if gp:
        return {scene.index(k): (int(v[0]), int(v[1])) for k, v in gp.items() if k in scene.names}
    if scene.grid is None:
        raise VibrInputError("light-field depth needs a grid (scene.grid or meta['grid_pos'])", scene.root)
    cols = scene.grid[1]
    return {i: (i // cols, i % cols) for i in range(len(scene))}


def epi_disparity(stack: np.ndarray, offsets: np.ndarray, axis: str = "x", *,
                  inner_sigma: float = 0.8, outer_sigma: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """Structure-tensor disparity on the EPIs through the reference view.

    Parameters
    ----------
    stack : (n, H, W) float grey images of one grid row (``axis="x"``) or column
        (``axis="y"``), ordered by ``offsets``.
    offsets : (n,) grid steps of each view from the reference (the reference has 0; steps
        may be non-contiguous, the derivative along s uses their actual spacing).
    inner_sigma, outer_sigma : pre-smoothing of the images and integration scale of the
        tensor (pixels; the tensor is also averaged along s with Gaussian weights).

    Returns
    -------
    d : (H, W) float64 disparity in pixels per grid step (``I_s(x) = I_0(x + s d)``).
    coherence : (H, W) float64 in [0, 1].
    """
    offsets = np.asarray(offsets, np.float64)
    order = np.argsort(offsets)
    s = offsets[order]
    L = np.stack([gaussian_filter(np.asarray(stack[k], np.float64), inner_sigma) for k in order])
    ax = 2 if axis == "x" else 1
    # the same central difference along x (or y) as along s: no cross-smoothing, which
    # would shrink I_x relative to I_s and bias d upwards
    Ix = np.gradient(L, axis=ax)
    Is = np.gradient(L, s, axis=0)
    # integrate along s with Gaussian weights centred on the reference
    wts = np.exp(-0.5 * (s / max(1.0, 0.5 * (s.max() - s.min()))) ** 2)
    wts /= wts.sum()
    def integ(P):
        return gaussian_filter(np.tensordot(wts, P, axes=(0, 0)), outer_sigma)
    Jxx = integ(Ix * Ix)
    Jxs = integ(Ix * Is)
    Jss = integ(Is * Is)
    phi = 0.5 * np.arctan2(2 * Jxs, Jxx - Jss)
    # |d| beyond 4 px per step is outside what a 3x3 derivative sees: clip (low coherence there)
    d = np.clip(np.tan(phi), -4.0, 4.0)
    coh = np.sqrt((Jxx - Jss) ** 2 + 4 * Jxs ** 2) / np.maximum(Jxx + Jss, 1e-12)
    return d, coh


@dataclass(frozen=True)
class LightFieldOptions:
    """How :func:`lightfield_depth` estimates a grid view's depth (every field has a
    default; the measurements behind them: docs/explanation/depth.md, "Defaults of estimate_depth").

    Attributes
    ----------
    depth_range : (near, far), optional
        Orthogonal depth range of the sweep in scene units; default from the local estimate
        (``margin_px``, ``st_max_disp``).
    refine : "st" | "sweep" | "sweep+tv"
        The local estimate only, the plane sweep, or the sweep then the TV-L1 (default).
    max_views : int
        At most this many neighbours in the sweep: the nearest in grid distance, preferring
        the reference's row, column and diagonals (the star of the grid).
    radius : int, optional
        ZNCC window half-size of the sweep. Default 3 (7×7) with up to 8 views, 2 (5×5)
        with more: the matching noise falls with window area × views, and a smaller window
        fattens depth edges less.
    step : float, optional
        Disparity step between planes, in px per grid step. Default: planes
        :data:`PARALLAX_STEP` px of parallax apart on the nearest view swept, whatever the
        spacing of the views (:func:`_plane_step`).
    n_best : int, optional
        Views whose costs are averaged per pixel and plane (the lowest ones), in the sweep
        and the refinement. Default: a quarter of the views, at least 2: next to an
        occlusion edge only the views along the edge (a quarter of the star) match cleanly.
    max_cost, eps, mem_bytes : float
        Aggregated ``1 − ZNCC`` above which a pixel is unknown; the ZNCC regulariser
        (intensity std, images in [0, 1]); the memory bound of the sweep's working set.
    st_min_coherence : float
        Coherence above which a local estimate is trusted (range, "st" mode).
    margin_px : float
        Disparity margin added around the local estimate's range.
    st_max_disp : float
        When the local estimate's disparities exceed this (px per step), the sweep's range
        comes from :func:`vibr.stereo.partners.default_depth_range` instead.
    tv_lambda, tv_iter : float, int
        Data weight and iterations of the TV-L1 refinement.
    pm_iter, pm_views, pm_stride : int
        Iterations of the slanted-plane refinement of the sweep
        (:func:`vibr.stereo.planesweep.refine_planes`, 0: none), the number of grid
        neighbours it uses (default: the sweep's; else the first of them, the nearest star
        views) and the sampling step of its window (default 1, dense: the grid's small
        baselines need a dense window and all the sweep's views).
    pm_radius : int, optional
        Window half-size of the refinement (default: the sweep's ``radius``; 2 is faster,
        docs/explanation/depth.md, "The depth alone at full size").
    pm_sigma_c, pm_sigma_s : float
        Grey-level and spatial scales of the refinement's adaptive-support weights on the
        colour image; tighter than the MVS defaults (0.05, the radius), since the dense
        window has samples next to the centre to weigh.
    pm_coarse_scale, pm_coarse_iter : float, int
        Coarse to fine (default :data:`COARSE_SCALE`; 1: none), :func:`_sweep_planes`.
    median_radius : int
        Half-size of the planes' joint weighted median
        (:func:`vibr.stereo.planesweep.median_planes`; 0, the default: none, renders lose).
    consensus_tol : float
        Once every requested view has its depth, :func:`vibr.stereo.estimate_depth` replaces
        each pixel's depth by the mean of its own and of its 8 nearest estimated views' depths
        that agree with it within this fraction (:func:`vibr.stereo.consensus_depth`; 0:
        none; default :data:`CONSENSUS_TOL`). Each view's estimate errs on its own, and a
        render places each source's samples by that source's depth: the consensus registers
        them with each other (docs/explanation/depth.md, "The views' consensus"). A single
        view estimated alone keeps its own depth.
    """

    depth_range: tuple[float, float] | None = None
    refine: str = "sweep+tv"
    max_views: int = 32
    radius: int | None = None
    step: float | None = None
    n_best: int | None = None
    max_cost: float = 0.6
    eps: float = 0.001
    mem_bytes: float = 2e9
    st_min_coherence: float = 0.7
    margin_px: float = 0.3
    st_max_disp: float = 2.5
    tv_lambda: float = 2.0
    tv_iter: int = 200
    pm_iter: int = 2
    pm_views: int | None = None
    pm_stride: int = 1
    pm_radius: int | None = None
    pm_sigma_c: float = 0.03
    pm_sigma_s: float = 2.0
    pm_coarse_scale: float = COARSE_SCALE
    pm_coarse_iter: int = 1
    median_radius: int = 0
    consensus_tol: float = CONSENSUS_TOL

    def __post_init__(self):
        if self.refine not in REFINE_MODES:
            raise VibrInputError(f"light-field refine must be one of {', '.join(REFINE_MODES)}, got {self.refine!r}")


def lightfield_depth(scene: Scene, ref: int, cams: list[Camera], img, inputs: list[int], *,
                     options: LightFieldOptions | None = None, return_disparity: bool = False, **kw):
    """Depth and sigma_z for grid view ``ref`` from the other (non-excluded) grid views.

    Parameters
    ----------
    cams : cameras at the working scale; ``img(i)`` returns view i's image at that scale.
    inputs : indices usable as inputs (``ref`` itself is the reference).
    options : LightFieldOptions, optional
        How to estimate; ``kw`` (its fields, e.g. ``refine="st"``) applies over it. Any
        other keyword raises ``TypeError``.
    return_disparity : bool
        Also return the disparity map.

    Returns
    -------
    (depth (H,W) float32 NaN unknown, sigma_z (H,W) float32, stats dict) and, when
    ``return_disparity``, the disparity map (H,W) float64 as a fourth element.
    """
    t0 = time.perf_counter()
    o = replace(options or LightFieldOptions(), **kw)
    pos = grid_positions(scene)
    if ref not in pos:
        raise VibrInputError(f"view {scene.views[ref].name} is not on the light-field grid", scene.root)
    others = [j for j in inputs if j != ref and j in pos]
    if not others:
        raise VibrInputError("light-field depth needs at least one other grid view", scene.root)
    a, b = _grid_disparity_model(cams, ref, others, pos)

    def d_to_w(d):
        return (-np.asarray(d, np.float64) - a) / b

    grey = {ref: to_grey(img(ref))}
    best_d, best_c = _local_estimate(ref, others, pos, img, grey)
    st_conf = best_c >= o.st_min_coherence
    stats = {"method": "lightfield", "refine": o.refine, "st_coherent": float(st_conf.mean())}
    if o.refine == "st":
        disp = best_d
        w = d_to_w(disp)
        ok = st_conf & (w > 0)
        z = np.where(ok, 1.0 / np.where(w > 0, w, 1.0), np.nan)
        # sigma of the local estimate: 0.05 px at full coherence, growing as coherence drops
        sigma = z * z * (0.05 / np.maximum(best_c, 0.05)) / abs(b)
    else:
        dr = _sweep_range(scene, ref, cams, img, others, pos, best_d, st_conf, d_to_w, o.depth_range,
                          o.st_max_disp, o.margin_px, stats)
        res, conf = _swept(scene, ref, cams, img, others, pos, dr, abs(b) * (1.0 / dr[0] - 1.0 / dr[1]), o, stats)
        disp = -(a + b * res.inv_depth)
        sigma_d = res.sigma_z / np.maximum(res.depth, 1e-12) ** 2 * abs(b)
        if o.refine == "sweep+tv":
            disp = _tv_refine(grey[ref], disp, conf, sigma_d, o.tv_lambda, o.tv_iter)
        w = d_to_w(disp)
        z = np.where(w > 0, 1.0 / np.where(w > 0, w, 1.0), np.nan)
        sigma = z * z * sigma_d / abs(b)
        if o.refine == "sweep":
            z = np.where(conf, z, np.nan)
    stats["kept"] = float(np.isfinite(z).mean())
    stats["time_s"] = time.perf_counter() - t0
    out = (np.asarray(z, np.float32), np.nan_to_num(np.asarray(sigma, np.float32), nan=0.0), stats)
    if return_disparity:
        out = out + (np.asarray(disp, np.float64),)
    return out


def _swept(scene, ref, cams, img, others, pos, dr, dspan, o: LightFieldOptions, stats):
    """The plane sweep of ``ref`` over its star neighbours in the depth range ``dr``
    (``dspan`` px of disparity per grid step), refined (:func:`_sweep_planes`); the
    result and its confident pixels, the sweep's settings into ``stats``."""
    r0, c0 = pos[ref]
    nb = _star_neighbours(others, pos, r0, c0)[:o.max_views]
    step, D = _plane_step(dspan, o.step, [pos[k] for k in nb], (r0, c0))
    n_best, radius = o.n_best, o.radius
    if n_best is None:
        # Occlusions: next to a depth edge only the views whose baseline runs along the
        # edge match cleanly, one of the star's 4 directions, a quarter of its views
        n_best = max(2, len(nb) // 4)
    if radius is None:
        # the ZNCC noise falls with the samples compared, window area × views: with more
        # than one ring of views a 5×5 window suffices and fattens depth edges less
        radius = 3 if len(nb) <= 8 else 2
    n_best = max(1, min(int(n_best), len(nb)))
    res = _sweep_planes(img, cams, ref, nb, dr, o, desc=f"light-field sweep {scene.views[ref].name}",
                        n_planes=D, radius=radius, n_best=n_best)
    conf = res.confident
    stats.update({"depth_range": dr, "n_planes": D, "step": step, "n_views": len(nb), "n_best": n_best,
                  "pm_iter": int(o.pm_iter),
                  "confident": float(conf.mean()), "sweep_s": res.meta["time_s"]})
    return res, conf


def _grid_disparity_model(cams: list[Camera], ref: int, others: list[int], pos: dict) -> tuple[float, float]:
    """``(a, b)`` of the affine model ``d = −(a + b w)``, per grid step, for view ``ref``.

    Any view in another column gives the x model (parallel grid: the x shift depends on
    the column offset only), the same row preferred; a grid with missing views may leave a
    view with same-column (or diagonal) neighbours only, which give the same model along y.
    """
    r0, c0 = pos[ref]
    cam = cams[ref]
    x_nb = [j for j in others if pos[j][1] != c0]
    if x_nb:
        j = min(x_nb, key=lambda k: (abs(pos[k][0] - r0), abs(pos[k][1] - c0)))
        a, b = disparity_model(cam, cams[j])
        ds = pos[j][1] - c0
    else:
        col_nb = [j for j in others if pos[j][1] == c0]
        j = min(col_nb, key=lambda k: abs(pos[k][0] - r0))
        cj = cams[j]
        # same model along y: swap axes by measuring the y shift
        x = np.array([(cam.width - 1) / 2, (cam.height - 1) / 2])
        ray = cam.pixel_rays(x)
        p_inf = cj.project(cam.camera_to_world(ray * 1e9))[0][1]
        p_1 = cj.project(cam.camera_to_world(ray * 1.0))[0][1]
        a, b, ds = float(p_inf - x[1]), float(p_1 - p_inf), pos[j][0] - r0
    return a / ds, b / ds


def _local_estimate(ref: int, others: list[int], pos: dict, img, grey: dict):
    """EPI structure-tensor disparity of the reference row and column (:func:`epi_disparity`),
    each pixel keeping the more coherent one. Returns ``(disparity, coherence)``, coherence
    −1 where neither EPI exists. ``grey`` caches grey images by view."""
    r0, c0 = pos[ref]
    shape = grey[ref].shape
    best_d = np.zeros(shape)
    best_c = np.full(shape, -1.0)
    row_nb = [j for j in others if pos[j][0] == r0]
    col_nb = [j for j in others if pos[j][1] == c0]
    for axis, group in (("x", row_nb), ("y", col_nb)):
        if not group:
            continue
        idx = [ref] + sorted(group, key=lambda k: pos[k][1] if axis == "x" else pos[k][0])
        offs = np.array([(pos[k][1] - c0) if axis == "x" else (pos[k][0] - r0) for k in idx], float)
        stack = np.stack([grey.setdefault(k, to_grey(img(k))) for k in idx])
        d, coh = epi_disparity(stack, offs, axis)
        better = coh > best_c
        best_d[better] = d[better]
        best_c[better] = coh[better]
    return best_d, best_c


def _sweep_range(scene: Scene, ref: int, cams, img, others, pos, best_d, st_conf, d_to_w,
                 depth_range, st_max_disp: float, margin_px: float, stats: dict):
    """Depth range of the fine sweep: the given one; else the coherent local disparities'
    1st–99th percentiles widened by ``margin_px``; else (large disparities, where the
    3-tap derivative along s aliases, or no local estimate) the generic coarse-sweep range
    of :func:`vibr.stereo.partners.default_depth_range`. Records ``range_from`` in ``stats``."""
    r0, c0 = pos[ref]
    dsel = best_d[st_conf] if st_conf.sum() > 100 else best_d.ravel()
    dlo, dhi = np.percentile(dsel, [1, 99])
    if depth_range is None and (st_conf.sum() <= 100 or max(abs(dlo), abs(dhi)) > st_max_disp):
        nb0 = sorted(others, key=lambda k: abs(pos[k][0] - r0) + abs(pos[k][1] - c0))[:4]
        depth_range = default_depth_range(scene, ref, cams, {k: img(k) for k in [ref] + nb0}, nb0,
                                          use_points=False)
        stats["range_from"] = "coarse sweep"
    if depth_range is not None:
        return depth_range
    stats["range_from"] = "structure tensor"
    dlo -= margin_px
    dhi += margin_px
    w_a, w_b = sorted((float(d_to_w(dlo)), float(d_to_w(dhi))))
    w_a = max(w_a, 1e-6 * max(w_b, 1e-6))
    return (1.0 / w_b, 1.0 / w_a)


def _small(img, k: int, camera: Camera) -> np.ndarray:
    """View ``k``'s image at ``camera``'s (smaller) size: the estimator's cached resize when
    ``img`` has one, else :func:`vibr.stereo.partners._resized`."""
    small = getattr(img, "small", None)
    if small is not None:
        return small(k, camera)

    return _resized(img(k), camera)


def _sweep_planes(img, cams, ref, nb, dr, o: LightFieldOptions, *, desc, n_planes, radius, n_best):
    """The fine plane sweep of ``ref`` over the grid views ``nb``, its slanted-plane
    refinement over the first ``o.pm_views`` of them and the optional weighted median
    (``n_planes``, ``radius``, ``n_best``: the sweep's, resolved from ``o``).

    ``(o.pm_coarse_scale, o.pm_coarse_iter)`` = (scale, iterations): with scale < 1 the sweep
    runs on the images resized by it, with planes the same parallax apart at that size
    (fewer), then the first ``min(iterations, pm_iter − 1)`` of the ``o.pm_iter`` refinement
    iterations at that size, the others at full size from the upsampled planes, without the fronto-parallel start
    and with a random search of the depth alone once a coarse iteration was made (the
    normals were refined at the coarse level); the refinement's window has half-size
    ``o.pm_radius`` (default: ``radius``). The MVS method's
    ``sweep_scale`` and ``coarse_iter`` (:func:`vibr.stereo.api.estimate_depth`), except
    that there the coarse iterations come on top of ``refine_iter``."""
    cam = cams[ref]
    nbr = nb if o.pm_views is None else nb[: max(1, int(o.pm_views))]
    scale, coarse_iter, pm_iter = float(o.pm_coarse_scale), int(o.pm_coarse_iter), o.pm_iter
    mask = getattr(img, "mask", None)  # the photographs' masks: a masked sample does not match

    def masks(views, cs=None):
        return None if mask is None else [mask(k, None if cs is None else cs[k]) for k in views]

    refine_kw = dict(n_best=min(n_best, len(nbr)), eps=o.eps, max_cost=o.max_cost,
                     radius=radius if o.pm_radius is None else o.pm_radius, stride=o.pm_stride,
                     sigma_c=o.pm_sigma_c, sigma_s=o.pm_sigma_s)
    coarse_done = False
    if pm_iter > 0 and scale < 1.0:
        # pm_iter iterations in all: the coarse ones first, at least one at full size
        coarse_iter = max(0, min(int(coarse_iter), pm_iter - 1))
        pm_iter -= coarse_iter

        cs = {k: cams[k].scaled(scale) for k in [ref] + list(nb)}
        # disparities shrink with the images: planes the same parallax apart are fewer
        res = plane_sweep(_small(img, ref, cs[ref]), cs[ref], [_small(img, k, cs[k]) for k in nb],
                          [cs[k] for k in nb], dr, n_planes=max(16, int(np.ceil(n_planes * scale))),
                          radius=radius, n_best=n_best, max_cost=o.max_cost, mem_bytes=o.mem_bytes, eps=o.eps,
                          desc=desc, src_masks=masks(nb, cs))
        if coarse_iter > 0:
            res = refine_planes(_small(img, ref, cs[ref]), cs[ref], [_small(img, k, cs[k]) for k in nbr],
                                [cs[k] for k in nbr], res, n_iter=coarse_iter, src_masks=masks(nbr, cs),
                                **refine_kw)
            coarse_done = True
        res = upsample_sweep(res, cs[ref], cam)
    else:
        res = plane_sweep(img(ref), cam, [img(k) for k in nb], [cams[k] for k in nb], dr,
                          n_planes=n_planes, radius=radius, n_best=n_best,
                          max_cost=o.max_cost, mem_bytes=o.mem_bytes, eps=o.eps, desc=desc, src_masks=masks(nb))
    if pm_iter > 0:
        res = refine_planes(img(ref), cam, [img(k) for k in nbr], [cams[k] for k in nbr], res,
                            n_iter=pm_iter, fronto_init=not coarse_done, joint_perturbation=not coarse_done,
                            normal_perturbation=not coarse_done, src_masks=masks(nbr), **refine_kw)
    if o.median_radius:
        res = median_planes(img(ref), res, radius=o.median_radius)
    return res


def _plane_step(dspan: float, step, nb_pos, ref_pos) -> tuple[float, int]:
    """``(step, number of planes)`` of a sweep over ``dspan`` px of disparity per grid step:
    ``step`` as given, or :data:`PARALLAX_STEP` px of parallax on the nearest view swept
    (grid positions ``nb_pos``) divided by its grid distance; 16 to 512 planes."""
    if step is None:
        step = PARALLAX_STEP / min(math.hypot(r - ref_pos[0], c - ref_pos[1]) for r, c in nb_pos)
    return step, int(np.clip(np.ceil(dspan / step) + 1, 16, 512))


def _star_neighbours(others: list[int], pos: dict, r0: int, c0: int) -> list[int]:
    """The grid views ordered for the sweep: the reference's row, column and diagonals (the
    star) first, then by grid distance."""
    def key(k):
        dr_, dc_ = pos[k][0] - r0, pos[k][1] - c0
        star = dr_ == 0 or dc_ == 0 or abs(dr_) == abs(dc_)
        return (0 if star else 1, max(abs(dr_), abs(dc_)), abs(dr_) + abs(dc_))
    return sorted(others, key=key)


def _tv_refine(grey_ref, disp, conf, sigma_d, tv_lambda: float, tv_iter: int):
    """Confidence-weighted TV-L1 of the disparity (:func:`vibr.stereo._kernels.tv_l1`), with
    edge-aware weights from the reference's grey image."""
    I = grey_ref.astype(np.float64)
    gm = np.hypot(sobel(I, 0), sobel(I, 1)) / 8.0
    g = np.maximum(np.exp(-gm / 0.02), 0.05)
    cw = np.where(conf, 1.0, 0.1) / np.maximum(sigma_d / 0.05, 1.0)
    return kern.tv_l1(disp.astype(np.float64), cw, g, float(tv_lambda), int(tv_iter))
