"""The one-pass kernels of the FISTA iteration equal the operators they fuse."""

import math

import numpy as np
import pytest

from vibr.render.fused import forward_step, hessian_power, hessian_terms, power_start, row_sum_bound
from vibr.render.operators import grad_image, grad_image_adj, stencil_apply, stencil_to_sparse
from vibr.render.tv import tv_value

SHAPES = [(1, 1), (1, 5), (2, 2), (3, 1), (5, 3), (7, 9), (24, 24), (25, 31), (50, 49), (97, 13)]


def _reference(A, Ag, x, alpha, gamma, scheme="forward"):
    x64 = x.astype(np.float64)
    C, H, W = x.shape
    Ax = stencil_apply(A.astype(np.float64), x64)
    Dx = grad_image(x64, scheme)
    G = grad_image_adj(stencil_apply(Ag.astype(np.float64), Dx.reshape(2 * C, H, W)).reshape(C, 2, H, W),
                       scheme)
    return Ax, G, alpha * Ax + gamma * G


@pytest.mark.parametrize("H,W", SHAPES)
@pytest.mark.parametrize("coupled", [True, False])
@pytest.mark.parametrize("gamma,scheme", [(0.0, "forward"), (1.7, "forward"), (1.7, "central")])
def test_hessian_terms_equals_the_composition(H, W, coupled, gamma, scheme):
    """h = alpha·Ax + gamma·DᵀA_gDx and the energy's inner products, bands and borders
    included (H = 97 spans several bands of rows)."""
    rng = np.random.default_rng(H * 100 + W)
    A, Ag = (rng.standard_normal((9, H, W)).astype(np.float32) for _ in range(2))
    x, b, bgt = (rng.standard_normal((3, H, W)).astype(np.float32) for _ in range(3))
    h, (xAx, bx, xGx, gx, tv) = hessian_terms(A, Ag if gamma else None, x, b, bgt, 0.7, gamma, coupled,
                                              scheme=scheme)
    Ax, G, want = _reference(A, Ag, x, 0.7, gamma, scheme)
    np.testing.assert_allclose(h, want, atol=1e-5 * np.abs(want).max())
    x64 = x.astype(np.float64)
    tol = 1e-5 * x.size
    assert abs(xAx - (x64 * Ax).sum()) < tol
    assert abs(bx - (x64 * b).sum()) < tol
    assert abs(xGx - ((x64 * G).sum() if gamma else 0.0)) < tol
    assert abs(gx - ((x64 * bgt).sum() if gamma else 0.0)) < tol
    assert abs(tv - tv_value(x, coupled)) < 1e-4 * max(1.0, tv)
    h2, (pAx, pGx, hh) = hessian_power(A, Ag if gamma else None, x, 0.7, gamma, scheme=scheme)
    np.testing.assert_array_equal(h2, h)
    assert abs(pAx - xAx) < tol and abs(pGx - xGx) < tol
    assert abs(hh - (h.astype(np.float64) ** 2).sum()) < 1e-5 * max(1.0, hh)


@pytest.mark.parametrize("H,W", [(2, 3), (7, 9), (40, 37)])
def test_preconditioned_power_iteration_equals_the_numpy_steps(H, W):
    """The preconditioned power iteration's fused passes (power_scale, power_unscale) give
    the step size of its numpy formulation bit for bit, and leave the same vector."""
    from _checks import random_model
    from vibr.render.operators import dot

    model, _ = random_model(H, W, 4, 3, gamma=0.5)
    d = model.gershgorin() + np.float32(0.1)
    state = {}
    L = model.lipschitz(n_iter=5, d=d, state=state)
    x = power_start(model.b.shape)
    s = (1.0 / np.sqrt(d))[None].astype(np.float32)
    for _ in range(5):
        x /= math.sqrt(max(dot(x, x), 1e-300))  # a Python float: divides in float32
        y, _ = hessian_power(model.A, model.Ag, x * s, model.alpha, model.gamma)
        y *= s
        lam = dot(x, y)
        x = y
    assert L == 1.05 * lam
    np.testing.assert_array_equal(state["v"], x)


def test_forward_step():
    rng = np.random.default_rng(0)
    x, xp, hx, hxp, r = (rng.standard_normal((3, 17, 9000 // 17)).astype(np.float32) for _ in range(5))
    d = rng.uniform(0.5, 2.0, x.shape[1:]).astype(np.float32)
    for beta, dinv in [(0.0, None), (0.6, None), (0.6, d)]:
        y = x + beta * (x - xp)
        hy = hx + beta * (hx - hxp)
        s = 0.3 * (1.0 if dinv is None else dinv[None])
        np.testing.assert_allclose(forward_step(x, hx, r, 0.3, dinv, xp, hxp, beta), y - s * (hy - r),
                                   atol=1e-5)


def test_power_iteration_finds_the_largest_eigenvalue():
    """The one-pass power iteration of QuadraticModel.lipschitz against scipy's eigsh on
    the explicit colour stencil."""
    import scipy.sparse.linalg as spl

    from _checks import random_model

    H, W = 20, 23
    model, A = random_model(H, W, 4, 5)
    lam_max = spl.eigsh(stencil_to_sparse(A), k=1, which="LA")[0][0]
    assert abs(model.lipschitz(n_iter=300) / 1.05 - lam_max) < 1e-3 * lam_max
    v = power_start((3, H, W))
    assert v.dtype == np.float32 and abs(v.mean()) < 0.05 and 0.2 < v.std() < 0.4


@pytest.mark.parametrize("H,W", SHAPES)
@pytest.mark.parametrize("with_grad", [True, False])
def test_row_sum_bound_equals_numpy_and_scipy(H, W, with_grad):
    """The compiled Gershgorin bound of the preconditioner is bit-identical to its numpy /
    scipy statement: alpha·Σ|A| + gamma_k·maximum_filter(Σ|Ag|, 3, nearest)."""
    from scipy.ndimage import maximum_filter

    rng = np.random.default_rng(H * 7 + W)
    A, Ag = (rng.standard_normal((9, H, W)).astype(np.float32) for _ in range(2))
    def abs_sum(S):  # in stencil order (numpy's axis-0 sum, except on 1-pixel images)
        out = np.abs(S[0])
        for k in range(1, 9):
            out = out + np.abs(S[k])
        return out

    want = 0.7 * abs_sum(A)
    if with_grad:
        want = want + 0.3 * 8.0 * maximum_filter(abs_sum(Ag), size=3, mode="nearest")
    got = row_sum_bound(A, Ag if with_grad else None, 0.7, 0.3 * 8.0)
    assert got.dtype == np.float32 and np.array_equal(got, want.astype(np.float32))
