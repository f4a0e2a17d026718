"""Depth transfer for light fields whose ground truth is one centre-view disparity (HCI),
and the planar proxy."""

import numpy as np
import pytest

from vibr.camera import Camera
from vibr.errors import VibrInputError
from vibr.geometry import compute_samples, ensure_source_depth, planar_proxy, transfer_depth
from vibr.scene import Scene, View


@pytest.fixture(scope="module")
def cotton_block(cotton_dir):
    import vibr.io as io

    scene = io.load_scene(cotton_dir)
    gp = scene.meta["grid_pos"]
    names = [n for n in scene.names if abs(gp[n][0] - 4) <= 1 and abs(gp[n][1] - 4) <= 1]
    block = ensure_source_depth(scene.subset(names))
    disp = np.asarray(io.read_pfm(cotton_dir / "gt_disp_lowres.pfm"), dtype=np.float64)
    return block, disp, gp


def _disparity_on_mesh(disp, tau):
    """Centre disparity at ``tau`` interpolated linearly on the triangles of the pixel-centre
    mesh (cells cut along their (i, j)–(i+1, j+1) diagonal)."""
    H, W = disp.shape
    tx, ty = tau[:, 0], tau[:, 1]
    i0 = np.clip(np.floor(ty).astype(int), 0, H - 2)
    j0 = np.clip(np.floor(tx).astype(int), 0, W - 2)
    fy, fx = ty - i0, tx - j0
    d00, d01 = disp[i0, j0], disp[i0, j0 + 1]
    d10, d11 = disp[i0 + 1, j0], disp[i0 + 1, j0 + 1]
    return np.where(fx >= fy, d00 + fx * (d01 - d00) + fy * (d11 - d01),
                    d00 + fy * (d10 - d00) + fx * (d11 - d10))


def test_transferred_depth_reproduces_the_grid_relation(cotton_block):
    """README: view (r, c) at x − (c−4)·d(x), y − (r−4)·d(x) shows centre pixel (x, y)."""
    block, disp, gp = cotton_block
    sources, centre = block.split("input_Cam040")
    assert all(v.depth is not None for v in sources.views)
    s = compute_samples(sources, centre.camera, keep="src_xy")
    worst = 0.0
    for k, v in enumerate(sources.views):
        r, c = gp[v.name]
        filled = block.meta["depth_filled"][v.name]
        sel = s.view == k
        src = s.src_xy[sel]
        known = ~filled[src[:, 1], src[:, 0]]  # depth known by transfer, not hole-filled
        tau = s.xy[sel][known]
        d = _disparity_on_mesh(disp, tau)
        pred = src[known] + np.stack([(c - 4) * d, (r - 4) * d], 1)
        err = np.abs(pred - tau).max()
        worst = max(worst, err)
        assert known.sum() > 0.95 * v.depth.size, v.name
    assert worst < 0.01, worst


def test_transfer_marks_holes_and_fills_them(cotton_block):
    block, _, _ = cotton_block
    for name, mask in block.meta["depth_filled"].items():
        d = block[name].depth
        assert 0 < mask.sum() < 0.05 * mask.size  # thin disocclusion/edge strips only
        assert np.all(np.isfinite(d[mask]))
        assert np.nanmin(d) > 3.0 and np.nanmax(d) < 5.5  # cotton depth range 3.67..5.12


def _two_cam_scene():
    W = H = 32
    K = Camera.intrinsics(40.0, W, H)
    a = Camera.from_centre(K, np.eye(3), [0, 0, 0], W, H)
    b = Camera.from_centre(K, np.eye(3), [0.1, 0, 0], W, H)
    img = np.random.default_rng(0).random((H, W, 3)).astype(np.float32)
    return a, b, img


def test_transfer_of_a_plane_and_errors():
    a, b, img = _two_cam_scene()
    sc = Scene([View("a", img, a, np.full(a.shape, 2.0)), View("b", img, b)])
    d = transfer_depth(sc, b.camera if isinstance(b, View) else b)
    ok = np.isfinite(d)
    assert ok[:, :-3].all() and not ok[:, -1].any()  # the right strip is not seen by a
    np.testing.assert_allclose(d[ok], 2.0, rtol=1e-6)
    flat = Scene([View("a", img, a, np.full(a.shape, 2.0)), View("b", np.full_like(img, 0.5), b)])
    full = ensure_source_depth(flat)  # a uniform guide: the strip fills from its neighbours
    assert np.isfinite(full["b"].depth).all()
    assert full.meta["depth_transferred"] == ["b"] and full.meta["depth_filled"]["b"][:, -1].all()
    with pytest.raises(VibrInputError):
        ensure_source_depth(Scene([View("a", img, a), View("b", img, b)]))


def test_planar_proxy_is_fronto_parallel_in_the_target():
    a, b, img = _two_cam_scene()
    rng = np.random.default_rng(3)
    sc = Scene([View("a", img, a, rng.uniform(2, 4, a.shape)), View("b", img, b, np.full(a.shape, 3.0))])
    tgt = Camera.from_centre(a.K, np.eye(3), [0.05, 0.02, 0.0], a.width, a.height)
    px = planar_proxy(sc, tgt)
    D = px.meta["proxy"]["depth"]
    assert 2.0 < D < 4.0
    # sigma_z: max(PROXY_SIGMA_Z_REL D, PROXY_SPREAD_REL (p95 - p5)) of the depth the target sees
    from vibr.geometry.proxy import PROXY_SIGMA_Z_REL, PROXY_SPREAD_REL, _target_depths

    wd = _target_depths(sc, tgt)
    spread = np.percentile(wd, 95) - np.percentile(wd, 5)
    assert PROXY_SPREAD_REL * spread > PROXY_SIGMA_Z_REL * D  # view a's depth spreads 2-4
    assert px["a"].sigma_z == pytest.approx(PROXY_SPREAD_REL * spread, rel=1e-12)
    flat = planar_proxy(sc.subset(["b"]), tgt)  # one depth: the floor
    assert flat["b"].sigma_z == pytest.approx(PROXY_SIGMA_Z_REL * flat.meta["proxy"]["depth"], rel=1e-12)
    for v in px.views:
        X = v.camera.backproject(v.camera.pixel_grid(), v.depth)
        np.testing.assert_allclose(tgt.project(X)[1], D, rtol=1e-5)
    s = compute_samples(px, tgt, keep="src_xy")
    assert np.allclose(s.sigma_z, px["a"].sigma_z)
    # a fronto-parallel plane seen by parallel cameras: a pure translation, det = 1
    sel = s.view == 0
    shift = np.array([-a.K[0, 0] * 0.05 / D, -a.K[0, 0] * 0.02 / D])
    np.testing.assert_allclose(s.xy[sel] - s.src_xy[sel], np.broadcast_to(shift, (sel.sum(), 2)),
                               atol=1e-4)
    np.testing.assert_allclose(s.inv_det, 1.0, atol=1e-9)
    px2 = planar_proxy(sc, tgt, depth=5.0, sigma_z=0.7)
    assert px2.meta["proxy"] == {"depth": 5.0, "sigma_z": 0.7}


def test_planar_proxy_without_depth_meets_the_optical_axes():
    """No depth maps and no points: the plane goes through the point the sources' optical axes
    meet at (a ring looking at its centre: exactly the centre, at the ring's radius from a
    target on it), with sigma_z its floor; cameras sharing one centre (a turn on the spot) see
    the same through any plane, at depth 1; parallel axes (a grid) are a one-line error."""
    from vibr.geometry.proxy import PROXY_SIGMA_Z_REL

    K = Camera.intrinsics(50.0, 32, 32)
    ring = [Camera.look_at([5 * np.cos(a), 0.3, 5 * np.sin(a)], [0, 0.3, 0], [0, 1, 0], K, 32, 32)
            for a in np.linspace(0, np.pi / 2, 5)]
    img = np.zeros((32, 32, 3), np.float32)
    src = Scene([View(f"c{k}", img, c) for k, c in enumerate(ring[:4])])
    px = planar_proxy(src, ring[4])
    assert px.meta["proxy"]["from"] == "optical axes"
    assert px.meta["proxy"]["depth"] == pytest.approx(5.0, rel=1e-9)
    assert px["c0"].sigma_z == pytest.approx(PROXY_SIGMA_Z_REL * 5.0, rel=1e-9)
    turn = [Camera.look_at([0, 0, 0], [np.cos(a), 0, np.sin(a)], [0, 1, 0], K, 32, 32) for a in (0, 0.2, 0.4)]
    pan = planar_proxy(Scene([View(f"t{k}", img, c) for k, c in enumerate(turn[:2])]), turn[2])
    assert pan.meta["proxy"]["from"].startswith("shared centre") and pan.meta["proxy"]["depth"] == 1.0
    off = Camera.look_at([0.1, 0, 0], [1, 0, 0.2], [0, 1, 0], K, 32, 32)  # a target off that centre
    pan_off = planar_proxy(Scene([View(f"t{k}", img, c) for k, c in enumerate(turn)]), off)
    assert pan_off.meta["proxy"]["depth"] == 1.0 and np.isfinite(pan_off["t0"].depth).any()
    a, b, _ = _two_cam_scene()  # parallel axes: nothing to place the plane at
    with pytest.raises(VibrInputError, match="optical axes do not meet"):
        planar_proxy(Scene([View("a", img, a), View("b", img, b)]), a)
