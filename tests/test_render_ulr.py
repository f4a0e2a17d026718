"""Unstructured Lumigraph blending (render/ulr.py) on closed-form cases."""

import numpy as np

from vibr.geometry import compute_samples
from vibr.render.ulr import ulr_blend
from vibr.scene import Scene
from vibr.synthetic import make_scene


def _centres(scene):
    return np.array([v.camera.centre for v in scene.views])


def test_a_source_at_the_target_reproduces_it():
    """A source with the target's own camera has penalty 0 (no angle, no resolution
    loss) on every sample: its weight is 1/eps against at most ~(1/p) for the others, so
    the blend is that source's image, exactly where its samples land on pixel centres."""
    sc = make_scene("grid", n_views=9, width=48, height=40, seed=3)
    tgt = sc.views[4]
    src = Scene([v for v in sc.views if v.name != tgt.name] + [tgt.replace(name="copy")], sc.name)
    S = compute_samples(src, tgt.camera)
    img, acc = ulr_blend(S, _centres(src), tgt.camera.centre)
    own = S.view == len(src) - 1
    assert own.sum() > 0.95 * tgt.image.shape[0] * tgt.image.shape[1]
    # the copy's samples land on the pixel centres it came from
    xy = S.xy[own]
    assert np.abs(xy - np.rint(xy)).max() < 1e-6
    ij = np.rint(xy).astype(int)
    seen = np.zeros(tgt.shape, bool)
    seen[ij[:, 1], ij[:, 0]] = True
    err = np.abs(img - tgt.image)[seen]
    assert err.max() < 2e-3, err.max()
    # without the copy the same blend is far from exact
    S2 = compute_samples(src.subset([v.name for v in src.views[:-1]]), tgt.camera)
    img2, _ = ulr_blend(S2, _centres(src)[:-1], tgt.camera.centre)
    assert np.abs(img2 - tgt.image)[seen].max() > 10 * err.max()


def test_single_view_and_k():
    """One source: every covered pixel is that source's splatted colour (weights
    normalise to 1 whatever the penalty); k limits how many views blend."""
    sc = make_scene("grid", n_views=9, width=40, height=32, seed=4)
    tgt = sc.views[4]
    one = sc.subset(["view_001"])
    S = compute_samples(one, tgt.camera)
    img, acc = ulr_blend(S, _centres(one), tgt.camera.centre)
    from vibr.render.operators import Splat

    sp = Splat(S.xy, tgt.shape)
    num = sp.adjoint(S.colour.astype(np.float64))
    w = sp.adjoint(np.ones((len(S), 1)))[..., 0]
    ok = w > 1e-3
    np.testing.assert_allclose(img[ok], num[ok] / w[ok, None], atol=1e-5)
    np.testing.assert_allclose(acc, w, atol=1e-5)
    assert np.all(img[~ok] == 0)


def _reference_ulr(S, Cs, Cu, k=4, beta_res=0.1, eps=1e-6):
    """ULR from its numpy formulas, view by view (a Splat per view, float64 sums): the
    implementation the compiled :func:`vibr.render.weights.ulr_pixels` replaced."""
    from vibr.render.operators import Splat
    from vibr.render.ulr import ulr_penalty, ulr_view_weights

    H, W = S.target_shape
    pen = ulr_penalty(S, Cs, Cu, beta_res)
    V = len(Cs)
    colour = np.zeros((V, H, W, 3))
    pview = np.full((V, H, W), np.inf)
    acc = np.zeros((H, W))
    for v in range(V):
        sel = S.view == v
        if not np.any(sel):
            continue
        s = Splat(S.xy[sel], (H, W)).adjoint(np.concatenate(
            [S.colour[sel].astype(np.float64), pen[sel, None], np.ones((int(sel.sum()), 1))], axis=1))
        wv = s[..., 4]
        ok = wv > 1e-3
        colour[v][ok] = s[ok, :3] / wv[ok, None]
        pview[v][ok] = s[ok, 3] / wv[ok]
        acc += wv
    wt = ulr_view_weights(pview, k, eps)
    sw = wt.sum(0)
    img = np.where(sw[..., None] > 0, (wt[..., None] * colour).sum(0) / np.maximum(sw, 1e-300)[..., None], 0.0)
    dev = ((colour - img[None]) ** 2).sum(-1)
    var = np.where(sw > 0, (wt * dev).sum(0) / (3 * np.maximum(sw, 1e-300)), 0.0)
    return img, acc, var


def test_compiled_ulr_equals_the_numpy_formulas():
    """The compiled two-pass ULR equals ULR's penalty and weights composed with one splat per
    view (float64), on a real render's samples: uneven views, holes, borders, each k."""
    sc = make_scene("handheld", n_views=7, width=64, height=48, seed=3)
    src, tg = sc.split(3)
    S = compute_samples(src, tg.camera)
    Cs, Cu = S.meta["source_centres"], S.meta["target_centre"]
    for k in (1, 2, 4):
        img, acc, var = ulr_blend(S, Cs, Cu, k=k, spread=True)
        want_img, want_acc, want_var = _reference_ulr(S, Cs, Cu, k=k)
        assert (acc > 0.5).mean() > 0.5 and (acc < 1e-3).any()  # holes and covered pixels both
        # float32 sums against float64: 1e-6 of a coverage, 1e-7 of an intensity here
        np.testing.assert_allclose(acc, want_acc, atol=5e-6)
        np.testing.assert_allclose(img, want_img, atol=1e-6)
        np.testing.assert_allclose(var, want_var, atol=1e-7)


def test_compiled_ulr_is_bit_identical_on_one_thread():
    """The splat writes each row from one thread (rows of even, then odd buckets) and the
    per-pixel pass reads only its pixel: the same bits on one thread as on all."""
    import numba

    sc = make_scene("handheld", n_views=7, width=64, height=48, seed=3)
    src, tg = sc.split(3)
    S = compute_samples(src, tg.camera)
    Cs, Cu = S.meta["source_centres"], S.meta["target_centre"]
    many = ulr_blend(S, Cs, Cu, spread=True)
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        one = ulr_blend(S, Cs, Cu, spread=True)
    finally:
        numba.set_num_threads(before)
    for a, b in zip(many, one):
        np.testing.assert_array_equal(a, b)
