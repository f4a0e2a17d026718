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
from dataclasses import replace

import numpy as np
from scipy.ndimage import map_coordinates

from ..camera import Camera, axes_meeting_point
from ..errors import VibrInputError
from ..io.images import resize_image
from ..scene import Scene
from .consistency import check_consistency
from .planesweep import SweepResult, median_planes, plane_sweep, refine_planes
from .segments import fill_segment_planes, segment_image

logger = logging.getLogger(__name__)


#: Default number of slanted-plane refinement iterations after the sweep (see
#: :func:`estimate_depth` and docs/DEPTH.md for the measurements behind it).
REFINE_ITER = 2


# --------------------------------------------------------------------------- helpers
def _resized(img: np.ndarray, camera: Camera) -> np.ndarray:
    """``img`` at ``camera``'s size (:func:`vibr.io.images.resize_image`: Gaussian
    anti-aliasing only, reflected border, float32 not quantised)."""
    return resize_image(img, camera.shape, box=False, mode="reflect", quantise=False)


def _lo_coords(camera_lo: Camera, camera_hi: Camera) -> list[np.ndarray]:
    """``[y_lo, x_lo]`` of every pixel of ``camera_hi``'s grid on ``camera_lo``'s, by the
    resize mapping of :meth:`Camera.scaled`, ``x_lo = s (x + ½) − ½`` (for map_coordinates)."""
    Hh, Wh = camera_hi.shape
    yy, xx = np.mgrid[0:Hh, 0:Wh].astype(np.float64)
    return [camera_lo.height / camera_hi.height * (yy + 0.5) - 0.5,
            camera_lo.width / camera_hi.width * (xx + 0.5) - 0.5]


def upsample_depth(depth: np.ndarray, camera_lo: Camera, camera_hi: Camera) -> np.ndarray:
    """Bring a depth map (NaN unknown) from ``camera_lo``'s grid to ``camera_hi``'s.

    Pixel x of the high-resolution grid sits at ``x_lo = s (x + ½) − ½`` (the mapping of
    :meth:`Camera.scaled`). Inverse depth is interpolated bilinearly where the four
    low-resolution neighbours are known, nearest-neighbour elsewhere (NaN stays NaN).
    """
    if depth.shape == camera_hi.shape:
        return depth
    yl, xl = _lo_coords(camera_lo, camera_hi)
    known = np.isfinite(depth)
    w = np.where(known, 1.0 / np.where(known, depth, 1.0), 0.0)
    wi = map_coordinates(w, [yl, xl], order=1, mode="nearest")
    ki = map_coordinates(known.astype(np.float64), [yl, xl], order=1, mode="nearest")
    dn = map_coordinates(np.where(known, depth, np.nan), [yl, xl], order=0, mode="nearest")
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(ki > 1 - 1e-9, 1.0 / wi, dn)
    return out.astype(np.float32)


def upsample_sweep(res: SweepResult, camera_lo: Camera, camera_hi: Camera) -> SweepResult:
    """A plane-sweep (or coarse refinement) result computed on ``camera_lo``'s grid,
    brought to ``camera_hi``'s as an initialisation of
    :func:`~vibr.stereo.planesweep.refine_planes`: inverse depth bilinear (every pixel of a
    sweep has one), its inverse-depth width (sigma_z / z²) and ``confident``
    nearest-neighbour; the planes ``winv`` are the same. A coarse refinement's per-pixel
    slopes (``meta["plane_gradient"]``, on the coarse grid) are dropped: the full-size
    refinement starts from the finite differences of the upsampled inverse depth."""
    yl, xl = _lo_coords(camera_lo, camera_hi)
    w = map_coordinates(np.asarray(res.inv_depth, np.float64), [yl, xl], order=1, mode="nearest")
    sigma_w = res.sigma_z.astype(np.float64) * np.asarray(res.inv_depth, np.float64) ** 2
    sigma_w = map_coordinates(sigma_w, [yl, xl], order=0, mode="nearest")
    z = 1.0 / w
    meta = {k: v for k, v in res.meta.items() if k != "plane_gradient"}
    return SweepResult(depth=z.astype(np.float32), inv_depth=w,
                       cost=map_coordinates(res.cost, [yl, xl], order=0, mode="nearest"),
                       sigma_z=(z * z * sigma_w).astype(np.float32),
                       confident=map_coordinates(res.confident.astype(np.uint8), [yl, xl], order=0,
                                                 mode="nearest").astype(bool),
                       winv=res.winv, meta=meta)


def upsample_map(m: np.ndarray, camera_lo: Camera, camera_hi: Camera) -> np.ndarray:
    """Nearest-neighbour resampling of a per-pixel map (e.g. sigma_z) to ``camera_hi``."""
    if m.shape == camera_hi.shape:
        return m
    yl, xl = _lo_coords(camera_lo, camera_hi)
    return map_coordinates(m, [yl, xl], order=0, mode="nearest").astype(np.float32)


def select_neighbours(cameras: list[Camera], ref: int, candidates: list[int], k: int,
                      max_angle_deg: float = 60.0) -> list[int]:
    """The ``k`` candidate views best suited as stereo partners of view ``ref``.

    Candidates whose optical axis turns by more than ``max_angle_deg`` from the
    reference's, or whose centre coincides with it, are dropped; the rest are ranked by the
    distance between centres (the nearest first: small baselines match best, and the
    plane sweep's robust aggregation copes with the loss of depth precision).
    """
    cr = cameras[ref]
    scored = sorted((float(np.linalg.norm(cameras[j].centre - cr.centre)), j) for j in candidates
                    if j != ref and _admissible(cr, cameras[j], max_angle_deg))
    return [j for _, j in scored[:k]]


def _admissible(ref: Camera, cam: Camera, max_angle_deg: float) -> bool:
    """A stereo partner for ``ref``: its optical axis within ``max_angle_deg`` of the
    reference's and its centre elsewhere (a zero baseline has no parallax)."""
    cosang = float(np.clip(ref.optical_axis @ cam.optical_axis, -1, 1))
    return np.degrees(np.arccos(cosang)) <= max_angle_deg and np.linalg.norm(cam.centre - ref.centre) >= 1e-12


def frustum_coverage(ref: Camera, srcs: list[Camera], depth_range, *, n_xy: int = 24,
                     n_depth: int = 8) -> np.ndarray:
    """Which source views see samples of the reference's viewing frustum.

    The reference image is sampled on an ``n_xy``-wide grid (rows in proportion) at
    ``n_depth`` depths uniform in inverse depth over ``depth_range`` (near, far); a sample
    is seen by a source when it lies in front of it and projects inside its image.
    Occlusions are ignored (the geometry is not known yet). Returns (n_src, n_samples) bool.
    """
    near, far = float(depth_range[0]), float(depth_range[1])
    ny = max(2, int(round(n_xy * ref.height / ref.width)))
    xs = (np.arange(n_xy) + 0.5) * ref.width / n_xy - 0.5
    ys = (np.arange(ny) + 0.5) * ref.height / ny - 0.5
    xy = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    z = 1.0 / np.linspace(1.0 / far, 1.0 / near, n_depth)
    X = ref.camera_to_world(ref.pixel_rays(xy)[None] * z[:, None, None]).reshape(-1, 3)
    seen = np.zeros((len(srcs), len(X)), bool)
    for v, c in enumerate(srcs):
        p, zc = c.project(X)
        seen[v] = (zc > 0) & (p[:, 0] > -0.5) & (p[:, 1] > -0.5) & (p[:, 0] < c.width - 0.5) & (p[:, 1] < c.height - 0.5)
    return seen


def complete_coverage(cameras: list[Camera], ref: int, chosen: list[int], candidates: list[int],
                      depth_range, n_need: int, *, min_gain: float = 0.02, max_extra: int = 4,
                      max_angle_deg: float = 60.0) -> list[int]:
    """Add partners to ``chosen`` until the reference's frustum is seen by ``n_need`` views.

    Nearest-first partners (:func:`select_neighbours`) can all sit on one side of a free
    (hand-held) layout and leave part of the reference image, e.g. the near ground at its
    bottom, outside every partner, where no depth can be matched. Here the frustum
    samples of :func:`frustum_coverage` seen by fewer than ``n_need`` chosen views are the
    deficit, and the candidate that removes the most of it is added, as long as it
    removes at least ``min_gain`` of the samples (a partner costs as much time as any
    other; a sliver of coverage is not worth it), at most ``max_extra`` times. This is
    the coverage side of Goesele et al. (2007, §4.1)'s view selection; candidates turned
    by more than ``max_angle_deg`` from the reference are not considered.
    """
    cr = cameras[ref]
    pool = [j for j in candidates
            if j != ref and j not in chosen and _admissible(cr, cameras[j], max_angle_deg)]
    out = list(chosen)
    if not pool or n_need < 1:
        return out
    seen = frustum_coverage(cr, [cameras[j] for j in out + pool], depth_range)
    count = seen[: len(out)].sum(0)
    pool_seen = dict(zip(pool, seen[len(out):]))
    for _ in range(max_extra):
        short = count < n_need
        if not short.any() or not pool_seen:
            break
        best = max(pool_seen, key=lambda j: (pool_seen[j] & short).mean())
        if (pool_seen[best] & short).mean() < min_gain:
            break
        out.append(best)
        count = count + pool_seen.pop(best)
    return out


def _parallax_rate(ref: Camera, src: Camera) -> float:
    """Pixels of parallax in ``src`` per unit of inverse depth ``w`` of the reference
    image centre's ray: ``|p(w=1) − p(w=0)|`` (the plane homography is affine in w)."""
    x = np.array([(ref.width - 1) / 2, (ref.height - 1) / 2])
    ray = ref.pixel_rays(x)
    xy_inf = src.project(ref.camera_to_world(ray * 1e9))[0]
    xy1 = src.project(ref.camera_to_world(ray * 1.0))[0]
    return float(np.linalg.norm(xy1 - xy_inf))


def default_depth_range(scene: Scene, ref: int, cameras: list[Camera], images: dict,
                        neighbours: list[int], *, coarse_width: int = 192,
                        max_parallax: float = 0.5, margin: float = 0.15,
                        use_points: bool = True, cache: dict | None = None) -> tuple[float, float]:
    """A depth range for the reference view when none is given.

    1. Sparse points (``scene.points``), when present: the 2nd–98th percentile of the
       depths of the points that project into the reference, widened by ``margin``.
    2. Otherwise a coarse plane sweep at ``coarse_width`` pixels over a wide range, from
       the plane whose parallax with the nearest neighbour is ``max_parallax`` × image width
       (near) to 100× that depth (far), extended to cover ``[z_c / 4, 4 z_c]`` when the
       cameras' optical axes meet at a depth ``z_c`` (:func:`vibr.camera.axes_meeting_point`)
       and ``[z_c / 2, 2 z_c]`` is not already inside,
       uniform in inverse depth; the 2nd–98th percentile of the confident coarse inverse
       depths, widened by ``margin`` of their span.

    ``cache``: a dict kept across calls (views) for the resized images of step 2, keyed
    by view and size, so that each image is resized once per scene rather than once per
    reference that uses it.
    """
    cam = cameras[ref]
    if use_points and scene.points is not None and len(scene.points) >= 20:
        xy, z = cam.project(np.asarray(scene.points, np.float64))
        inside = (z > 0) & (xy[:, 0] >= 0) & (xy[:, 0] <= cam.width - 1) & (xy[:, 1] >= 0) & (xy[:, 1] <= cam.height - 1)
        if inside.sum() >= 20:
            lo, hi = np.percentile(z[inside], [2, 98])
            span = hi - lo
            return float(max(lo - margin * span, lo * 0.5)), float(hi + margin * span)
    rate = _parallax_rate(cam, cameras[neighbours[0]])
    w_max = max_parallax * cam.width / max(rate, 1e-12)
    w_min = w_max / 100.0
    # Cameras that converge on an object (a ring, an arc) put it near the point their axes
    # meet. A wide baseline can put that point nearer than the half-image parallax limit
    # above: when a factor 2 around its depth is not inside the sweep, widen the sweep to a
    # factor 4 around it.
    X = axes_meeting_point([cameras[ref]] + [cameras[j] for j in neighbours])
    if X is not None:
        z_c = float((X - cam.centre) @ cam.optical_axis)
        if z_c > 0 and not (w_min <= 0.5 / z_c and 2.0 / z_c <= w_max):
            w_max = max(w_max, 4.0 / z_c)
            w_min = min(w_min, 0.25 / z_c)
    s = min(1.0, coarse_width / cam.width)
    cref = cam.scaled(s)
    csrc = [cameras[j].scaled(s) for j in neighbours]
    n_planes = int(np.clip(np.ceil(max_parallax * cref.width / 0.75), 32, 256))
    cache = {} if cache is None else cache

    def small(j, c):
        key = (j, c.shape)
        if key not in cache:
            cache[key] = _resized(images[j], c)
        return cache[key]

    res = plane_sweep(small(ref, cref), cref, [small(j, c) for j, c in zip(neighbours, csrc)], csrc,
                      (1.0 / w_max, 1.0 / w_min), n_planes=n_planes, radius=2,
                      desc="coarse depth range")
    good = res.confident & (res.cost < 0.5 * res.meta.get("max_cost", 0.6))
    w = res.inv_depth[good]
    if w.size < 50:
        return 1.0 / w_max, 1.0 / w_min
    lo, hi = np.percentile(w, [3, 97])
    span = max(hi - lo, 1e-9 * hi)
    lo = max(lo - margin * span, w_min)
    hi = min(hi + margin * span, w_max)
    return float(1.0 / hi), float(1.0 / lo)


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
    rate = max(_parallax_rate(ref, c) for c in srcs)
    span_px = rate * (1.0 / depth_range[0] - 1.0 / depth_range[1])
    return int(np.clip(np.ceil(span_px / step_px) + 1, lo, hi))


# --------------------------------------------------------------------------- main API
def estimate_depth(scene: Scene, *, views=None, scale: float = 1.0, depth_range=None,
                   method: str = "auto", exclude=(), n_neighbours: int = 4,
                   n_planes: int | None = None, step_px: float = 3.0, max_planes: int = 128, radius: int | None = None,
                   n_best: int | None = None, max_cost: float = 0.6, consistency: bool = True,
                   min_agree: int = 1, rel_tol: float = 0.01, px_tol: float = 1.0,
                   n_partners: int = 2, eps: float = 0.002, mem_bytes: float = 2e9,
                   refine_iter: int = REFINE_ITER, median_radius: int | None = None,
                   coverage_gain: float | None = 0.02, sweep_scale: float = 0.5,
                   coarse_iter: int = 1, fill_segments: bool = False,
                   **lf_params) -> Scene:
    """Estimate orthogonal depth and its uncertainty for views of a scene.

    Parameters
    ----------
    scene : Scene
        Calibrated views with images (existing depth is ignored and replaced on the
        requested views).
    views : list of int or str, optional
        Views to estimate (default: every view not in ``exclude``).
    scale : float
        Resolution factor of the estimation; the maps are upsampled back (module docstring).
    depth_range : (near, far), optional
        Orthogonal depth range in scene units for every reference view; default
        :func:`default_depth_range` per view.
    method : "auto" | "mvs" | "lightfield"
        "auto" is "lightfield" when ``scene.grid`` is set, else "mvs".
    exclude : views never used as inputs (e.g. an evaluation's held-out target).
    n_neighbours : stereo partners per reference view (MVS), nearest first
        (:func:`select_neighbours`).
    coverage_gain : when the nearest partners leave part of the reference's frustum seen by
        fewer than ``n_best`` of them, add the candidate that sees most of that part, while
        it adds at least this fraction of the frustum (:func:`complete_coverage`, at most 4
        extra views; ``None``: never). In a hand-held layout the nearest views can all miss
        the near ground at the bottom of the image; in a sequence (fountain) only its end
        views get a fifth partner.
    n_planes : planes of the sweep (default: from ``step_px``, 64 … ``max_planes``).
    step_px : parallax step between planes on the farthest partner, in pixels. The
        slanted-plane refinement then searches depth continuously, so the sweep only has
        to put each pixel in the right basin of its cost; 3 px (under half the 7×7 window)
        does (docs/DEPTH.md: fountain kept 86.1 % vs 86.2 % at 2 px, 7 s faster).
    max_planes : upper bound on the number of planes per view.
    radius : ZNCC window half-size (default 3 for MVS; light fields: see
        :func:`~vibr.stereo.lightfield.lightfield_depth`).
    n_best : views averaged per pixel and plane (default half of the partners; for light
        fields see :func:`~vibr.stereo.lightfield.lightfield_depth`).
    max_cost : aggregated ``1 − ZNCC`` above which a pixel is unknown.
    eps : ZNCC regulariser (intensity std, images in [0, 1]); see
        :func:`~vibr.stereo.planesweep.plane_sweep`.
    consistency : run the cross-view forward-backward check (MVS); views whose partners
        are not requested get ``n_partners`` extra (non-excluded) views estimated for it.
    min_agree, rel_tol, px_tol : consistency check parameters
        (:func:`vibr.stereo.consistency.check_consistency`).
    mem_bytes : memory bound of one plane sweep's working set.
    refine_iter : iterations of the slanted-plane PatchMatch refinement after the sweep
        (:func:`~vibr.stereo.planesweep.refine_planes`; 0: the sweep's winner-take-all
        depth). The light-field method takes it too (its ``pm_iter``).
    median_radius : half-size of the window of the joint weighted median of the planes
        after the refinement (:func:`~vibr.stereo.planesweep.median_planes`, sampled
        every 3 px; 0: none). Default: 9 for MVS (19×19, about three times the matching
        window), none for light fields. On cotton the median lowers the centre view's
        BadPix and MSE but costs 0.5–1.25 dB when the held-out view is rendered from the
        estimated source depths (docs/DEPTH.md); on fountain the render gains.
    sweep_scale : image scale of the coarse level (MVS, with ``refine_iter > 0``): the
        plane sweep and the first ``coarse_iter`` refinement iterations run on the images
        resized by it, their planes are upsampled (:func:`upsample_sweep`), and the last
        ``refine_iter`` iterations, the median and the check run at full size
        (coarse to fine). The sweep only has to put each pixel in the basin of its cost,
        and at half size it costs a quarter as much; its planes are ``step_px`` apart in
        the resized images' pixels. After the coarse iterations, the full-size ones start
        from the upsampled slopes alone and leave out the joint random perturbation
        (``refine_planes(fronto_init=False, joint_perturbation=False)``). 1: the sweep at
        full size, no coarse level. Default 0.5, measured against the full-size sweep
        (docs/DEPTH.md, sixth session): fountain kept 88.7 % instead of 88.2 %,
        reprojection error 0.224 px instead of 0.230 px, in 45.2 and 49.4 s against 56.8
        and 62.6 s in alternating runs; on the hand-held synthetic scenes at 512 px, % within
        1 % within 0.03 points of the full-size sweep or above it on all seven seeds. The
        leaner full-size level (seventh session): fountain 88.6 %, 0.223 px, 56.1 and
        59.0 s against 75.9 and 68.8 s on a slow machine state; hand-held +0.45 points
        summed over the seven seeds.
    coarse_iter : slanted-plane refinement iterations at ``sweep_scale`` before the
        upsampling (ignored when ``sweep_scale`` is 1). Without it the half-size sweep
        lost up to 0.6 points on the hand-held scenes: a plane refined at the coarse level
        lands more full-size pixels in the right basin than the sweep's winner.
    fill_segments : dense output (MVS). After the consistency check, fill the unknown
        pixels of each colour segment whose known depths mostly lie on one plane with that
        plane, then run the weighted median of the planes again
        (:mod:`vibr.stereo.segments`; the median is skipped with ``median_radius=0``):
        the prior that reaches past the matching window, for a flat surface beside a
        textured one and for points that too few partners see. Hand-held synthetic
        scenes at 512 px: 97.1–98.6 % of textured pixels within 1 % instead of
        92.65–97.1 %. Off by default: the renderer leaves unknown source pixels out, and
        on fountain renders view 5 0.5 dB better without the filled ones (docs/DEPTH.md,
        step 9). ``stats["kept"]`` stays the fraction kept by the check;
        ``stats["filled"]`` is the fraction filled.
    **lf_params : passed to :func:`vibr.stereo.lightfield.lightfield_depth` (``step``,
        ``max_views``, ``refine``, ``tv_lambda``, ...). The light-field method uses
        ``depth_range``, ``radius``, ``max_cost``
        and ``mem_bytes``; it ignores ``n_neighbours``, ``step_px`` and the consistency
        options (its sweep already uses the grid views; its eps defaults to 0.001).

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
    neighbours' depths from the consistency check.
    """
    t_all = time.perf_counter()
    n = len(scene)
    excl = {scene.index(k) for k in exclude}
    if views is None:
        targets = [i for i in range(n) if i not in excl]
    else:
        targets = [scene.index(k) for k in views]
    for i in targets:
        if i in excl:
            raise VibrInputError(f"view {scene.views[i].name} is both requested and excluded", scene.root)
        if scene.views[i].image is None:
            raise VibrInputError(f"view {scene.views[i].name} has no image", scene.root)
    inputs = [i for i in range(n) if i not in excl and scene.views[i].image is not None]
    if len(inputs) < 2:
        raise VibrInputError("depth estimation needs at least two input views", scene.root)
    if not (0 < scale <= 1.0 + 1e-9):
        raise VibrInputError(f"scale must be in (0, 1], got {scale}", scene.root)
    if not (0 < sweep_scale <= 1.0 + 1e-9):
        raise VibrInputError(f"sweep_scale must be in (0, 1], got {sweep_scale}", scene.root)
    if int(coarse_iter) != coarse_iter or coarse_iter < 0:
        raise VibrInputError(f"coarse_iter must be an integer >= 0, got {coarse_iter}", scene.root)
    if method == "auto":
        method = "lightfield" if scene.grid is not None else "mvs"
    if method not in ("mvs", "lightfield"):
        raise VibrInputError(f"unknown depth method {method!r} (auto, mvs, lightfield)", scene.root)
    if depth_range is not None:
        depth_range = (float(depth_range[0]), float(depth_range[1]))
        if not 0 < depth_range[0] < depth_range[1]:
            raise VibrInputError(f"bad depth range {depth_range}", scene.root)

    cams = [v.camera.scaled(scale) if scale != 1.0 else v.camera for v in scene.views]
    images: dict[int, np.ndarray] = {}

    def img(i):
        if i not in images:
            images[i] = _resized(scene.views[i].image, cams[i])
        return images[i]

    # reduced-size images (coarse level, depth-range sweep), each resized once per size
    resized: dict[tuple, np.ndarray] = {}

    def small(i, camera):
        key = (i, camera.shape)
        if key not in resized:
            resized[key] = _resized(img(i), camera)
        return resized[key]

    if method == "lightfield":
        from .lightfield import lightfield_depth

        results = {}
        for i in targets:
            lf = dict(lf_params)
            lf.setdefault("pm_iter", refine_iter)
            if median_radius is not None:
                lf.setdefault("median_radius", median_radius)
            results[i] = lightfield_depth(scene, i, cams, img, inputs, depth_range=depth_range,
                                          radius=radius, max_cost=max_cost, mem_bytes=mem_bytes,
                                          n_best=n_best, **lf)
        stats = {scene.views[i].name: dict(results[i][2], role="target") for i in targets}
        depths = {i: results[i][0] for i in targets}
        sigmas = {i: results[i][1] for i in targets}
    else:
        # views to estimate: the targets plus consistency partners
        nbrs = {i: select_neighbours(cams, i, inputs, n_neighbours) for i in targets}
        for i in targets:
            if not nbrs[i]:
                raise VibrInputError(f"view {scene.views[i].name} has no usable stereo partner", scene.root)
        est = list(targets)
        if consistency:
            for i in targets:
                for j in nbrs[i][:n_partners]:
                    if j not in est:
                        est.append(j)
                        nbrs[j] = select_neighbours(cams, j, inputs, n_neighbours)
        depths, sigmas, stats = {}, {}, {}
        raw = {}
        med_r = 9 if median_radius is None else int(median_radius)  # MVS default: 19×19 window
        for i in est:
            t0 = time.perf_counter()
            nb = nbrs[i]
            if not nb:
                continue
            dr = depth_range or default_depth_range(scene, i, cams, {j: img(j) for j in [i] + nb}, nb,
                                                    cache=resized)
            # the views averaged per pixel stay those the nearest-first set implies; the
            # coverage partners only stand in where that set does not see
            nbest_i = n_best or max(1, len(nb) // 2)
            if coverage_gain is not None:
                nb = complete_coverage(cams, i, nb, inputs, dr, nbest_i, min_gain=coverage_gain)
                nbrs[i] = nb
            D = n_planes or _planes_for(cams[i], [cams[j] for j in nb], dr, step_px, min(64, max_planes), max_planes)
            coarse_done = False
            if refine_iter > 0 and sweep_scale < 1.0:
                # coarse level: the sweep only has to put each pixel in the basin of its
                # cost, and at a reduced size it costs sweep_scale² as much
                cs = [cams[j].scaled(sweep_scale) for j in [i] + nb]
                ims = [small(j, c) for j, c in zip([i] + nb, cs)]
                if not n_planes:  # step_px is in pixels of the images swept
                    D = _planes_for(cs[0], cs[1:], dr, step_px, min(64, max_planes), max_planes)
                res = plane_sweep(ims[0], cs[0], ims[1:], cs[1:], dr, n_planes=D,
                                  radius=radius or 3, n_best=nbest_i, max_cost=max_cost, eps=eps,
                                  mem_bytes=mem_bytes, desc=f"depth {scene.views[i].name}")
                if coarse_iter > 0:
                    res = refine_planes(ims[0], cs[0], ims[1:], cs[1:], res, n_iter=int(coarse_iter),
                                        n_best=nbest_i, eps=eps, max_cost=max_cost, radius=radius or 3)
                    coarse_done = True
                res = upsample_sweep(res, cs[0], cams[i])
            else:
                res = plane_sweep(img(i), cams[i], [img(j) for j in nb], [cams[j] for j in nb], dr,
                                  n_planes=D, radius=radius or 3, n_best=nbest_i, max_cost=max_cost,
                                  eps=eps, mem_bytes=mem_bytes, desc=f"depth {scene.views[i].name}")
            if refine_iter > 0:
                # after a refined coarse level the upsampled inverse depth carries its
                # slopes and the joint random moves have been made at the coarse size: the
                # fronto-parallel start and the joint perturbation are not worth their costs
                res = refine_planes(img(i), cams[i], [img(j) for j in nb], [cams[j] for j in nb], res,
                                    n_iter=refine_iter, n_best=nbest_i, eps=eps, max_cost=max_cost,
                                    radius=radius or 3, fronto_init=not coarse_done,
                                    joint_perturbation=not coarse_done)
            if med_r > 0:
                res = median_planes(img(i), res, radius=med_r)
            d = np.where(res.confident, res.depth, np.nan).astype(np.float32)
            raw[i] = (d, res.sigma_z, res.meta.get("plane_gradient"), dr)
            stats[scene.views[i].name] = {
                "depth_range": dr, "n_planes": D, "neighbours": [scene.views[j].name for j in nb],
                "confident": float(res.confident.mean()), "sweep_s": res.meta["time_s"],
                "time_s": time.perf_counter() - t0,
                "role": "target" if i in targets else "consistency partner"}
        for i in targets:
            d, s, grad, dr = raw[i]
            st = stats[scene.views[i].name]
            if consistency:
                t0 = time.perf_counter()
                partners = [j for j in est if j != i and j in raw and (j in nbrs[i] or i in nbrs.get(j, []))]
                cr = check_consistency(d, cams[i], [raw[j][0] for j in partners],
                                       [cams[j] for j in partners], rel_tol=rel_tol,
                                       px_tol=px_tol, min_agree=min_agree)
                d = np.where(cr.keep, d, np.nan).astype(np.float32)
                spread = np.where(np.isfinite(cr.spread), cr.spread, 0.0)
                s = np.sqrt(s.astype(np.float64) ** 2 + spread ** 2).astype(np.float32)
                st["consistency_partners"] = [scene.views[j].name for j in partners]
                st["reproj_px"] = float(np.nanmean(cr.reproj[cr.keep])) if cr.keep.any() else float("nan")
                st["consistency_s"] = time.perf_counter() - t0
            st["kept"] = float(np.isfinite(d).mean())
            if fill_segments:
                t0 = time.perf_counter()
                # segmented at half size: the segmentation costs 0.6 s a view at 768x512
                small_img = small(i, cams[i].scaled(0.5))
                d, s, n_filled = _segment_completion(img(i), small_img, cams[i], d, s, grad, dr, rel_tol, med_r)
                st["filled"] = n_filled / d.size
                st["segments_s"] = time.perf_counter() - t0
            depths[i], sigmas[i] = d, s

    new_views = list(scene.views)
    for i in targets:
        v = scene.views[i]
        d = upsample_depth(depths[i], cams[i], v.camera)
        s = upsample_map(np.asarray(sigmas[i], np.float32), cams[i], v.camera)
        known = np.isfinite(d)
        fill = float(np.nanmax(s[known])) if known.any() else 1.0
        s = np.where(known & np.isfinite(s), s, fill).astype(np.float32)
        new_views[i] = v.replace(depth=d, sigma_z=s)
    meta = dict(scene.meta)
    meta["depth_estimation"] = {"method": method, "scale": scale, "views": stats,
                                "sweep_scale": sweep_scale, "coarse_iter": int(coarse_iter),
                                "fill_segments": bool(fill_segments) and method == "mvs",
                                "excluded": [scene.views[i].name for i in sorted(excl)],
                                "time_s": time.perf_counter() - t_all}
    logger.info(f"depth: {len(targets)} view(s) by {method} in {time.perf_counter() - t_all:.1f} s")
    return replace(scene, views=new_views, meta=meta)
