"""The variational render from warped samples, in named steps (paper §4, docs/METHOD.md §3-7).

    splat_coverage    the image-formation operator B (bilinear or footprint PSF), the
                      unweighted coverage Bᵀ1 and, with the gradient term, Bᵀ B and Bᵀ ∇v
    sample_density    rho, the mean coverage: data terms are divided by it
    initial_image     the W-weighted blend of the samples, holes filled by push–pull
    assemble_model    the quadratic model of one outer pass (colour and gradient stencils)
    solve_variational the outer passes: re-estimate the weights from u, assemble, FISTA

Which of these a method uses (gradient term, re-weighting, geometric uncertainty) is
declared by its :class:`vibr.render.methods.Method`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from ..errors import VibrInputError
from ..geometry.samples import Samples
from .weights import geometric_weights, robust_factor, view_prior
from .operators import DEFAULT_GRAD_SCHEME, Splat
from .pushpull import push_pull
from .result import RenderResult
from .solver import QuadraticModel, fista
from .tv import TVProx

__all__ = ["SplatCoverage", "splat_coverage", "sample_density", "initial_image", "solve_variational",
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


def splat_coverage(samples: Samples, p: dict, *, footprint: bool, gradient: bool) -> SplatCoverage:
    """B for ``samples`` and the coverage ``Bᵀ1 ≥ hole_threshold``.

    With ``footprint``, ``B_kmp = area(P_km ∩ p) / area(P_km)``, ``P_km`` the source pixel's
    parallelogram (paper §4.1, fig. discretization right; footprints over 1 px shrunk per
    axis); otherwise the bilinear PSF. With ``gradient``, ``Bᵀ B`` and ``Bᵀ ∇v`` with unit
    weights: the gradient term's stencil up to its constant weight (grad_weighting
    visibility/none), and ``Σ_s (BᵀB)[s] = Bᵀ1`` is the coverage.
    """
    shape = samples.target_shape
    if footprint:
        sp = Splat(samples.xy, shape, jac=samples.jac, psf="footprint")
    else:
        sp = Splat(samples.xy, shape)
    # per-sample blend weight in [0, 1] (vibr.flythrough fades a source leaving the set), else 1
    sw = samples.meta.get("sample_weight")
    ones = np.ones(len(samples), np.float32) if sw is None else np.asarray(sw, np.float32)
    if gradient:
        grad_vals = samples.grad.reshape(len(samples), -1)  # (N, 6): (c0x, c0y, c1x, ...)
        BtB, Btg, cg_unit = sp.normal(ones, grad_vals, dtype=np.float32)
        acc = BtB.sum(0, dtype=np.float64)
        return _covering(SplatCoverage(sp, acc, acc >= p["hole_threshold"], BtB, Btg, cg_unit, grad_vals))
    acc = sp.adjoint(ones)
    return _covering(SplatCoverage(sp, acc, acc >= p["hole_threshold"]))


def _covering(cov: SplatCoverage) -> SplatCoverage:
    """A target no sample covers is an error (not a grey image)."""
    if not cov.coverage.any():
        raise VibrInputError("the target camera sees nothing of the scene (coverage 0 %): check its "
                             "position, orientation and intrinsics")
    return cov


#: TV weightings (docs/METHOD.md §10): ``"uniform"`` lam everywhere, ``"samples"`` lam raised where
#: few samples land (:func:`tv_weight_map`).
TV_WEIGHTINGS = ("uniform", "samples")


def tv_weight_map(acc, weighting: str = "samples", k_max: float = 100.0, m_full: float = 0.792,
                  blur: float = 1.0):
    """The spatially varying TV's weight ``g(p)/lam`` (H, W) float32, or None for "uniform".

    ``g = max(lam, k_max·lam − (k_max − 1)·lam·m/m_full)`` with ``m`` the samples landing
    on the pixel (the accumulated splat weight ``Bᵀ1``) blurred by a Gaussian of ``blur``
    px: ``k_max`` (100) times lam where no sample lands, falling linearly to lam at
    ``m_full`` samples. The defaults are the authors' light-field rule
    ``max(λ, 100λ − m/8)`` at λ = 0.001 (docs/METHOD.md §10: 100λ − m/8 = λ at m = 99·8λ = 0.792),
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


def initial_image(sp: Splat, Wk, colour, acc) -> np.ndarray:
    """``Σ W b c / Σ W b`` (the W-weighted splat), holes filled by push–pull; (H, W, 3).

    The push–pull weight is the plain coverage, so that "≥ 1" means "one full sample
    landed here"."""
    A0, bw, _ = sp.normal(Wk, colour, dtype=np.float32)
    wsum = A0.sum(0)  # Σ_s (BᵀWB)[s] = Bᵀ W 1: rows of B sum to one (either PSF)
    del A0
    blend = np.where(wsum > 0, bw / np.maximum(wsum, 1e-30), 0.0).transpose(1, 2, 0)
    return push_pull(blend * acc[..., None], acc)


class _Weights:
    """``W_km`` (docs/METHOD.md §3) divided by rho, timed into ``times["weights"]``."""

    def __init__(self, samples, p, sp, rho, geometric: bool, times, centres=(None, None)):
        self.samples, self.p, self.sp, self.rho, self.times = samples, p, sp, rho, times
        self.sigma_z = p["sigma_z"] if geometric else 0.0
        self.prior = None
        if p.get("view_k", 0) and centres[0] is not None and centres[1] is not None:
            # what ULR knows: angle and resolution penalties, the view_k best views per pixel
            t0 = time.perf_counter()
            self.prior = view_prior(samples, centres[0], centres[1], int(p["view_k"]), p["ulr_beta_res"])
            times["weights"] += time.perf_counter() - t0

    def __call__(self, u):
        t0 = time.perf_counter()
        p = self.p
        w = geometric_weights(self.samples, u, p["sigma_s"], self.sigma_z, scale=float(p["scale"]),
                              grad_max=p["grad_max"], splat=self.sp, dtype=np.float32, prior=self.prior)
        w *= np.float32(1.0 / self.rho)
        sw = self.samples.meta.get("sample_weight")
        if sw is not None:  # vibr.flythrough's blend weight of the sample's view
            w *= np.asarray(sw, np.float32)
        if u is not None and p["robust"] != "none":
            w *= robust_factor(self.samples, u, self.sp, p["robust_c"], p["robust"])
        self.times["weights"] += time.perf_counter() - t0
        return w


class _GradientTerm:
    """The gradient term's stencils ``A_g, b_g, c_g`` for each outer pass."""

    def __init__(self, cov: SplatCoverage, p, rho):
        self.cov, self.p, self.rho = cov, p, rho
        self.Ag = self.bg = None
        self.cg = 0.0

    def stencils(self, Wk):
        cov, p = self.cov, self.p
        if p["grad_weighting"] == "W":
            self.Ag, self.bg, self.cg = cov.splat.normal(Wk, cov.grad_vals, dtype=np.float32)
        elif self.Ag is None:
            # visibility / none: every (visible) sample, sensor precision 1/sigma_s²
            cw = 1.0 / (p["sigma_s"] ** 2 * self.rho)
            self.Ag, self.bg, self.cg = cov.BtB * np.float32(cw), cov.Btg * np.float32(cw), cov.cg_unit * cw
            cov.BtB = cov.Btg = None
        H, W = cov.acc.shape
        self.bg = self.bg.reshape(3, 2, H, W)
        return self.Ag, self.bg, self.cg


def _outer_line(name, o, n_outer, res) -> str:
    return (f"render {name}: outer {o + 1}/{n_outer}: {res.n_iter} iterations ({res.stopped}), "
            f"E = {res.energy[-1]:.6g} (color {res.terms[-1][0]:.4g}, grad {res.terms[-1][1]:.4g}, "
            f"TV {res.terms[-1][2]:.4g}), {res.time_s:.2f} s")


def solve_variational(samples: Samples, p: dict, method, *, callback=None, progress_bar: bool = False,
                      verbose: bool = False, uncertainty=False, centres=(None, None)) -> RenderResult:
    """Render from ``samples`` with a variational ``method`` (a
    :class:`vibr.render.methods.Method` with ``solve``): weights, initial image, then
    ``n_outer`` passes of (re-weight, assemble, FISTA). See :func:`vibr.render.render`."""
    t_all = time.perf_counter()
    times = {"weights": 0.0, "init": 0.0, "assembly": 0.0, "solve": 0.0}
    s = float(p["scale"])
    gamma = p["gamma"] if method.gradient else 0.0
    t0 = time.perf_counter()
    cov = splat_coverage(samples, p, footprint=p["psf"] == "footprint", gradient=gamma > 0)
    sp = cov.splat
    times["assembly"] += time.perf_counter() - t0
    rho = sample_density(cov.acc, cov.coverage, p["normalise"])
    weights = _Weights(samples, p, sp, rho, method.geometric, times, centres)

    # initial weights: deformation only (u unknown yet); initial image: their blend + push-pull
    Wk = weights(None)
    t0 = time.perf_counter()
    init = initial_image(sp, Wk, samples.colour, cov.acc)
    u = np.ascontiguousarray(init.transpose(2, 0, 1))  # planar (3, H, W) from here on
    times["init"] = time.perf_counter() - t0

    # D of the target side = the D the geometry stage applied to the sources
    grad_scheme = samples.meta.get("grad_scheme", DEFAULT_GRAD_SCHEME)
    n_outer = max(1, int(p["n_outer"]))
    energy, terms, outer = [], [], []
    tv_w = tv_weight_map(cov.acc, p["tv_weighting"])
    prox = TVProx(u.shape, p["coupled_tv"], p["tv_iter"], weight=tv_w)
    grad_term = _GradientTerm(cov, p, rho) if gamma > 0 else None
    power_state: dict = {}
    n_iter = n_power = 0
    bar = None
    if progress_bar:
        from ..progress import progress

        bar = progress(total=n_outer, desc=f"render {method.name}")
    for o in range(n_outer):
        if method.reweight or (o == 0 and p["robust"] != "none"):
            # savsr keeps its weights, but a robust loss reweights them once from the blend
            Wk = weights(u.transpose(1, 2, 0))
        t0 = time.perf_counter()
        A, b, c = sp.normal(Wk, samples.colour, dtype=np.float32)
        Ag, bg, cg = grad_term.stencils(Wk) if grad_term is not None else (None, None, 0.0)
        model = QuadraticModel(A, b, float(c), Ag, bg, float(cg),
                               p["alpha"], gamma, p["lam"] / s, s, p["coupled_tv"], grad_scheme, tv_w)
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
        logger.log(logging.INFO if verbose else logging.DEBUG, "%s", _outer_line(method.name, o, n_outer, res))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    sig = None
    if uncertainty:  # issue 28: Jacobi diag(H⁻¹) of the last pass's model + spread of the sources
        from .uncertainty import variational_sigma

        t0 = time.perf_counter()
        sig = variational_sigma(model, sp, Wk, samples.colour, u, cov.coverage, scale=s, density=rho,
                                terms=uncertainty)
        times["uncertainty"] = time.perf_counter() - t0
    times["total"] = time.perf_counter() - t_all
    img = np.ascontiguousarray(np.clip(u, 0, 1).transpose(1, 2, 0), dtype=np.float32)
    p = dict(p, density=rho, psf_shrunk=sp.shrunk_fraction, psf_degenerate=sp.n_degenerate / max(sp.n, 1))
    return RenderResult(img, cov.coverage, energy, terms, outer, times, method.name, p, len(samples),
                        init=init, iterations=n_iter, power_iterations=n_power, uncertainty=sig)
