"""The geometry stage end to end: source views with depth + target camera → :class:`Samples`.

Steps (paper §5, docs/explanation/method.md §2), per source view k:

1. depth preparation: NaN = unknown; optionally fill holes (joint bilateral, Kopf 2007);
   slopes ``(z_x, z_y)`` (edge-aware, :func:`vibr.geometry.depth.depth_derivatives`);
2. splat every pixel's quad into the target z-buffer (all views into one buffer); the pixels
   of a fallback proxy (:attr:`vibr.scene.View.fallback`) into a second one, that counts
   only where the first is empty (known geometry wins, whatever the depths);
3. per pixel: warp ``tau_k``, in-target test, visibility against the z-buffer;
4. per visible sample: ``tau``, ``∂tau/∂x_m``, ``1/|det|`` (capped), ``∂tau/∂z``, world
   point, colour, colour gradient ``∇v`` (the renderer's own ``D``, the rows of
   :mod:`vibr.geometry.gradient` formed in the same pass: one discretisation for both sides
   of the gradient term), ``sigma_z``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from numba import njit, prange

from ..camera import Camera
from ..errors import VibrInputError, check_stop
from ..scene import Scene, View
from .depth import DEFAULT_EDGE_REL, DEFAULT_SIGMA_Z_REL, depth_derivatives, fill_depth_holes
from .gradient import DEFAULT_GRAD_SCHEME, GRAD_SCHEMES, _grad_row
from .proxy import PROXY_Z_CORR
from .samples import Samples
from .visibility import (
    DEFAULT_MAX_QUAD_PX,
    DEFAULT_VIS_THRESHOLD,
    OCCLUDED,
    VISIBLE,
    new_zbuffers,
    reduce_zbuffers,
    splat_zbuffer,
    visibility_mask,
)
from .warp import DEFAULT_MAX_INV_DET, _project_one, _warp_one, warp_constants

__all__ = ["compute_samples", "SampleOptions", "prepare_depth", "DEFAULT_SIGMA_Z_REL", "OPTIONAL_FIELDS"]

#: Sample fields no default render reads, computed only when asked for (``keep``): the
#: warp's Jacobian (the footprint PSF) and the source pixel (diagnostics, tests); 16 + 8 of
#: the 108 bytes a sample takes.
OPTIONAL_FIELDS = ("jac", "src_xy")

#: How the gradient term reads a source's image gradient ``∇v`` (per source pixel) against
#: the target's ``D u`` (per target pixel): "translation", as it is (the paper's
#: approximation, eq. gradient: the warp is locally a translation); "chain", carried to the
#: target's pixels by the warp's Jacobian, ``∇u(τ(x)) = J⁻ᵀ ∇v(x)`` (``J = ∂τ/∂x``, 1/det
#: capped as the deformation weight is): right where a source is finer or coarser than the
#: target, or seen slanted.
GRAD_MODELS = ("translation", "chain")
DEFAULT_GRAD_MODEL = "translation"


def usable_pixels(mask: np.ndarray) -> np.ndarray:
    """The pixels of a view's mask whose 3×3 neighbourhood is in the mask too: a sample's
    colour gradient ∇v (the renderer's stencil reaches one pixel each way) must not read a
    masked pixel's colour."""
    from scipy.ndimage import binary_erosion

    return binary_erosion(mask, np.ones((3, 3), bool), border_value=1)


def prepare_depth(view: View, *, fill_holes: bool = False, edge_rel: float = DEFAULT_EDGE_REL):
    """Depth of a view as float64 plus slopes: returns ``(z, z_x, z_y)``, (H, W) float64,
    NaN where unknown (holes filled first when ``fill_holes``) and outside the view's
    :attr:`~vibr.scene.View.mask` (less a pixel: :func:`usable_pixels`)."""
    if view.depth is None:
        raise VibrInputError(f"source view {view.name} has no depth map", view.path or view.name)
    z = view.depth
    if fill_holes and np.isnan(z).any():
        z, _ = fill_depth_holes(z, view.image)
    z = np.ascontiguousarray(z, dtype=np.float64)
    if view.mask is not None:  # masked pixels: no sample, no occluder
        z = np.where(usable_pixels(view.mask), z, np.nan)
    zx, zy = depth_derivatives(z, edge_rel)
    return z, zx, zy


@njit(cache=True, inline="always")
def _cell_key(x, y, H, W):
    """Target cell of a landing point: the top-left pixel of its bilinear 2×2 block, clamped
    as :class:`vibr.render.operators.Splat` clamps it, row-major."""
    nr, nc = max(H - 1, 1), max(W - 1, 1)
    x = min(max(x, 0.0), W - 1.0)
    y = min(max(y, 0.0), H - 1.0)
    return min(int(np.floor(y)), nr - 1) * nc + min(int(np.floor(x)), nc - 1)


@njit(parallel=True, cache=True)
def _keys_kernel(state, row_off, z, M, c, H_t, W_t, key):
    """The target cell (:func:`_cell_key`) of every VISIBLE pixel of one view, at its place
    in source order (row ``i``'s samples start at ``row_off[i]``)."""
    H, W = z.shape
    for i in prange(H):
        s = row_off[i]
        for j in range(W):
            if state[i, j] != VISIBLE:
                continue
            u, v = _project_one(float(j), float(i), z[i, j], M, c)
            key[s] = _cell_key(u, v, H_t, W_t)
            s += 1


@njit(cache=True)
def _cell_dest(key, n_cells):
    """Where each sample goes when the samples are sorted by target cell: a stable counting
    sort (ties keep source order), returned as destinations (int64)."""
    counts = np.zeros(n_cells + 1, np.int64)
    for i in range(key.shape[0]):
        counts[key[i] + 1] += 1
    for c in range(n_cells):
        counts[c + 1] += counts[c]
    dest = np.empty(key.shape[0], np.int64)
    for i in range(key.shape[0]):
        dest[i] = counts[key[i]]
        counts[key[i]] += 1
    return dest


@njit(parallel=True, cache=True)
def _fields_kernel(state, row_off, dest, z, zx, zy, M, c, A, Ck, img, forward, chain, max_inv_det, sig_map,
                   sig_scalar, k_view, xy, jac, inv_det, dtau, X, colour, grad, src, sig, view):
    """Write the fields of the VISIBLE pixels of one view; row ``i``'s samples are numbered
    from ``row_off[i]`` in source order, and sample ``s`` is written at ``dest[s]``
    (``jac``, ``src`` only when they have a row per sample). The image gradient ``∇v`` is
    formed row by row from ``img`` (H, W, C) by the one gradient
    (:func:`vibr.geometry.gradient._grad_row`, ``forward`` or central), in cache: no planar
    copy of the image and no gradient image in memory; with ``chain``, carried to the
    target's pixels, ``J⁻ᵀ ∇v`` (:data:`GRAD_MODELS`)."""
    H, W = z.shape
    C = img.shape[2]
    use_map = sig_map.shape[0] > 0
    keep_jac = jac.shape[0] == xy.shape[0]
    keep_src = src.shape[0] == xy.shape[0]
    for i in prange(H):
        buf = np.empty(10)
        gx = np.empty((C, W), img.dtype)
        gy = np.empty((C, W), img.dtype)
        for ch in range(C):
            _grad_row(img[:, :, ch], i, forward, gx[ch], gy[ch])
        n = row_off[i]
        y = float(i)
        for j in range(W):
            if state[i, j] != VISIBLE:
                continue
            s = dest[n]
            n += 1
            x = float(j)
            zc = z[i, j]
            _warp_one(x, y, zc, zx[i, j], zy[i, j], M, c, buf)
            xy[s, 0] = buf[0]
            xy[s, 1] = buf[1]
            if keep_jac:
                jac[s, 0, 0] = buf[3]
                jac[s, 0, 1] = buf[4]
                jac[s, 1, 0] = buf[5]
                jac[s, 1, 1] = buf[6]
            dtau[s, 0] = buf[7]
            dtau[s, 1] = buf[8]
            ad = abs(buf[9])
            # 1/|det| capped at max_inv_det (also covers det = 0)
            inv_det[s] = 1.0 / ad if ad * max_inv_det > 1.0 else max_inv_det
            # world point X = z (R_kᵀ K_k⁻¹) x̄ + C_k
            for r in range(3):
                X[s, r] = zc * (A[r, 0] * x + A[r, 1] * y + A[r, 2]) + Ck[r]
            if keep_src:
                src[s, 0] = j
                src[s, 1] = i
            view[s] = k_view
            sig[s] = sig_map[i, j] if use_map else sig_scalar
            if chain:  # ∇u = J⁻ᵀ ∇v, 1/det capped as inv_det is
                sd = inv_det[s] if buf[9] >= 0.0 else -inv_det[s]
                for ch in range(3):
                    colour[s, ch] = img[i, j, ch]
                    a, b = gx[ch, j], gy[ch, j]
                    grad[s, ch, 0] = (buf[6] * a - buf[5] * b) * sd
                    grad[s, ch, 1] = (buf[3] * b - buf[4] * a) * sd
            else:
                for ch in range(3):
                    colour[s, ch] = img[i, j, ch]
                    grad[s, ch, 0] = gx[ch, j]
                    grad[s, ch, 1] = gy[ch, j]


def _view_sigma(view: View, z: np.ndarray, sigma_z_default):
    """Per-pixel or scalar sigma_z of a view (documented default when it has none)."""
    if view.sigma_z is not None:
        return view.sigma_z
    if sigma_z_default is not None:
        return float(sigma_z_default)
    med = np.nanmedian(z) if np.isfinite(z).any() else 1.0
    return DEFAULT_SIGMA_Z_REL * float(med)


@dataclass(frozen=True)
class SampleOptions:
    """How :func:`compute_samples` warps the sources (every field has a default).

    Attributes
    ----------
    vis_threshold : float
        Relative depth tolerance of the visibility test (``w ≤ (1 + thr) z_u``), see
        :mod:`vibr.geometry.visibility` (measurements there); default 0.02.
    fill_holes : bool
        Fill unknown depth with the joint bilateral filter before warping.
    max_inv_det : float
        Cap of the deformation weight ``1/|det ∂tau/∂x_m|`` (default 4, see
        :data:`vibr.geometry.warp.DEFAULT_MAX_INV_DET`; the authors use 1, docs/explanation/method.md §10).
    edge_rel : float
        Edge detection of the depth slopes (:func:`depth_derivatives`).
    max_quad_px : int
        Larger projected quads are not splatted into the z-buffer.
    splat_mode : "affine" or "projective"
        How quads are rasterised into the z-buffer (:func:`splat_zbuffer`).
    sigma_z_default : float, optional
        sigma_z (scene units) for views without one; default ``0.01 · median depth``.
    grad_scheme : {"forward", "central"}, optional
        Discretisation of the sources' ``∇v`` (:data:`vibr.geometry.gradient.GRAD_SCHEMES`;
        default :data:`vibr.geometry.gradient.DEFAULT_GRAD_SCHEME`), recorded in
        ``meta["grad_scheme"]``: the renderer applies the same ``D`` to the target.
    grad_model : {"translation", "chain"}, optional
        The sources' ``∇v`` as the gradient term compares them with the target's (:data:`GRAD_MODELS`;
        default :data:`DEFAULT_GRAD_MODEL`).
    keep : iterable of str
        Optional fields to compute (:data:`OPTIONAL_FIELDS`): ``"jac"`` (the footprint PSF
        reads it; :func:`vibr.render.methods.sample_fields` says what a render needs),
        ``"src_xy"``; the others are None.
    same_ray_px : float
        A source pixel that the target sees along its own ray, to within this many target
        pixels (:func:`same_ray`: at the view's own camera, every pixel), shows what the
        target sees there: it is placed with the known geometry even when it is a fallback
        pixel (:attr:`vibr.scene.View.fallback`), and no other view's surface hides it.
        Half a pixel: the sample stays in its target pixel whatever its depth, from the
        nearest its view sees to its own plus sigma_z. 0: the layers and the visibility
        test decide alone.
    """

    vis_threshold: float = DEFAULT_VIS_THRESHOLD
    fill_holes: bool = False
    max_inv_det: float = DEFAULT_MAX_INV_DET
    edge_rel: float = DEFAULT_EDGE_REL
    max_quad_px: int = DEFAULT_MAX_QUAD_PX
    splat_mode: str = "affine"
    sigma_z_default: float | None = None
    grad_scheme: str | None = None
    grad_model: str | None = None
    keep: tuple = ()
    same_ray_px: float = 0.5


def compute_samples(sources: Scene, target, *, options: SampleOptions | None = None,
                    prepared: dict | None = None, return_zbuffer: bool = False, stop=None, **kw) -> Samples:
    """Visible warped source samples for a target camera (paper §5).

    Parameters
    ----------
    sources : Scene
        Source views; every one must have a depth map (NaN pixels are skipped, or filled
        first when ``options.fill_holes``) — use :func:`vibr.geometry.ensure_source_depth`
        for views without depth.
    target : Camera or View
        What to render (a View's camera is used).
    options : SampleOptions, optional
        How to warp; ``kw`` (its fields, e.g. ``keep=("jac",)``) applies over it. Any other
        keyword raises ``TypeError``.
    prepared : dict, optional
        ``view name → (z, z_x, z_y)`` from :func:`prepare_depth` with the same
        ``fill_holes`` / ``edge_rel``: target-independent, computed once per source by
        callers rendering many targets (:mod:`vibr.paths.flythrough`).
    return_zbuffer : bool
        Put the target depth map z_u (+inf where empty) in ``samples.meta["zbuffer"]``, and
        the fallback proxy's where no known surface lands in ``meta["zbuffer_fallback"]``
        (when a view has a fallback; :func:`target_depth` combines them).
    stop : callable, optional
        Polled after the z-buffer and after the visibility test; True raises
        :class:`vibr.errors.RenderStopped` (:func:`vibr.render.render`'s ``stop``).

    Returns
    -------
    Samples
        ``meta`` holds per-view counts (``counts``: name → dict of visible / occluded /
        outside / behind / unknown, and for a view with a fallback proxy its fallback
        pixels' ``fallback visible`` / ``fallback hidden``) and per-stage times in seconds
        (``times``: wall clock, ``cpu_times``: process CPU time of all threads).

    Raises
    ------
    VibrInputError
        A source without depth, or no source sample landing in the target.
    """
    o = replace(options or SampleOptions(), **kw)
    grad_scheme, grad_model, keep = _checked_fields(o.grad_scheme, o.grad_model, o.keep)
    cam = target.camera if isinstance(target, View) else target
    if not isinstance(cam, Camera):
        raise VibrInputError("target must be a Camera or a View", None)
    tname = cam.source or (target.name if isinstance(target, View) else "target camera")
    if min(cam.width, cam.height) < 2:  # a sample's bilinear cell needs two rows and columns
        raise VibrInputError(f"the target is {cam.width}x{cam.height}: at least 2 pixels a side", tname)
    times = {"depth": 0.0, "zbuffer": 0.0, "visibility": 0.0, "assembly": 0.0}
    cpu = dict(times)  # process CPU time (all threads), less sensitive to a shared machine
    with _Timer(times, cpu, "depth"):
        known, proxy = _split_fallback(_prepare_views(sources, cam, o.fill_holes, o.edge_rel, prepared), o.edge_rel,
                                       o.same_ray_px)
    zproxy = None
    with _Timer(times, cpu, "zbuffer"):
        zbuf = _target_zbuffer(known, cam.shape, o.max_quad_px, o.splat_mode)
        if proxy:
            # known geometry wins: a fallback sample only shows where no known surface lands
            zproxy = _target_zbuffer(proxy, cam.shape, o.max_quad_px, o.splat_mode)
            zproxy[np.isfinite(zbuf)] = -np.inf
    check_stop(stop)
    with _Timer(times, cpu, "visibility"):
        states, counts = _visibility(known, zbuf, o.vis_threshold, o.same_ray_px)
        if proxy:
            st, cnt = _visibility(proxy, zproxy, o.vis_threshold)
            states += st
            for name, c in cnt.items():
                counts[name].update({"fallback visible": c["visible"], "fallback hidden": c["occluded"]})
    check_stop(stop)
    with _Timer(times, cpu, "assembly"):
        out = _gather_samples(known + proxy, states, cam.shape, o.max_inv_det, o.sigma_z_default, grad_scheme, keep,
                              grad_model)
        del known, proxy, states
    if len(out) == 0:
        blind = [v.name for v in sources.views if v.depth is None or not np.isfinite(v.depth).any()]
        if blind and len(blind) == len(sources.views):  # not a matter of where the target looks
            raise VibrInputError(f"the depth is unknown (all zero in its file) in every source view: "
                                 f"{', '.join(blind[:8])}{', ...' if len(blind) > 8 else ''}",
                                 sources.views[0].path or tname)
        raise VibrInputError("no source view sees the target", tname)
    out.meta["counts"] = counts
    out.meta["times"] = times
    out.meta["cpu_times"] = cpu
    out.meta["vis_threshold"] = float(o.vis_threshold)
    out.meta["grad_scheme"] = grad_scheme
    out.meta["grad_model"] = grad_model
    # one proxy for every view: its depth error at a target pixel is the views' shared one
    out.meta["z_corr"] = PROXY_Z_CORR if sources.meta.get("proxy") else 0.0
    # where the views are: ULR and the view prior weigh the samples by the rays' angles
    out.meta["source_centres"] = np.array([v.camera.centre for v in sources.views], np.float64)
    out.meta["target_centre"] = np.asarray(cam.centre, np.float64)
    if return_zbuffer:
        out.meta["zbuffer"] = zbuf
        if zproxy is not None:
            out.meta["zbuffer_fallback"] = zproxy
    return out


def target_depth(samples: Samples) -> np.ndarray | None:
    """The target's depth map as the geometry stage computed it: its z-buffer (orthogonal
    depth in scene units of the nearest source surface at each pixel centre, the known
    geometry first, the fallback proxy where none lands), float32, NaN where no surface
    lands. None when ``samples`` were computed without ``return_zbuffer``."""
    z = samples.meta.get("zbuffer")
    if z is None:
        return None
    zf = samples.meta.get("zbuffer_fallback")
    if zf is not None:
        z = np.where(np.isfinite(z), z, zf)
    return np.where(np.isfinite(z), z, np.nan).astype(np.float32)


def _checked_fields(grad_scheme, grad_model, keep):
    """``compute_samples``' field options, defaults filled and checked (a one-line error)."""
    grad_scheme = DEFAULT_GRAD_SCHEME if grad_scheme is None else grad_scheme
    grad_model = DEFAULT_GRAD_MODEL if grad_model is None else grad_model
    if grad_model not in GRAD_MODELS:
        raise VibrInputError(f"grad_model must be one of {GRAD_MODELS}, got {grad_model!r}")
    keep = (keep,) if isinstance(keep, str) else tuple(keep)
    if set(keep) - set(OPTIONAL_FIELDS):
        raise VibrInputError(f"keep: unknown field(s) {sorted(set(keep) - set(OPTIONAL_FIELDS))} "
                             f"(choose from {', '.join(OPTIONAL_FIELDS)})")
    if grad_scheme not in GRAD_SCHEMES:
        raise VibrInputError(f"grad_scheme must be one of {GRAD_SCHEMES}, got {grad_scheme!r}")
    return grad_scheme, grad_model, keep


class _Timer:
    """Adds the wall-clock and process CPU seconds of a block to ``times[key]``, ``cpu[key]``."""

    def __init__(self, times, cpu, key):
        self.times, self.cpu, self.key = times, cpu, key

    def __enter__(self):
        self.t0, self.c0 = time.perf_counter(), time.process_time()

    def __exit__(self, *exc):
        self.times[self.key] += time.perf_counter() - self.t0
        self.cpu[self.key] += time.process_time() - self.c0
        return False


def _prepare_views(sources: Scene, cam: Camera, fill_holes, edge_rel, prepared=None) -> list:
    """Per source view k: ``(k, view, z, z_x, z_y, M, c)``, its depth and slopes (from
    ``prepared`` when given) and the constants of its warp into ``cam``."""
    prepped = []
    for k, v in enumerate(sources.views):
        pre = prepared.get(v.name) if prepared else None
        z, zx, zy = pre if pre is not None else prepare_depth(v, fill_holes=fill_holes, edge_rel=edge_rel)
        if v.image is None:
            raise VibrInputError(f"source view {v.name} has no image", v.path or v.name)
        M, c = warp_constants(v.camera, cam)
        prepped.append((k, v, z, zx, zy, M, c))
    return prepped


def same_ray(view: View, z: np.ndarray, M: np.ndarray, c: np.ndarray, ys, xs, max_px: float) -> np.ndarray:
    """Whether the target sees the pixels ``(ys, xs)`` of ``view`` (depth ``z``, warp
    constants ``M``, ``c`` into the target) along the view's own ray: bool, True where the
    landing point moves less than ``max_px`` target pixels as the depth runs from the
    nearest depth the view sees (its smallest known one; the camera itself where the
    pixel's depth less its sigma_z is nearer) to the pixel's depth plus its sigma_z, every
    point in front of the target.

    Such a pixel is placed whatever its depth in that range, and whatever could hide it
    from the target lies on the view's own ray in front of it, where the photograph would
    show it: the photograph's colour is what the target sees. At the view's own camera
    every pixel is; the farther the target, the fewer."""
    zc = np.asarray(z[ys, xs], np.float64)
    out = np.zeros(zc.shape, bool)
    fin = np.isfinite(z) if view.fallback is None else np.isfinite(z) & ~view.fallback
    if not max_px > 0 or not len(zc) or not fin.any():
        return out
    near = float(np.min(z[fin]))
    sz = np.zeros_like(zc) if view.sigma_z is None else \
        np.broadcast_to(np.asarray(view.sigma_z, np.float64), z.shape)[ys, xs]
    q = M @ np.stack([xs, ys, np.ones_like(xs)]).astype(np.float64)

    def land(d):
        p = d * q + c[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            return p[:2] / p[2], (p[2] > 0) & (d > 0)

    # from the nearest depth (or, if a sigma_z reaches past the camera, from the camera itself)
    lo = np.maximum(np.minimum(near, zc - sz), 1e-9 * zc)
    (u0, ok0), (u1, ok1), (u2, ok2) = land(zc), land(lo), land(zc + sz)
    move = np.maximum(np.hypot(*(u1 - u0)), np.hypot(*(u2 - u0)))  # the landing point is monotone in depth
    return np.isfinite(zc) & ok0 & ok1 & ok2 & (move < max_px)


def _split_fallback(prepped, edge_rel, same_ray_px: float = 0.0) -> tuple[list, list]:
    """The layers warped into the target: each view's known depth, and apart, the fallback
    proxy of the views that have one (:attr:`vibr.scene.View.fallback`), each NaN where the
    other has depth and with its own slopes: the known layer is the view as it would be
    without the proxy. The fallback pixels the target sees along their own ray to within
    ``same_ray_px`` (:func:`same_ray`) join the known layer."""
    known, proxy = [], []
    for k, v, z, zx, zy, M, c in prepped:
        m = v.fallback
        if m is not None and same_ray_px > 0:
            ys, xs = np.nonzero(m)
            m = m.copy()
            m[ys, xs] = ~same_ray(v, z, M, c, ys, xs, same_ray_px)
        if m is None or not m.any():
            known.append((k, v, z, zx, zy, M, c))
            continue
        for layers, part in ((known, np.where(m, np.nan, z)), (proxy, np.where(m, z, np.nan))):
            layers.append((k, v, part, *depth_derivatives(part, edge_rel), M, c))
    return known, proxy


def _target_zbuffer(layers, shape, max_quad_px, splat_mode) -> np.ndarray:
    """Every layer's pixel quads splatted into one target z-buffer (+inf where empty)."""
    bufs = new_zbuffers(tuple(shape))
    for k, v, z, zx, zy, M, c in layers:
        splat_zbuffer(bufs, M, c, z, zx, zy, max_quad_px, splat_mode)
    return reduce_zbuffers(bufs)


def _visibility(layers, zbuf, vis_threshold, same_ray_px: float = 0.0):
    """Per layer: ``(state, visible pixels per row)``, and the counts per state by view name.
    An occluded pixel that the target sees along its own ray (:func:`same_ray`, to within
    ``same_ray_px``) is visible: what hides it is not on the ray the photograph saw."""
    states, counts = [], {}
    for k, v, z, zx, zy, M, c in layers:
        state, row_counts = visibility_mask(M, c, z, zx, zy, zbuf, vis_threshold, return_counts=True)
        if same_ray_px > 0:
            ys, xs = np.nonzero(state == OCCLUDED)
            seen = same_ray(v, z, M, c, ys, xs, same_ray_px)
            if seen.any():
                state[ys[seen], xs[seen]] = VISIBLE
                np.subtract.at(row_counts[:, OCCLUDED], ys[seen], 1)
                np.add.at(row_counts[:, VISIBLE], ys[seen], 1)
        hist = row_counts.sum(axis=0)
        counts[v.name] = {"unknown": int(hist[0]), "behind": int(hist[1]), "outside": int(hist[2]),
                          "occluded": int(hist[3]), "visible": int(hist[4])}
        states.append((state, row_counts[:, VISIBLE]))
    return states, counts


def _gather_samples(layers, states, shape, max_inv_det, sigma_z_default, grad_scheme, keep,
                    grad_model=None) -> Samples:
    """The fields of every visible pixel, sorted by target cell (:func:`_cell_dest`): one
    allocation for all samples, each layer's kernel writing its samples in place.

    The order matters for speed only: the renderer's passes over the samples, bucketed by
    target row, then stream through memory instead of gathering from every view's stretch
    of the arrays. The cells are found first (one warp pass), so that the fields are written
    once, at their sorted place, rather than written and then permuted."""
    N = int(sum(int(r.sum()) for _, r in states))
    offsets = []
    o = 0
    for _, vis_rows in states:
        offsets.append(o + np.concatenate([[0], np.cumsum(vis_rows)[:-1]]).astype(np.int64))
        o += int(vis_rows.sum())
    H_t, W_t = shape
    key = np.empty(N, np.int64)
    for (k, v, z, zx, zy, M, c), (state, _), row_off in zip(layers, states, offsets):
        _keys_kernel(state, row_off, z, M, c, H_t, W_t, key)
    dest = _cell_dest(key, max(H_t - 1, 1) * max(W_t - 1, 1))
    del key
    # positions in float64 (they set the splat coefficients); the other fields in float32,
    # the optional ones only when kept (the sample arrays are most of a render's memory)
    f4 = np.float32
    xy = np.empty((N, 2))
    jac = np.empty((N if "jac" in keep else 0, 2, 2), f4)
    inv_det = np.empty(N, f4)
    dtau = np.empty((N, 2), f4)
    X = np.empty((N, 3), f4)
    colour = np.empty((N, 3), np.float32)
    grad = np.empty((N, 3, 2), np.float32)
    src = np.empty((N if "src_xy" in keep else 0, 2), np.int32)
    sig = np.empty(N, f4)
    view = np.empty(N, np.int32)
    for (k, v, z, zx, zy, M, c), (state, vis_rows), row_off in zip(layers, states, offsets):
        if int(vis_rows.sum()) == 0:
            continue
        A = np.ascontiguousarray(v.camera.R.T @ np.linalg.inv(v.camera.K))
        sz = _view_sigma(v, z, sigma_z_default)
        if np.ndim(sz) == 0:
            sig_map, sig_scalar = np.zeros((0, 0)), float(sz)
        else:
            sig_map, sig_scalar = np.ascontiguousarray(sz, dtype=np.float64), 0.0
        _fields_kernel(state, row_off, dest, z, zx, zy, M, c, A, np.ascontiguousarray(v.camera.centre),
                       v.image, grad_scheme == "forward", grad_model == "chain", float(max_inv_det), sig_map,
                       sig_scalar, np.int32(k),
                       xy, jac, inv_det, dtau, X, colour, grad, src, sig, view)
    return Samples(xy, colour, grad, jac if "jac" in keep else None, inv_det, dtau, sig, view,
                   src if "src_xy" in keep else None, X, tuple(shape))
