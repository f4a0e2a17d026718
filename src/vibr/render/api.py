"""``vibr.render.render``: a novel view from a scene (paper §4, METHOD §3-7)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..camera import Camera
from ..errors import VibrInputError
from ..geometry.samples import Samples
from ..geometry.weights import geometric_weights
from ..scene import Scene, View
from .methods import METHODS, method_params
from .operators import Splat
from .pushpull import push_pull
from .solver import QuadraticModel, fista
from .tv import TVProx
from .ulr import ulr_blend

__all__ = ["RenderResult", "render", "render_samples"]


@dataclass
class RenderResult:
    """What :func:`render` returns.

    Attributes
    ----------
    image : (H, W, 3) float32 in [0, 1]
    coverage : (H, W) bool
        Pixels reached by the source samples (accumulated bilinear weight ≥
        ``hole_threshold``); the rest was filled (push–pull, then TV).
    energy : list of float
        Total energy after each FISTA iteration, all outer passes concatenated, in
        ``scale²`` units (intensities on the 0..scale range).
    terms : list of (E_color, E_grad, TV)
        The three terms (unweighted) per iteration, same units (TV in ``scale`` units).
    outer : list of int
        Index into ``energy`` where each outer (weight-update) pass starts.
    times : dict
        Seconds per stage: ``geometry``, ``weights``, ``init``, ``assembly``, ``solve``,
        ``total``.
    method : str
    params : dict
        The parameters used (defaults filled in), plus (variational methods) ``density``
        (the normalisation rho), ``psf_shrunk`` (fraction of the samples whose footprint
        was shrunk to fit a 2×2 block; 0 with the bilinear PSF) and ``psf_degenerate``
        (fraction with a non-finite or singular Jacobian, given the unit-square PSF).
    n_samples : int
    metrics : dict
        ``psnr`` / ``ssim`` / ``dssim`` against the held-out view (when the target is a
        View with an image), over the covered pixels with a 2-pixel border excluded.
    init : (H, W, 3) float32 or None
        The initial image (weighted blend + push–pull) the solver started from.
    iterations, power_iterations : int
        FISTA iterations and power iterations (step size) over all outer passes.
    uncertainty : (H, W) float32 or None
        Per-pixel standard deviation, grey levels of ``scale`` (``uncertainty=True``;
        :mod:`vibr.render.uncertainty`, docs/RENDERER.md "Uncertainty").
    """

    image: np.ndarray
    coverage: np.ndarray
    energy: list = field(default_factory=list)
    terms: list = field(default_factory=list)
    outer: list = field(default_factory=list)
    times: dict = field(default_factory=dict)
    method: str = "gradient"
    params: dict = field(default_factory=dict)
    n_samples: int = 0
    metrics: dict = field(default_factory=dict)
    init: np.ndarray | None = None
    iterations: int = 0
    power_iterations: int = 0
    uncertainty: np.ndarray | None = None


def _log(msg, verbose):
    if verbose:
        from ..progress import log

        log(msg)


def render_samples(samples: Samples, method: str = "gradient", *, source_centres=None,
                   target_centre=None, callback=None, progress_bar: bool = False,
                   verbose: bool = False, uncertainty: bool = False, **params) -> RenderResult:
    """Render from precomputed :class:`~vibr.geometry.Samples` (see :func:`render` for the
    parameters). ``source_centres`` (K, 3) and ``target_centre`` (3,) are needed by ulr."""
    p = method_params(method, **params)
    t_all = time.perf_counter()
    times = {"weights": 0.0, "init": 0.0, "assembly": 0.0, "solve": 0.0}
    H, W = samples.target_shape
    if len(samples) == 0:
        raise VibrInputError("no source sample lands in the target view")
    s = float(p["scale"])

    t0 = time.perf_counter()
    if method != "ulr" and p["psf"] == "footprint":
        # B_kmp = area(P_km ∩ p) / area(P_km), P_km the source pixel's parallelogram
        # (paper §4.1, fig. discretization right); footprints over 1 px shrunk per axis
        sp = Splat(samples.xy, (H, W), jac=samples.jac, psf="footprint")
    else:
        sp = Splat(samples.xy, (H, W))  # bilinear PSF (ulr: only its coverage)
    gamma = p["gamma"] if method == "gradient" else 0.0
    BtB = Btg = None
    cg_unit = 0.0
    if gamma > 0:
        # Bᵀ B and Bᵀ ∇v with unit weights: the gradient term's stencil up to its constant
        # weight (grad_weighting visibility/none), and Σ_s (BᵀB)[s] = Bᵀ 1 is the coverage
        grad_vals = samples.grad.reshape(len(samples), -1)  # (N, 6): (c0x, c0y, c1x, ...)
        BtB, Btg, cg_unit = sp.normal(np.ones(len(samples), np.float32), grad_vals, dtype=np.float32)
        acc = BtB.sum(0, dtype=np.float64)
    else:
        acc = sp.adjoint(np.ones(len(samples), np.float32))  # unweighted coverage Bᵀ1
    coverage = acc >= p["hole_threshold"]
    times["assembly"] += time.perf_counter() - t0

    colour = samples.colour
    if method == "ulr":
        t0 = time.perf_counter()
        if source_centres is None or target_centre is None:
            raise ValueError("ulr needs source_centres and target_centre")
        img, _, *var = ulr_blend(samples, source_centres, target_centre, k=p["ulr_k"],
                                 beta_res=p["ulr_beta_res"], spread=bool(uncertainty))
        img = push_pull(img * acc[..., None], acc)
        times["init"] = time.perf_counter() - t0
        sig = None
        if uncertainty:  # issue 28: ULR-weighted spread of the blended views
            from .uncertainty import ulr_sigma

            sig = ulr_sigma(var[0], coverage, scale=s)
        times["total"] = time.perf_counter() - t_all
        return RenderResult(np.clip(img, 0, 1), coverage, times=times, method=method, params=p,
                            n_samples=len(samples), uncertainty=sig)

    # Sample density rho: mean accumulated bilinear weight over covered pixels (≈ number of
    # views seeing a pixel, at equal resolution). Data terms are divided by it so that
    # alpha, gamma and lam mean the same whatever the number of views (the authors' code
    # divides the data gradient by the accumulated splat weight to the same effect).
    rho = float(acc[coverage].mean()) if p["normalise"] and coverage.any() else 1.0

    def weights(u):
        t0 = time.perf_counter()
        sz = 0.0 if method == "savsr" else p["sigma_z"]
        w = geometric_weights(samples, u, p["sigma_s"], sz, scale=s, grad_max=p["grad_max"], splat=sp,
                              dtype=np.float32)
        w *= np.float32(1.0 / rho)
        times["weights"] += time.perf_counter() - t0
        return w

    # initial weights: deformation only (u unknown yet); initial image: their blend + push-pull
    Wk = weights(None)
    t0 = time.perf_counter()
    A0, bw, _ = sp.normal(Wk, colour, dtype=np.float32)
    wsum = A0.sum(0)  # Σ_s (BᵀWB)[s] = Bᵀ W 1: rows of B sum to one (either PSF)
    del A0
    blend = np.where(wsum > 0, bw / np.maximum(wsum, 1e-30), 0.0).transpose(1, 2, 0)
    # blend = Σ W b c / Σ W b (W-weighted bilinear splat); the push–pull weight is the plain
    # coverage, so that "≥ 1" means "one full sample landed here"
    init = push_pull(blend * acc[..., None], acc)
    u = np.ascontiguousarray(init.transpose(2, 0, 1))  # planar (3, H, W) from here on
    times["init"] = time.perf_counter() - t0

    alpha = p["alpha"]
    lam_int = p["lam"] / s
    n_outer = max(1, int(p["n_outer"]))
    energy, terms, outer = [], [], []
    prox = TVProx(u.shape, p["coupled_tv"], p["tv_iter"])
    power_state: dict = {}
    n_iter = n_power = 0
    Ag = bg = None
    cg = 0.0
    bar = None
    if progress_bar:
        from ..progress import progress

        bar = progress(total=n_outer, desc=f"render {method}")
    for o in range(n_outer):
        if method != "savsr":
            Wk = weights(u.transpose(1, 2, 0))
        t0 = time.perf_counter()
        A, b, c = sp.normal(Wk, colour, dtype=np.float32)
        if gamma > 0:
            if p["grad_weighting"] == "W":
                Ag, bg, cg = sp.normal(Wk, grad_vals, dtype=np.float32)
            elif Ag is None:
                # visibility / none: every (visible) sample, sensor precision 1/sigma_s²
                cw = 1.0 / (p["sigma_s"] ** 2 * rho)
                Ag, bg, cg = BtB * np.float32(cw), Btg * np.float32(cw), cg_unit * cw
                BtB = Btg = None
            bg = bg.reshape(3, 2, H, W)
        model = QuadraticModel(A, b, float(c), Ag, bg, float(cg),
                               alpha, gamma, lam_int, s, p["coupled_tv"])
        times["assembly"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        outer.append(len(energy))

        def cb(k, e, tr, _o=o):
            if callback is not None:
                callback(_o, k, e, tr)

        res = fista(model, u, max_iter=p["max_iter"], tol=p["tol"], min_iter=p["min_iter"],
                    tv_iter=p["tv_iter"], precond=p["precond"], d_floor=p["d_floor"], prox=prox,
                    callback=cb, power_state=power_state)
        times["solve"] += time.perf_counter() - t0
        u = res.u
        n_iter += res.n_iter
        n_power += res.n_power
        energy += res.energy
        terms += res.terms
        _log(f"render {method}: outer {o + 1}/{n_outer}: {res.n_iter} iterations ({res.stopped}), "
             f"E = {res.energy[-1]:.6g} (color {res.terms[-1][0]:.4g}, grad {res.terms[-1][1]:.4g}, "
             f"TV {res.terms[-1][2]:.4g}), {res.time_s:.2f} s", verbose)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    img = np.ascontiguousarray(np.clip(u, 0, 1).transpose(1, 2, 0), dtype=np.float32)
    sig = None
    if uncertainty:  # issue 28: Jacobi diag(H⁻¹) of the last model + spread of the sources
        from .uncertainty import variational_sigma

        t0 = time.perf_counter()
        sig = variational_sigma(model, sp, Wk, colour, u, coverage, scale=s, density=rho,
                                terms=uncertainty)
        times["uncertainty"] = time.perf_counter() - t0
    times["total"] = time.perf_counter() - t_all
    p = dict(p, density=rho, psf_shrunk=sp.shrunk_fraction, psf_degenerate=sp.n_degenerate / max(sp.n, 1))
    return RenderResult(img, coverage, energy, terms, outer, times, method, p, len(samples), init=init,
                        iterations=n_iter, power_iterations=n_power, uncertainty=sig)


def _prepare_sources(sources: Scene, target, depth: str, sigma_z_proxy=None):
    """Drop the target from the sources, give every source depth (light fields: transfer
    from the views that have it, the held-out view included), or the planar proxy."""
    from ..geometry import ensure_source_depth, planar_proxy

    cam = target.camera if isinstance(target, View) else target
    tname = target.name if isinstance(target, View) else None
    views = [v for v in sources.views if v.name != tname]
    if not views:
        raise VibrInputError("no source views left after holding out the target", sources.root)
    if depth == "planar":
        pool = views + ([target] if isinstance(target, View) and target.depth is not None
                        and not all(v.depth is not None for v in views) else [])
        scene = Scene(pool, sources.name, sources.root, None, sources.points, dict(sources.meta))
        prox = planar_proxy(scene, cam, sigma_z=sigma_z_proxy)
        keep = [v for v in prox.views if v.name != tname]
        return Scene(keep, sources.name, sources.root, None, sources.points, dict(prox.meta))
    if depth != "given":
        raise VibrInputError(f"depth must be 'given' or 'planar', got {depth!r}")
    if all(v.depth is not None for v in views):
        return Scene(views, sources.name, sources.root, None, sources.points, dict(sources.meta))
    pool = list(views)
    if isinstance(target, View) and target.depth is not None:
        # the light-field case: only the held-out centre view carries (ground-truth) depth;
        # it is used only to give the sources depth, never to render
        pool.append(target)
    full = ensure_source_depth(Scene(pool, sources.name, sources.root, None, sources.points,
                                     dict(sources.meta)))
    keep = [v for v in full.views if v.name != tname]
    return Scene(keep, sources.name, sources.root, None, sources.points, dict(full.meta))


def render(sources: Scene, target: View | Camera, method: str = "gradient", *,
           depth: str = "given", samples: Samples | None = None, callback=None,
           progress_bar: bool = False, verbose: bool = False, geometry_kw: dict | None = None,
           uncertainty: bool = False, **params) -> RenderResult:
    """Render the view of ``target`` from ``sources`` (Nieto, Devernay & Crowley 2016).

    Minimises (METHOD §5, paper eq. energy_final)

        E(u) = alpha · ½ Σ_km W_km ((B_k u)(m) − v_k(m))²
             + gamma · ½ Σ_km C_km ‖(B_k D u)(m) − ∇v_k(m)‖²
             + lam · TV(u)

    with ``W_km = omega_km / |det ∂tau_k/∂x_m|`` (METHOD §3) by monotone FISTA, re-estimating
    omega from u in ``n_outer`` passes; ulr blends directly.

    Parameters
    ----------
    sources : Scene
        Source views with images and (for most views) depth. A view named like the target
        is held out.
    target : View or Camera
        A held-out view (its image is the reference for ``metrics``) or a bare camera.
    method : {"gradient", "bvs", "savsr", "ulr"}
    depth : {"given", "planar"}
        Use the views' depth (views without depth get it by transfer,
        :func:`vibr.geometry.ensure_source_depth`) or the planar proxy
        (:func:`vibr.geometry.planar_proxy`, with its raised sigma_z).
    samples : Samples, optional
        Skip the geometry stage.
    callback : callable, optional
        ``callback(outer, k, energy, (E_color, E_grad, TV))`` per FISTA iteration.
    uncertainty : bool
        Also compute ``RenderResult.uncertainty``, the per-pixel std. dev. in grey levels
        (:mod:`vibr.render.uncertainty`).
    **params
        alpha (1.0), gamma (1.0; gradient only), lam (0.1), sigma_s (1.0, grey levels),
        sigma_z (None: the geometry's), scale (255: the intensity scale all these refer to;
        images are [0, 1] internally), n_outer (2), max_iter (60), tol (1e-4, relative
        energy change), tv_iter (2), coupled_tv (True), grad_weighting ("visibility" | "none"
        | "W"), grad_max (64 grey levels / px), precond (False), hole_threshold (0.5),
        ulr_k (4), ulr_beta_res (0.1), psf ("bilinear" | "footprint": the image-formation
        model ``v_k = B_k u``, paper §4.1 eq. normal; with "footprint"
        ``B_kmp = area(P_km ∩ p) / area(P_km)``, ``P_km = tau_k(x_m) + ∂tau_k/∂x_m·[-½, ½]²``
        the source pixel's parallelogram, footprints larger than one target pixel shrunk
        per axis to 1 px; ulr ignores it). See :mod:`vibr.render.methods`.

    Returns
    -------
    RenderResult
    """
    if method not in METHODS:
        raise VibrInputError(f"unknown method {method!r} (choose from {', '.join(METHODS)})")
    t_all = time.perf_counter()
    cam = target.camera if isinstance(target, View) else target
    if not isinstance(cam, Camera):
        raise VibrInputError("target must be a View or a Camera")
    t0 = time.perf_counter()
    src = _prepare_sources(sources, target, depth)
    if samples is None:
        from ..geometry import compute_samples

        samples = compute_samples(src, cam, **(geometry_kw or {}))
    t_geo = time.perf_counter() - t0
    res = render_samples(samples, method, source_centres=np.array([v.camera.centre for v in src.views]),
                         target_centre=cam.centre, callback=callback, progress_bar=progress_bar,
                         verbose=verbose, uncertainty=uncertainty, **params)
    res.times["geometry"] = t_geo
    res.times["total"] = time.perf_counter() - t_all
    if isinstance(target, View) and target.image is not None:
        from ..metrics import psnr, ssim

        m = res.coverage
        res.metrics = {"psnr": psnr(res.image, target.image, mask=m, border=2),
                       "ssim": ssim(res.image, target.image, mask=m, border=2)}
        res.metrics["dssim"] = 1e4 * (1 - res.metrics["ssim"])
    return res
