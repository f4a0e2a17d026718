"""``estimate_depth``: per-view depth maps and their uncertainty from calibrated photos.

The paper's first stage (Nieto et al. 2016, §5.3) computes the geometric proxy with MVS
(Goesele et al. 2007) for unstructured views and with the EPI structure tensor (Wanner &
Goldluecke 2012) for light fields. vibr does both on the CPU:

* ``method="mvs"``: plane sweep (:func:`vibr.stereo.planesweep.plane_sweep`) over the
  ``n_neighbours`` nearest views (plus views that see what they miss,
  :func:`complete_coverage`) and slanted-plane refinement, then the forward-backward consistency check
  across the estimated views (:mod:`vibr.stereo.consistency`); unreliable or inconsistent
  pixels become NaN (the geometry stage's bilateral filter fills them).
* ``method="lightfield"``: :func:`vibr.stereo.lightfield.lightfield_depth` (structure
  tensor on the epipolar-plane images, refined by a fine plane sweep over the grid and a
  confidence-weighted TV-L1).

Resolution: the estimate is computed at ``scale`` (images resampled, cameras
:meth:`~vibr.camera.Camera.scaled`) and the depth and sigma_z maps are **upsampled back to
the scene's resolution** (bilinear in inverse depth where the four neighbours are known,
nearest otherwise), so the returned scene has the input's resolution. To work at a
reduced resolution end to end, load the scene at that scale (``load_scene(path,
scale=...)``) and call with ``scale=1``.
"""

from __future__ import annotations

import logging
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, fields, replace

import numpy as np

from .._runtime.checkpoint import ViewCheckpoint
from ..camera import Camera, shared_centre
from ..errors import VibrInputError
from ..executor import run_tasks
from ..geometry.resample import resize_mask
from ..progress import progress
from ..scene import Scene
from .checks import check_depth_params
from .consistency import check_consistency, consensus_depth
from .lightfield import LightFieldOptions, lightfield_depth
from .partners import (
    _ray_parallax,
    _resized,
    complete_coverage,
    default_depth_range,
    select_neighbours,
    upsample_depth,
    upsample_map,
    upsample_sweep,
)
from .planesweep import SweepResult, median_planes, plane_sweep, refine_planes
from .segments import fill_segment_planes, segment_image

logger = logging.getLogger(__name__)


#: Default number of slanted-plane refinement iterations after the sweep (see
#: :func:`estimate_depth` and docs/explanation/depth.md for the measurements behind it).
REFINE_ITER = 2

#: Changes whenever :func:`estimate_depth` gives other depths for the same inputs and
#: options (a new default, a changed algorithm): the on-disk depth cache
#: (:mod:`vibr.stereo.cache`) keys on it, so a cache written by an older estimator is not
#: served. 2: the light-field sweep's plane step from the parallax (docs/explanation/depth.md). 3: the
#: light field's coarse level (sweep and first refinement iteration at half size). 4: the
#: light field's full-size refinement with a random search of the depth alone. 5: the MVS
#: sigma_z times :data:`MVS_SIGMA_SCALE`. 6: the light-field views' consensus
#: (``LightFieldOptions.consensus_tol``).
ESTIMATOR_VERSION = 6


#: At most this many light-field views are estimated side by side (threads,
#: :func:`map_views`): each holds its own working arrays, so the peak memory grows with
#: it. The MVS method estimates one view at a time: side by side it was no faster on
#: fountain (docs/explanation/depth.md, "Views side by side").
VIEW_THREADS = 2


# --------------------------------------------------------------------------- helpers
def map_views(fn, items: list) -> list:
    """``[fn(i) for i in items]``, with up to :data:`VIEW_THREADS` views side by side.

    With ``w`` views at a time on numba's ``n`` threads, each view's kernels run on
    ``max(1, n // w)`` of them (``numba.set_num_threads`` is per thread). The kernels release
    the GIL, and their results do not depend on the thread count (every ``prange`` iteration
    writes its own pixels: tested bit for bit against the serial loop), so the depths are
    the serial loop's. Why: the Python and SciPy work between one view's kernels (EPI
    structure tensor, resizing, upsampling) runs on one core; side by side, the other view
    keeps the second one busy (docs/explanation/depth.md, "Views side by side")."""
    import numba

    n = numba.get_num_threads()
    w = min(len(items), n, VIEW_THREADS)
    if w < 2 or not _threadsafe_layer():
        return [fn(i) for i in items]
    per = max(1, n // w)

    def run(i):
        numba.set_num_threads(per)
        return fn(i)

    with ThreadPoolExecutor(w, thread_name_prefix="vibr-depth") as ex:
        return list(ex.map(run, items))


def _threadsafe_layer() -> bool:
    """Whether numba's threading layer takes parallel kernels launched from several threads
    at once: ``omp`` and ``tbb`` do; ``workqueue``, the fallback where neither library is
    found, aborts the process."""
    import numba

    try:
        layer = numba.threading_layer()
    except ValueError:  # chosen at the first parallel launch: make one
        from . import _kernels as kern

        kern.box_mean_std(np.zeros((2, 2)), 1, 1.0)
        layer = numba.threading_layer()
    return layer in ("omp", "tbb")


def _segment_completion(image, image_small, camera: Camera, d, s, grad, depth_range, rel_tol: float,
                        median_radius: int):
    """Segment-plane filling and the second weighted median (``fill_segments`` of
    :func:`estimate_depth`). Returns (depth, sigma_z, number of filled pixels)."""
    labels = segment_image(image_small, camera.shape)
    fs = fill_segment_planes(d, labels, rel_tol=rel_tol, depth_range=depth_range)
    known = np.isfinite(fs.depth)
    z = np.where(known, fs.depth, 1.0).astype(np.float64)
    # a filled depth is as uncertain as its plane's fit, and at least the inlier tolerance
    s = np.where(fs.filled, z * np.maximum(fs.rel_rms, rel_tol), s).astype(np.float32)
    if median_radius > 0:
        gx0, gy0 = grad if grad is not None else (np.zeros(d.shape), np.zeros(d.shape))
        res = SweepResult(depth=z.astype(np.float32), inv_depth=1.0 / z, cost=np.zeros(d.shape),
                          sigma_z=s, confident=known,
                          winv=np.array([1.0 / depth_range[1], 1.0 / depth_range[0]]),
                          meta={"plane_gradient": (np.where(fs.filled, fs.gx, gx0),
                                                   np.where(fs.filled, fs.gy, gy0))})
        res = median_planes(image, res, radius=median_radius)
        z, s = res.depth, res.sigma_z
    return (np.where(known, z, np.nan).astype(np.float32), np.asarray(s, np.float32),
            int(fs.filled.sum()))


def _planes_for(ref: Camera, srcs: list[Camera], depth_range, step_px: float, lo: int, hi: int) -> int:
    """Number of planes so that consecutive planes move the farthest neighbour's pixel by
    about ``step_px`` (the sub-label fit refines below that), clipped to [lo, hi]."""
    w_near, w_far = 1.0 / depth_range[0], 1.0 / depth_range[1]
    span_px = 0.0
    for c in srcs:
        f, _ = _ray_parallax(ref, c)
        span_px = max(span_px, f(w_near) - f(w_far))  # inf (the near plane behind c): hi planes
    return int(np.clip(np.ceil(span_px / step_px) + 1, lo, hi))


# --------------------------------------------------------------------------- options
@dataclass(frozen=True)
class DepthOptions:
    """How :func:`estimate_depth` estimates depth (every field has a default).

    Where each default comes from (the measurements) is in docs/explanation/depth.md, "Defaults of
    estimate_depth".

    Attributes
    ----------
    scale : float
        Resolution factor of the estimation, in (0, 1]; the maps are upsampled back
        (module docstring).
    depth_range : (near, far), optional
        Orthogonal depth range in scene units for every reference view; default
        :func:`default_depth_range` per view.
    method : "auto" | "mvs" | "lightfield"
        "auto" is "lightfield" when ``scene.grid`` is set, else "mvs".
    n_neighbours : int
        Stereo partners per reference view (MVS), nearest first (:func:`select_neighbours`).
    coverage_gain : float or None
        When the nearest partners leave part of the reference's frustum seen by fewer than
        ``n_best`` of them, add the candidate that sees most of that part while it adds at
        least this fraction of the frustum (:func:`complete_coverage`, at most 4 extra
        views; ``None``: never).
    n_planes : int, optional
        Planes of the sweep (default: from ``step_px``, 64 … ``max_planes``).
    step_px : float
        Parallax step between planes on the farthest partner, in pixels of the images
        swept. The slanted-plane refinement then searches depth continuously, so the sweep
        only has to put each pixel in the basin of its cost (3 px: under half the 7×7
        window).
    max_planes : int
        Upper bound on the number of planes per view.
    radius : int, optional
        ZNCC window half-size (default 3 for MVS; light fields: see
        :class:`~vibr.stereo.lightfield.LightFieldOptions`).
    n_best : int, optional
        Views averaged per pixel and plane, the lowest costs (default half of the
        partners; light fields: see :class:`~vibr.stereo.lightfield.LightFieldOptions`).
    max_cost : float
        Aggregated ``1 − ZNCC`` above which a pixel is unknown.
    eps : float
        ZNCC regulariser (intensity std, images in [0, 1]) of the MVS sweep
        (:func:`~vibr.stereo.planesweep.plane_sweep`); the light-field method has its own
        (``lightfield={"eps": ...}``, default 0.001).
    consistency : bool
        Run the cross-view forward-backward check (MVS); views whose partners are not
        requested get ``n_partners`` extra (non-excluded) views estimated for it.
    min_agree, rel_tol, px_tol : consistency check parameters
        (:func:`vibr.stereo.consistency.check_consistency`).
    n_partners : int
        Partners of each requested view estimated for the check.
    mem_bytes : float
        Memory bound of one plane sweep's working set.
    refine_iter : int
        Iterations of the slanted-plane PatchMatch refinement after the sweep
        (:func:`~vibr.stereo.planesweep.refine_planes`; 0: the sweep's winner-take-all
        depth). The light-field method takes it as its ``pm_iter``.
    median_radius : int, optional
        Half-size of the window of the joint weighted median of the planes after the
        refinement (:func:`~vibr.stereo.planesweep.median_planes`, sampled every 3 px; 0:
        none). Default: 9 for MVS (19×19, about three times the matching window), none for
        light fields.
    sweep_scale : float
        Image scale of the coarse level (with ``refine_iter > 0``): the sweep and the
        first ``coarse_iter`` refinement iterations run on images resized by it, their
        planes are upsampled (:func:`upsample_sweep`), and the last ``refine_iter``
        iterations, the median and the check run at full size (coarse to fine). After the
        coarse iterations the full-size ones start from the upsampled slopes alone and
        leave out the joint random perturbation. 1: the sweep at full size. Light fields:
        the same, except that the coarse iterations are the first of the ``refine_iter``
        (at least one stays at full size; ``LightFieldOptions.pm_coarse_scale``).
    coarse_iter : int
        Slanted-plane refinement iterations at ``sweep_scale`` before the upsampling
        (ignored when ``sweep_scale`` is 1): a plane refined at the coarse level lands more
        full-size pixels in the right basin than the sweep's winner.
    fill_segments : bool
        Dense output (MVS). After the consistency check, fill the unknown pixels of each
        colour segment whose known depths mostly lie on one plane with that plane, then run
        the weighted median of the planes again (:mod:`vibr.stereo.segments`; skipped with
        ``median_radius=0``). Off by default: the renderer leaves unknown source pixels out.
        ``stats["kept"]`` stays the fraction kept by the check; ``stats["filled"]`` is the
        fraction filled.
    lightfield : dict
        Further fields of :class:`~vibr.stereo.lightfield.LightFieldOptions`
        (``step``, ``max_views``, ``refine``, ``tv_lambda``, ...); checked by
        :func:`depth_options`. The light-field method also uses ``depth_range``,
        ``radius``, ``n_best``, ``max_cost``, ``mem_bytes``, ``refine_iter``,
        ``median_radius``, ``sweep_scale`` and ``coarse_iter``; it ignores the MVS-only
        fields.
    """

    scale: float = 1.0
    depth_range: tuple[float, float] | None = None
    method: str = "auto"
    n_neighbours: int = 4
    coverage_gain: float | None = 0.02
    n_planes: int | None = None
    step_px: float = 3.0
    max_planes: int = 128
    radius: int | None = None
    n_best: int | None = None
    max_cost: float = 0.6
    eps: float = 0.002
    consistency: bool = True
    min_agree: int = 1
    rel_tol: float = 0.01
    px_tol: float = 1.0
    n_partners: int = 2
    mem_bytes: float = 2e9
    refine_iter: int = REFINE_ITER
    median_radius: int | None = None
    sweep_scale: float = 0.5
    coarse_iter: int = 1
    fill_segments: bool = False
    lightfield: dict = field(default_factory=dict)


def _lightfield_keywords() -> frozenset[str]:
    """Fields of :class:`~vibr.stereo.lightfield.LightFieldOptions` a caller may set through
    ``DepthOptions.lightfield`` (the others come from the DepthOptions fields)."""

    own = {"depth_range", "radius", "max_cost", "mem_bytes", "n_best"}
    return frozenset(f.name for f in fields(LightFieldOptions) if f.name not in own)


def depth_options(options: DepthOptions | None = None, /, **kw) -> DepthOptions:
    """``options`` (default :class:`DepthOptions`) with ``kw`` applied: a field of
    DepthOptions by name, or a field of
    :class:`~vibr.stereo.lightfield.LightFieldOptions` (added to ``lightfield``). Any other
    name raises ``TypeError`` (a misspelt option is an error, not a default)."""
    opt = DepthOptions() if options is None else options
    names = {f.name for f in fields(DepthOptions)}
    lf_names = _lightfield_keywords()
    own = {k: v for k, v in kw.items() if k in names}
    lf = {k: v for k, v in kw.items() if k not in names and k in lf_names}
    unknown = sorted(set(kw) - set(own) - set(lf))
    if unknown:
        raise TypeError(f"estimate_depth() got unexpected keyword argument(s) {', '.join(unknown)} "
                        f"(depth options: {', '.join(sorted(names))}; light-field options: "
                        f"{', '.join(sorted(lf_names))})")
    bad = sorted(set(own.get("lightfield", {})) - lf_names)
    if bad:
        raise TypeError(f"unknown light-field option(s) {', '.join(bad)} "
                        f"(choose from {', '.join(sorted(lf_names))})")
    if lf:
        own["lightfield"] = {**opt.lightfield, **own.get("lightfield", {}), **lf}
    return replace(opt, **own) if own else opt


# --------------------------------------------------------------------------- main API
def estimate_depth(scene: Scene, *, views=None, exclude=(), options: DepthOptions | None = None,
                   checkpoint=None, executor=None, **kw) -> Scene:
    """Estimate orthogonal depth and its uncertainty for views of a scene.

    Parameters
    ----------
    scene : Scene
        Calibrated views with images (existing depth is ignored and replaced on the
        requested views).
    views : list of int or str, optional
        Views to estimate (default: every view not in ``exclude``).
    exclude : views never used as inputs (e.g. an evaluation's held-out target).
    options : DepthOptions, optional
        How to estimate (:class:`DepthOptions`).
    checkpoint : folder, optional
        MVS: keep each view's sweep result there as it finishes (atomic writes, keyed by the
        view, its partners and the options: :class:`vibr._runtime.checkpoint.ViewCheckpoint`) and
        read back the matching ones, so that a job killed midway and run again resumes.
    executor : None, int, str or distributed.Client
        MVS: where the views' sweeps run (:func:`vibr.executor.run_tasks`: None this
        process, ``N`` local processes, ``"local"`` or an address a Dask cluster); each
        worker receives the scene once. The depths are the serial run's, bit for bit (the
        consistency check and the rest run here). With ``checkpoint`` the workers keep their
        results there as they finish: on a cluster, a folder they share resumes.
    **kw : fields of :class:`DepthOptions` (``scale=0.5``, ``fill_segments=True``, ...) or
        fields of :class:`~vibr.stereo.lightfield.LightFieldOptions` (``step=0.05``), applied
        over ``options`` (:func:`depth_options`); any other name raises ``TypeError``.

    Returns
    -------
    Scene
        A copy of ``scene`` at its own resolution with ``depth`` (H×W float32, NaN unknown)
        and ``sigma_z`` (H×W float32, scene units; unknown pixels get the largest known
        value) set on the requested views. ``meta["depth_estimation"]`` holds per-view
        statistics (kept fraction, reprojection error, time, depth range, planes); its
        ``role`` is "target" or "consistency partner" (estimated only for the check, not
        stored on the returned scene).

    sigma_z = sqrt(sigma_curv² + spread²): the cost-curvature width of
    :func:`~vibr.stereo.planesweep.plane_sweep` combined with the spread of the agreeing
    neighbours' depths from the consistency check; for MVS, times :data:`MVS_SIGMA_SCALE`.
    """
    t_all = time.perf_counter()
    opt = depth_options(options, **kw)

    check_depth_params(**{f.name: getattr(opt, f.name) for f in fields(opt)})  # ranges
    targets, inputs, excl, method, opt = _check_request(scene, views, exclude, opt)
    cams = [v.camera.scaled(opt.scale) if opt.scale != 1.0 else v.camera for v in scene.views]
    imgs = _Images(scene, cams)
    if method == "lightfield":
        if executor is not None:
            logger.info("depth: a light field's views are estimated in this process (the executor is for MVS)")
        depths, sigmas, stats = _estimate_lightfield(scene, targets, inputs, cams, imgs, opt)
        for i in targets:  # masked samples did not match; a masked pixel gets no depth
            m = imgs.mask(i)
            if m is not None:
                depths[i] = np.where(m, depths[i], np.nan).astype(np.float32)
    else:
        depths, sigmas, stats = _estimate_mvs(scene, targets, inputs, cams, imgs, opt, checkpoint, executor)
    new_views = _at_scene_resolution(scene, targets, cams, depths, sigmas)
    meta = dict(scene.meta)
    meta["depth_estimation"] = {"method": method, "scale": opt.scale, "views": stats,
                                "sweep_scale": opt.sweep_scale, "coarse_iter": int(opt.coarse_iter),
                                "fill_segments": bool(opt.fill_segments) and method == "mvs",
                                "excluded": [scene.views[i].name for i in sorted(excl)],
                                "time_s": time.perf_counter() - t_all}
    logger.info(f"depth: {len(targets)} view(s) by {method} in {time.perf_counter() - t_all:.1f} s")
    _warn_if_little_kept(stats)
    return replace(scene, views=new_views, meta=meta)


#: The plane sweep's sigma_z (the cost curvature and the partners' spread, a heuristic) is
#: multiplied by this so that it reads as the renderer reads it, the standard deviation of the
#: depth error: unscaled, 68 % of the errors on the procedural scenes without depth lie within
#: a fourteenth of it, and the renders' colour weights collapsed on texture that was in place.
#: Chosen on those scenes, the best mean all-pixel PSNR among 1, 0.3, 0.1, 0.07, 0.03 and 0.01
#: (``benchmarks/quality/mvs_sigma.py``; docs/explanation/depth.md, "sigma_z").
MVS_SIGMA_SCALE = 0.1

#: Below this fraction of pixels kept (mean over the views), the estimate is said to be poor.
FEW_KEPT = 0.1


def _warn_if_little_kept(stats: dict) -> None:
    """A warning when the estimate kept little: the depth maps are then mostly holes, which
    a render fills from the fallback proxy or leaves empty."""
    kept = [v["kept"] for v in stats.values() if v.get("role") == "target" and "kept" in v]
    if kept and float(np.mean(kept)) < FEW_KEPT:
        logger.warning(f"depth: only {100 * float(np.mean(kept)):.1f} % of pixels kept: the views may "
                       f"barely overlap, or the depth range (--depth-range) or the planes "
                       f"(--max-planes, --step-px) may miss the scene")


def depth_method(scene: Scene, method: str = "auto") -> str:
    """The estimator ``method`` means for ``scene``: "auto" is "lightfield" on a light-field
    grid (``scene.grid``), else "mvs"."""
    if method == "auto":
        return "lightfield" if scene.grid is not None else "mvs"
    if method not in ("mvs", "lightfield"):
        raise VibrInputError(f"unknown depth method {method!r} (auto, mvs, lightfield)", scene.root)
    return method


def _check_request(scene: Scene, views, exclude, opt: DepthOptions):
    """The requested views (``targets``), the usable inputs, the excluded set, the
    resolved method, and ``opt`` with its depth range as floats; bad requests raise
    :class:`VibrInputError`."""
    n = len(scene)
    excl = {scene.index(k) for k in exclude}
    targets = [i for i in range(n) if i not in excl] if views is None else [scene.index(k) for k in views]
    if not targets:
        raise VibrInputError("no views to estimate depth for" + (" (every view is excluded)" if views is None
                                                                   else " (the list of views is empty)"), scene.root)
    if len(set(targets)) < len(targets):
        raise VibrInputError("a view is listed twice in the views to estimate", scene.root)
    for i in targets:
        if i in excl:
            raise VibrInputError(f"view {scene.views[i].name} is both requested and excluded", scene.root)
        if scene.views[i].image is None:
            raise VibrInputError(f"view {scene.views[i].name} has no image", scene.root)
    inputs = [i for i in range(n) if i not in excl and scene.views[i].image is not None]
    if len(inputs) < 2:
        raise VibrInputError("depth estimation needs at least two input views", scene.root)
    if not (0 < opt.scale <= 1.0 + 1e-9):
        raise VibrInputError(f"scale must be in (0, 1], got {opt.scale}", scene.root)
    if not (0 < opt.sweep_scale <= 1.0 + 1e-9):
        raise VibrInputError(f"sweep_scale must be in (0, 1], got {opt.sweep_scale}", scene.root)
    if int(opt.coarse_iter) != opt.coarse_iter or opt.coarse_iter < 0:
        raise VibrInputError(f"coarse_iter must be an integer >= 0, got {opt.coarse_iter}", scene.root)
    r = opt.lightfield.get("pm_radius")  # LightFieldOptions.pm_radius: the refinement's window
    if r is not None and (int(r) != r or r < 1):
        raise VibrInputError(f"pm_radius must be an integer >= 1, got {r}", scene.root)
    method = depth_method(scene, opt.method)
    if method == "lightfield":
        LightFieldOptions(**opt.lightfield)  # its checks, before any view is estimated
    if opt.depth_range is not None:
        dr = (float(opt.depth_range[0]), float(opt.depth_range[1]))
        if not 0 < dr[0] < dr[1]:
            raise VibrInputError(f"bad depth range {dr}", scene.root)
        opt = replace(opt, depth_range=dr)
    return targets, inputs, excl, method, opt


class _Images:
    """The views' images at the working scale (``imgs(i)``) and reduced copies of them
    (``imgs.small(i, camera)``: coarse level, depth-range sweep), each resized once; their
    masks likewise (``imgs.mask(i[, camera])``)."""

    def __init__(self, scene: Scene, cams: list[Camera]):
        self.scene, self.cams = scene, cams
        self.full: dict[int, np.ndarray] = {}
        self.resized: dict[tuple, np.ndarray] = {}  # keyed (view, shape), shared with default_depth_range

    def __call__(self, i: int) -> np.ndarray:
        if i not in self.full:
            self.full[i] = _resized(self.scene.views[i].image, self.cams[i])
        return self.full[i]

    def small(self, i: int, camera: Camera) -> np.ndarray:
        key = (i, camera.shape)
        if key not in self.resized:
            self.resized[key] = _resized(self(i), camera)
        return self.resized[key]

    def mask(self, i: int, camera: Camera | None = None) -> np.ndarray | None:
        """View ``i``'s mask (:attr:`vibr.scene.View.mask`) at ``camera``'s size (default
        the working scale), or None."""

        m = self.scene.views[i].mask
        if m is None:
            return None
        shape = (camera or self.cams[i]).shape
        key = ("mask", i, shape)
        if key not in self.resized:
            self.resized[key] = resize_mask(m, shape)
        return self.resized[key]


def _estimate_lightfield(scene, targets, inputs, cams, imgs, opt: DepthOptions):
    """Light-field depth of each requested view (:func:`lightfield_depth`)."""

    def one(i):
        lf = dict(opt.lightfield)
        lf.setdefault("pm_iter", opt.refine_iter)
        # one coarse level for both methods (for light fields its iterations are part of
        # refine_iter: LightFieldOptions.pm_coarse_iter)
        lf.setdefault("pm_coarse_scale", opt.sweep_scale)
        lf.setdefault("pm_coarse_iter", int(opt.coarse_iter))
        if opt.median_radius is not None:
            lf.setdefault("median_radius", opt.median_radius)
        return lightfield_depth(scene, i, cams, imgs, inputs, depth_range=opt.depth_range,
                                radius=opt.radius, max_cost=opt.max_cost, mem_bytes=opt.mem_bytes,
                                n_best=opt.n_best, **lf)[:3]

    # one bar over the views (a light field's 80 take minutes): its count and time left
    with progress(total=len(targets), desc="depth views", unit="view") as bar:
        def counted(i):
            out = one(i)
            bar.update(1)
            return out

        results = map_views(counted, list(targets))
    depths, sigmas, stats = {}, {}, {}
    for i, (z, s, st) in zip(targets, results):
        depths[i], sigmas[i] = z, s
        stats[scene.views[i].name] = dict(st, role="target")
    tol = float(opt.lightfield.get("consensus_tol", LightFieldOptions.consensus_tol))
    if tol > 0 and len(targets) > 1:
        t0 = time.perf_counter()
        fused, agree = consensus_depth([depths[i] for i in targets], [cams[i] for i in targets], rel_tol=tol)
        for i, z, a in zip(targets, fused, agree):
            depths[i] = z
            stats[scene.views[i].name].update(consensus_agree=a)
        logger.info("light-field consensus of %d views (tolerance %g): %.1f s", len(targets), tol,
                    time.perf_counter() - t0)
    return depths, sigmas, stats


def _estimate_mvs(scene, targets, inputs, cams, imgs, opt: DepthOptions, checkpoint=None, executor=None):
    """Plane-sweep MVS of each requested view (and of its consistency partners), then the
    consistency check and the optional segment completion of the requested views."""
    est, nbrs = _mvs_views(scene, cams, targets, inputs, opt)
    med_r = 9 if opt.median_radius is None else int(opt.median_radius)  # MVS default: 19×19 window
    ck = None
    if checkpoint is not None:
        ck = ViewCheckpoint(checkpoint, {**{f.name: getattr(opt, f.name) for f in fields(opt)}, "med_r": med_r})

    todo = [i for i in est if nbrs[i]]
    # serial: here, on this call's images; else each worker receives them once
    swept = dict(zip(todo, run_tasks(sweep_task, [(i, nbrs[i]) for i in todo], setup=sweep_setup,
                                     setup_args=(imgs, inputs, opt, med_r, ck), executor=executor,
                                     desc="depth views")))
    raw, stats = {}, {}
    for i in todo:
        raw[i], st, nbrs[i] = swept[i]
        st["role"] = "target" if i in targets else "consistency partner"
        stats[scene.views[i].name] = st
    depths, sigmas = {}, {}
    for i in targets:
        if i not in raw:  # no stereo partner (_mvs_views): nothing known
            depths[i] = np.full(cams[i].shape, np.nan, np.float32)
            sigmas[i] = np.zeros(cams[i].shape, np.float32)
            stats[scene.views[i].name] = {"role": "target", "kept": 0.0, "neighbours": [], "time_s": 0.0}
            continue
        d, s, grad, dr = raw[i]
        st = stats[scene.views[i].name]
        if opt.consistency:
            d, s = _check_view(scene, i, d, s, raw, est, nbrs, cams, opt, st)
        st["kept"] = float(np.isfinite(d).mean())
        if opt.fill_segments:
            t0 = time.perf_counter()
            # segmented at half size: the segmentation is the slow part at full size
            small_img = imgs.small(i, cams[i].scaled(0.5))
            d, s, n_filled = _segment_completion(imgs(i), small_img, cams[i], d, s, grad, dr,
                                                 opt.rel_tol, med_r)
            st["filled"] = n_filled / d.size
            st["segments_s"] = time.perf_counter() - t0
        depths[i], sigmas[i] = d, s * np.float32(MVS_SIGMA_SCALE)
    return depths, sigmas, stats


def sweep_setup(imgs: "_Images", inputs, opt: DepthOptions, med_r: int, ck) -> dict:
    """Per worker of a depth estimate (:func:`vibr.executor.run_tasks`): what every view's
    sweep shares (the scene and cameras in ``imgs``, whose resized images it reuses)."""
    return {"imgs": imgs, "inputs": inputs, "opt": opt, "med_r": med_r, "ck": ck}


def sweep_task(ctx: dict, task) -> tuple:
    """One view's sweep: ``task`` = (view index, partners); returns what :func:`_sweep_view`
    returns, with its time (the consistency check runs in the caller)."""
    i, nb = task
    imgs, ck = ctx["imgs"], ctx["ck"]
    t0 = time.perf_counter()
    if ck is None:
        raw, st, nb = _sweep_view(imgs.scene, i, list(nb), imgs.cams, imgs, ctx["inputs"], ctx["opt"], ctx["med_r"])
    else:
        raw, st, nb = _sweep_view_resumable(ck, imgs.scene, i, list(nb), imgs.cams, imgs, ctx["inputs"],
                                            ctx["opt"], ctx["med_r"])
    st["time_s"] = st.get("time_s", time.perf_counter() - t0)
    return raw, st, nb


def _why_no_partner(cams, i, inputs) -> str:
    others = [j for j in inputs if j != i]
    if others and shared_centre([cams[i]] + [cams[j] for j in others]) is not None:
        return (": every view shares its centre (a rotation-only capture), so there is no parallax to "
                "estimate depth from; rendering needs none (vibr render / eval / view put a sphere around "
                "that centre)")
    return " (none within 60 degrees of its viewing direction at another centre)"


def _mvs_views(scene, cams, targets, inputs, opt: DepthOptions):
    """The views to estimate (the targets, then their consistency partners) and the
    nearest-first stereo partners of each."""
    nbrs = {i: select_neighbours(cams, i, inputs, opt.n_neighbours) for i in targets}
    lonely = [i for i in targets if not nbrs[i]]
    if len(lonely) == len(targets):
        i = lonely[0]
        raise VibrInputError(f"view {scene.views[i].name} has no usable stereo partner{_why_no_partner(cams, i, inputs)}",
                             scene.root)
    for i in lonely:  # the others' depth is still worth having (the fallback proxy covers these)
        logger.warning(f"depth: view {scene.views[i].name} has no usable stereo partner"
                       f"{_why_no_partner(cams, i, inputs)}: its depth is left unknown")
    est = list(targets)
    if opt.consistency:
        for i in targets:
            for j in nbrs[i][:opt.n_partners]:
                if j not in est:
                    est.append(j)
                    nbrs[j] = select_neighbours(cams, j, inputs, opt.n_neighbours)
    return est, nbrs


def _sweep_view(scene, i, nb, cams, imgs, inputs, opt: DepthOptions, med_r: int):
    """Sweep (coarse to fine), slanted-plane refinement and weighted median of view ``i``
    against partners ``nb``. Returns ``((depth NaN unknown, sigma_z, plane gradient, depth
    range), stats, partners)``; the partners gain coverage views (:func:`complete_coverage`)."""
    dr = opt.depth_range or default_depth_range(scene, i, cams, {j: imgs(j) for j in [i] + nb}, nb,
                                                cache=imgs.resized)
    # the views averaged per pixel stay those the nearest-first set implies; the
    # coverage partners only stand in where that set does not see
    nbest_i = opt.n_best or max(1, len(nb) // 2)
    if opt.coverage_gain is not None:
        nb = complete_coverage(cams, i, nb, inputs, dr, nbest_i, min_gain=opt.coverage_gain)
    lo_planes = min(64, opt.max_planes)
    D = opt.n_planes or _planes_for(cams[i], [cams[j] for j in nb], dr, opt.step_px, lo_planes, opt.max_planes)
    radius = opt.radius or 3
    common = dict(n_best=nbest_i, eps=opt.eps, max_cost=opt.max_cost, radius=radius)
    desc = f"depth {scene.views[i].name}"
    coarse_done = False
    if opt.refine_iter > 0 and opt.sweep_scale < 1.0:
        # coarse level: the sweep only has to put each pixel in the basin of its
        # cost, and at a reduced size it costs sweep_scale² as much
        cs = [cams[j].scaled(opt.sweep_scale) for j in [i] + nb]
        ims = [imgs.small(j, c) for j, c in zip([i] + nb, cs)]
        if not opt.n_planes:  # step_px is in pixels of the images swept
            D = _planes_for(cs[0], cs[1:], dr, opt.step_px, lo_planes, opt.max_planes)
        mks = [imgs.mask(j, c) for j, c in zip(nb, cs[1:])]
        res = plane_sweep(ims[0], cs[0], ims[1:], cs[1:], dr, n_planes=D, mem_bytes=opt.mem_bytes,
                          desc=desc, src_masks=mks, **common)
        if opt.coarse_iter > 0:
            res = refine_planes(ims[0], cs[0], ims[1:], cs[1:], res, n_iter=int(opt.coarse_iter),
                                src_masks=mks, **common)
            coarse_done = True
        res = upsample_sweep(res, cs[0], cams[i])
    else:
        res = plane_sweep(imgs(i), cams[i], [imgs(j) for j in nb], [cams[j] for j in nb], dr,
                          n_planes=D, mem_bytes=opt.mem_bytes, desc=desc,
                          src_masks=[imgs.mask(j) for j in nb], **common)
    if opt.refine_iter > 0:
        # after a refined coarse level the upsampled inverse depth carries its
        # slopes and the joint random moves have been made at the coarse size: the
        # fronto-parallel start and the joint perturbation are not worth their costs
        res = refine_planes(imgs(i), cams[i], [imgs(j) for j in nb], [cams[j] for j in nb], res,
                            n_iter=opt.refine_iter, fronto_init=not coarse_done,
                            joint_perturbation=not coarse_done, src_masks=[imgs.mask(j) for j in nb],
                            **common)
    if med_r > 0:
        res = median_planes(imgs(i), res, radius=med_r)
    keep = res.confident if imgs.mask(i) is None else res.confident & imgs.mask(i)
    d = np.where(keep, res.depth, np.nan).astype(np.float32)  # masked pixels: no depth
    stats = {"depth_range": dr, "n_planes": D, "neighbours": [scene.views[j].name for j in nb],
             "confident": float(res.confident.mean()), "sweep_s": res.meta["time_s"]}
    return (d, res.sigma_z, res.meta.get("plane_gradient"), dr), stats, nb


def _sweep_view_resumable(ck, scene, i, nb, cams, imgs, inputs, opt: DepthOptions, med_r: int):
    """:func:`_sweep_view` through the checkpoint ``ck``: a result kept by an interrupted
    run (same view, partners and options) is read back, a new one is kept."""
    v = scene.views[i]
    key = ck.key(v, cams[i], [scene.views[j] for j in nb])
    hit = ck.load(v.name, key)
    if hit is not None:
        a, info = hit
        grad = (a["grad_x"], a["grad_y"]) if "grad_x" in a else None
        st = dict(info["stats"], resumed=True)
        return (a["depth"], a["sigma_z"], grad, tuple(info["dr"])), st, [scene.index(n) for n in info["nb"]]
    t0 = time.perf_counter()
    (d, s, grad, dr), st, nb = _sweep_view(scene, i, nb, cams, imgs, inputs, opt, med_r)
    st["time_s"] = time.perf_counter() - t0
    arrays = {"depth": d, "sigma_z": np.asarray(s, np.float32)}
    if grad is not None:
        arrays["grad_x"], arrays["grad_y"] = grad
    ck.save(v.name, key, arrays, {"dr": list(dr), "nb": [scene.views[j].name for j in nb], "stats": st})
    return (d, s, grad, dr), st, nb


def _check_view(scene, i, d, s, raw, est, nbrs, cams, opt: DepthOptions, st: dict):
    """Forward-backward consistency of view ``i`` against the estimated views it is a
    partner of or that are its partners: inconsistent pixels become NaN and sigma_z
    gains the agreeing views' spread. Records partners, reprojection error and time in
    ``st``."""
    t0 = time.perf_counter()
    partners = [j for j in est if j != i and j in raw and (j in nbrs[i] or i in nbrs.get(j, []))]
    cr = check_consistency(d, cams[i], [raw[j][0] for j in partners], [cams[j] for j in partners],
                           rel_tol=opt.rel_tol, px_tol=opt.px_tol, min_agree=opt.min_agree)
    d = np.where(cr.keep, d, np.nan).astype(np.float32)
    spread = np.where(np.isfinite(cr.spread), cr.spread, 0.0)
    s = np.sqrt(s.astype(np.float64) ** 2 + spread ** 2).astype(np.float32)
    st["consistency_partners"] = [scene.views[j].name for j in partners]
    st["reproj_px"] = float(np.nanmean(cr.reproj[cr.keep])) if cr.keep.any() else float("nan")
    st["consistency_s"] = time.perf_counter() - t0
    return d, s


def _at_scene_resolution(scene, targets, cams, depths, sigmas) -> list:
    """The scene's views with the estimated depth and sigma_z upsampled to each view's own
    size; unknown pixels get the largest known sigma_z."""
    new_views = list(scene.views)
    for i in targets:
        v = scene.views[i]
        d = upsample_depth(depths[i], cams[i], v.camera)
        s = upsample_map(np.asarray(sigmas[i], np.float32), cams[i], v.camera)
        known = np.isfinite(d)
        fill = float(np.nanmax(s[known])) if known.any() else 1.0
        s = np.where(known & np.isfinite(s), s, fill).astype(np.float32)
        new_views[i] = v.replace(depth=d, sigma_z=s)
    return new_views
