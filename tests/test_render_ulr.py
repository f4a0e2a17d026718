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
