"""Checks shared by several test modules (imported as a plain module: pytest puts this
folder on sys.path)."""

import contextlib
import logging

import numpy as np

from vibr.render.operators import stencil_apply


@contextlib.contextmanager
def messages_logged(name: str, level: int = logging.WARNING):
    """The messages logger ``name`` logs at ``level`` or above inside the block (a list,
    filled as they come): a handler of its own, since the CLI's tests stop the "vibr"
    logger's propagation to pytest's capture; the logger's level is lowered to ``level``
    for the block when it was higher."""
    seen = []
    handler = logging.Handler(level)
    handler.emit = lambda record: seen.append(record.getMessage())
    lg = logging.getLogger(name)
    before = lg.level
    lg.addHandler(handler)
    if not lg.isEnabledFor(level):
        lg.setLevel(level)
    try:
        yield seen
    finally:
        lg.removeHandler(handler)
        lg.setLevel(before)


def assert_quadratic_form(s, w, rng):
    """``½⟨u, Au⟩ − ⟨b, u⟩ + c`` from ``s.normal(w, v)`` equals ``½ Σ w |Bu − v|²``."""
    H, W = s.shape
    v = rng.standard_normal((s.n, 3))
    A, b, c = s.normal(w, v)
    u = rng.standard_normal((3, H, W))
    direct = 0.5 * np.sum(w[:, None] * (s.apply(u.transpose(1, 2, 0)) - v) ** 2)
    quad = 0.5 * np.sum(u * stencil_apply(A, u)) - np.sum(b * u) + c
    assert abs(direct - quad) < 1e-9 * direct


def dottest(forward, adjoint, x_shape, y_shape, *, rng=None, tol: float = 1e-10,
            complex_input: bool = False, raise_error: bool = True) -> bool:
    """Dot test of a linear operator and its adjoint (after pylops.utils.dottest).

    Draws random ``x`` (shape ``x_shape``) and ``y`` (shape ``y_shape``), standard normal
    (complex with independent real and imaginary parts when ``complex_input``), and checks

        |⟨A x, y⟩ − ⟨x, Aᴴ y⟩| ≤ tol · (‖A x‖ ‖y‖ + ‖x‖ ‖Aᴴ y‖),

    with ``⟨a, b⟩ = Σ conj(b) a``. The scale on the right bounds both inner products
    (Cauchy–Schwarz), so the test does not pass by accident when ⟨A x, y⟩ is near 0 and
    does not fail on float round-off when it is large. ``forward(x)`` and ``adjoint(y)``
    are callables; pass ``tol`` ≈ 1e-5 for float32 operators.

    Returns True when the identity holds; otherwise raises AssertionError (with the two
    inner products) when ``raise_error``, else returns False.
    """
    rng = np.random.default_rng(0) if rng is None else rng

    def draw(shape):
        a = rng.standard_normal(shape)
        return a + 1j * rng.standard_normal(shape) if complex_input else a

    x, y = draw(x_shape), draw(y_shape)
    Ax, Aty = np.asarray(forward(x)), np.asarray(adjoint(y))
    if Ax.shape != tuple(y_shape) or Aty.shape != tuple(x_shape):
        raise AssertionError(f"dottest: A maps {x_shape} to {Ax.shape} (expected {tuple(y_shape)}), "
                             f"Aᴴ maps {y_shape} to {Aty.shape} (expected {tuple(x_shape)})")
    lhs = np.vdot(y, Ax)  # ⟨Ax, y⟩
    rhs = np.vdot(Aty, x)  # ⟨x, Aᴴy⟩
    scale = np.linalg.norm(Ax) * np.linalg.norm(y) + np.linalg.norm(x) * np.linalg.norm(Aty)
    ok = bool(abs(lhs - rhs) <= tol * max(scale, np.finfo(float).tiny))
    if not ok and raise_error:
        raise AssertionError(f"dottest failed: <Ax, y> = {lhs}, <x, A^H y> = {rhs}, "
                             f"|difference| = {abs(lhs - rhs):.3e} > {tol:g} * {scale:.3e}")
    return ok


def random_model(H, W, per_pixel, seed, gamma=0.0, scheme="forward"):
    """A :class:`vibr.render.solver.QuadraticModel` of random samples (``per_pixel`` per
    target pixel, uniform positions, random weights and colours) on an H × W target: the
    colour term, and with ``gamma`` the gradient term at unit weights. Returns
    ``(model, A)``, ``A`` the colour stencil in float64."""
    from vibr.render.operators import Splat
    from vibr.render.solver import QuadraticModel

    rng = np.random.default_rng(seed)
    n = per_pixel * H * W
    s = Splat(np.c_[rng.uniform(0, W - 1, n), rng.uniform(0, H - 1, n)], (H, W))
    A, b, c = s.normal(rng.uniform(0.2, 1.0, s.n), rng.uniform(0, 1, (s.n, 3)))
    Ag = bg = None
    cg = 0.0
    if gamma:
        Ag, bg, cg = s.normal(np.ones(s.n), rng.normal(0, 0.1, (s.n, 6)))
        Ag, bg = Ag.astype(np.float32), bg.reshape(3, 2, H, W).astype(np.float32)
    model = QuadraticModel(A.astype(np.float32), b.astype(np.float32), c, Ag, bg, cg, 1.0, gamma, 0.01,
                           grad_scheme=scheme)
    return model, A
