"""FISTA for the energy of METHOD §5 (paper §4.2-4.4, eq. energy_final).

    E(u) = alpha · E_color(u) + gamma · E_grad(u) + lam · TV(u)

    E_color = ½ Σ_k Σ_m W_km ((B_k u)(m) − v_k(m))²
    E_grad  = ½ Σ_k Σ_m C_km ‖(B_k D u)(m) − ∇v_k(m)‖²       (paper eq. poor_assumption)

The smooth part is quadratic: ``f(u) = ½⟨u, Hu⟩ − ⟨r, u⟩ + c`` with
``H = alpha·A + gamma·Dᵀ A_g D``, ``A = Σ BᵀWB`` and ``A_g = Σ BᵀCB`` two 9-point stencils
(:mod:`vibr.render.operators`) assembled once per weight update. The solver is the
monotone FISTA (MFISTA, Beck & Teboulle 2009, IEEE TIP 18(11)) with the TV proximal step of
:class:`~vibr.render.tv.TVProx` (warm-started dual). Because ``f`` is quadratic, the
products ``(A x, DᵀA_g D x)`` are linear in ``x``: the extrapolated point's products are the
same combination of stored products, so each iteration costs one stencil pair, and the
forward step at the extrapolated point is computed in one pass from the stored iterates
(:meth:`QuadraticModel.forward`) without storing that point.

**Intensity scale.** Images are [0, 1]; the parameters refer to intensities on the scale
``s`` (default 255). The energy is ``s²·E`` of the [0, 1] image, so the TV weight inside is
``lam / s`` and the reported energies are in ``s²`` units (what the same energy would read
with [0, s] images).

``precond=True`` runs the variable-metric variant (the authors' diagonal preconditioner,
METHOD §10): gradient step divided per pixel by ``d ≥ row-sum|H|`` (floored where few
samples land, which raises lambda there) and the TV prox taken in the same metric
(weighted ROF), the step from a power iteration on ``d^{-½} H d^{-½}``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from numba import njit, prange

from .operators import grad_central, grad_central_adj, stencil_apply, dot
from .tv import TVProx, tv_value

__all__ = ["QuadraticModel", "SolveResult", "fista"]


# ---------------------------------------------------------------- fused element-wise kernels
# One pass over memory each; these run once or more per FISTA iteration.
@njit(parallel=True, cache=True, fastmath=True)
def _dots4_kernel(x, a, b, c, d):
    n = x.shape[0]
    nb = 64
    chunk = (n + nb - 1) // nb
    parts = np.zeros((nb, 4))
    for k in prange(nb):
        s0 = s1 = s2 = s3 = 0.0
        for i in range(k * chunk, min(n, (k + 1) * chunk)):
            xi = np.float64(x[i])
            s0 += xi * a[i]
            s1 += xi * b[i]
            s2 += xi * c[i]
            s3 += xi * d[i]
        parts[k, 0] = s0
        parts[k, 1] = s1
        parts[k, 2] = s2
        parts[k, 3] = s3
    return parts.sum(0)


def _dots4(x, a, b, c, d):
    """(⟨x,a⟩, ⟨x,b⟩, ⟨x,c⟩, ⟨x,d⟩) in float64, one pass."""
    r = _dots4_kernel(x.ravel(), a.ravel(), b.ravel(), c.ravel(), d.ravel())
    return float(r[0]), float(r[1]), float(r[2]), float(r[3])


@njit(parallel=True, cache=True, fastmath=True)
def _axpby_kernel(a, x, b, y, out):
    for i in prange(x.shape[0]):
        out[i] = a * x[i] + b * y[i]


def _axpby(a, x, b, y):
    """a·x + b·y (same shape, float32)."""
    out = np.empty_like(x)
    _axpby_kernel(np.float32(a), x.ravel(), np.float32(b), y.ravel(), out.ravel())
    return out


@njit(parallel=True, cache=True, fastmath=True)
def _forward_kernel(x, xp, Ax, Axp, Gx, Gxp, r, beta, alpha, gamma, dinv, step, out):
    """Forward step at the extrapolated point y = x + beta (x − x_prev), whose products are
    the same combination of the stored ones (f is quadratic):
    out = y − step · d⁻¹ · (alpha·Ay + gamma·Gy − r); planar (C, n); dinv (n,) or empty."""
    C, n = x.shape
    use_d = dinv.shape[0] == n
    for i in prange(n):
        s = step * dinv[i] if use_d else step
        for c in range(C):
            y = x[c, i] + beta * (x[c, i] - xp[c, i])
            ay = Ax[c, i] + beta * (Ax[c, i] - Axp[c, i])
            gy = Gx[c, i] + beta * (Gx[c, i] - Gxp[c, i])
            out[c, i] = y - s * (alpha * ay + gamma * gy - r[c, i])


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

    @property
    def use_grad(self) -> bool:
        return self.gamma != 0 and self.Ag is not None

    def __post_init__(self):
        # Dᵀ b_g, so that the gradient term's products stay 3-channel:
        # E_grad = ½⟨x, DᵀA_gD x⟩ − ⟨Dᵀb_g, x⟩ + c_g
        self.bgt = grad_central_adj(self.bg) if self.use_grad else None
        # the constant part of ∇f = alpha A x + gamma DᵀA_gD x − r
        self.r = self.alpha * self.b if not self.use_grad else _axpby(self.alpha, self.b, self.gamma, self.bgt)

    def products(self, x):
        """(A x, DᵀA_g D x): everything the energy and its gradient need, linear in x."""
        Ax = stencil_apply(self.A, x)
        if not self.use_grad:
            return (Ax, None)
        Dx = grad_central(x)
        C, _, H, W = Dx.shape
        AgDx = stencil_apply(self.Ag, Dx.reshape(2 * C, H, W)).reshape(Dx.shape)
        return (Ax, grad_central_adj(AgDx))

    def terms(self, x, P):
        """(E_color, E_grad, TV) of x on the [0, 1] scale (unweighted by alpha, gamma, lam)."""
        Ax, Gx = P
        if self.use_grad:
            xAx, bx, xGx, gx = _dots4(x, Ax, self.b, Gx, self.bgt)
            eg = 0.5 * xGx - gx + self.cg
        else:
            xAx, bx, _, _ = _dots4(x, Ax, self.b, Ax, self.b)
            eg = 0.0
        ec = 0.5 * xAx - bx + self.c
        return ec, eg, tv_value(x, self.coupled)

    def energy(self, terms) -> float:
        ec, eg, tv = terms
        return self.alpha * ec + self.gamma * eg + self.lam_int * tv

    def grad(self, P):
        """∇f from the products of the point: alpha (Ax − b) + gamma (DᵀA_g D x − Dᵀb_g)
        (the solver fuses it into :meth:`forward`)."""
        Ax, Gx = P
        h = _axpby(self.alpha, Ax, self.gamma, Gx) if self.use_grad else self.alpha * Ax
        return h - self.r

    def forward(self, x, P, step, dinv=None, x_prev=None, P_prev=None, beta=0.0):
        """The forward (gradient) step ``y − step · d⁻¹ · ∇f(y)`` at ``y = x + beta (x −
        x_prev)`` from the products ``P`` of ``x`` (and ``P_prev`` of ``x_prev``), in one
        pass: the extrapolated point and its products are never stored."""
        if x_prev is None or beta == 0.0:
            x_prev, P_prev, beta = x, P, 0.0
        Ax, Gx = P
        Axp, Gxp = P_prev
        if not self.use_grad:
            Gx = Gxp = Ax
        C = x.shape[0]
        flat = lambda a: a.reshape(C, -1)  # noqa: E731
        out = np.empty_like(x)
        d = np.zeros(0, np.float32) if dinv is None else np.ascontiguousarray(dinv, np.float32).ravel()
        g = self.gamma if self.use_grad else 0.0
        _forward_kernel(flat(x), flat(x_prev), flat(Ax), flat(Axp), flat(Gx), flat(Gxp), flat(self.r),
                        np.float32(beta), np.float32(self.alpha), np.float32(g), d, np.float32(step),
                        flat(out))
        return out

    def hess_apply(self, x):
        Ax, Gx = self.products(x)
        if self.use_grad:
            return _axpby(self.alpha, Ax, self.gamma, Gx)
        return self.alpha * Ax

    def gershgorin(self) -> np.ndarray:
        """Per-pixel upper bound ``d ≥ row-sum |H|`` (H, W) so that ``diag(d) ⪰ H``.

        The colour part is exact; for ``Dᵀ A_g D``, ‖D‖² ≤ 2 per axis pair, bounded with the
        3×3 max of the A_g row sums."""
        d = self.alpha * np.abs(self.A).sum(0)
        if self.use_grad:
            from scipy.ndimage import maximum_filter

            rg = np.abs(self.Ag).sum(0)
            d = d + self.gamma * 2.0 * maximum_filter(rg, size=3, mode="nearest")
        return d.astype(np.float32)

    def lipschitz(self, n_iter: int = 15, d=None, seed: int = 0, v0=None, state=None) -> float:
        """Largest eigenvalue of ``H`` (or of ``d^{-½} H d^{-½}``) by power iteration, ×1.05
        (the iteration approaches it from below).

        ``v0`` starts the iteration (e.g. the eigenvector of a previous, similar ``H``: the
        outer re-weighting changes ``H`` little, so a few iterations then suffice); the last
        iterate is stored in ``state["v"]`` when ``state`` is a dict."""
        if v0 is None:
            rng = np.random.default_rng(seed)
            x = rng.standard_normal(self.b.shape).astype(np.float32)
        else:
            x = np.array(v0, np.float32)
        s = None if d is None else (1.0 / np.sqrt(d))[None].astype(np.float32)
        lam = 0.0
        for _ in range(n_iter):
            x /= math.sqrt(max(dot(x, x), 1e-300))
            y = self.hess_apply(x * s if s is not None else x)
            if s is not None:
                y *= s
            lam = dot(x, y)
            x = y
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
        prox = TVProx(x.shape, model.coupled, tv_iter)
    prox.n_iter = tv_iter
    d = dinv = None
    if precond:
        d = model.gershgorin()
        pos = d[d > 0]
        floor = d_floor * (float(np.median(pos)) if pos.size else 1.0)
        d = np.maximum(d, floor).astype(np.float32)
        dinv = (1.0 / d)[None]
        L, n_power = _step_size(model, power_state, d)
    else:
        L, n_power = _step_size(model, power_state, None)
    Px = model.products(x)
    Tx = model.terms(x, Px)
    Fx = model.energy(Tx)
    res = SolveResult(u=x, L=L, n_power=n_power)
    res.energy.append(Fx * s2)
    res.terms.append((Tx[0] * s2, Tx[1] * s2, Tx[2] * model.scale))
    if callback:
        callback(0, res.energy[-1], res.terms[-1])
    x_prev, P_prev = x, Px
    beta = 0.0  # momentum of the next step: y = x + beta (x − x_prev)
    t = 1.0
    rejected = 0
    res.stopped = "max_iter"
    for k in range(1, max_iter + 1):
        zin = model.forward(x, Px, 1.0 / L, None if dinv is None else dinv[0], x_prev, P_prev, beta)
        z = prox(zin, model.lam_int / L, d=d) if precond else prox(zin, model.lam_int / L)
        Pz = model.products(z)
        Tz = model.terms(z, Pz)
        Fz = model.energy(Tz)
        t_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * t * t))
        if Fz <= Fx:
            dec = Fx - Fz
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
        res.energy.append(Fx * s2)
        res.terms.append((Tx[0] * s2, Tx[1] * s2, Tx[2] * model.scale))
        res.n_iter = k
        if callback:
            callback(k, res.energy[-1], res.terms[-1])
        if stop:
            res.stopped = "tol" if rejected == 0 else "rejected"
            break
    res.u = x
    res.time_s = time.perf_counter() - t0
    return res
