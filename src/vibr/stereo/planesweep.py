"""Plane-sweep multi-view stereo for one reference view (fronto-parallel planes).

The reference camera's viewing frustum is cut by planes ``z = 1/w`` (orthogonal depth),
with ``w`` sampled uniformly in inverse depth (uniform in disparity, so equally fine for
near and far points). For each plane every source image is warped into the reference by
the plane homography (:func:`vibr.stereo._kernels.sweep_slab`), compared with the
reference by ZNCC in a small window, and the per-view costs ``1 − ZNCC`` are aggregated by
the mean of the best ``n_best`` views (robust to occlusion). Winner-take-all with a
parabolic sub-label fit gives the depth; the fit's curvature gives an uncertainty.

Memory: the planes are processed in slabs and only the running minimum and its two
neighbouring costs are kept (O(H · W) working memory besides the images, never a D × H × W volume).
For light fields with fronto-parallel, parallel cameras this sweep is exact as well.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..camera import Camera
from ..progress import progress
from . import _kernels as kern

_LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)


def to_grey(img: np.ndarray) -> np.ndarray:
    """H×W×3 float image → H×W float32 luma (ITU-R 601 weights)."""
    img = np.asarray(img, dtype=np.float32)
    if img.ndim == 2:
        return img
    return np.ascontiguousarray(img @ _LUMA)


@dataclass
class SweepResult:
    """Output of :func:`plane_sweep` for one reference view.

    depth : (H, W) float32, orthogonal depth in scene units (every pixel gets a value;
        ``confident`` says which are reliable).
    inv_depth : (H, W) float64, 1/depth.
    cost : (H, W) float64, aggregated cost ``1 − ZNCC`` ∈ [0, 2] at the minimum.
    sigma_z : (H, W) float32, depth std from the cost curvature (scene units).
    confident : (H, W) bool, textured, convex minimum not at the range ends, cost below
        ``max_cost``.
    winv : (D,) float64, the plane inverse depths.
    meta : dict, timings and parameters.
    """

    depth: np.ndarray
    inv_depth: np.ndarray
    cost: np.ndarray
    sigma_z: np.ndarray
    confident: np.ndarray
    winv: np.ndarray
    meta: dict = field(default_factory=dict)


def plane_homographies(ref: Camera, srcs: list[Camera]) -> tuple[np.ndarray, np.ndarray]:
    """Per-source ``A_v`` (nv,3,3) and ``b_v`` (nv,3) such that the fronto-parallel plane of
    inverse depth ``w`` in ``ref`` maps reference pixels x̄ to ``x̃_v = (A_v + w b_v e₃ᵀ) x̄``.

    With R_rel = R_v R_rᵀ, t_rel = t_v − R_rel t_r (reference camera frame → source frame):
    a point ``X_r = z K_r⁻¹ x̄`` on the plane maps to ``K_v (R_rel X_r + t_rel)``
    ∝ ``K_v R_rel K_r⁻¹ x̄ + w K_v t_rel`` (Hartley & Zisserman eq. 13.2 with n = e₃, d = z).
    """
    Kr_inv = np.linalg.inv(ref.K)
    A = np.empty((len(srcs), 3, 3))
    b = np.empty((len(srcs), 3))
    for v, c in enumerate(srcs):
        R_rel = c.R @ ref.R.T
        t_rel = c.t - R_rel @ ref.t
        A[v] = c.K @ R_rel @ Kr_inv
        b[v] = c.K @ t_rel
    # the kernel adds w*b to the full homogeneous vector, i.e. (A x̄ + w b) with the
    # third coordinate of x̄ equal to 1: b e₃ᵀ x̄ = b.
    return A, b


def _stack_greys(images):
    """Grey versions of the source images in one zero-padded (n, Hmax, Wmax) float32 stack
    (the kernels index views by number) and their (H, W) sizes."""
    greys = [to_grey(s) for s in images]
    srcs = np.zeros((len(greys), max(g.shape[0] for g in greys), max(g.shape[1] for g in greys)),
                    np.float32)
    sizes = np.zeros((len(greys), 2), np.int64)
    for v, g in enumerate(greys):
        srcs[v, : g.shape[0], : g.shape[1]] = g
        sizes[v] = g.shape
    return srcs, sizes


def _stack_masks(masks, srcs) -> np.ndarray:
    """The sources' masks (None: every pixel usable) as the kernels' ``valid`` stack, uint8
    of ``srcs``' shape with 0 at masked pixels, or an empty (0, 1, 1) array when none has
    one (the kernels then test nothing)."""
    if masks is None or all(m is None for m in masks):
        return np.zeros((0, 1, 1), np.uint8)
    valid = np.ones(srcs.shape, np.uint8)
    for v, m in enumerate(masks):
        if m is not None:
            valid[v, : m.shape[0], : m.shape[1]] = np.asarray(m, bool)
    return valid


def plane_sweep(ref_image: np.ndarray, ref_camera: Camera, src_images: list[np.ndarray],
                src_cameras: list[Camera], depth_range: tuple[float, float], *,
                n_planes: int = 128, radius: int = 3, n_best: int | None = None,
                eps: float = 0.002, max_cost: float = 0.6, slab: int | None = None,
                mem_bytes: float = 2e9, desc: str | None = None, src_masks=None) -> SweepResult:
    """Plane-sweep stereo for one reference view.

    Parameters
    ----------
    ref_image : (H, W, 3) or (H, W) float32 in [0, 1]
    ref_camera : Camera of the reference (size H×W).
    src_images, src_cameras : the neighbouring views (any sizes).
    depth_range : (near, far) orthogonal depth in the reference camera, scene units.
    n_planes : number of planes D, uniform in inverse depth 1/far … 1/near.
    radius : ZNCC window half-size (window (2r+1)²).
    n_best : aggregate the mean of the ``n_best`` lowest per-view costs (default: half of
        the views, at least 1).
    eps : ZNCC regulariser: ``ncc = cov / sqrt((var_I + eps²)(var_J + eps²))`` (intensity
        units in [0, 1]); flat windows get ncc → 0 instead of noise.
    max_cost : pixels with aggregated cost above this are not ``confident``.
    slab : planes per compiled call (for the progress bar); default chosen from mem_bytes.
    mem_bytes : bound on the working memory (the sweep needs ~ (40 + 4 · views) bytes · H · W,
        independent of D; a ValueError is raised if that alone exceeds the bound).
    src_masks : list of (H_v, W_v) bool or None, optional
        The sources' masks (:attr:`vibr.scene.View.mask`): a view whose sample of a
        reference pixel lands on a masked pixel counts as not seeing it (as outside its
        image), so the ``n_best`` mean is taken over the other views.

    Returns
    -------
    SweepResult
        ``sigma_z`` is ``z² · Δw · max(1/√12, sqrt(c₀ / (2a)))``: the inverse-depth step Δw
        times the width of the parabola ``c₀ + a (l − l*)²`` at the level ``2 c₀`` (a
        larger minimum cost or a flatter minimum → larger uncertainty), propagated by
        ``dz = z² dw``. It is a heuristic scale, not a calibrated probability.
    """
    t0 = time.perf_counter()
    H, W = ref_camera.shape
    I = to_grey(ref_image).astype(np.float64)
    if I.shape != (H, W):
        raise ValueError(f"reference image {I.shape} does not match its camera {(H, W)}")
    nv = len(src_images)
    if nv == 0 or nv != len(src_cameras):
        raise ValueError("plane_sweep needs at least one source view with its camera")
    near, far = float(depth_range[0]), float(depth_range[1])
    if not (0 < near < far):
        raise ValueError(f"bad depth range {depth_range}")
    work = (40.0 + 4.0 * nv) * H * W
    if work > mem_bytes:
        raise ValueError(f"plane sweep working set {work/1e9:.2f} GB exceeds mem_bytes")
    n_best = max(1, nv // 2) if n_best is None else max(1, min(int(n_best), nv))
    # planes from far to near, uniform in inverse depth
    winv = np.linspace(1.0 / far, 1.0 / near, int(n_planes))
    srcs, sizes = _stack_greys(src_images)
    valid = _stack_masks(src_masks, srcs)
    A, b = plane_homographies(ref_camera, list(src_cameras))
    eps2 = float(eps) ** 2
    mu, sd = kern.box_mean_std(I, radius, eps2)
    best_c = np.full((H, W), np.inf)
    best_l = np.zeros((H, W), np.int64)
    c_minus = np.full((H, W), np.inf)
    c_plus = np.full((H, W), np.inf)
    prev = np.full((H, W), np.inf)
    D = len(winv)
    slab = max(1, int(slab) if slab else max(1, D // 16))
    # row bands of the compiled sweep: enough bands for the threads, each a few windows tall
    block = int(max(2 * radius + 2, min(32, -(-H // 8))))
    starts = range(0, D, slab)
    for l0 in progress(starts, desc=desc or "plane sweep", total=len(starts), unit="slab"):
        kern.sweep_slab(I, mu, sd, srcs, sizes, valid, A, b, winv[l0 : l0 + slab], l0, int(radius),
                        n_best, eps2, block, best_c, best_l, c_minus, c_plus, prev)
    lab, curv = kern.subpixel(best_c, best_l, c_minus, c_plus)
    dw = winv[1] - winv[0] if D > 1 else 1.0 / near
    w = winv[0] + lab * dw
    z = 1.0 / w
    # std in labels: half-width of the parabola at twice the minimum cost (see docstring)
    with np.errstate(divide="ignore", invalid="ignore"):
        sl = np.where(curv > 0, np.sqrt(np.maximum(best_c, 1e-3) / (2 * np.maximum(curv, 1e-12))), D / 4.0)
    sl = np.maximum(sl, 1.0 / np.sqrt(12.0))
    sigma_z = (z * z * sl * abs(dw)).astype(np.float32)
    textured = sd > 2.0 * eps  # window std above the regulariser
    confident = (curv > 0) & (best_c <= max_cost) & textured
    return SweepResult(
        depth=z.astype(np.float32), inv_depth=w, cost=best_c, sigma_z=sigma_z,
        confident=confident, winv=winv,
        meta={"time_s": time.perf_counter() - t0, "n_planes": D, "n_views": nv, "n_best": n_best,
              "radius": radius, "depth_range": (near, far), "max_cost": max_cost},
    )


def window_offsets(radius: int, stride: int) -> np.ndarray:
    """(n, 2) offsets (dy, dx) of a square window from ``−radius`` to ``radius`` sampled
    every ``stride`` pixels (the centre is a sample when ``stride`` divides ``radius``)."""
    r = np.arange(-radius, radius + 1, stride)
    dy, dx = np.meshgrid(r, r, indexing="ij")
    return np.ascontiguousarray(np.c_[dy.ravel(), dx.ravel()].astype(np.int64))


@dataclass(frozen=True)
class RefineOptions:
    """How :func:`refine_planes` refines a sweep's planes (every field has a default; what
    each does: :func:`refine_planes`).

    Attributes
    ----------
    n_iter : int
        PatchMatch iterations.
    radius, stride : int
        The matching window, ``(2·radius+1)²`` sampled every ``stride`` pixels.
    sigma_c, sigma_s : float
        Grey-level and spatial scales of the window's adaptive-support weights
        (``sigma_s`` None: ``radius``).
    n_best : int, optional
        Views averaged per pixel (the lowest costs; default half of them).
    eps, max_cost : float
        The ZNCC regulariser; the aggregated ``1 − ZNCC`` above which a pixel is not confident.
    dn : float
        Initial size of the normals' random perturbation.
    seed : int
        Seed of the random search.
    single_view_penalty : float or None
        Added to the best view's cost where that alone replaces the mean (None: never).
    fronto_init, joint_perturbation, normal_perturbation : bool
        The fronto-parallel start, the joint depth-and-normal perturbation and the normal
        perturbations of the random search.
    """

    n_iter: int = 2
    radius: int = 3
    stride: int = 2
    sigma_c: float = 0.05
    sigma_s: float | None = None
    n_best: int | None = None
    eps: float = 0.002
    max_cost: float = 0.6
    dn: float = 1.0
    seed: int = 0
    single_view_penalty: float | None = 0.1
    fronto_init: bool = True
    joint_perturbation: bool = True
    normal_perturbation: bool = True


def refine_planes(ref_image: np.ndarray, ref_camera: Camera, src_images: list[np.ndarray],
                  src_cameras: list[Camera], init: SweepResult, *, options: RefineOptions | None = None,
                  src_masks=None, **kw) -> SweepResult:
    """Sub-plane, slanted refinement of a plane-sweep result (PatchMatch, continuous).

    The sweep is winner-take-all over fronto-parallel planes: its depth is quantised (the
    parabola fit only partly recovers the sub-plane position) and its square window is
    wrong on slanted surfaces (a floor seen at a grazing angle) and across depth edges.
    Here every pixel carries a plane ``w(x') = w + g·(x' − x)`` in inverse depth (affine in
    the reference pixel, which is exactly the image of a 3D plane), initialised from the
    sweep (fronto-parallel, or slanted by the finite-difference gradient of the sweep's
    inverse depth, whichever costs less), and ``n_iter`` PatchMatch iterations
    (:func:`vibr.stereo._kernels.patchmatch_refine`: propagation sweeps along the rows and
    the columns, then random perturbations of halving size) minimise the multi-view cost
    over continuous depths and orientations. The matching window is ``(2·radius+1)²`` sampled every
    ``stride`` pixels with adaptive-support (bilateral) weights of grey-level scale
    ``sigma_c`` (:func:`vibr.stereo._kernels.support_weights`), and the views are
    aggregated as in the sweep (mean of the ``n_best`` best ``1 − ZNCC``), except that the
    best view alone plus ``single_view_penalty`` replaces that mean when lower (a point
    seen by a single partner: the mean would average in a view that sees something else;
    ``None``: never).

    ``fronto_init``: whether the initial plane may be fronto-parallel. Without it every
    pixel starts slanted by the finite differences of ``init``'s inverse depth, one cost
    evaluation per pixel instead of two: for an initialisation that is itself refined
    (the coarse level of :func:`~vibr.stereo.estimate_depth`, upsampled), whose inverse
    depth already carries the slopes.

    ``joint_perturbation``: whether the random search tries a perturbation of the depth
    and the normal together, besides the depth alone and the normal alone (which, tried
    in turn from the best plane so far, also move both). Without it, one evaluation in
    eight fewer per iteration, for a refinement that starts from a refined plane (the
    full-size iterations after the coarse level).

    ``src_masks``: the sources' masks, as in :func:`plane_sweep` (a view whose window
    centre lands on a masked pixel is left out of that cost). The other parameters are the
    fields of ``options`` (:class:`RefineOptions`), to which ``kw`` (its fields by name)
    applies.

    ``normal_perturbation``: whether the random search tries the normal alone and a random
    normal. Without it (and without the joint perturbation) the random search only moves
    the depth, and propagation alone spreads orientations: for full-size iterations whose
    planes, normals included, were refined at the coarse level, where the normal
    candidates no longer win often enough to be worth their cost (the light-field method;
    docs/explanation/depth.md, "The depth alone at full size").

    Returns a :class:`SweepResult` with the refined depth and cost (``meta["plane_gradient"]``
    holds the planes' ``(gx, gy)``, inverse depth per pixel); ``confident`` = the
    sweep's textured test, cost ≤ ``max_cost`` and a depth inside the sweep's range (not
    at its ends); ``sigma_z`` keeps the sweep's inverse-depth width at the new depth.
    """
    t0 = time.perf_counter()
    o = replace(options or RefineOptions(), **kw)
    H, W = ref_camera.shape
    I = to_grey(ref_image).astype(np.float64)
    nv = len(src_images)
    n_best = max(1, nv // 2) if o.n_best is None else max(1, min(int(o.n_best), nv))
    lam1 = -1.0 if o.single_view_penalty is None else float(o.single_view_penalty)
    srcs, sizes = _stack_greys(src_images)
    valid = _stack_masks(src_masks, srcs)
    A, b = plane_homographies(ref_camera, list(src_cameras))
    offs = window_offsets(int(o.radius), int(o.stride))
    guide = np.asarray(ref_image, np.float32)
    guide = np.ascontiguousarray(guide if guide.ndim == 3 else guide[..., None])
    wts, wI, sdI = kern.support_weights(I, offs, float(o.sigma_c),
                                        float(o.sigma_s or max(o.radius, 1)), guide)
    eps2 = float(o.eps) ** 2
    winv = init.winv
    step = abs(winv[1] - winv[0]) if len(winv) > 1 else 0.05 * winv[0]
    wmin, wmax = float(winv.min()), float(winv.max())
    w = np.clip(np.asarray(init.inv_depth, np.float64), wmin, wmax)
    zero = np.zeros((H, W))
    gy, gx = np.gradient(w)
    cost = kern.plane_costs(wts, wI, sdI, offs, srcs, sizes, valid, A, b, n_best, eps2, w, gx, gy, lam1)
    if o.fronto_init:
        c0 = kern.plane_costs(wts, wI, sdI, offs, srcs, sizes, valid, A, b, n_best, eps2, w, zero, zero, lam1)
        fronto = c0 <= cost
        gx = np.where(fronto, 0.0, gx)
        gy = np.where(fronto, 0.0, gy)
        cost = np.where(fronto, c0, cost)
    n_eval = kern.patchmatch_refine(wts, wI, sdI, offs, srcs, sizes, valid, A, b, n_best, eps2, w, gx, gy,
                           cost, int(o.n_iter), 2.0 * step, float(o.dn), np.linalg.inv(ref_camera.K),
                           wmin, wmax, int(o.seed), lam1, 0 if o.joint_perturbation else 1, True,
                           4 if o.normal_perturbation else 2)  # every argument given: one compiled signature
    z = 1.0 / w
    sigma_w = init.sigma_z.astype(np.float64) / np.asarray(init.depth, np.float64) ** 2
    sigma_z = (z * z * sigma_w).astype(np.float32)
    _, sd_box = kern.box_mean_std(I, int(init.meta.get("radius", 3)), eps2)
    textured = sd_box > 2.0 * o.eps
    inside = (w > wmin + 0.5 * step) & (w < wmax - 0.5 * step)
    confident = textured & (cost <= o.max_cost) & inside
    meta = dict(init.meta)
    meta.update({"refine_s": time.perf_counter() - t0, "refine_iter": int(o.n_iter),
                 "refine_evals": int(n_eval),
                 "plane_gradient": (gx, gy),
                 "time_s": init.meta.get("time_s", 0.0) + time.perf_counter() - t0})
    return SweepResult(depth=z.astype(np.float32), inv_depth=w, cost=cost, sigma_z=sigma_z,
                       confident=confident, winv=winv, meta=meta)


def median_planes(ref_image: np.ndarray, res: SweepResult, *, radius: int = 9, stride: int = 3,
                  sigma_c: float = 0.05, sigma_s: float | None = None) -> SweepResult:
    """Joint weighted median of the per-pixel planes (Ma et al. 2013, the weighted median
    filter of local stereo), guided by the colour image.

    Each confident pixel of the ``(2·radius+1)²`` window (sampled every ``stride`` pixels)
    votes for its plane extended to the centre (exact for pixels on one planar surface;
    ``meta["plane_gradient"]`` of :func:`refine_planes`, fronto-parallel without it), with
    the bilateral weight ``exp(−‖ΔG‖²/(2σ_c²·3) − |Δx|²/2σ_s²)``
    (:func:`vibr.stereo._kernels.plane_median`); every pixel takes the weighted median.
    Why: the matching cost cannot always tell depths apart, and its winner is then an
    outlier among the pixels of its surface, e.g. next to a depth edge a background pixel
    whose own window is flat takes the foreground's depth (edge fattening). Its
    neighbours of the same colour outvote it, and the median also averages out the
    sub-percent scatter of the surface's own pixels. The window (19×19, 49 votes) is
    about three times the matching window, so a band of fattened pixels as wide as the
    matching window's radius is a minority in it. ``confident`` is unchanged: unknown pixels stay unknown (the geometry stage fills
    them). ``sigma_z`` keeps its inverse-depth width at the new depth.
    """
    t0 = time.perf_counter()
    offs = window_offsets(int(radius), int(stride))
    guide = np.asarray(ref_image, np.float64)
    guide = np.ascontiguousarray(guide if guide.ndim == 3 else guide[..., None])
    grad = res.meta.get("plane_gradient")
    if grad is None:
        gx = gy = np.zeros(res.inv_depth.shape)
    else:
        gx, gy = (np.ascontiguousarray(g, np.float64) for g in grad)
    w, gx, gy = kern.plane_median(np.ascontiguousarray(res.inv_depth, np.float64), gx, gy,
                                  np.ascontiguousarray(res.confident), guide, offs,
                                  float(sigma_c), float(sigma_s or radius))
    w = np.clip(w, float(res.winv.min()), float(res.winv.max()))
    z = 1.0 / w
    sigma_w = res.sigma_z.astype(np.float64) / np.asarray(res.depth, np.float64) ** 2
    meta = dict(res.meta)
    meta.update({"plane_gradient": (gx, gy), "median_s": time.perf_counter() - t0,
                 "time_s": res.meta.get("time_s", 0.0) + time.perf_counter() - t0})
    return SweepResult(depth=z.astype(np.float32), inv_depth=w, cost=res.cost,
                       sigma_z=(z * z * sigma_w).astype(np.float32), confident=res.confident,
                       winv=res.winv, meta=meta)
