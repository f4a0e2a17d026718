"""Tests of the synthetic scene generator (vibr.synthetic)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import label, map_coordinates

from vibr import Camera, VibrInputError
from vibr.metrics import psnr
from vibr.synthetic import (
    DEFAULT_BBOX,
    DEFAULT_SIGMA_Z,
    FAR_GAP_X,
    SCENE_CENTRE,
    World,
    arc_cameras,
    default_world,
    degrade_depth,
    free_cameras,
    grid_cameras,
    make_scene,
    planar_depth,
    render_view,
)


@pytest.fixture(scope="module")
def grid_scene():
    return make_scene()


@pytest.fixture(scope="module")
def world():
    return default_world(0)


def _centre_rays(cam: Camera):
    """World directions R^T K^-1 [x, y, 1] of all pixel centres (row-major)."""
    return (cam.pixel_rays(cam.pixel_grid()) @ cam.R).reshape(-1, 3)


# ------------------------------------------------------------------ scenes and images
def test_default_scene_views(grid_scene):
    s = grid_scene
    assert len(s) == 9 and s.grid == (3, 3)
    assert s.names[0] == "view_000" and s.names[-1] == "view_008"
    assert s.meta["layout"] == "grid" and s.meta["format"] == "synthetic"
    assert s.meta["grid_pos"]["view_005"] == (1, 2)
    for v in s.views:
        assert v.image.shape == (128, 128, 3) and v.image.dtype == np.float32
        assert v.image.min() >= 0.0 and v.image.max() <= 1.0
        assert v.image.std() > 0.05  # textured, not blank
        assert v.depth.dtype == np.float32 and v.depth.shape == (128, 128)
        assert np.all(np.isfinite(v.depth))  # the back wall and floor catch every ray
        assert v.sigma_z == DEFAULT_SIGMA_Z
    assert s.has_depth


def test_depth_within_bbox(grid_scene):
    (x0, x1), (y0, y1), (z0, z1) = DEFAULT_BBOX
    v = grid_scene.views[4]
    X = v.camera.backproject(v.camera.pixel_grid(), v.depth).reshape(-1, 3)
    tol = 1e-4
    assert np.all((X[:, 0] >= x0 - tol) & (X[:, 0] <= x1 + tol))
    assert np.all((X[:, 1] >= y0 - tol) & (X[:, 1] <= y1 + tol))
    assert np.all((X[:, 2] >= z0 - tol) & (X[:, 2] <= z1 + tol))


def test_determinism_and_seed():
    a = make_scene(n_views=4, width=48, height=40, seed=3)
    b = make_scene(n_views=4, width=48, height=40, seed=3)
    c = make_scene(n_views=4, width=48, height=40, seed=4)
    assert a.grid == (2, 2) and a.views[0].image.shape == (40, 48, 3)
    for va, vb in zip(a.views, b.views):
        np.testing.assert_array_equal(va.image, vb.image)
        np.testing.assert_array_equal(va.depth, vb.depth)
    assert not np.array_equal(a.views[0].image, c.views[0].image)
    f1 = free_cameras(3, seed=5)
    f2 = free_cameras(3, seed=5)
    f3 = free_cameras(3, seed=6)
    assert all(p.allclose(q) for p, q in zip(f1, f2))
    assert not f1[0].allclose(f3[0])


def test_handheld_layout_bounded_baselines_and_overlap():
    from vibr.synthetic import handheld_cameras

    cams = handheld_cameras(7, seed=2, width=64, height=48)
    assert cams[0].allclose(handheld_cameras(7, seed=2, width=64, height=48)[0])
    np.testing.assert_allclose(cams[0].centre, (0.0, -0.3, 0.0), atol=1e-12)
    off = np.array([c.centre - cams[0].centre for c in cams[1:]])
    lateral = np.hypot(off[:, 0], off[:, 1])
    assert np.all((lateral >= 0.3 - 1e-9) & (lateral <= 0.6 + 1e-9)) and np.all(np.abs(off[:, 2]) <= 0.15)
    # directions spread around the reference: consecutive views ~ 60° apart (± 20° each)
    ang = np.degrees(np.arctan2(off[:, 1], off[:, 0])) % 360
    gaps = np.diff(np.sort(ang))
    assert gaps.max() < 110, ang
    s = make_scene("handheld", width=64, height=48, seed=2)
    assert len(s) == 7 and s.meta["layout"] == "handheld"
    # every view sees the scene centre
    for c in cams:
        xy, z = c.project(np.array([SCENE_CENTRE]))
        assert z[0] > 0 and 0 < xy[0, 0] < 63 and 0 < xy[0, 1] < 47


def test_far_background_is_seen_past_the_corner_only():
    """default_world(far=...): left of the back wall's edge the rays stop on the wall (z = 6),
    right of it they reach the façade at z = far; the standard world is unchanged elsewhere."""
    far = 30.0
    w, w0 = default_world(0, far=far), default_world(0)
    # rays from the origin through the back wall's plane at heights between ceiling and floor
    xs = np.array([-2.0, 0.5, FAR_GAP_X + 0.3, 3.0])
    target = np.stack([xs, np.full(4, -3.5), np.full(4, 6.0)], -1)  # above the card and the sphere
    t, obj, _ = w.raycast(np.zeros((4, 3)), target)
    z = t * target[:, 2]  # the direction's z is 6: the hit's depth
    assert np.allclose(z[:2], 6.0) and np.allclose(z[2:], far)
    assert all(w.names[o] == "far façade" for o in obj[2:])
    t0, _, _ = w0.raycast(np.zeros((4, 3)), target)
    assert np.allclose(t0 * 6.0, 6.0)  # the standard world's wall is whole
    assert w.bbox[2][1] == far and w0.bbox[2][1] == DEFAULT_BBOX[2][1]
    with pytest.raises(VibrInputError, match="behind the back wall"):
        default_world(0, far=5.0)


def test_unknown_layout():
    with pytest.raises(VibrInputError, match="layout"):
        make_scene("spiral")


# ------------------------------------------------------------------ ray casting and depth
def test_render_depth_equals_raycast(world):
    cam = grid_cameras(1, 1, width=40, height=32)[0]
    img, depth = render_view(world, cam, supersample=1)
    t, obj, col = world.raycast(cam.centre[None], _centre_rays(cam), footprint=1 / cam.K[0, 0])
    np.testing.assert_allclose(depth.ravel(), t, rtol=1e-6)
    assert np.all(obj >= 0)
    # with supersample=1 the colour is the pixel-centre ray's (same mip-map level)
    np.testing.assert_allclose(img.reshape(-1, 3), col, atol=1e-4)
    # the finest level (no footprint) is sharper than the footprint-selected one
    _, _, col0 = world.raycast(cam.centre[None], _centre_rays(cam))
    assert 0.005 < np.abs(col0 - col).mean() < 0.2


def test_raycast_miss():
    w = World(background=(0.2, 0.3, 0.4))
    w.add_rect([-1, -1, 5], [2, 0, 0], [0, 2, 0], "gravel")
    t, obj, col = w.raycast([[0, 0, 0], [0, 0, 0], [0, 0, 6]], [[0, 0, 1], [0, 5, 1], [0, 0, 1]])
    assert t[0] == pytest.approx(5.0) and obj[0] == 0
    assert np.isinf(t[1]) and obj[1] == -1 and np.allclose(col[1], [0.2, 0.3, 0.4])
    assert np.isinf(t[2])  # the plane is behind this ray
    # t is the parameter along the (non-unit) direction
    t2, _, _ = w.raycast([[0, 0, 0]], [[0, 0, 2.5]])
    assert t2[0] == pytest.approx(2.0)


def test_depth_consistency_across_views(world):
    """A pixel back-projected with its depth lies on a surface: the ray from another
    camera towards that point hits it (t = 1) or something in front (t < 1), never
    beyond, and where it is visible the object ids agree."""
    cams = grid_cameras(3, 3, 0.1, width=96, height=96)
    other = arc_cameras(3, width=96, height=96)[0]
    cam = cams[4]
    _, depth = render_view(world, cam)
    X = cam.backproject(cam.pixel_grid(), depth).reshape(-1, 3)
    _, obj0, _ = world.raycast(cam.centre[None], _centre_rays(cam))
    for o in (cams[0], other):
        C = o.centre
        t, obj, _ = world.raycast(C[None], X - C)
        assert np.mean(t <= 1 + 1e-5) > 0.999
        vis = np.abs(t - 1) < 1e-5
        assert vis.mean() > 0.6
        assert np.all(obj[vis] == obj0[vis])
        # the other view's rendered depth at the projection agrees (nearest pixel)
        _, dep_o = render_view(world, o, supersample=1)
        xy, z = o.project(X[vis])
        ij = np.round(xy).astype(int)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < o.width) & (ij[:, 1] >= 0) & (ij[:, 1] < o.height)
        dz = np.abs(dep_o[ij[ok, 1], ij[ok, 0]] - z[ok]) / z[ok]
        assert np.median(dz) < 0.01


def test_plane_depth_closed_form(world):
    # the back wall z = 6 is fronto-parallel to the grid cameras (at z = 0)
    cam = grid_cameras(1, 1, width=64, height=64)[0]
    _, depth = render_view(world, cam, supersample=1)
    _, obj, _ = world.raycast(cam.centre[None], _centre_rays(cam))
    wall = obj.reshape(depth.shape) == 0
    assert wall.mean() > 0.2
    np.testing.assert_allclose(depth[wall], planar_depth(cam, 6.0)[wall], rtol=1e-6)
    # a tilted plane n . X = d seen by a rotated camera
    n = np.array([0.3, -0.2, 1.0])
    n /= np.linalg.norm(n)
    d = 4.0
    u = np.cross(n, [0, 1, 0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    w = World()
    w.add_rect(d * n - 50 * u - 50 * v, 100 * u, 100 * v, "brick")
    cam2 = free_cameras(1, seed=2, width=50, height=40, eye=(0.2, 0.1, -0.5), target=(0, 0, 4))[0]
    _, dep2 = render_view(w, cam2)
    ref = planar_depth(cam2, d, normal=n)
    assert np.all(np.isfinite(ref))
    np.testing.assert_allclose(dep2, ref, rtol=1e-5)


def test_sphere_hits_lie_on_sphere():
    w = World()
    c, r = np.array([0.3, -0.2, 5.0]), 1.5
    w.add_sphere(c, r, "chelsea")
    cam = grid_cameras(1, 1, width=64, height=64)[0]
    _, depth = render_view(w, cam)
    hit = np.isfinite(depth)
    assert 0.2 < hit.mean() < 0.9  # NaN where the ray misses
    X = cam.backproject(cam.pixel_grid()[hit], depth[hit])
    np.testing.assert_allclose(np.linalg.norm(X - c, axis=1), r, rtol=1e-5)


def test_exact_depth_warp_is_accurate(grid_scene):
    """Band-limited images: warping a neighbour with exact depth (bilinear) reproduces
    the centre view closely on pixels visible in both (the renderer's model)."""
    tgt, src = grid_scene.views[4], grid_scene.views[5]
    X = tgt.camera.backproject(tgt.camera.pixel_grid(), tgt.depth)
    xy, z = src.camera.project(X)
    coords = [xy[..., 1].ravel(), xy[..., 0].ravel()]
    warped = np.stack([map_coordinates(src.image[..., c], coords, order=1, mode="nearest")
                       for c in range(3)], -1).reshape(tgt.image.shape)
    zs = map_coordinates(src.depth, coords, order=1, mode="nearest").reshape(z.shape)
    H, W = tgt.shape
    inside = (xy[..., 0] >= 0) & (xy[..., 0] <= W - 1) & (xy[..., 1] >= 0) & (xy[..., 1] <= H - 1)
    vis = inside & (np.abs(zs - z) < 0.01 * z)
    assert vis.mean() > 0.85
    assert psnr(warped, tgt.image, mask=vis) > 38.0


# ------------------------------------------------------------------ camera layouts
def _check_camera_sees(cam: Camera, point):
    xy, z = cam.project(np.asarray(point, dtype=np.float64))
    assert z > 0
    assert 0 <= xy[0] <= cam.width - 1 and 0 <= xy[1] <= cam.height - 1
    return xy


def test_grid_layout():
    cams = grid_cameras(2, 3, 0.25, width=30, height=20)
    assert len(cams) == 6
    for c in cams:
        np.testing.assert_allclose(c.R, np.eye(3))
        assert c.shape == (20, 30)
    C = np.array([c.centre for c in cams])
    np.testing.assert_allclose(C[1] - C[0], [0.25, 0, 0])  # next column: +x
    np.testing.assert_allclose(C[3] - C[0], [0, 0.25, 0])  # next row: +y (down)
    np.testing.assert_allclose(C.mean(0), 0, atol=1e-12)


@pytest.mark.parametrize("cams", [arc_cameras(4, width=64, height=48), free_cameras(4, seed=1, width=64, height=48)],
                         ids=["arc", "free"])
def test_arc_and_free_layouts(cams):
    for c in cams:
        assert abs(np.linalg.det(c.R) - 1) < 1e-9
        np.testing.assert_allclose(c.R @ c.R.T, np.eye(3), atol=1e-12)
        xy = _check_camera_sees(c, SCENE_CENTRE)
        # upright: a point above the scene centre (world up = -y) is higher in the image
        xy_up = _check_camera_sees(c, np.add(SCENE_CENTRE, (0, -0.5, 0)))
        assert xy_up[1] < xy[1]
        # and a point to the right (+x) is to the right in the image
        xy_r = _check_camera_sees(c, np.add(SCENE_CENTRE, (0.5, 0, 0)))
        assert xy_r[0] > xy[0]


def test_arc_geometry():
    cams = arc_cameras(5, arc_deg=40.0, radius=3.0)
    tgt = np.asarray(SCENE_CENTRE)
    d = [np.linalg.norm(c.centre - tgt) for c in cams]
    np.testing.assert_allclose(d, d[0])
    for c in cams:  # looks straight at the target: it projects to the principal point
        xy, _ = c.project(tgt)
        np.testing.assert_allclose(xy, c.K[:2, 2], atol=1e-9)
    a = [np.degrees(np.arctan2(c.centre[0] - tgt[0], tgt[2] - c.centre[2])) for c in cams]
    np.testing.assert_allclose(a, np.linspace(-20, 20, 5), atol=1e-9)


@pytest.mark.parametrize("layout", ["arc", "free"])
def test_arc_free_scenes(layout):
    s = make_scene(layout, n_views=3, width=40, height=40)
    assert len(s) == 3 and s.grid is None and s.meta["layout"] == layout
    assert all(np.all(np.isfinite(v.depth)) for v in s.views)


# ------------------------------------------------------------------ depth degradation
def _ramp(h=120, w=160):
    return np.linspace(2.0, 6.0, h * w, dtype=np.float32).reshape(h, w)


def test_degrade_identity_and_nan():
    d = _ramp()
    np.testing.assert_array_equal(degrade_depth(d), d)
    d2 = d.copy()
    d2[:5] = np.nan
    out = degrade_depth(d2, noise=0.05, quantise=0.01)
    assert np.all(np.isnan(out[:5])) and np.all(np.isfinite(out[5:]))


def test_degrade_holes_fraction_and_blobs():
    d = _ramp()
    out = degrade_depth(d, holes=0.2, seed=1)
    frac = np.isnan(out).mean()
    assert abs(frac - 0.2) < 0.005
    np.testing.assert_array_equal(out[~np.isnan(out)], d[~np.isnan(out)])
    _, n_blobs = label(np.isnan(out))
    assert n_blobs < 0.05 * np.isnan(out).sum()  # blobs, not salt-and-pepper


def test_degrade_noise_std():
    d = _ramp()
    out = degrade_depth(d, noise=0.02, seed=2)
    rel = out / d - 1
    assert abs(rel.std() - 0.02) < 0.001
    assert abs(rel.mean()) < 0.001
    np.testing.assert_array_equal(degrade_depth(d, noise=0.02, seed=2), out)
    assert not np.array_equal(degrade_depth(d, noise=0.02, seed=3), out)


def test_degrade_quantise():
    d = _ramp()
    q = 0.01
    out = degrade_depth(d, quantise=q)
    k = 1.0 / (out.astype(np.float64) * q)
    np.testing.assert_allclose(k, np.round(k), atol=1e-3)  # 1/z on a grid of step q
    assert np.abs(1 / out - 1 / d).max() <= q / 2 + 1e-5
    assert len(np.unique(out)) < 0.1 * out.size


def test_photograph_noise_gain_blur_and_8_bits():
    """photograph: 8-bit images; with only noise the residual has the asked std; with only
    exposure each view is its ray-cast image times one gain within the bound; a blur lowers
    the image's high frequencies; cameras and depth are kept; the same seed, the same images."""
    from vibr.synthetic import photograph

    sc = make_scene("free", n_views=3, width=96, height=72, seed=0)
    noisy = photograph(sc, noise=3.0, blur=0.0, exposure=0.0, seed=5)
    for a, b in zip(sc.views, noisy.views):
        assert np.array_equal(np.round(b.image * 255), b.image * 255)
        inner = (a.image > 0.05) & (a.image < 0.95)  # unclipped
        assert abs(np.std((b.image - a.image)[inner]) * 255 - 3.0) < 0.15
        assert b.camera is a.camera and np.array_equal(b.depth, a.depth, equal_nan=True)
    gains = []
    for a, b in zip(sc.views, photograph(sc, noise=0.0, blur=0.0, exposure=0.1).views):
        m = (a.image > 0.1) & (a.image < 0.85)
        g = float(np.median(b.image[m] / a.image[m]))
        assert 0.9 - 0.01 <= g <= 1.1 + 0.01 and np.abs(b.image[m] - g * a.image[m]).max() <= 1 / 255
        gains.append(g)
    assert np.ptp(gains) > 0.005  # each view its own gain
    lap = lambda im: np.abs(np.diff(im, 2, axis=1)).mean()  # noqa: E731
    blurred = photograph(sc, noise=0.0, blur=1.0, exposure=0.0)
    assert all(lap(b.image) < 0.7 * lap(a.image) for a, b in zip(sc.views, blurred.views))
    again = photograph(sc, noise=3.0, blur=0.0, exposure=0.0, seed=5)
    assert all(np.array_equal(a.image, b.image) for a, b in zip(noisy.views, again.views))
    with pytest.raises(ValueError):
        photograph(sc, noise=-1.0)
