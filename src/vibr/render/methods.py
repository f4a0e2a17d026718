"""The four rendering methods and their default parameters.

=========  ==========================================================================
ulr        Unstructured Lumigraph Rendering (Buehler et al. 2001): direct blend of the
           k best views per pixel with angle and resolution penalties; no solve.
savsr      Wanner & Goldluecke 2012: variational, W = deformation weight only
           (omega = 1/sigma_s², no geometric uncertainty), gamma = 0, one solve.
bvs        Pujades et al. 2014: variational with the Bayesian weights of docs/explanation/method.md §3
           (omega re-estimated from u in outer iterations), gamma = 0.
gradient   Nieto et al. 2016 (this paper, the default): bvs + the gradient term, gamma > 0.
=========  ==========================================================================

Parameter defaults (paper names; intensities on the scale ``scale`` = 255, docs/explanation/method.md §9):

* ``alpha = 1.0`` colour-term weight (eq. energy_final; the paper's light-field setting).
* ``gamma = 0.3`` gradient-term weight for ``gradient`` and ``lam = 0.6`` TV weight (grey
  levels of 255: a 1-grey-level step costs 1 per pixel of edge where 3 views weigh a pixel,
  ``lam_density`` below), with the uniform TV
  (eq. energy_final; vibr's units: forward differences, docs/explanation/renderer.md "One image
  gradient"; the paper's γ is reached through ``preset="paper"``), the view prior
  (``view_k = 4``), the gradient term's consistency weights (``grad_consistency = 24``),
  the TV weight against the data's sum (``lam_density = 3``), the holes filled by push–pull
  and the preconditioned solver (``precond = True``): chosen together by
  ``benchmarks/quality/sweep_defaults.py``, the best mean all-pixel PSNR over the
  *choose* half of a sweep (the scenes ``vibr.synthetic`` generates, their sources
  photographed by :func:`vibr.synthetic.photograph`), reported on the other
  half (the photographs: cotton, backgammon, fountain, temple; docs/results/defaults.md); gamma forced to 0 for savsr and bvs,
  which keep their published form (``view_k = 0``, ``precond = False``, ``lam_density = 0``)
  unless given.
  With the view prior the colour term is divided by the prior-weighted density
  (:func:`vibr.render.variational.colour_density`), the gradient term by the plain one.
  ``"auto"`` for either: chosen per scene by leave-one-source-out (:mod:`vibr.render.autotune`).
* ``sigma_s = 1.0`` sensor noise, grey levels of 255 (docs/explanation/method.md §3, the authors' value).
* ``sigma_z = None`` depth std. dev., scene units: the samples' own (the geometry stage's
  per-view value, default 1 % of the median depth).
* ``psf = "bilinear"`` the image-formation model ``v_k = B_k u`` (paper §4.1 eq. normal,
  docs/explanation/method.md §4): ``"bilinear"`` (unit-square transformed PSF: the bilinear coefficients of
  ``tau_k(x_m)``) or ``"footprint"`` (``B_kmp = area(P_km ∩ p) / area(P_km)``, the source
  pixel's parallelogram ``P_km = tau_k(x_m) + ∂tau_k/∂x_m·[-½, ½]²``, paper fig.
  discretization right; footprints larger than a target pixel shrunk per axis to 1 px, see
  :class:`vibr.render.operators.Splat`). Worth it when the sources are finer than the
  target. ulr ignores it.
* ``robust = "none"``, ``robust_c = 3`` the data term's loss; ``"cauchy"``: the weights are
  multiplied in each outer pass by the Cauchy IRLS factor ``1/(1 + (r/s)²)`` of each
  sample's residual against the current estimate, ``s = robust_c · 1.4826 · median(r)``
  (:func:`vibr.render.weights.robust_factor`): samples that disagree with the others
  (occluded, mismatched: speckles) stop pulling the render; ``"none"`` is least squares.
  Off by default: it wins on cotton and fountain but loses on the synthetic scenes
  (docs/explanation/renderer.md "Robust data term").
* ``view_k = 4``: > 0 multiplies each sample's data weight by ULR's view prior
  (:func:`vibr.render.weights.view_prior`: Buehler's angle + ``ulr_beta_res`` × resolution
  penalty, the ``view_k`` best views per pixel; docs/explanation/renderer.md "What ULR knows"); 0 weighs
  every view alike. Needs the camera centres (stored by :func:`vibr.geometry.compute_samples`).
  ``view_tie = 1.1``: Buehler's threshold ``p_(k+1)`` is at least this times the pixel's best
  penalty, so views that nearly tie with the best (a grid's four neighbours) share the
  weight; ≤ 1: Buehler's threshold (docs/explanation/renderer.md "Views that tie").
* ``precond = True``: variable-metric FISTA (:func:`vibr.render.solver.fista`, the authors'
  diagonal preconditioner, ``d_floor`` its floor); the same energy, reached in fewer
  iterations where the sample density is uneven (docs/explanation/renderer.md "Preconditioned solver").
* ``tol = 1e-4``: FISTA stops when an accepted step lowers the energy by less than this
  fraction (the authors' rule); ``tol_outer = None``: the passes before the last stop at
  ``tol`` too. A looser ``tol_outer`` saves iterations at the same mean PSNR but moves single
  scenes' results, so it is not the default (docs/explanation/renderer.md, "Solver settings").
* ``lam_density = 3`` (views): lam is the TV weight where the colour term's density counted
  in views (:func:`vibr.render.variational.view_density`) is 3, and scales by 3 over it
  elsewhere: the TV weight of a MAP estimate, constant against the data's *sum*, so a pixel
  that two views see is smoothed more than one that eight see. 0: lam as it is, against
  data terms divided by their density rho (the paper's normalisation; bvs and savsr keep
  it). Chosen with lam by the cross-scene sweep, its few-view cases included (docs/explanation/renderer.md,
  "Few views").
* ``grid_factor = 1``: the samples lie on a grid this many times finer than the target
  (set by :func:`vibr.render.render` when it supersamples, :func:`vibr.render.fine_grid`);
  lam is divided by it, since the ``k × k`` average that follows smooths too (measured on
  four scenes at two factors: docs/explanation/renderer.md, "Sources finer than the target").
* ``grid_source_size = 1``: the median size of a source pixel on the grid rendered on (set
  with ``grid_factor``); above 1, sources coarser than the target (a camera closer to the
  scene than the photographs, a video larger than them), gamma is divided by its square: a
  coarse source's gradient says nothing of the finer grid's detail, and the term then pulls
  the image toward its blur (docs/explanation/renderer.md, "Sources coarser than the target").
* ``grad_consistency = 24`` (grey levels per pixel, on the intensity scale ``scale``): each
  sample's weight in the gradient term is multiplied by ``1 / (1 + |∇v_m − (B Ḡ)_m|² / c²)``,
  ``Ḡ = Bᵀ∇v / Bᵀ1`` the mean of the views' gradients at each target pixel (a Cauchy
  M-estimator's weight, Holland & Welsch 1977, against the views' consensus): a gradient no
  other view confirms (a misregistered edge, an occlusion boundary) stops steering the image,
  where integrated it would drift (docs/explanation/renderer.md, "The gradient term's consistency
  weights"). 0: every visible sample at full weight, the paper's term.
* ``grad_coverage = 1.5`` (samples): with the consistency weights, a sample's weight in the
  gradient term is also multiplied by ``min(1, (B acc)_m / 1.5)``, ``acc = Bᵀ1`` the number
  of samples landing on each target pixel: where fewer than 1.5 land (a crack between the
  views' footprints, a border seen by one view), the views' mean gradient is mostly the
  sample's own and confirms nothing, and the term's integrated gradients there, with almost
  no colour data to hold them, drift (docs/explanation/renderer.md, "The gradient term where few samples
  land"). 0: no such factor.
* ``hole_fill = "push-pull"``: the holes (pixels no sample covers) take the push–pull fill
  of the solved image's covered pixels, as ULR's blend and the initial image fill theirs,
  for bvs and savsr too; ``"solve"``: the energy's minimiser there, where only TV and the
  gradient term act and the gradient samples at a hole's edge, integrated into it, streak it
  (docs/explanation/renderer.md, "Few views").
* ``tv_weighting = "uniform"``: lam everywhere; ``"samples"``: the spatially varying TV of
  the authors' code (docs/explanation/method.md §10), lam raised up to 100× where few samples land
  (:func:`vibr.render.variational.tv_weight_map`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import VibrInputError
from ..geometry.samples import Samples
from .operators import PSFS as _PSFS
from .params import (
    AUTO,
    DEFAULTS,
    GRAD_WEIGHTINGS,
    HOLE_FILLS,
    METHOD_REGISTRY,
    PAPER_DEFAULTS,
    PAPER_GAMMA_FACTOR,
    PAPER_LAM_FACTOR,
    PRESETS,
    RenderParams,
    paper_params,
)
from .pushpull import push_pull
from .result import RenderResult
from .ulr import ulr_blend
from .uncertainty import ulr_sigma
from .variational import solve_variational, splat_coverage

__all__ = ["Method", "REGISTRY", "METHODS", "DEFAULTS", "PSFS", "GRAD_WEIGHTINGS", "HOLE_FILLS", "get_method",
           "method_params", "register_method", "unregister_method", "PRESETS", "PAPER_DEFAULTS", "PAPER_GAMMA_FACTOR",
           "PAPER_LAM_FACTOR", "paper_params", "sample_fields", "with_sample_fields", "wants_fine_sources",
           "RenderParams", "AUTO", "as_params"]

#: Image-formation models, named once by :class:`vibr.render.operators.Splat`.
PSFS = _PSFS


@dataclass(frozen=True)
class Method:
    """A rendering method: what it uses, its parameter overrides, and how it renders.

    Attributes
    ----------
    name : str
    summary : str
        One line for ``--help``.
    solve : bool
        Variational (minimise the energy by FISTA) or a direct blend (ulr).
    gradient : bool
        Uses the gradient term (``gamma``; forced to 0 otherwise).
    reweight : bool
        Re-estimates the weights omega from ``u`` before each outer pass.
    geometric : bool
        The weights carry the geometric (depth) uncertainty ``sigma_z`` (savsr: no).
    overrides : dict
        Parameter defaults that differ from :data:`DEFAULTS`.
    """

    name: str
    summary: str
    solve: bool = True
    gradient: bool = False
    reweight: bool = True
    geometric: bool = True
    overrides: dict = field(default_factory=dict)

    def ignored_params(self) -> tuple[str, ...]:
        """The render parameters this method does not read: ulr solves nothing (no weights,
        no energy, no PSF model), only ``gradient`` has gamma, savsr's weights carry no
        sigma_z (nor its correlation z_corr). The CLI refuses a value given for one of them
        rather than ignore it."""
        grad = ("gamma", "grad_consistency", "grad_coverage")
        if not self.solve:
            return ("alpha", *grad, "lam", "sigma_s", "sigma_z", "z_corr", "n_outer", "max_iter", "precond", "psf")
        return (() if self.gradient else grad) + (() if self.geometric else ("sigma_z", "z_corr"))

    def render(self, samples, p: dict, *, source_centres=None, target_centre=None, callback=None,
               progress_bar: bool = False, verbose: bool = False, uncertainty=False, stop=None):
        """Render from :class:`~vibr.geometry.Samples` with filled parameters ``p``
        (:func:`method_params`); returns a :class:`~vibr.render.RenderResult` (with its
        ``uncertainty`` map when asked, :mod:`vibr.render.uncertainty`)."""
        if self.solve:
            return solve_variational(samples, p, self, callback=callback, progress_bar=progress_bar,
                                     verbose=verbose, uncertainty=uncertainty,
                                     centres=(source_centres, target_centre), stop=stop)
        return _render_ulr(self, samples, p, source_centres, target_centre, uncertainty)


def _render_ulr(method: Method, samples, p, source_centres, target_centre, uncertainty=False):
    """Buehler et al.'s blend of the ``ulr_k`` best views per pixel, holes by push–pull."""
    import time


    if source_centres is None or target_centre is None:
        raise ValueError("ulr needs source_centres and target_centre")
    t_all = time.perf_counter()
    times = {"weights": 0.0, "init": 0.0, "assembly": 0.0, "solve": 0.0}
    cov = splat_coverage(samples, p, footprint=False, gradient=False)  # only its coverage
    times["assembly"] = time.perf_counter() - t_all
    t0 = time.perf_counter()
    img, _, *var = ulr_blend(samples, source_centres, target_centre, k=p["ulr_k"],
                             beta_res=p["ulr_beta_res"], spread=bool(uncertainty))
    img = push_pull(img * cov.acc[..., None], cov.acc)
    times["init"] = time.perf_counter() - t0
    sig = None
    if uncertainty:  # the ULR-weighted spread of the blended views
        sig = ulr_sigma(var[0], cov.coverage, scale=float(p["scale"]))
    times["total"] = time.perf_counter() - t_all
    return RenderResult(np.clip(img, 0, 1), cov.coverage, times=times, method=method.name, params=p,
                        n_samples=len(samples), uncertainty=sig)


#: The methods by name, in the order shown to users.
REGISTRY: dict[str, Method] = METHOD_REGISTRY


def register_method(method: Method) -> Method:
    """Add ``method`` to :data:`REGISTRY` (and :data:`METHODS`)."""
    global METHODS
    REGISTRY[method.name] = method
    METHODS = tuple(REGISTRY)
    return method


def unregister_method(name: str) -> Method:
    """Remove the method ``name`` from :data:`REGISTRY` (and :data:`METHODS`); returns it."""
    global METHODS
    method = get_method(name)
    del REGISTRY[name]
    METHODS = tuple(REGISTRY)
    return method


register_method(Method("ulr", "Unstructured Lumigraph Rendering (direct blend, no solve)",
                       solve=False, reweight=False, overrides=dict(gamma=0.0, n_outer=0)))
# the baselines keep their published form (no view prior, plain FISTA) unless asked, and
# the TV weight they had before the gradient method's defaults moved with the prior-weighted
# density (docs/explanation/renderer.md, "Density with the view prior")
_PUBLISHED = dict(view_k=0, precond=False, lam=0.3, z_corr=0.0, lam_density=0.0)
register_method(Method("savsr", "Wanner & Goldluecke 2012: deformation weights, one solve",
                       reweight=False, geometric=False, overrides=dict(gamma=0.0, n_outer=1, **_PUBLISHED)))
register_method(Method("bvs", "Pujades et al. 2014: Bayesian weights re-estimated from u",
                       overrides=dict(gamma=0.0, **_PUBLISHED)))
register_method(Method("gradient", "Nieto et al. 2016: bvs + the gradient term (the default)",
                       gradient=True))

#: Names of the registered methods (CLI choices).
METHODS: tuple[str, ...] = tuple(REGISTRY)

#: Per-method overrides (derived from the registry).
METHOD_OVERRIDES = {name: m.overrides for name, m in REGISTRY.items()}


def get_method(method: "str | Method") -> Method:
    """The registered :class:`Method` named ``method`` (a Method passes through)."""
    if isinstance(method, Method):
        return method
    try:
        return REGISTRY[method]
    except (KeyError, TypeError):
        raise VibrInputError(f"unknown method {method!r} (choose from {', '.join(REGISTRY)})") from None


def method_params(method: str, preset: str | None = None, **params) -> dict:
    """The filled parameters of ``method`` as a dict: ``RenderParams.from_kwargs(method,
    preset, **params).as_dict()`` (:class:`vibr.render.params.RenderParams`; None values keep
    the method's default, unknown names raise TypeError, every value is checked)."""
    return RenderParams.from_kwargs(method, preset, **params).as_dict()


def as_params(method, params) -> RenderParams:
    """``params`` (a :class:`RenderParams`, or a dict of keyword arguments of
    :meth:`RenderParams.from_kwargs`, ``preset`` included) as a RenderParams for ``method``."""
    if isinstance(params, RenderParams):
        return RenderParams.coerce(method, params)
    return RenderParams.from_kwargs(method, **dict(params or {}))


def sample_fields(method="gradient", params: RenderParams | None = None, **kw) -> tuple:
    """The optional sample fields (:data:`vibr.geometry.sampling.OPTIONAL_FIELDS`) a render
    of ``method`` with ``params`` (or the keyword arguments ``kw``) reads, for
    :func:`vibr.geometry.compute_samples`'s ``keep``: ``("jac",)`` with the footprint PSF,
    else none."""
    return ("jac",) if wants_fine_sources(method, params, **kw) else ()


def wants_fine_sources(method="gradient", params: RenderParams | None = None, **kw) -> bool:
    """True where the render models sources finer than the target itself (the footprint
    PSF, ``psf="footprint"``, reads the warps' Jacobians): then
    :func:`vibr.render.api.reduce_sources` leaves the sources at their resolution."""
    return RenderParams.coerce(method, params, **kw).psf == "footprint"


def with_sample_fields(geometry_kw: dict | None, *renders) -> dict:
    """``geometry_kw`` (arguments of :func:`vibr.geometry.compute_samples`) with its
    ``keep`` extended by the :func:`sample_fields` of every render ``(method, params)`` the
    samples are for (``params`` a :class:`RenderParams` or a dict of keyword arguments):
    the one place that decides what the geometry computes."""
    keep = set((geometry_kw or {}).get("keep", ()))
    for method, params in renders:
        keep |= set(sample_fields(method, as_params(method, params)))
    return {**(geometry_kw or {}), "keep": tuple(sorted(keep))}


def render_samples(samples: Samples, method="gradient", *, params: RenderParams | None = None,
                   source_centres=None, target_centre=None, callback=None, progress_bar: bool = False,
                   verbose: bool = False, uncertainty: bool = False, stop=None, **kw) -> RenderResult:
    """Render from precomputed :class:`~vibr.geometry.Samples` (see :func:`render` for the
    parameters) with the registered method (:mod:`vibr.render.methods`).
    ``params`` (a :class:`RenderParams` for ``method``) and/or the keyword arguments ``kw``
    of :meth:`RenderParams.from_kwargs` (``preset`` included) give the parameters.
    ``source_centres`` (K, 3) and ``target_centre`` (3,) are needed by ulr and the view prior
    (``view_k``); None takes those :func:`vibr.geometry.compute_samples` stored in
    ``samples.meta``."""
    m = get_method(method)
    rp = RenderParams.coerce(m, params, **kw)
    if rp.auto:
        raise VibrInputError("gamma/lam 'auto' tunes on the source views: use vibr.render.render "
                             "(render_samples has only the samples)")
    if len(samples) == 0:
        raise VibrInputError("no source sample lands in the target view")
    if source_centres is None:
        source_centres = samples.meta.get("source_centres")
    if target_centre is None:
        target_centre = samples.meta.get("target_centre")
    return m.render(samples, rp.as_dict(), source_centres=source_centres, target_centre=target_centre,
                    callback=callback, progress_bar=progress_bar, verbose=verbose, uncertainty=uncertainty,
                    stop=stop)
