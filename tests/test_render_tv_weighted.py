"""Spatially varying TV (docs/explanation/method.md §10): the weighted prox, the weighted energy, the
weight map and the solver's monotone energy with it on."""

import numpy as np
import pytest

from vibr.render.fused import hessian_terms
from vibr.render.operators import Splat
from vibr.render.solver import QuadraticModel, fista
from vibr.render.tv import TVProx, tv_value
from vibr.render.variational import tv_weight_map


def test_weighted_tv_value_and_prox_match_uniform_scaling():
    """A constant weight k is the plain TV times k: value, and prox of mu equals prox of k·mu."""
    rng = np.random.default_rng(0)
    z = rng.random((3, 12, 13)).astype(np.float32)
    w = np.full((12, 13), 2.5, np.float32)
    for coupled in (True, False):
        assert abs(tv_value(z, coupled, w) - 2.5 * tv_value(z, coupled)) < 1e-4 * tv_value(z, coupled)
        a = TVProx(z.shape, coupled, 150, weight=w)(z, 0.05)
        b = TVProx(z.shape, coupled, 150)(z, 0.125)
        np.testing.assert_allclose(a, b, atol=2e-4)


def test_weighted_prox_minimises_its_objective():
    """The weighted prox beats random perturbations of itself on ½|x − z|² + mu Σ w|∇x|."""
    rng = np.random.default_rng(1)
    z = rng.random((3, 10, 11)).astype(np.float32)
    w = rng.uniform(1, 20, (10, 11)).astype(np.float32)
    mu = 0.02
    x = TVProx(z.shape, True, 200, weight=w)(z, mu)
    f = lambda y: 0.5 * np.sum((y.astype(np.float64) - z) ** 2) + mu * tv_value(y, True, w)  # noqa: E731
    fx = f(x)
    for _ in range(20):
        assert fx <= f(x + 1e-3 * rng.standard_normal(x.shape).astype(np.float32)) + 1e-7


def test_weight_map_rule():
    acc = np.zeros((9, 9))
    acc[:, 5:] = 2.0
    w = tv_weight_map(acc, "samples", blur=0)
    assert w[0, 0] == 100 and w[0, 8] == 1 and w.min() >= 1
    assert tv_weight_map(acc, "uniform") is None
    with pytest.raises(ValueError):
        tv_weight_map(acc, "nope")


def test_fista_with_weighted_tv_energy_never_increases():
    rng = np.random.default_rng(2)
    H, W = 20, 22
    u_true = rng.uniform(0, 1, (H, W, 3)).astype(np.float32)
    xy = np.c_[rng.uniform(0, W - 1, 2 * H * W), rng.uniform(0, H - 1, 2 * H * W)]
    xy = xy[(xy[:, 0] > 6)]  # a region with no sample: the weight map rises there
    s = Splat(xy, (H, W))
    v = s.apply(u_true) + 0.02 * rng.standard_normal((s.n, 3))
    A, b, c = s.normal(np.ones(s.n), v)
    Ag, bg, cg = s.normal(np.ones(s.n), rng.standard_normal((s.n, 6)) * 0.05)
    tw = tv_weight_map(s.adjoint(np.ones(s.n)), "samples")
    assert tw.max() > 50
    model = QuadraticModel(A.astype(np.float32), b.astype(np.float32), c, Ag.astype(np.float32),
                           bg.reshape(3, 2, H, W).astype(np.float32), cg, 1.0, 0.5, 2.0 / 255, tv_weight=tw)
    u0 = rng.uniform(0, 1, model.b.shape).astype(np.float32)
    res = fista(model, u0, max_iter=80, tol=0)
    E = np.array(res.energy)
    assert len(E) > 10 and np.all(np.diff(E) <= 1e-6 * abs(E[0])) and E[-1] < 0.5 * E[0]
    # the fused energy's TV term is the weighted TV
    _, dots = hessian_terms(model.A, model.Ag, res.u, model.b, model.bgt, 1.0, 0.5, tv_weight=tw)
    assert abs(dots[4] - tv_value(res.u, True, tw)) < 1e-4 * dots[4]
