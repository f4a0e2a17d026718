"""One image gradient for both sides of the gradient term: adjoint, sources'
∇v = the operator applied to the source image (borders included), and no checkerboard."""

import numpy as np
import pytest

from vibr.camera import Camera
from vibr.geometry import compute_samples
from vibr.metrics import checkerboard_energy, speckle_density
from vibr.render.operators import GRAD_SCHEMES, grad_image, grad_image_adj
from vibr.scene import Scene, View


@pytest.mark.parametrize("scheme", GRAD_SCHEMES)
@pytest.mark.parametrize("H,W", [(1, 1), (1, 4), (3, 1), (5, 7), (16, 9)])
def test_grad_image_adjoint(scheme, H, W):
    rng = np.random.default_rng(H * 10 + W)
    u = rng.standard_normal((3, H, W))
    g = rng.standard_normal((3, 2, H, W))
    lhs = np.sum(grad_image(u, scheme) * g)
    rhs = np.sum(u * grad_image_adj(g, scheme))
    assert abs(lhs - rhs) < 1e-10 * max(1.0, abs(lhs))


def test_forward_gradient_is_the_compact_laplacian():
    """DᵀD of forward differences = −Δ₄ (5-point Laplacian, Neumann) in the interior."""
    rng = np.random.default_rng(0)
    u = rng.standard_normal((1, 8, 9))
    L = grad_image_adj(grad_image(u, "forward"), "forward")[0]
    x = u[0]
    lap = 4 * x[1:-1, 1:-1] - x[:-2, 1:-1] - x[2:, 1:-1] - x[1:-1, :-2] - x[1:-1, 2:]
    np.testing.assert_allclose(L[1:-1, 1:-1], lap, atol=1e-12)


@pytest.mark.parametrize("scheme", GRAD_SCHEMES)
def test_source_gradient_is_the_operator(scheme):
    """Every sample's ∇v (border pixels included) = grad_image of its source image there."""
    H, W, f = 20, 24, 30.0
    img = np.random.default_rng(1).random((H, W, 3)).astype(np.float32)
    K = Camera.intrinsics(f, W, H)
    src = View("s", img, Camera.from_centre(K, np.eye(3), np.zeros(3), W, H), np.full((H, W), 3.0))
    s = compute_samples(Scene([src]), Camera.from_centre(K, np.eye(3), np.zeros(3), W, H), grad_scheme=scheme,
                        keep="src_xy")
    assert s.meta["grad_scheme"] == scheme and len(s) == H * W
    g = grad_image(np.ascontiguousarray(img.transpose(2, 0, 1)), scheme)  # (3, 2, H, W)
    x, y = s.src_xy[:, 0], s.src_xy[:, 1]
    np.testing.assert_array_equal(s.grad, g[:, :, y, x].transpose(2, 0, 1))


def test_metrics_checkerboard_and_speckles():
    ramp = np.add.outer(np.arange(16.0), np.arange(16.0)) / 40
    cb = ramp + 0.05 * (-1.0) ** np.add.outer(np.arange(16), np.arange(16))
    assert checkerboard_energy(ramp) < 1e-12
    assert abs(checkerboard_energy(cb) - 0.2) < 1e-12
    spk = ramp.copy()
    spk[8, 8] += 0.5
    assert speckle_density(ramp) == 0 and speckle_density(spk) > 0


def test_gradient_render_has_no_more_checkerboard_than_bvs():
    """The Nyquist (checkerboard) energy of the gradient render ≤ the BVS render's."""
    from vibr.render import render
    from vibr.synthetic import make_scene

    sc = make_scene("grid", n_views=9, width=64, height=64, seed=2)
    out = {m: render(sc, sc.views[4], m) for m in ("bvs", "gradient")}
    e = {m: checkerboard_energy(r.image, r.coverage, 2) for m, r in out.items()}
    assert e["gradient"] <= e["bvs"] * 1.0001, e


def test_robust_loss_downweights_an_outlier_sample():
    """The Cauchy IRLS factor: ~1 for samples that agree with u, small for an outlier."""
    from vibr.geometry.samples import Samples
    from vibr.render.operators import Splat
    from vibr.render.weights import robust_factor

    rng = np.random.default_rng(0)
    H, W, n = 8, 8, 200
    u = rng.random((H, W, 3)).astype(np.float32)
    xy = rng.uniform(0, 7, (n, 2))
    sp = Splat(xy, (H, W))
    col = (sp.apply(u) + 0.01 * rng.standard_normal((n, 3))).astype(np.float32)
    col[0] += 0.5
    z = np.zeros
    s = Samples(xy, col, z((n, 3, 2), np.float32), z((n, 2, 2)), np.ones(n), z((n, 2)), np.ones(n),
                z(n, np.int32), z((n, 2), np.int32), z((n, 3)), (H, W))
    f = robust_factor(s, u, sp, c=3.0)
    assert f[0] < 0.01 and np.median(f[1:]) > 0.9
    np.testing.assert_array_equal(robust_factor(s, u, sp, loss="none"), 1.0)


def test_consistency_weights_of_one_give_the_plain_gradient_term():
    """With a consistency scale so large that every weight is 1, the render equals the one
    without consistency weights (the other path: coverage Bᵀ1 and the stencils assembled
    apart) to float32 rounding; at the default scale it differs."""
    from vibr.render import render
    from vibr.synthetic import make_scene

    sc = make_scene("grid", n_views=9, width=48, height=40, seed=1)
    src = sc.subset([v.name for v in sc.views if v.name != "view_004"])
    plain = render(src, sc.views[4], "gradient", grad_consistency=0.0)
    huge = render(src, sc.views[4], "gradient", grad_consistency=1e12)
    default = render(src, sc.views[4], "gradient")
    assert np.array_equal(plain.coverage, huge.coverage)
    np.testing.assert_allclose(huge.image, plain.image, atol=2e-5)
    assert np.abs(default.image - plain.image).max() > 1e-3
    assert default.params["grad_consistency"] > 0
