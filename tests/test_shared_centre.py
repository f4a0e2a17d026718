"""Rotation-only captures (every camera at one centre, a panorama from a tripod): no depth
can be estimated and none is needed. vibr renders them on a sphere around the centre, turns
between the views in a fly-through, and refuses the paths that would leave the centre."""

from __future__ import annotations

import numpy as np
import pytest

from vibr.camera import Camera, shared_centre
from vibr.errors import VibrInputError
from vibr.geometry import sphere_proxy
from vibr.synthetic import make_scene


@pytest.fixture(scope="module")
def pan():
    sc = make_scene("pan", n_views=5, width=80, height=60)
    return sc.replace(views=[v.replace(depth=None, sigma_z=None) for v in sc.views])


def test_shared_centre_closed_form():
    K = Camera.intrinsics(50.0, 64, 48)
    R2 = Camera.look_at([0, 0, 0], [1, 0, 1], [0, -1, 0], K, 64, 48).R
    C = np.array([2.0, -1.0, 3.0])
    cams = [Camera.from_centre(K, np.eye(3), C, 64, 48), Camera.from_centre(K, R2, C + 1e-9, 64, 48)]
    assert np.allclose(shared_centre(cams), C)
    moved = [cams[0], Camera.from_centre(K, R2, C + [1e-3, 0, 0], 64, 48)]
    assert shared_centre(moved) is None
    assert shared_centre(cams[:1]) is None  # one camera is not a capture
    # the scene's scale from its points: 1e-10 is a millionth of a scene 1e-4 units deep
    pts = C + 1e-4 * np.random.default_rng(0).normal(size=(50, 3))
    tiny = [cams[0], Camera.from_centre(K, R2, C + 3e-10, 64, 48)]
    assert shared_centre(tiny, 1e3 * (pts - C) + C) is not None and shared_centre(tiny, pts) is None
    # georeferenced coordinates: half a million units from the origin, a metre apart
    far = np.array([5e5, -1.7e5, 7e4])
    assert shared_centre([Camera.from_centre(K, np.eye(3), far, 64, 48),
                          Camera.from_centre(K, R2, far + [0.3, 0, 0], 64, 48)]) is None
    assert shared_centre([Camera.from_centre(K, np.eye(3), far, 64, 48),
                          Camera.from_centre(K, R2, far, 64, 48)]) is not None


def test_sphere_proxy_puts_every_pixel_at_the_radius(pan):
    c = shared_centre([v.camera for v in pan.views])
    sp = sphere_proxy(pan, c, radius=2.5)
    for v in sp.views:
        X = v.camera.backproject(v.camera.pixel_grid(), v.depth)
        np.testing.assert_allclose(np.linalg.norm(X - c, axis=-1), 2.5, rtol=1e-6)
        assert v.sigma_z == pytest.approx(0.25 * 2.5)
    assert sp.meta["proxy"]["kind"] == "sphere"
    with pytest.raises(VibrInputError, match="radius"):
        sphere_proxy(pan, c, radius=0.0)


def test_buehler_weights_with_views_tied_at_zero_penalty():
    """Views at the target's own centre all have penalty 0: the threshold (the (k+1)-th
    penalty) was 0 and the weights 0/0 (a ZeroDivisionError in the compiled blend of a
    fly-through frame at the shared centre); now those views weigh alike."""
    from vibr.render.ulr import ulr_view_weights
    from vibr.render.weights import _buehler_weights

    p = np.zeros((5, 2, 2))
    w = ulr_view_weights(p, k=2)
    assert np.all(np.isfinite(w)) and np.allclose(w, w[0])
    a = np.zeros((5, 2))
    a[:, 1] = 1.0  # coverage 1, penalty sum 0
    out, srt = np.empty(5), np.empty(5)
    top = _buehler_weights(a, 2, 1e-6, 0.0, out, srt)
    assert np.isfinite(top) and np.allclose(out, top)


def test_render_without_depth_uses_the_sphere(pan):
    from vibr.pipeline import prepare
    from vibr.render import render

    truth = make_scene("pan", n_views=5, width=80, height=60)
    src, target = prepare(pan, "view_002", cache_dir=False)
    assert src.meta["depth_source"] == "shared centre"
    res = render(src, target, "gradient")
    ulr = render(src, target, "ulr")
    assert res.metrics["psnr"] > 33.0 and ulr.metrics["psnr"] > 33.0, (res.metrics, ulr.metrics)
    # the exact depth gives the same views (homographies): the sphere loses nothing
    src_gt, _ = prepare(truth, "view_002")
    exact = render(src_gt, target, "gradient")
    assert res.metrics["psnr"] > exact.metrics["psnr"] - 0.5


def test_paths_turn_on_the_spot(pan, tmp_path):
    from vibr.paths.camera_path import interpolate, orbit, spiral
    from vibr.paths.flythrough import render_path

    p = interpolate(pan, n_frames=9)
    assert p.meta["views"] == [v.name for v in pan.views] or p.meta["views"] == [v.name for v in pan.views][::-1]
    C = np.array([c.centre for c in p.cameras])
    assert np.abs(C - C[0]).max() < 1e-9
    for make in (orbit, spiral):
        with pytest.raises(VibrInputError, match="share one centre"):
            make(pan, n_frames=5)
    res = render_path(pan, interpolate(pan, n_frames=3), tmp_path / "frames", method="ulr", cache_dir=False,
                      executor=None, progress=False)
    assert len(list((tmp_path / "frames").glob("*.png"))) == 3 and res.rendered == 3
    assert res.depth_source == "shared centre"


def test_depth_estimation_says_why(pan):
    from vibr.stereo import estimate_depth

    with pytest.raises(VibrInputError, match="rotation-only capture.*rendering needs none"):
        estimate_depth(pan)


def test_info_says_one_centre(pan):
    assert "one centre: a rotation-only capture" in pan.summary()
    assert "bounding-box diagonal" in make_scene("arc", n_views=3, width=32, height=24).summary()


def test_viewer_draws_the_frustums_of_one_centre(pan):
    from vibr.viewer.geometry import frustum_size, scene_scale

    assert scene_scale(pan) == 1.0
    assert frustum_size(pan, 1.0) == pytest.approx(0.06)
