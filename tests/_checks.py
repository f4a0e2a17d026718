"""Checks shared by several test modules (imported as a plain module: pytest puts this
folder on sys.path)."""

import numpy as np

from vibr.render.operators import stencil_apply


def assert_quadratic_form(s, w, rng):
    """``½⟨u, Au⟩ − ⟨b, u⟩ + c`` from ``s.normal(w, v)`` equals ``½ Σ w |Bu − v|²``."""
    H, W = s.shape
    v = rng.standard_normal((s.n, 3))
    A, b, c = s.normal(w, v)
    u = rng.standard_normal((3, H, W))
    direct = 0.5 * np.sum(w[:, None] * (s.apply(u.transpose(1, 2, 0)) - v) ** 2)
    quad = 0.5 * np.sum(u * stencil_apply(A, u)) - np.sum(b * u) + c
    assert abs(direct - quad) < 1e-9 * direct
