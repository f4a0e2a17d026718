"""FISTA for the energy of docs/explanation/method.md §5 (paper §4.2-4.4, eq. energy_final).

    E(u) = alpha · E_color(u) + gamma · E_grad(u) + lam · TV(u)

    E_color = ½ Σ_k Σ_m W_km ((B_k u)(m) − v_k(m))²
    E_grad  = ½ Σ_k Σ_m C_km ‖(B_k D u)(m) − ∇v_k(m)‖²       (paper eq. poor_assumption)

The smooth part is quadratic: ``f(u) = ½⟨u, Hu⟩ − ⟨r, u⟩ + c`` with
``H = alpha·A + gamma·Dᵀ A_g D``, ``A = Σ BᵀWB`` and ``A_g = Σ BᵀCB`` two 9-point stencils
(:mod:`vibr.render.operators`) assembled once per weight update. The solver is the
monotone FISTA (MFISTA, Beck & Teboulle 2009, IEEE TIP 18(11)) with the TV proximal step of
:class:`~vibr.render.tv.TVProx` (warm-started dual). Because ``f`` is quadratic, ``H x`` is
linear in ``x``: the extrapolated point's product is the same combination of the stored
``H x`` and ``H x_prev``, so each iteration costs one Hessian product, computed together
with every inner product of the energy in one pass over memory
(:func:`vibr.render.fused.hessian_terms`), and the forward step at the extrapolated point
is one more pass from the stored iterates (:meth:`QuadraticModel.forward`) without storing
that point. The loop allocates nothing: three image buffers and three product buffers
rotate between x, x_prev and the candidate.

**Intensity scale.** Images are [0, 1]; the parameters refer to intensities on the scale
``s`` (default 255). The energy is ``s²·E`` of the [0, 1] image, so the TV weight inside is
``lam / s`` and the reported energies are in ``s²`` units (what the same energy would read
with [0, s] images).

``precond=True`` runs the variable-metric variant (the authors' diagonal preconditioner,
docs/explanation/method.md §10): gradient step divided per pixel by ``d ≥ row-sum|H|`` (floored where few
samples land, which raises lambda there) and the TV prox taken in the same metric
(weighted ROF), the step from a power iteration on ``d^{-½} H d^{-½}``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .fused import forward_step, hessian_power, hessian_terms, power_scale, power_start, power_unscale, row_sum_bound
from .operators import dot, grad_image_adj
from .tv import TVProx

__all__ = ["QuadraticModel", "Products", "SolveResult", "fista", "median"]


class Products(NamedTuple):
    """What one pass over ``x`` gives: ``h = H x`` and ``dots = (⟨x,Ax⟩, ⟨b,x⟩,
    ⟨x,DᵀA_gDx⟩, ⟨Dᵀb_g,x⟩, TV(x))`` (float64)."""

    h: np.ndarray
    dots: tuple


@dataclass
class QuadraticModel:
    """The smooth part and the prior, ready to solve.

    A : (9, H, W) float32      colour stencil Σ BᵀWB
    b : (C, H, W) float32      Σ BᵀW v   (planar images throughout)
    c : float                  ½ Σ W v²
    Ag, bg, cg : same for the gradient term (bg is (C, 2, H, W)), or None when gamma = 0
    alpha, gamma : float       term weights (eq. energy_final)
    lam_int : float            TV weight for [0, 1] images (= lam / scale)
    scale : float              intensity scale the parameters refer to (energies × scale²)
    coupled : bool             colour-coupled TV
    grad_scheme : str          discretisation of D (operators.GRAD_SCHEMES), as the samples' ∇v
    tv_weight : (H, W) or None spatially varying TV: TV(u) = Σ_p tv_weight(p)|∇u(p)|
    """

    A: np.ndarray
    b: np.ndarray
    c: float
    Ag: np.ndarray | None
    bg: np.ndarray | None
    cg: float
    alpha: float
    gamma: float
    lam_int: float
    scale: float = 255.0
    coupled: bool = True
    grad_scheme: str = "forward"
    tv_weight: np.ndarray | None = None

    @property
    def use_grad(self) -> bool:
        return self.gamma != 0 and self.Ag is not None

    def __post_init__(self):
        # Dᵀ b_g, so that the gradient term's products stay 3-channel:
        # E_grad = ½⟨x, DᵀA_gD x⟩ − ⟨Dᵀb_g, x⟩ + c_g
        self.bgt = grad_image_adj(self.bg, self.grad_scheme) if self.use_grad else None
        # the constant part of ∇f = H x − r, H = alpha A + gamma DᵀA_gD (in place: the
        # same arithmetic as alpha·b + gamma·bgt, without a sum array and its copy)
        r = np.multiply(self.b, self.alpha)
        if self.use_grad:
            r += self.gamma * self.bgt
        self.r = r.astype(np.float32, copy=False)

    def products(self, x, out=None) -> Products:
        """``H x`` and the inner products of the energy, in one pass over memory
        (:func:`vibr.render.fused.hessian_terms`); everything the energy and its gradient
        at ``x`` need. ``out`` receives ``H x``."""
        h, dots = hessian_terms(self.A, self.Ag if self.use_grad else None, x, self.b,
                                self.bgt if self.use_grad else None, self.alpha, self.gamma,
                                self.coupled, out=out, scheme=self.grad_scheme, tv_weight=self.tv_weight)
        return Products(h, dots)

    def terms(self, x, P: Products):
        """(E_color, E_grad, TV) of x on the [0, 1] scale (unweighted by alpha, gamma, lam),
        from the products ``P`` of x."""
        xAx, bx, xGx, gx, tv = P.dots
        ec = 0.5 * xAx - bx + self.c
        eg = 0.5 * xGx - gx + self.cg if self.use_grad else 0.0
        return ec, eg, tv

    def energy(self, terms) -> float:
        ec, eg, tv = terms
        return self.alpha * ec + self.gamma * eg + self.lam_int * tv

    def grad(self, P: Products):
        """∇f = H x − r (the solver fuses it into :meth:`forward`)."""
        return P.h - self.r

    def forward(self, x, P, step, dinv=None, x_prev=None, P_prev=None, beta=0.0, out=None):
        """The forward (gradient) step ``y − step · d⁻¹ · ∇f(y)`` at ``y = x + beta (x −
        x_prev)`` from the products ``P`` of ``x`` (and ``P_prev`` of ``x_prev``), in one
        pass: the extrapolated point and its products are never stored."""
        h_prev = None if P_prev is None else P_prev.h
        return forward_step(x, P.h, self.r, step, dinv, x_prev, h_prev, beta, out=out)

    def hess_apply(self, x, out=None):
        """``H x``."""
        return self.products(x, out=out).h

    def gershgorin(self) -> np.ndarray:
        """Per-pixel upper bound ``d ≥ row-sum |H|`` (H, W) so that ``diag(d) ⪰ H``.

        The colour part is exact; for ``Dᵀ A_g D``, the row sums of |Dᵀ|·|D| are ≤ 2
        (central) or 8 (forward), bounded with the 3×3 max of the A_g row sums."""
        k = 8.0 if self.grad_scheme == "forward" else 2.0
        return row_sum_bound(self.A, self.Ag if self.use_grad else None, self.alpha, self.gamma * k)

    def lipschitz(self, n_iter: int = 15, d=None, v0=None, state=None) -> float:
        """Largest eigenvalue of ``H`` (or of ``d^{-½} H d^{-½}``) by power iteration, ×1.05
        (the iteration approaches it from below).

        ``v0`` starts the iteration (e.g. the eigenvector of a previous, similar ``H``: the
        outer re-weighting changes ``H`` little, so a few iterations then suffice); the last
        iterate is stored in ``state["v"]`` when ``state`` is a dict."""
        x = power_start(self.b.shape) if v0 is None else np.array(v0, np.float32)
        lam = 0.0
        if d is None:
            # one pass per iteration: h = H x/‖x‖ (the scale folded into alpha, gamma), the
            # Rayleigh quotient ⟨x, Hx⟩/‖x‖² and ‖h‖² come out of the same pass
            Ag = self.Ag if self.use_grad else None
            nx = dot(x, x)
            buf = np.empty_like(x)
            for _ in range(n_iter):
                sc = 1.0 / math.sqrt(max(nx, 1e-300))
                h, (xAx, xGx, hh) = hessian_power(self.A, Ag, x, self.alpha * sc, self.gamma * sc, out=buf,
                                                   scheme=self.grad_scheme)
                lam = (self.alpha * xAx + self.gamma * xGx) / max(nx, 1e-300)
                x, buf, nx = h, x, hh
        else:
            # the Hessian product alone (hessian_power: no energy terms), as hess_apply gives
            # it; the scalings and both inner products in two passes around it
            s = (1.0 / np.sqrt(d)).astype(np.float32)
            Ag = self.Ag if self.use_grad else None
            xs, y = np.empty_like(x), np.empty_like(x)
            nx = dot(x, x)
            for _ in range(n_iter):
                power_scale(x, s, nx, out=xs)  # x /= ‖x‖, xs = s x
                y, _ = hessian_power(self.A, Ag, xs, self.alpha, self.gamma, out=y, scheme=self.grad_scheme)
                lam, nx = power_unscale(y, s, x)  # y ← s y; ⟨x, y⟩, ‖y‖²
                x, y = y, x
        if state is not None:
            state["v"] = x
        return 1.05 * max(lam, 1e-12)


@dataclass
class SolveResult:
    u: np.ndarray
    energy: list = field(default_factory=list)     # total, scale² units, per iteration
    terms: list = field(default_factory=list)      # (E_color, E_grad, TV) scale² / scale units
    n_iter: int = 0
    L: float = 0.0
    n_power: int = 0          # power iterations spent on the step size
    time_s: float = 0.0
    stopped: str = ""


def _step_size(model, state, d):
    """(L, power iterations). A few power iterations: the Rayleigh quotient approaches L
    from below, and an underestimate is caught by the monotone step (a rejected plain
    step doubles L)."""
    if state is not None and "v" in state and np.shape(state["v"]) == model.b.shape:
        return model.lipschitz(n_iter=2, d=d, v0=state["v"], state=state), 2
    return model.lipschitz(n_iter=4, d=d, state=state), 4


def median(x) -> float:
    """``np.median`` of a 1-d array without NaN, from one partition (np.median partitions at
    both middle places and checks for NaN, several times slower); equal to it bit for bit
    (tested)."""
    n = x.size
    k = n // 2
    p = np.partition(x, k)
    if n % 2:
        return float(p[k])
    return float((p[:k].max() + p[k]) / 2)  # as np.mean of the two: in x's dtype, halved exactly


def _metric_and_step(model, precond: bool, d_floor: float, power_state):
    """(d, d⁻¹, L, power iterations): the diagonal metric of the variable-metric variant
    (``d ≥ row-sum|H|`` floored at ``d_floor · median(d)``; None without ``precond``) and the
    step size in that metric."""
    if not precond:
        return (None, None) + _step_size(model, power_state, None)
    d = model.gershgorin()
    pos = d[d > 0]
    floor = d_floor * (median(pos) if pos.size else 1.0)
    d = np.maximum(d, floor).astype(np.float32)
    return (d, (1.0 / d)[None]) + _step_size(model, power_state, d)


def _record(res: SolveResult, k: int, F: float, T, s2: float, scale: float, callback) -> None:
    """Append iteration ``k``'s energy and terms (scale² units, TV in scale units)."""
    res.energy.append(F * s2)
    res.terms.append((T[0] * s2, T[1] * s2, T[2] * scale))
    if callback:
        callback(k, res.energy[-1], res.terms[-1])


def fista(model: QuadraticModel, u0, *, max_iter: int = 100, tol: float = 1e-4,
          min_iter: int = 3, tv_iter: int = 5, precond: bool = False, d_floor: float = 0.05,
          prox: TVProx | None = None, callback=None, power_state: dict | None = None) -> SolveResult:
    """Minimise ``f(u) + lam_int·TV(u)`` by monotone FISTA from planar ``u0`` (C, H, W).

    Parameters
    ----------
    max_iter : int
        FISTA iterations at most.
    tol : float
        Stop when the relative energy decrease of an accepted step is below ``tol`` (the
        authors' rule, 1e-4), after ``min_iter`` iterations, or after three rejected steps
        in a row.
    tv_iter : int
        Inner dual iterations of the TV prox (warm-started).
    precond : bool
        Variable-metric FISTA with the diagonal metric ``d`` of
        :meth:`QuadraticModel.gershgorin`, floored at ``d_floor · median(d)``.
    prox : TVProx, optional
        Reuse a prox (and its dual) from a previous call (outer re-weighting).
    callback : callable, optional
        ``callback(k, energy, (E_color, E_grad, TV))`` after each iteration (scale² units).
    power_state : dict, optional
        Shared between calls on similar models (outer re-weighting): the power iteration
        for the step size then restarts from the previous eigenvector with 2 iterations
        instead of 4 from a random vector (benchmarks: 4/2 needs no more FISTA iterations
        than 6/3 on cotton and the synthetic scene; 3/1 does, through backtracking).

    Each iteration: ``z = prox_{lam/L TV}(y − ∇f(y)/L)``, accept ``z`` only if it lowers E
    (MFISTA); after an accepted step the momentum is ``y = x + (t−1)/t'(x − x_prev)``; a
    rejected step restarts it (``y = x``), and a rejected plain step (no momentum) doubles
    ``L``. The energy sequence is therefore non-increasing.
    """
    t0 = time.perf_counter()
    s2 = model.scale ** 2
    x = np.ascontiguousarray(u0, dtype=np.float32).copy()
    if prox is None:
        prox = TVProx(x.shape, model.coupled, tv_iter, weight=model.tv_weight)
    prox.n_iter = tv_iter
    d, dinv, L, n_power = _metric_and_step(model, precond, d_floor, power_state)
    # three image buffers and three product buffers rotate (x, x_prev, candidate z): after
    # an accepted step the old x_prev is free for the next candidate; nothing is
    # allocated in the loop (fresh pages cost as much as the kernels at this size)
    zin = np.empty_like(x)
    zbuf, xpbuf = np.empty_like(x), np.empty_like(x)
    hz, hxp = np.empty_like(x), np.empty_like(x)
    Px = model.products(x, out=np.empty_like(x))
    Tx = model.terms(x, Px)
    Fx = model.energy(Tx)
    res = SolveResult(u=x, L=L, n_power=n_power)
    _record(res, 0, Fx, Tx, s2, model.scale, callback)
    x_prev, P_prev = xpbuf, Products(hxp, ())
    beta = 0.0  # momentum of the next step: y = x + beta (x − x_prev)
    t = 1.0
    rejected = 0
    res.stopped = "max_iter"
    for k in range(1, max_iter + 1):
        model.forward(x, Px, 1.0 / L, None if dinv is None else dinv[0], x_prev, P_prev, beta, out=zin)
        z = prox(zin, model.lam_int / L, d=d, out=zbuf, dinv=None if dinv is None else dinv[0])
        Pz = model.products(z, out=hz)
        Tz = model.terms(z, Pz)
        Fz = model.energy(Tz)
        t_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * t * t))
        if Fz <= Fx:
            dec = Fx - Fz
            # rotate: x_prev ← x, x ← z, the old x_prev buffers take the next candidate
            zbuf, hz = x_prev, P_prev.h
            x_prev, P_prev = x, Px
            x, Px, Tx, Fx = z, Pz, Tz, Fz
            rejected = 0
            beta = (t - 1.0) / t_new
            t = t_new
            stop = k >= min_iter and dec <= tol * abs(Fx)
        else:
            rejected += 1
            if beta == 0.0:
                # a plain proximal-gradient step from x failed: 1/L is too long (L was
                # estimated from below), backtrack
                L *= 2.0
                res.L = L
            # MFISTA: x unchanged, restart the momentum
            beta, t = 0.0, 1.0
            stop = rejected >= 3
        res.n_iter = k
        _record(res, k, Fx, Tx, s2, model.scale, callback)
        if stop:
            res.stopped = "tol" if rejected == 0 else "rejected"
            break
    res.u = x
    res.time_s = time.perf_counter() - t0
    return res
