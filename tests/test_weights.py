"""Geometric weights W = omega / |det ∂tau/∂x| (docs/explanation/method.md §3)."""

import numpy as np

from vibr.geometry.samples import Samples
from vibr.render.weights import geometric_weights, luminance_gradient


def _samples(xy, dtau, sigma_z, inv_det, shape):
    n = len(xy)
    return Samples(np.asarray(xy, float), np.zeros((n, 3), np.float32), np.zeros((n, 3, 2), np.float32),
                   np.tile(np.eye(2), (n, 1, 1)), np.asarray(inv_det, float), np.asarray(dtau, float),
                   np.asarray(sigma_z, float), np.zeros(n, np.int32), np.zeros((n, 2), np.int32),
                   np.zeros((n, 3)), shape)


def test_closed_form_on_a_ramp():
    H, W = 10, 12
    slope = 0.01  # per pixel, on [0, 1] intensities → 2.55 grey levels per pixel
    u = np.repeat((slope * np.arange(W))[None, :, None], H, 0).repeat(3, 2).astype(np.float32)
    g = luminance_gradient(u)
    np.testing.assert_allclose(g[:, 1:-1, 0], slope, rtol=1e-5)
    np.testing.assert_allclose(g[..., 1], 0, atol=1e-7)
    xy = [[5.5, 4.2], [3.0, 7.0], [8.25, 1.5]]
    dtau = [[10.0, 0.0], [0.0, 10.0], [3.0, 4.0]]
    sz = [0.05, 0.05, 0.1]
    inv_det = [1.0, 0.5, 2.0]
    S = _samples(xy, dtau, sz, inv_det, (H, W))
    w = geometric_weights(S, u, sigma_s=1.0, scale=255.0, grad_max=None)
    gx = slope * 255
    proj = np.array([10 * gx, 0.0, 3 * gx])
    want = np.array(inv_det) / (1.0 + (np.array(sz) * proj) ** 2)
    np.testing.assert_allclose(w, want, rtol=1e-5)
    # the clamp caps the gradient magnitude (grey levels per pixel)
    wc = geometric_weights(S, u, sigma_s=1.0, scale=255.0, grad_max=1.0)
    np.testing.assert_allclose(wc, np.array(inv_det) / (1.0 + (np.array(sz) * np.array([10, 0, 3])) ** 2), rtol=1e-5)
    # no depth uncertainty (SAVSR): only the deformation weight over sigma_s²
    np.testing.assert_allclose(geometric_weights(S, u, sigma_s=2.0, sigma_z=0.0), np.array(inv_det) / 4)
    np.testing.assert_allclose(geometric_weights(S, None, sigma_s=1.0), inv_det)


def test_fused_assembly_equals_weights_then_normal():
    """weighted_normal (the weights computed inside the assembly) is bit-identical to
    geometric_weights → ×1/rho, ×sample_weight, ×robust factor → Splat.normal; and
    coverage_blend's stencils equal Splat.normal at unit weight, its blend the deformation
    weights' splat (bilinear and footprint PSF)."""
    from vibr.render.operators import Splat
    from vibr.render.weights import coverage_blend, weighted_normal

    rng = np.random.default_rng(3)
    H, W, n = 23, 31, 4000
    xy = np.c_[rng.uniform(0, W - 1, n), rng.uniform(0, H - 1, n)]
    inv_det = rng.uniform(0.2, 3, n)
    inv_det[::50] = np.inf
    sz = rng.uniform(0, 0.05, n)
    sz[::70] = np.nan
    S = _samples(xy, rng.normal(0, 20, (n, 2)), sz, inv_det, (H, W))
    S.colour[:] = rng.uniform(0, 1, (n, 3))
    S.grad[:] = rng.normal(0, 0.1, (n, 3, 2))
    S.jac[:] = np.eye(2) * 0.7 + rng.normal(0, 0.1, (n, 2, 2))
    S.meta["sample_weight"] = rng.uniform(0, 1, n).astype(np.float32)
    u = rng.uniform(0, 1, (H, W, 3)).astype(np.float32)
    rf = rng.uniform(0.1, 1, n).astype(np.float32)
    for psf in ("bilinear", "footprint"):
        sp = Splat(S.xy, (H, W), jac=S.jac, psf=psf)
        w = geometric_weights(S, u, 1.5, None, splat=sp, dtype=np.float32)
        w *= np.float32(1 / 2.5)
        w *= S.meta["sample_weight"]
        w *= rf
        A, b, c = sp.normal(w, S.colour, dtype=np.float32)
        A2, b2, c2, w2 = weighted_normal(S, sp, u, 1.5, None, wscale=1 / 2.5, factor=rf, keep_weights=True)
        assert np.array_equal(w, w2) and np.array_equal(A, A2) and np.array_equal(b, b2) and c == c2
        A0, g0, c0, wsum, bw = coverage_blend(S, sp, 1.5, gradient=True)
        Ar, gr, cr = sp.normal(S.meta["sample_weight"], S.grad.reshape(n, 6), dtype=np.float32)
        assert np.array_equal(A0, Ar) and np.array_equal(g0, gr) and c0 == cr
        wd = (geometric_weights(S, None, 1.5, dtype=np.float32) * S.meta["sample_weight"]).astype(np.float64)
        np.testing.assert_allclose(wsum[0], sp.adjoint(wd), rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(bw, sp.adjoint(S.colour, wd).transpose(2, 0, 1), rtol=1e-5, atol=1e-6)


def test_gradient_consistency_equals_its_formula():
    """w_m = 1 / (1 + |∇v_m − (B Ḡ)_m|² / c²), Ḡ = Bᵀ(sw ∇v) / Bᵀ sw, for both PSFs, times
    min(1, (B acc)_m / t) with min_coverage t; and coverage_blend(stencils=False) gives Bᵀ sw
    and Bᵀ (sw ∇v) in one pass."""
    from vibr.render.operators import Splat
    from vibr.render.weights import coverage_blend, gradient_consistency

    rng = np.random.default_rng(5)
    H, W, n = 17, 21, 3000
    xy = np.c_[rng.uniform(0, W - 1, n), rng.uniform(0, H - 1, n)]
    S = _samples(xy, np.zeros((n, 2)), np.zeros(n), np.ones(n), (H, W))
    S.grad[:] = rng.normal(0, 0.1, (n, 3, 2))
    S.jac[:] = np.eye(2) * 0.8 + rng.normal(0, 0.1, (n, 2, 2))
    sw = rng.uniform(0.2, 1, n).astype(np.float32)
    S.meta["sample_weight"] = sw
    g = S.grad.reshape(n, 6).astype(np.float64)
    for psf in ("bilinear", "footprint"):
        sp = Splat(S.xy, (H, W), jac=S.jac, psf=psf)
        A0, btg, _, _, _ = coverage_blend(S, sp, 1.0, gradient=True, stencils=False)
        assert A0.shape == (1, H, W)
        acc = sp.adjoint(sw.astype(np.float64))
        np.testing.assert_allclose(A0[0], acc, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(btg, sp.adjoint(g, sw.astype(np.float64)).transpose(2, 0, 1), rtol=1e-5, atol=1e-6)
        c = 0.05
        A, b, cst, w = gradient_consistency(S, sp, btg, A0[0].astype(np.float64), c)
        G = sp.adjoint(g, sw.astype(np.float64)) / np.maximum(acc, 1e-12)[..., None]
        want = 1.0 / (1.0 + np.sum((g - sp.apply(G)) ** 2, axis=1) / c ** 2)
        assert w.dtype == np.float32 and w.shape == (n,)
        np.testing.assert_allclose(w, want, rtol=2e-4)
        # the stencils assembled in the same pass are Splat.normal's with those weights
        Ar, br, cr = sp.normal(w * sw, S.grad.reshape(n, 6), dtype=np.float32)
        assert np.array_equal(A, Ar) and np.array_equal(b, br) and cst == cr
        # with the coverage factor min(1, (B acc)_m / t): t above the typical coverage, so
        # that the factor is below 1 for most samples and at 1 for some
        t = float(np.quantile(sp.apply(acc[..., None].astype(np.float32))[:, 0], 0.7))
        A, b, cst, wt = gradient_consistency(S, sp, btg, A0[0].astype(np.float64), c, min_coverage=t)
        f = np.minimum(1.0, sp.apply(A0[0][..., None].astype(np.float64))[:, 0] / t)
        assert 0.5 < np.mean(f < 1) < 0.9
        np.testing.assert_allclose(wt, want * f, rtol=2e-4)
        Ar, br, cr = sp.normal(wt * sw, S.grad.reshape(n, 6), dtype=np.float32)
        assert np.array_equal(A, Ar) and np.array_equal(b, br) and cst == cr


def test_gradient_consistency_weighs_the_dissenting_view_down():
    """Four views land on the same pixels; three agree on the gradient, one says otherwise:
    the mean is 0.05 per channel, so (closed form) the three keep 1 / (1 + 3·0.05²/c²) and
    the fourth 1 / (1 + 3·0.15²/c²), a quarter of that."""
    from vibr.render.operators import Splat
    from vibr.render.weights import coverage_blend, gradient_consistency

    H, W = 6, 6
    pts = np.array([[x + 0.5, y + 0.5] for y in range(1, 4) for x in range(1, 4)], float)
    xy = np.tile(pts, (4, 1))
    n = len(xy)
    S = _samples(xy, np.zeros((n, 2)), np.zeros(n), np.ones(n), (H, W))
    S.grad[:, :, 0] = 0.1  # 25.5 grey levels per pixel in x
    S.grad[3 * len(pts):, :, 0] = -0.1  # the fourth view's edge runs the other way
    sp = Splat(S.xy, (H, W))
    A0, btg, _, _, _ = coverage_blend(S, sp, 1.0, gradient=True, stencils=False)
    c = 24.0 / 255
    w = gradient_consistency(S, sp, btg, A0[0].astype(np.float64), c)[3]
    np.testing.assert_allclose(w[: 3 * len(pts)], 1 / (1 + 3 * 0.05 ** 2 / c ** 2), rtol=1e-5)
    np.testing.assert_allclose(w[3 * len(pts):], 1 / (1 + 3 * 0.15 ** 2 / c ** 2), rtol=1e-5)
    assert w[-1] < 0.25 * w[0]


def test_gradient_consistency_weighs_a_lone_sample_by_its_coverage():
    """Closed form: one view lands alone on a pixel centre (coverage 1: its own bilinear
    weight), four views land together on another pixel centre (coverage 4). With
    ``min_coverage`` 1.5 the lone sample weighs 1/1.5 and the four keep their consistency
    weight; with 0 (the former term) every agreeing sample weighs 1."""
    from vibr.render.operators import Splat
    from vibr.render.weights import coverage_blend, gradient_consistency

    H, W = 6, 8
    xy = np.array([[1.0, 1.0]] + [[5.0, 3.0]] * 4)  # pixel centres: integer coordinates
    n = len(xy)
    S = _samples(xy, np.zeros((n, 2)), np.zeros(n), np.ones(n), (H, W))
    S.grad[:, :, 0] = 0.1
    sp = Splat(S.xy, (H, W))
    A0, btg, _, _, _ = coverage_blend(S, sp, 1.0, gradient=True, stencils=False)
    assert A0[0][1, 1] == 1 and A0[0][3, 5] == 4
    c = 24.0 / 255
    w0 = gradient_consistency(S, sp, btg, A0[0].astype(np.float64), c)[3]
    w = gradient_consistency(S, sp, btg, A0[0].astype(np.float64), c, min_coverage=1.5)[3]
    np.testing.assert_allclose(w0, 1.0)
    np.testing.assert_allclose(w, [1 / 1.5, 1, 1, 1, 1], rtol=1e-6)


def _ramp(H, W, slope=0.01):
    """u with luminance gradient (slope·255, 0) grey levels per pixel inside."""
    return np.repeat((slope * np.arange(W))[None, :, None], H, 0).repeat(3, 2).astype(np.float32)


def test_shared_depth_error_weights_are_the_gls_weights():
    """Closed form: samples at one pixel centre (B's row picks that pixel alone) with
    misregistrations a_k = sigma_z (∂τ/∂z · ∇u) and errors a_k δ_k whose depth errors δ_k
    have correlation ρ: their weights are generalised least squares', Σ⁻¹1 with
    Σ = diag((σ_s² + (1 − ρ) a_k²) / d_k) + ρ a aᵀ (d_k = 1/|det|). With ρ = 0 they are the
    paper's d_k / (σ_s² + a_k²)."""
    H, W = 8, 10
    u = _ramp(H, W)
    gx = 0.01 * 255
    xy = [[4.0, 3.0]] * 3
    dtau = [[2.0, 0.0], [-3.0, 1.0], [0.5, 7.0]]
    sz, inv_det, s2 = [0.1, 0.1, 0.2], np.array([1.0, 0.5, 2.0]), 1.5 ** 2
    S = _samples(xy, dtau, sz, inv_det, (H, W))
    a = np.array(sz) * np.array(dtau)[:, 0] * gx
    for rho in (0.0, 0.5, 0.9):
        w = geometric_weights(S, u, sigma_s=1.5, grad_max=None, z_corr=rho)
        cov = np.diag((s2 + (1 - rho) * a ** 2) / inv_det) + rho * np.outer(a, a)
        want = np.linalg.solve(cov, np.ones(3))
        assert np.all(want > 0)  # no weight clamped at 0 in this case
        np.testing.assert_allclose(w, want, rtol=1e-5)
        if rho == 0:
            np.testing.assert_allclose(w, inv_det / (s2 + a ** 2), rtol=1e-5)
    # a cap on 1/|det| is the d_k of Σ too, in the shared error's sums as in the weights
    d = np.minimum(inv_det, 1.2)
    cov = np.diag((s2 + 0.1 * a ** 2) / d) + 0.9 * np.outer(a, a)
    w = geometric_weights(S, u, sigma_s=1.5, grad_max=None, z_corr=0.9, inv_det_cap=1.2)
    np.testing.assert_allclose(w, np.linalg.solve(cov, np.ones(3)), rtol=1e-5)


def test_shared_depth_error_balances_opposite_views():
    """Two views misregistered the opposite way by one depth error (a = +20 σ_s and −10 σ_s
    per unit of it): the paper's weights (ρ 0), 1/401 and 1/101, favour the smaller error and
    leave a first-order bias Σ w a / Σ w of about −4 σ_s per unit depth error; with ρ 0.99
    the weights cancel most of it. Two views on the same side (a = 10 and 20): the GLS
    weight of the second would be negative (an extrapolation); it is 0."""
    H, W = 8, 10
    u = _ramp(H, W)
    gx = 0.01 * 255

    def weights(a, rho):
        S = _samples([[4.0, 3.0]] * len(a), [[x / gx, 0.0] for x in a], [1.0] * len(a), [1.0] * len(a), (H, W))
        return geometric_weights(S, u, grad_max=None, z_corr=rho)

    a = np.array([20.0, -10.0])
    w0, w = weights(a, 0.0), weights(a, 0.99)
    np.testing.assert_allclose(w0, [1 / 401, 1 / 101], rtol=1e-5)
    bias0, bias = (w0 * a).sum() / w0.sum(), (w * a).sum() / w.sum()
    assert -4.0 < bias0 < -3.9 and abs(bias) < 0.1 * abs(bias0)
    w2 = weights(np.array([10.0, 20.0]), 0.99)
    assert w2[0] > 0 and w2[1] == 0


def test_fused_assembly_with_shared_depth_error():
    """weighted_normal with z_corr is bit-identical to geometric_weights(z_corr, factor)
    → ×1/rho, ×sample_weight, ×factor → Splat.normal (bilinear and footprint PSF), and
    shared_error_beta is its formula."""
    from vibr.render.operators import Splat
    from vibr.render.weights import _weight_gradient, shared_error_beta, weighted_normal

    rng = np.random.default_rng(4)
    H, W, n = 19, 27, 3000
    xy = np.c_[rng.uniform(0, W - 1, n), rng.uniform(0, H - 1, n)]
    inv_det = rng.uniform(0.2, 3, n)
    sz = rng.uniform(0, 0.05, n)
    S = _samples(xy, rng.normal(0, 20, (n, 2)), sz, inv_det, (H, W))
    S.colour[:] = rng.uniform(0, 1, (n, 3))
    S.jac[:] = np.eye(2) * 0.7 + rng.normal(0, 0.1, (n, 2, 2))
    S.meta["sample_weight"] = rng.uniform(0, 1, n).astype(np.float32)
    u = rng.uniform(0, 1, (H, W, 3)).astype(np.float32)
    rf = rng.uniform(0.1, 1, n).astype(np.float32)
    g = _weight_gradient(u, 255.0, 64.0)
    for psf in ("bilinear", "footprint"):
        sp = Splat(S.xy, (H, W), jac=S.jac, psf=psf)
        gs = sp.apply(g.astype(np.float64)) if psf == "bilinear" else None
        w = geometric_weights(S, u, 1.5, None, splat=sp, dtype=np.float32, z_corr=0.8, factor=rf)
        w *= np.float32(1 / 2.5)
        w *= S.meta["sample_weight"]
        w *= rf
        A, b, c = sp.normal(w, S.colour, dtype=np.float32)
        A2, b2, c2, w2 = weighted_normal(S, sp, u, 1.5, None, wscale=1 / 2.5, factor=rf, keep_weights=True,
                                         z_corr=0.8)
        assert np.array_equal(w, w2) and np.array_equal(A, A2) and np.array_equal(b, b2) and c == c2
        if gs is None:
            continue
        a = sz * np.sum(np.asarray(S.dtau_dz) * gs, axis=1)
        P = inv_det * S.meta["sample_weight"] * rf / (1.5 ** 2 + 0.2 * a * a)
        want = 0.8 * sp.adjoint(P * a) / (1 + 0.8 * sp.adjoint(P * a * a))
        np.testing.assert_allclose(shared_error_beta(S, sp, g, None, 1.5, 0.8, rf), want, rtol=1e-4, atol=1e-7)
        wb = geometric_weights(S, u, 1.5, None, splat=sp, z_corr=0.8, factor=rf)
        np.testing.assert_allclose(wb, inv_det / (1.5 ** 2 + 0.2 * a * a) * np.maximum(0, 1 - a * sp.apply(want)),
                                   rtol=1e-4, atol=1e-9)


def test_z_corr_is_validated():
    """z_corr is a correlation: in [0, 1]; the baselines and the paper's preset keep the
    paper's independent errors."""
    import pytest

    from vibr.errors import VibrInputError
    from vibr.render.methods import method_params

    for bad in (-0.1, 1.1, float("nan")):
        with pytest.raises(VibrInputError, match="z_corr"):
            method_params("gradient", z_corr=bad)
    assert method_params("gradient")["z_corr"] is None and method_params("bvs")["z_corr"] == 0
    assert method_params("gradient", preset="paper")["z_corr"] == 0


def test_z_corr_defaults_to_the_geometrys():
    """A proxy's samples (the plane: one depth for every view) carry PROXY_Z_CORR, per-view
    depth 0; the default (None) renders with that, bit for bit."""
    from vibr.geometry import compute_samples
    from vibr.geometry.proxy import PROXY_Z_CORR
    from vibr.pipeline import prepare
    from vibr.render import render
    from vibr.synthetic import make_scene

    sc = make_scene("arc", n_views=6, width=48, height=48, seed=2)
    t = sc.views[3].name
    src, tv = prepare(sc, t, depth="gt")
    assert compute_samples(src, tv.camera).meta["z_corr"] == 0.0
    src, tv = prepare(sc, t, depth="planar")
    S = compute_samples(src, tv.camera)
    assert S.meta["z_corr"] == PROXY_Z_CORR > 0
    img = render(src, tv.camera, "gradient", samples=S).image
    assert np.array_equal(img, render(src, tv.camera, "gradient", samples=S, z_corr=PROXY_Z_CORR).image)
    assert not np.array_equal(img, render(src, tv.camera, "gradient", samples=S, z_corr=0.0).image)


def test_uncertainty_with_the_shared_depth_error_reads_the_independent_weights(monkeypatch):
    """On a proxy (z_corr 0.9) the passes assemble the shared-error weights and σ reads the
    independent errors' weights of the last estimate, assembled once more after the solve;
    the image is the one rendered without σ, bit for bit, and σ is finite and positive where
    the samples cover."""
    import vibr.render.variational as V
    from vibr.geometry import compute_samples
    from vibr.pipeline import prepare
    from vibr.render import render
    from vibr.synthetic import make_scene

    sc = make_scene("arc", n_views=6, width=48, height=48, seed=2)
    src, tv = prepare(sc, sc.views[3].name, depth="planar")
    S = compute_samples(src, tv.camera)
    assert S.meta["z_corr"] > 0
    plain = render(src, tv.camera, "gradient", samples=S)
    calls, seen = [], []
    wn, vs = V.weighted_normal, V.variational_sigma

    def spy_wn(*a, **k):
        out = wn(*a, **k)
        calls.append((k.get("z_corr"), out[3]))
        return out

    def spy_vs(model, splat, weight, *a, **k):
        seen.append(weight)
        return vs(model, splat, weight, *a, **k)

    monkeypatch.setattr(V, "weighted_normal", spy_wn)
    monkeypatch.setattr(V, "variational_sigma", spy_vs)  # the name the solve calls
    r = render(src, tv.camera, "gradient", samples=S, uncertainty=True)
    assert [z for z, _ in calls] == [S.meta["z_corr"]] * 2 + [0.0]
    assert seen[0] is calls[-1][1]
    assert np.array_equal(r.image, plain.image)
    sig = r.uncertainty[r.coverage]
    assert sig.size and np.all(np.isfinite(sig)) and np.all(sig > 0)
    # with grad_weighting W the gradient term's stencils of σ's model read those weights too
    calls.clear()
    seen.clear()
    st, grads = V._GradientTerm.stencils, []

    def spy_st(self, Wk):
        grads.append(Wk)
        return st(self, Wk)

    monkeypatch.setattr(V._GradientTerm, "stencils", spy_st)
    render(src, tv.camera, "gradient", samples=S, uncertainty=True, grad_weighting="W")
    assert grads[-1] is calls[-1][1] is seen[0] and calls[-1][0] == 0.0
