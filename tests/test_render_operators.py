"""Operators of the renderer: adjoints, the assembled 9-point stencil, the TV prox."""

import numpy as np
import pytest
import scipy.sparse as sp

from _checks import assert_quadratic_form, dottest
from vibr.render.operators import (
    Splat,
    div_bwd,
    explicit_B,
    grad_central,
    grad_central_adj,
    grad_fwd,
    stencil_apply,
    stencil_to_sparse,
)
from vibr.render.pushpull import push_pull
from vibr.render.tv import TVProx, tv_value


def _random_splat(rng, H=11, W=14, n=600):
    xy = np.c_[rng.uniform(0, W - 1, n), rng.uniform(0, H - 1, n)]
    # the edges and corners, where the bilinear cell is clamped
    xy[:6] = [[W - 1, H - 1], [0, 0], [W - 1, 0], [0, H - 1], [W - 1, 3.3], [2.7, H - 1]]
    return Splat(xy, (H, W)), xy


def test_B_matches_explicit_and_adjoint():
    rng = np.random.default_rng(0)
    s, xy = _random_splat(rng)
    H, W = s.shape
    u = rng.standard_normal((H, W, 3))
    v = rng.standard_normal((s.n, 3))
    Bm = explicit_B(s)
    assert Bm.shape == (s.n, H * W)
    np.testing.assert_allclose(Bm.sum(1).A.ravel(), 1.0, atol=1e-12)  # partition of unity
    Bu = s.apply(u)
    np.testing.assert_allclose(Bu, Bm @ u.reshape(-1, 3), atol=1e-12)
    np.testing.assert_allclose(s.adjoint(v).reshape(-1, 3), Bm.T @ v, atol=1e-12)  # Bᵀ, explicitly
    # bilinear interpolation of a linear function is exact (up to the fractions' float32:
    # 3e-8 px each)
    lin = (2 * np.arange(W)[None, :] - 3 * np.arange(H)[:, None]).astype(float)
    np.testing.assert_allclose(s.apply(lin), 2 * xy[:, 0] - 3 * xy[:, 1], atol=2e-7)
    dottest(s.apply, s.adjoint, (H, W, 3), (s.n, 3), rng=rng)  # <Bu, v> = <u, Bᵀv>


def test_stencil_equals_sparse_normal_operator():
    """Σ_k B_kᵀ W_k B_k assembled as a 9-point stencil == the explicit sparse product."""
    rng = np.random.default_rng(1)
    H, W = 9, 12
    parts, ws = [], []
    for k in range(3):  # three random "warps"
        s, _ = _random_splat(rng, H, W, 300 + 50 * k)
        parts.append(s)
        ws.append(rng.uniform(0.1, 3.0, s.n))
    A_st = sum(s.normal(w, np.zeros(s.n))[0] for s, w in zip(parts, ws))
    A_sp = sum(explicit_B(s).T @ sp.diags(w) @ explicit_B(s) for s, w in zip(parts, ws))
    assert abs(stencil_to_sparse(A_st) - A_sp).max() < 1e-12 * abs(A_sp).max()
    u = rng.standard_normal((2, H, W))
    got = stencil_apply(A_st.astype(np.float32), u.astype(np.float32))
    want = (A_sp @ u.reshape(2, -1).T).T.reshape(2, H, W)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5 * abs(want).max())


def test_quadratic_form_equals_weighted_residual():
    rng = np.random.default_rng(2)
    s, _ = _random_splat(rng)
    assert_quadratic_form(s, rng.uniform(0, 2, s.n), rng)


@pytest.mark.parametrize("H,W", [(7, 9), (1, 5), (6, 1)])
def test_gradient_adjoints(H, W):
    rng = np.random.default_rng(3)
    # div = -∇ᵀ
    dottest(grad_fwd, lambda g: -div_bwd(g), (3, H, W), (3, 2, H, W), rng=rng)
    # central differences and their adjoint
    dottest(grad_central, grad_central_adj, (3, H, W), (3, 2, H, W), rng=rng)


def test_central_gradient_of_a_ramp():
    H, W = 6, 8
    u = (0.5 * np.arange(W)[None, :] + 0.25 * np.arange(H)[:, None])[None].astype(np.float64)
    g = grad_central(u)
    np.testing.assert_allclose(g[0, 0, :, 1:-1], 0.5)
    np.testing.assert_allclose(g[0, 1, 1:-1, :], 0.25)


def test_gradient_term_operator_adjoint():
    """The gradient term's operator u ↦ B D u (per channel and axis) and its adjoint
    Dᵀ Bᵀ, as the solver uses them (stencil of Bᵀ C B on D u)."""
    rng = np.random.default_rng(4)
    s, _ = _random_splat(rng)
    H, W = s.shape
    u = rng.standard_normal((3, H, W))

    def fwd(u):
        Du = grad_central(u).reshape(6, H, W)
        return s.apply(Du.transpose(1, 2, 0))

    def adj(r):
        g = s.adjoint(r).transpose(2, 0, 1).reshape(3, 2, H, W)
        return grad_central_adj(np.ascontiguousarray(g))

    dottest(fwd, adj, (3, H, W), (s.n, 6), rng=rng)
    # and the stencil form: Dᵀ (Bᵀ C B) D u == adj(C · fwd(u))
    C = rng.uniform(0.5, 2, s.n)
    Ag, _, _ = s.normal(C, np.zeros(s.n))
    Du = grad_central(u).reshape(6, H, W)
    st = grad_central_adj(stencil_apply(Ag, Du).reshape(3, 2, H, W))
    np.testing.assert_allclose(st, adj(C[:, None] * fwd(u)), atol=1e-10)


@pytest.mark.parametrize("coupled", [True, False])
def test_tv_prox_minimises_rof(coupled):
    rng = np.random.default_rng(5)
    z = rng.standard_normal((3, 12, 10)).astype(np.float32)
    mu = 0.3
    x = TVProx(z.shape, coupled, n_iter=400)(z, mu)

    def F(x):
        return 0.5 * np.sum((x.astype(np.float64) - z) ** 2) + mu * tv_value(x, coupled)

    fx = F(x)
    assert fx < F(z)
    for _ in range(20):  # x is (near) optimal: random perturbations do not lower F
        assert F(x + 1e-2 * rng.standard_normal(x.shape).astype(np.float32)) > fx - 1e-4


def test_weighted_tv_prox_reduces_to_plain_with_unit_metric():
    rng = np.random.default_rng(6)
    z = rng.standard_normal((3, 8, 9)).astype(np.float32)
    a = TVProx(z.shape, True, 100)(z, 0.2)
    b = TVProx(z.shape, True, 100)(z, 0.2, d=np.ones((8, 9)))
    np.testing.assert_allclose(a, b, atol=1e-5)


def test_push_pull_leaves_no_hole():
    rng = np.random.default_rng(7)
    H, W = 37, 53
    w = np.zeros((H, W))
    S = np.zeros((H, W, 3))
    idx = rng.choice(H * W, 40, replace=False)  # 2 % of the pixels observed
    w.flat[idx] = rng.uniform(1, 3, 40)
    col = rng.uniform(0.2, 0.8, (40, 3))
    S.reshape(-1, 3)[idx] = col * w.flat[idx][:, None]
    out = push_pull(S, w)
    assert out.shape == (H, W, 3) and np.all(np.isfinite(out))
    assert out.min() >= 0.2 - 1e-6 and out.max() <= 0.8 + 1e-6  # a convex fill: no hole, no overshoot
    np.testing.assert_allclose(out.reshape(-1, 3)[idx], col, atol=1e-6)  # observed pixels kept


def _fgp_reference(z, p, mu, n, coupled, d):
    """Beck & Teboulle's FGP on the dual, plainly in numpy (float64), warm-started at p."""
    dinv = np.ones(z.shape[1:]) if d is None else 1.0 / d
    step = 1.0 / (8.0 * mu * dinv.max())
    r, p_prev, t = p.copy(), p.copy(), 1.0
    for _ in range(n):
        x = z + mu * dinv * div_bwd(r)
        q = r + step * grad_fwd(x)
        nrm = np.sqrt((q ** 2).sum((0, 1)))[None, None] if coupled else np.sqrt((q ** 2).sum(1))[:, None]
        p_new = q / np.maximum(1.0, nrm)
        t_new = 0.5 * (1 + np.sqrt(1 + 4 * t * t))
        r = p_new + (t - 1) / t_new * (p_new - p_prev)
        p_prev, t = p_new, t_new
    return z + mu * dinv * div_bwd(p_prev), p_prev


@pytest.mark.parametrize("coupled", [True, False])
@pytest.mark.parametrize("weighted", [False, True])
def test_tv_prox_banded_kernels_match_plain_fgp(coupled, weighted):
    """The banded, fused dual steps (several bands of rows, halo rows, the primal folded
    into the last step, warm starts across calls, in-place output) follow the textbook
    iteration."""
    rng = np.random.default_rng(8)
    shape = (3, 97, 41)
    d = rng.uniform(0.5, 2.0, shape[1:]) if weighted else None
    prox = TVProx(shape, coupled, n_iter=1)
    p = np.zeros((3, 2) + shape[1:])
    for n in (1, 2, 3, 2):
        z = rng.uniform(0, 1, shape).astype(np.float32)
        want, p = _fgp_reference(z.astype(np.float64), p, 0.05, n, coupled, d)
        out = z.copy() if n == 3 else None  # n = 3: in place
        got = prox(out if out is not None else z, 0.05, d=d, out=out, n_iter=n)
        np.testing.assert_allclose(got, want, atol=2e-5)
        np.testing.assert_allclose(prox.p, p, atol=2e-5)


def test_samples_in_block_order_need_no_row_order():
    """Samples already in block order (as compute_samples returns them) get an empty row
    order, read as the identity; the operator and its normal equations are those of the
    same samples in any order, permuted."""
    rng = np.random.default_rng(5)
    s, xy = _random_splat(rng)
    H, W = s.shape
    assert s.order.size == s.n  # random order: the counting sort's permutation
    key = s.by0.astype(np.int64) * W + s.bx0
    perm = np.argsort(key, kind="stable")
    t = Splat(xy[perm], (H, W))
    assert t.order.size == 0
    np.testing.assert_array_equal(t.starts, s.starts)
    u = rng.standard_normal((H, W, 3))
    np.testing.assert_allclose(t.apply(u), s.apply(u)[perm], atol=1e-12)
    w = rng.uniform(0.1, 2.0, s.n)
    v = rng.standard_normal((s.n, 3))
    A1, b1, c1 = s.normal(w, v)
    A2, b2, c2 = t.normal(w[perm], v[perm])
    np.testing.assert_allclose(A2, A1, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(b2, b1, rtol=1e-12, atol=1e-12)
    assert c2 == pytest.approx(c1, rel=1e-12)
    dottest(t.apply, t.adjoint, (H, W, 3), (t.n, 3), rng=rng)


@pytest.mark.parametrize("n", [0, 1, 7, 1000, 64 * 37 + 5])
def test_bucket_by_cell_parallel_check_equals_the_counting_sort(n):
    """The samples' row buckets: the parallel order check with binary searches gives the
    counting sort's (order, starts) for sorted samples, and falls back to it otherwise,
    also when the one inversion sits at a chunk boundary of the check."""
    from vibr.render.operators import _bucket_by_cell, bucket_by_cell

    rng = np.random.default_rng(n)
    H, W = 13, 17
    x0 = rng.integers(0, W - 1, n).astype(np.int32)
    y0 = rng.integers(0, H - 1, n).astype(np.int32)
    key = np.argsort(y0.astype(np.int64) * W + x0, kind="stable")
    cases = [(x0, y0), (x0[key], y0[key])]
    if n > 64:
        xs, ys = x0[key].copy(), y0[key].copy()
        b = (n + 63) // 64  # the check's chunk length: swap across the first boundary
        xs[b - 1], xs[b], ys[b - 1], ys[b] = W - 2, 0, H - 2, 0
        cases.append((xs, ys))
    for xa, ya in cases:
        order, starts = bucket_by_cell(xa, ya, H - 1, W)
        want_order, want_starts = _bucket_by_cell(xa, ya, H - 1, W)
        np.testing.assert_array_equal(order, want_order)
        np.testing.assert_array_equal(starts, want_starts)
        assert starts.dtype == want_starts.dtype
