"""The variational render from warped samples, in named steps (paper §4, docs/explanation/method.md §3-7).

    splat_coverage    the image-formation operator B (bilinear or footprint PSF), the
                      unweighted coverage Bᵀ1 and, with the gradient term, Bᵀ B and Bᵀ ∇v
    sample_density    rho, the mean coverage: data terms are divided by it
    colour_density    rho_c, rho weighted by the view prior: the colour term's divisor
    view_density      rho_c counted in views (lam_density's divisor)
    initial_image     the W-weighted blend of the samples, holes filled by push–pull
    fill_holes        the solved image's holes filled by push–pull of its covered pixels
    _Problem          what the outer passes share (splat, densities, terms), and the
                      quadratic model of one pass (colour and gradient stencils)
    solve_variational the outer passes: re-estimate the weights from u, assemble, FISTA

Which of these a method uses (gradient term, re-weighting, geometric uncertainty) is
declared by its :class:`vibr.render.methods.Method`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from ..errors import VibrInputError, check_stop
from ..geometry.samples import Samples
from ..progress import progress
from .operators import DEFAULT_GRAD_SCHEME, Splat
from .pushpull import push_pull
from .result import RenderResult
from .solver import QuadraticModel, fista
from .tv import TVProx
from .uncertainty import variational_sigma
from .weights import coverage_blend, gradient_consistency, robust_factor, view_prior, weighted_normal

__all__ = ["SplatCoverage", "splat_coverage", "sample_density", "colour_density", "view_density", "initial_image", "fill_holes", "solve_variational",
           "TV_WEIGHTINGS", "tv_weight_map"]

logger = logging.getLogger(__name__)


@dataclass
class SplatCoverage:
    """The operator B, the coverage and (gradient term) its unit-weight normal stencils."""

    splat: Splat
    acc: np.ndarray             # (H, W) Bᵀ1, the unweighted accumulated splat weight
    coverage: np.ndarray        # (H, W) bool, acc ≥ hole_threshold
    BtB: np.ndarray | None = None
    Btg: np.ndarray | None = None
    cg_unit: float = 0.0
    grad_vals: np.ndarray | None = None
    wsum: np.ndarray | None = None   # (1, H, W) Bᵀ w, w the deformation-only weight (initial blend)
    bw: np.ndarray | None = None     # (3, H, W) Bᵀ (w · colour)
    grad_conf: np.ndarray | None = None  # (N,) the gradient term's consistency weights (kept for grad_weighting W)


def make_splat(samples: Samples, footprint: bool) -> Splat:
    """``B`` of the samples: the footprint PSF (paper §4.1) or the bilinear one."""
    if footprint:
        if samples.jac is None:
            raise VibrInputError("the footprint PSF needs the samples' Jacobians: compute them with "
                                 "compute_samples(..., keep=('jac',)) (vibr.render.methods.sample_fields)")
        return Splat(samples.xy, samples.target_shape, jac=samples.jac, psf="footprint")
    return Splat(samples.xy, samples.target_shape)


def splat_coverage(samples: Samples, p: dict, *, footprint: bool, gradient: bool,
                   blend_factor=None, splat=None) -> SplatCoverage:
    """B for ``samples`` and the coverage ``Bᵀ1 ≥ hole_threshold``.

    With ``footprint``, ``B_kmp = area(P_km ∩ p) / area(P_km)``, ``P_km`` the source pixel's
    parallelogram (paper §4.1, fig. discretization right; footprints over 1 px shrunk per
    axis); otherwise the bilinear PSF. With ``gradient``, ``Bᵀ B`` and ``Bᵀ ∇v`` with unit
    weights: the gradient term's stencil up to its constant weight (grad_weighting
    visibility/none), and ``Σ_s (BᵀB)[s] = Bᵀ1`` is the coverage; with ``grad_consistency``
    > 0 the stencil weighs each sample by :func:`vibr.render.weights.gradient_consistency`
    (times its coverage over ``grad_coverage`` where that is lower; the coverage still counts
    every sample). ``blend_factor`` (N,)
    multiplies the initial blend's weights (the view prior, :func:`vibr.render.weights.view_prior`);
    ``splat``: ``B`` already built (:func:`make_splat` with the same ``footprint``).
    """
    sp = splat if splat is not None else make_splat(samples, footprint)
    c = float(p.get("grad_consistency") or 0.0) if gradient else 0.0
    # one pass: the unit-weight stencils (the per-sample blend weight sw in [0, 1] of
    # vibr.paths.flythrough, else 1), or with consistency weights only the mean gradient they need,
    # and the initial blend's deformation-weighted splat
    A0, rhs0, c0, wsum, bw = coverage_blend(samples, sp, p["sigma_s"], gradient, blend_factor, stencils=c <= 0)
    if not gradient:
        acc = A0[0].astype(np.float64)
        return _covering(SplatCoverage(sp, acc, acc >= p["hole_threshold"], wsum=wsum, bw=bw))
    grad_vals = samples.grad.reshape(len(samples), -1)  # (N, 6): (c0x, c0y, c1x, ...)
    if c <= 0:
        acc = A0.sum(0, dtype=np.float64)
        return _covering(SplatCoverage(sp, acc, acc >= p["hole_threshold"], A0, rhs0, c0, grad_vals, wsum, bw))
    acc = A0[0].astype(np.float64)
    # the weights themselves only for the W weighting, which multiplies them by W each pass
    BtB, Btg, cg, conf = gradient_consistency(samples, sp, rhs0, acc, c / float(p["scale"]),
                                              keep_weights=p["grad_weighting"] == "W",
                                              min_coverage=float(p.get("grad_coverage") or 0.0))
    return _covering(SplatCoverage(sp, acc, acc >= p["hole_threshold"], BtB, Btg, cg, grad_vals, wsum, bw, conf))


def _covering(cov: SplatCoverage) -> SplatCoverage:
    """A target no sample covers is an error (not a grey image)."""
    if not cov.coverage.any():
        raise VibrInputError("the target camera sees nothing of the scene (coverage 0 %): check its "
                             "position, orientation and intrinsics")
    return cov


#: TV weightings (docs/explanation/method.md §10): ``"uniform"`` lam everywhere, ``"samples"`` lam raised where
#: few samples land (:func:`tv_weight_map`).
TV_WEIGHTINGS = ("uniform", "samples")


def tv_weight_map(acc, weighting: str = "samples", k_max: float = 100.0, m_full: float = 0.792,
                  blur: float = 1.0):
    """The spatially varying TV's weight ``g(p)/lam`` (H, W) float32, or None for "uniform".

    ``g = max(lam, k_max·lam − (k_max − 1)·lam·m/m_full)`` with ``m`` the samples landing
    on the pixel (the accumulated splat weight ``Bᵀ1``) blurred by a Gaussian of ``blur``
    px: ``k_max`` (100) times lam where no sample lands, falling linearly to lam at
    ``m_full`` samples. The defaults are the authors' light-field rule
    ``max(λ, 100λ − m/8)`` at λ = 0.001 (docs/explanation/method.md §10: 100λ − m/8 = λ at m = 99·8λ = 0.792),
    made relative to lam so that it holds whatever lam's value and scale.
    """
    if weighting not in TV_WEIGHTINGS:
        raise ValueError(f"tv_weighting must be one of {TV_WEIGHTINGS}, got {weighting!r}")
    if weighting == "uniform":
        return None
    from scipy.ndimage import gaussian_filter

    m = gaussian_filter(np.asarray(acc, np.float64), blur, mode="nearest") if blur > 0 else acc
    return np.maximum(1.0, k_max - (k_max - 1.0) * m / m_full).astype(np.float32)


def sample_density(acc, coverage, normalise: bool) -> float:
    """rho: the mean accumulated bilinear weight over covered pixels (≈ number of views
    seeing a pixel, at equal resolution). Data terms are divided by it so that alpha, gamma
    and lam mean the same whatever the number of views (the authors' code divides the data
    gradient by the accumulated splat weight to the same effect)."""
    return float(acc[coverage].mean()) if normalise and coverage.any() else 1.0


def view_density(rho_c: float, samples) -> float:
    """rho_c counted in views rather than samples: times the mean target area of a source
    pixel, ``|det ∂tau/∂x|`` (``1 / inv_det``), so that sources finer than the target, which
    put several samples in a pixel each, count once (``lam_density``'s divisor)."""
    inv = np.asarray(samples.inv_det, np.float64)
    inv = inv[inv > 0]
    return max(rho_c * float(np.mean(1.0 / inv)), 1e-12) if inv.size else rho_c


def colour_density(rho: float, prior, normalise: bool) -> float:
    """rho_c, the density the colour term is divided by: ``rho · mean_m(prior_m)``, the
    number of views a covered pixel weighs once ULR's view prior (``prior`` (N,) in [0, 1],
    :func:`vibr.render.weights.view_prior`; None: 1) has weighed them.

    The prior keeps about ``view_k`` views per pixel whatever the number of sources, so
    dividing the colour term by rho (every view that lands) would shrink it against the
    TV and the gradient term as the sources grow (docs/explanation/renderer.md, "Density with the view
    prior")."""
    if prior is None or not normalise or len(prior) == 0:
        return rho
    return max(rho * float(np.mean(prior, dtype=np.float64)), 1e-12)


def fill_holes(img: np.ndarray, coverage: np.ndarray) -> np.ndarray:
    """``img`` with its holes (``~coverage``) replaced by the push–pull fill of its covered
    pixels (:func:`vibr.render.pushpull.push_pull` with weight 1 there, 0 in the holes);
    ``img`` itself where nothing or everything is covered."""
    if coverage.all() or not coverage.any():
        return img
    m = coverage.astype(np.float32)
    return np.where(coverage[..., None], img, push_pull(img * m[..., None], m)).astype(np.float32)


def initial_image(cov: SplatCoverage) -> np.ndarray:
    """``Σ W b c / Σ W b`` (the deformation-weighted splat of :func:`splat_coverage`), holes
    filled by push–pull; (H, W, 3).

    The push–pull weight is the plain coverage, so that "≥ 1" means "one full sample
    landed here"."""
    wsum = cov.wsum[0]  # Σ_s (BᵀWB)[s] = Bᵀ W 1: rows of B sum to one (either PSF)
    blend = np.where(wsum > 0, cov.bw / np.maximum(wsum, 1e-30), 0.0).transpose(1, 2, 0)
    return push_pull(blend * cov.acc[..., None], cov.acc)


def _view_prior(samples, p, centres, times, splat):
    """ULR's view prior per sample (:func:`vibr.render.weights.view_prior`) when
    ``p["view_k"]`` > 0 and the centres are known, else None; timed into ``times["weights"]``."""
    if not p.get("view_k", 0) or centres[0] is None or centres[1] is None:
        return None
    t0 = time.perf_counter()
    prior = view_prior(samples, centres[0], centres[1], int(p["view_k"]), p["ulr_beta_res"], splat=splat,
                       tie=p["view_tie"])
    times["weights"] += time.perf_counter() - t0
    return prior


class _ColourTerm:
    """The colour term's stencils ``A, b, c`` with the weights ``W_km`` (docs/explanation/method.md §3)
    divided by rho, the weights computed inside the assembly
    (:func:`vibr.render.weights.weighted_normal`); timed into ``times["weights"]``. ``W``
    (N,) is kept only when something needs it (``keep``)."""

    def __init__(self, samples, p, sp, rho, geometric: bool, times, keep: bool, prior=None):
        self.samples, self.p, self.sp, self.rho, self.times, self.keep = samples, p, sp, rho, times, keep
        self.sigma_z = p["sigma_z"] if geometric else 0.0
        self.prior = prior
        # None: the geometry's (a proxy's views share its depth error; compute_samples says)
        z = p.get("z_corr")
        self.z_corr = float(samples.meta.get("z_corr", 0.0) if z is None else z) if geometric else 0.0

    def __call__(self, u, z_corr=None):
        t0 = time.perf_counter()
        p = self.p
        z_corr = self.z_corr if z_corr is None else z_corr
        rf = None
        if u is not None and p["robust"] != "none":
            rf = robust_factor(self.samples, u, self.sp, p["robust_c"], p["robust"])
        if self.prior is not None:
            rf = self.prior if rf is None else rf * self.prior
        A, b, c, Wk = weighted_normal(self.samples, self.sp, u, p["sigma_s"], self.sigma_z, scale=float(p["scale"]),
                                      grad_max=p["grad_max"], wscale=1.0 / self.rho, factor=rf,
                                      keep_weights=self.keep, z_corr=z_corr)
        self.times["weights"] += time.perf_counter() - t0
        return A, b, c, Wk


class _GradientTerm:
    """The gradient term's stencils ``A_g, b_g, c_g`` for each outer pass."""

    def __init__(self, cov: SplatCoverage, p, rho):
        self.cov, self.p, self.rho = cov, p, rho
        self.Ag = self.bg = None
        self.cg = 0.0

    def stencils(self, Wk):
        cov, p = self.cov, self.p
        if p["grad_weighting"] == "W":
            w = Wk if cov.grad_conf is None else Wk * cov.grad_conf
            self.Ag, self.bg, self.cg = cov.splat.normal(w, cov.grad_vals, dtype=np.float32)
        elif self.Ag is None:
            # visibility / none: every (visible) sample, sensor precision 1/sigma_s²
            cw = 1.0 / (p["sigma_s"] ** 2 * self.rho)
            cov.BtB *= np.float32(cw)  # in place: the unit-weight stencils are not needed again
            cov.Btg *= np.float32(cw)
            self.Ag, self.bg, self.cg = cov.BtB, cov.Btg, cov.cg_unit * cw
            cov.BtB = cov.Btg = None
        H, W = cov.acc.shape
        self.bg = self.bg.reshape(3, 2, H, W)
        return self.Ag, self.bg, self.cg


def _outer_line(name, o, n_outer, res) -> str:
    return (f"render {name}: outer {o + 1}/{n_outer}: {res.n_iter} iterations ({res.stopped}), "
            f"E = {res.energy[-1]:.6g} (color {res.terms[-1][0]:.4g}, grad {res.terms[-1][1]:.4g}, "
            f"TV {res.terms[-1][2]:.4g}), {res.time_s:.2f} s")


class _Problem:
    """What every outer pass of one render shares (docs/explanation/method.md §3-7): the splat ``B`` and
    its coverage, the densities rho and rho_c, the colour and gradient terms, the TV weights
    and the model's constants. :meth:`model` assembles one pass's energy from the colour term's
    stencils."""

    def __init__(self, samples: Samples, p: dict, method, centres, times: dict, stop, keep_weights: bool):
        self.p, self.times = p, times
        # sources coarser than the grid: their gradients weigh less (methods: grid_source_size)
        self.gamma = p["gamma"] / max(1.0, p["grid_source_size"]) ** 2 if method.gradient else 0.0
        footprint = p["psf"] == "footprint"
        t0 = time.perf_counter()
        sp = make_splat(samples, footprint)
        times["assembly"] += time.perf_counter() - t0
        prior = _view_prior(samples, p, centres, times, sp)
        check_stop(stop)
        t0 = time.perf_counter()
        self.cov = splat_coverage(samples, p, footprint=footprint, gradient=self.gamma > 0, blend_factor=prior,
                                  splat=sp)
        self.sp = self.cov.splat
        times["assembly"] += time.perf_counter() - t0
        self.rho = sample_density(self.cov.acc, self.cov.coverage, p["normalise"])
        self.rho_c = colour_density(self.rho, prior, p["normalise"])
        check_stop(stop)
        self.colour_term = _ColourTerm(samples, p, self.sp, self.rho_c, method.geometric, times, keep_weights, prior)
        # D of the target side = the D the geometry stage applied to the sources
        self.grad_scheme = samples.meta.get("grad_scheme", DEFAULT_GRAD_SCHEME)
        self.tv_w = tv_weight_map(self.cov.acc, p["tv_weighting"])
        # on a grid k times finer than the target (supersampling), lam / k: the k × k average
        # smooths too (docs/explanation/renderer.md, "Sources finer than the target")
        self.lam_eff = p["lam"] / p["grid_factor"] * (p["lam_density"] / view_density(self.rho_c, samples)
                                                     if p.get("lam_density") else 1.0)
        self.grad_term = _GradientTerm(self.cov, p, self.rho) if self.gamma > 0 else None

    def initial_image(self) -> np.ndarray:
        """The deformation-weighted blend (u unknown yet), push–pull filled, (H, W, 3); the
        blend's sums are dropped after it."""
        t0 = time.perf_counter()
        init = initial_image(self.cov)
        self.cov.wsum = self.cov.bw = None
        self.times["init"] = time.perf_counter() - t0
        return init

    def model(self, A, b, c, Wk) -> QuadraticModel:
        """The energy of one pass from the colour term's stencils and weights ``Wk`` (the
        gradient term's stencils read them with grad_weighting W)."""
        p, s = self.p, float(self.p["scale"])
        Ag, bg, cg = self.grad_term.stencils(Wk) if self.grad_term is not None else (None, None, 0.0)
        return QuadraticModel(A, b, float(c), Ag, bg, float(cg), p["alpha"], self.gamma, self.lam_eff / s, s,
                              p["coupled_tv"], self.grad_scheme, self.tv_w)


@dataclass
class _Passes:
    """What the outer passes leave: the image, the energies, and the last pass's weights
    (``Wk``) with the estimate they were computed from (``u_w``; None: not re-weighted)."""

    u: np.ndarray
    energy: list
    terms: list
    outer: list
    n_iter: int = 0
    n_power: int = 0
    model: QuadraticModel | None = None
    Wk: np.ndarray | None = None
    u_w: np.ndarray | None = None


def _outer_passes(prob: _Problem, method, u, *, callback, progress_bar, verbose, stop) -> _Passes:
    """``n_outer`` passes of (re-weight from u, assemble, FISTA) from the initial image ``u``
    (3, H, W)."""
    p, times = prob.p, prob.times
    n_outer = max(1, int(p["n_outer"]))
    out = _Passes(u, [], [], [])
    prox = TVProx(u.shape, p["coupled_tv"], p["tv_iter"], weight=prob.tv_w)
    power_state: dict = {}
    passes = range(n_outer)
    if progress_bar:
        passes = progress(passes, desc=f"render {method.name}")
    A = b = c = None
    for o in passes:
        if method.reweight or (o == 0 and p["robust"] != "none"):
            # savsr keeps its weights, but a robust loss reweights them once from the blend
            out.model = A = b = None  # the previous pass's stencils go before the new ones come
            out.u_w = out.u  # the estimate the weights come from (fista copies it)
            A, b, c, out.Wk = prob.colour_term(out.u_w.transpose(1, 2, 0))
        elif o == 0:
            A, b, c, out.Wk = prob.colour_term(None)  # deformation only
        check_stop(stop)
        t0 = time.perf_counter()
        out.model = prob.model(A, b, c, out.Wk)
        times["assembly"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        out.outer.append(len(out.energy))

        def cb(k, e, tr, _o=o):
            if callback is not None:
                callback(_o, k, e, tr)
            check_stop(stop)

        # a pass before the last only supplies the image the weights are re-estimated from
        tol = p["tol"] if o == n_outer - 1 or p.get("tol_outer") is None else p["tol_outer"]
        res = fista(out.model, out.u, max_iter=p["max_iter"], tol=tol, min_iter=p["min_iter"],
                    tv_iter=p["tv_iter"], precond=p["precond"], d_floor=p["d_floor"], prox=prox,
                    callback=cb, power_state=power_state)
        times["solve"] += time.perf_counter() - t0
        out.u = res.u
        out.n_iter += res.n_iter
        out.n_power += res.n_power
        out.energy += res.energy
        out.terms += res.terms
        logger.log(logging.INFO if verbose else logging.DEBUG, "%s", _outer_line(method.name, o, n_outer, res))
    return out


def _uncertainty(prob: _Problem, method, samples: Samples, run: _Passes, terms):
    """The Jacobi diag(H⁻¹) of the last pass's model + the sources' spread
    (:func:`vibr.render.uncertainty.variational_sigma`); timed into ``times["uncertainty"]``."""

    t0 = time.perf_counter()
    model, Wk = run.model, run.Wk
    if prob.colour_term.z_corr > 0 and method.reweight and Wk is not None:
        # σ from the independent errors' weights: the shared-error weights count a first-order
        # cancellation as certainty (docs/explanation/renderer.md, "Depth errors the views share")
        run.model = model = None  # the last pass's stencils go before these come, as between passes
        A, b, c, Wk = prob.colour_term(run.u_w.transpose(1, 2, 0), z_corr=0.0)
        model = prob.model(A, b, c, Wk)
    sig = variational_sigma(model, prob.sp, Wk, samples.colour, run.u, prob.cov.coverage,
                            scale=float(prob.p["scale"]), density=prob.rho_c, grad_density=prob.rho, terms=terms,
                            view=samples.view)
    prob.times["uncertainty"] = time.perf_counter() - t0
    return sig


def solve_variational(samples: Samples, p: dict, method, *, callback=None, progress_bar: bool = False,
                      verbose: bool = False, uncertainty=False, centres=(None, None), stop=None) -> RenderResult:
    """Render from ``samples`` with a variational ``method`` (a
    :class:`vibr.render.methods.Method` with ``solve``): weights, initial image, then
    ``n_outer`` passes of (re-weight, assemble, FISTA). See :func:`vibr.render.render`.
    ``centres`` = (source centres (V, 3), target centre (3,)) for the view prior
    (``p["view_k"]`` > 0); ``stop`` is polled between those stages and after each FISTA
    iteration (:func:`vibr.errors.check_stop`)."""
    t_all = time.perf_counter()
    times = {"weights": 0.0, "init": 0.0, "assembly": 0.0, "solve": 0.0}
    need_w = p["grad_weighting"] == "W" or bool(uncertainty)
    prob = _Problem(samples, p, method, centres, times, stop, need_w)
    init = prob.initial_image()
    u = np.ascontiguousarray(init.transpose(2, 0, 1))  # planar (3, H, W) from here on
    run = _outer_passes(prob, method, u, callback=callback, progress_bar=progress_bar, verbose=verbose, stop=stop)
    sig = _uncertainty(prob, method, samples, run, uncertainty) if uncertainty else None
    img = np.ascontiguousarray(np.clip(run.u, 0, 1).transpose(1, 2, 0), dtype=np.float32)
    if p["hole_fill"] == "push-pull":
        img = fill_holes(img, prob.cov.coverage)
    times["total"] = time.perf_counter() - t_all
    sp = prob.sp
    p = dict(p, density=prob.rho, colour_density=prob.rho_c, psf_shrunk=sp.shrunk_fraction,
             psf_degenerate=sp.n_degenerate / max(sp.n, 1))
    return RenderResult(img, prob.cov.coverage, run.energy, run.terms, run.outer, times, method.name, p, len(samples),
                        init=init, iterations=run.n_iter, power_iterations=run.n_power, uncertainty=sig)
