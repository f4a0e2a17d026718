"""``vibr.render.render``: a novel view from a scene (paper §4, docs/explanation/method.md §3-7)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from ..camera import Camera
from ..errors import VibrInputError, check_stop
from ..geometry import compute_samples, ensure_source_depth, target_depth
from ..geometry.resample import scaled_view
from ..geometry.resolution import ResolutionPlan, check_supersample, resolution_plan
from ..geometry.samples import Samples
from ..metrics import view_metrics
from ..scene import Scene, View
from .autotune import resolve_auto
from .checks import check_render_memory
from .methods import as_params, get_method, render_samples, wants_fine_sources, with_sample_fields
from .params import RenderParams
from .result import RenderResult

__all__ = ["RenderResult", "RenderParams", "render", "render_samples", "fine_grid", "grid_params",
           "SharedGeometry", "shared_geometry"]

logger = logging.getLogger(__name__)


def _resolve_auto(src: Scene, cam: Camera, params: RenderParams) -> RenderParams:
    """``gamma`` / ``lam`` = "auto" replaced by the leave-one-source-out choice of
    :func:`vibr.render.autotune.tune` (only the target's camera is passed: never its image)."""
    return resolve_auto(src, cam, params) if params.auto else params


def _ready_sources(sources: Scene, target) -> Scene:
    """``sources`` unchanged when ready to render from; else the target held out and depth
    transferred to the views lacking it (:func:`vibr.geometry.ensure_source_depth`), which
    is :func:`vibr.pipeline.prepare`'s ``depth="gt"``. Estimating depth is the pipeline's
    job, not the renderer's (docs/explanation/architecture.md)."""

    tname = target.name if isinstance(target, View) else None
    names = sources.names
    if tname not in names and sources.has_depth:
        return sources
    views = [v for v in sources.views if v.name != tname]
    if not views:
        raise VibrInputError("no source views left after holding out the target", sources.root)
    # a held-out target with depth lends it to the transfer (a light field whose only depth
    # is the centre's); it is never rendered from
    pool = views + ([target] if isinstance(target, View) and target.depth is not None else [])
    full = ensure_source_depth(sources.replace(views=pool))
    return full.replace(views=[v for v in full.views if v.name != tname])


def fine_grid(sources: Scene, camera: Camera, supersample="auto", prepared: dict | None = None, renders=()):
    """The grid to render ``camera`` on, and the sources to render it from
    (:func:`vibr.geometry.resolution.resolution_plan`).

    Returns ``(sources, camera, prepared, plan)``: ``camera`` scaled by ``plan.grid_scale``
    (:meth:`Camera.scaled`: pixel centres such that ``k × k`` blocks average back to the
    target's pixels, or a coarser grid enlarges onto them; :meth:`RenderResult.on_target`
    brings the result back); the sources in ``plan.scales``
    resized by :func:`vibr.geometry.resample.scaled_view` (as :func:`vibr.io.load_scene` resizes
    with ``scale``); ``prepared`` (depth prepared per view name, for
    :func:`vibr.geometry.compute_samples`) without those, whose full-size preparation no
    longer applies. On "auto", when one of ``renders`` (``(method, params)`` pairs) models
    fine sources itself (:func:`vibr.render.methods.wants_fine_sources`: the footprint PSF),
    the target's own grid and the sources as they are, unless the sources are coarser (a
    coarser grid then, as for the others). Render on the grid with :func:`grid_params`.
    """

    supersample = check_supersample(supersample)
    plan = resolution_plan(sources, camera, supersample)
    if supersample == "auto" and plan.coarsen == 1 and any(wants_fine_sources(m, as_params(m, p))
                                                           for m, p in renders):
        return sources, camera, prepared, ResolutionPlan()
    if plan.scales:
        sources = sources.replace(views=[scaled_view(v, plan.scales[v.name]) if v.name in plan.scales else v
                                         for v in sources.views])
        if prepared:
            prepared = {k: val for k, val in prepared.items() if k not in plan.scales}
    if plan.grid_scale != 1 or plan.scales:
        logger.debug("target %dx%d rendered on a grid ×%.3g; sources reduced first: %s", camera.width, camera.height,
                     plan.grid_scale, ", ".join(f"{k} ×{r:.3g}" for k, r in plan.scales.items()) or "none")
    return sources, plan.grid_camera(camera), prepared, plan


def grid_params(method, params, plan):
    """``params`` (a :class:`RenderParams` or a dict of keyword arguments; the same type
    returned) for a render of ``method`` on ``plan``'s grid (the variational methods):
    ``grid_factor`` = its supersampling factor (lam / k there) and ``grid_source_size`` = the
    median size of a source pixel on it (gamma / s² where the sources are coarser), see
    :mod:`vibr.render.methods`."""
    if plan is None or not get_method(method).solve:
        return params
    out = {}
    if plan.supersample > 1:
        out["grid_factor"] = plan.supersample
    if plan.grid_source_size > 1.0:
        out["grid_source_size"] = plan.grid_source_size
    return params.replace(**out) if isinstance(params, RenderParams) else {**params, **out}


@dataclass(frozen=True)
class SharedGeometry:
    """One geometry stage for several renders of one target (``vibr eval``'s settings, a
    parameter sweep): the sources and the samples on the grid :func:`render` chooses
    (:func:`fine_grid`), ``camera`` that grid's camera, ``plan`` its
    :class:`~vibr.geometry.resolution.ResolutionPlan`, ``target`` the target's camera.
    Made by :func:`shared_geometry`."""

    sources: Scene
    camera: Camera
    samples: Samples
    plan: ResolutionPlan
    target: Camera

    def render(self, method=None, *, params: RenderParams | None = None, uncertainty: bool = False,
               **kw) -> RenderResult:
        """What :func:`render` gives for ``method`` and ``params`` / ``kw`` (the grid's
        ``grid_factor`` and ``grid_source_size`` included, "auto" weights tuned for the
        target's camera, the result brought back to the target's size), from the shared samples."""
        rp = RenderParams.coerce(method, params, **kw)
        m = get_method(rp.method if method is None else method)
        rp = grid_params(m, _resolve_auto(self.sources, self.target, rp), self.plan)
        res = render(self.sources, self.camera, m, params=rp, samples=self.samples, uncertainty=uncertainty)
        return res.on_target(self.plan, self.target.shape)


def shared_geometry(sources: Scene, target: View | Camera, renders=(("gradient", {}),), *,
                    geometry_kw: dict | None = None, supersample="auto") -> SharedGeometry:
    """The geometry stage of :func:`render` done once for every ``(method, params)`` of
    ``renders``: the sources made ready as :func:`render` makes them, the grid
    :func:`fine_grid` chooses for them and the samples on it, with the fields any of them
    reads (:func:`vibr.render.methods.with_sample_fields`); ``params`` of each a
    :class:`RenderParams` or a dict of keyword arguments. ``SharedGeometry.render(method,
    params=...)`` then equals ``render(sources, target, method, params=...)`` without computing
    the samples again."""

    cam = target.camera if isinstance(target, View) else target
    renders = list(renders)
    src, grid, _, plan = fine_grid(_ready_sources(sources, target), cam, supersample, None, renders)
    samples = compute_samples(src, grid, **with_sample_fields(geometry_kw, *renders))
    return SharedGeometry(src, grid, samples, plan, cam)


def _fine_samples(sources, target, cam, m, params, geometry_kw, supersample, stop=None):
    """The geometry stage of :func:`render`: ``(sources, samples, plan)``, the samples on
    :func:`fine_grid`'s grid (``stop`` polled between its stages)."""

    src = _ready_sources(sources, target)
    gkw = with_sample_fields(geometry_kw, (m, params))
    src, grid, gkw["prepared"], plan = fine_grid(src, cam, supersample, gkw.get("prepared"), [(m, params)])
    check_render_memory([v.camera.shape for v in src.views], grid.shape, cam.source,  # before allocating
                        keep=gkw["keep"], output_shape=cam.shape)
    return src, compute_samples(src, grid, stop=stop, return_zbuffer=True, **gkw), plan


def render(sources: Scene, target: View | Camera, method=None, *, params: RenderParams | None = None,
           samples: Samples | None = None, callback=None, progress_bar: bool = False,
           verbose: bool = False, geometry_kw: dict | None = None, uncertainty: bool = False,
           supersample="auto", stop=None, **kw) -> RenderResult:
    """Render the view of ``target`` from ``sources`` (Nieto, Devernay & Crowley 2016).

    Minimises (docs/explanation/method.md §5, paper eq. energy_final)

        E(u) = alpha · ½ Σ_km W_km ((B_k u)(m) − v_k(m))²
             + gamma · ½ Σ_km C_km ‖(B_k D u)(m) − ∇v_k(m)‖²
             + lam · TV(u)

    with ``W_km = omega_km / |det ∂tau_k/∂x_m|`` (docs/explanation/method.md §3) by monotone FISTA, re-estimating
    omega from u in ``n_outer`` passes; ulr blends directly.

    Parameters
    ----------
    sources : Scene
        Source views with images and depth, as :func:`vibr.pipeline.prepare` returns them.
        For convenience, sources that are not ready (a view named like the target among
        them, or a view without depth) are made ready as ``prepare(..., depth="gt")`` would:
        the target is held out and depth transferred from the views that have it.
    target : View or Camera
        A held-out view (its image is the reference for ``metrics``) or a bare camera.
    method : str or Method, optional
        A name of :data:`vibr.render.methods.METHODS` ("gradient", "bvs", "savsr", "ulr");
        default ``params.method``, else "gradient".
    params : RenderParams, optional
        The render's parameters (:class:`vibr.render.params.RenderParams`, for ``method``);
        default the method's. Keyword arguments ``**kw`` change them.
    samples : Samples, optional
        Skip the geometry stage (the sources are then used as given).
    callback : callable, optional
        ``callback(outer, k, energy, (E_color, E_grad, TV))`` per FISTA iteration.
    stop : callable, optional
        ``stop()`` is polled between the geometry's stages (z-buffer, visibility, sample
        fields), between the solve's (view prior, coverage, weights) and after each FISTA
        iteration; when it returns True the render raises
        :class:`RenderStopped` (a viewer whose camera has moved on stops in a fraction of
        a render rather than after its first iteration).
    progress_bar : bool
        A bar over the outer passes (:func:`vibr.progress.progress`: on a terminal only).
    verbose : bool
        Log each outer pass at INFO (else DEBUG) on the ``vibr.render`` logger.
    geometry_kw : dict, optional
        Arguments of :func:`vibr.geometry.compute_samples`.
    uncertainty : bool
        Also fill ``RenderResult.uncertainty``, the per-pixel std. dev. in grey levels
        (:mod:`vibr.render.uncertainty`).
    supersample : "auto" or int
        Sources finer than the target: render on a grid ``k`` times finer, then average
        ``k × k`` blocks (:func:`fine_grid`; "auto": ``k`` from the sources' pixel size in
        the target, at most 4; sources still more than twice finer than that grid are reduced
        first). Not with ``samples`` given; "auto" does nothing with ``psf="footprint"``, which
        models fine sources itself. ``RenderResult.params`` records ``supersample`` and
        ``reduced_sources``.
    **kw
        Render parameters by name (a field of :class:`~vibr.render.params.RenderParams`, None:
        the method's default), applied to ``params``, and ``preset`` (``"paper"``: alpha,
        gamma and lam in the paper's units, :data:`vibr.render.params.PRESETS`). E.g.
        ``render(src, tgt, "gradient", gamma=0.5)``. Every parameter's meaning, units, range
        and default: docs/reference/parameters.md.

    Returns
    -------
    RenderResult

    Examples
    --------
    The centre of a synthetic 3×3 grid, held out and rendered from the other eight:

    >>> from vibr.synthetic import make_scene
    >>> sources, target = make_scene("grid", n_views=9, width=48, height=48).split(4)
    >>> res = render(sources, target)
    >>> res.image.shape, bool(res.metrics["psnr"] > 35)
    ((48, 48, 3), True)
    """
    rp = RenderParams.coerce(method, params, **kw)
    m = get_method(rp.method if method is None else method)
    t_all = time.perf_counter()
    cam = target.camera if isinstance(target, View) else target
    if not isinstance(cam, Camera):
        hint = ("; a view of a scene by name or index: vibr.pipeline.prepare(scene, target)"
                if isinstance(target, (str, int)) else "")
        raise VibrInputError(f"target must be a View or a Camera, got {type(target).__name__}{hint}")
    if not isinstance(sources, Scene):
        raise VibrInputError(f"sources must be a Scene, got {type(sources).__name__}")
    t0 = time.perf_counter()
    src, plan = sources, None
    if samples is None:
        src, samples, plan = _fine_samples(sources, target, cam, m, rp, geometry_kw, supersample, stop)
    elif isinstance(target, View) and target.name in sources.names:
        src = sources.replace(views=[v for v in sources.views if v.name != target.name])
    t_geo = time.perf_counter() - t0
    check_stop(stop)
    rp = grid_params(m, _resolve_auto(src, cam, rp), plan)
    res = render_samples(samples, m, params=rp, source_centres=np.array([v.camera.centre for v in src.views]),
                         target_centre=cam.centre, callback=callback, progress_bar=progress_bar,
                         verbose=verbose, uncertainty=uncertainty, stop=stop)
    res.depth = target_depth(samples)
    res = res.on_target(plan, cam.shape)
    res.times["geometry"] = t_geo
    res.times["total"] = time.perf_counter() - t_all
    if isinstance(target, View) and target.image is not None:
        cover = res.coverage if target.mask is None else res.coverage & target.mask
        res.metrics = view_metrics(res.image, target.image, cover)
    return res
