"""compute_samples end to end: closed-form case, per-sample fields, bad input, degenerate views."""

import numpy as np
import pytest

from _helpers import pinhole
from vibr.camera import Camera
from vibr.errors import VibrInputError
from vibr.geometry import Samples, compute_samples
from vibr.scene import Scene, View

W, H, F = 40, 30, 50.0


def _cam_at(C, R=np.eye(3), f=F):
    """The W × H test camera at centre ``C``."""
    return pinhole(f, W, H, R, C)


def _img(seed=0):
    return np.random.default_rng(seed).random((H, W, 3)).astype(np.float32)


def test_translation_plane_samples():
    b, z = 0.2, 2.5
    img = _img()
    src = View("s", img, _cam_at([0, 0, 0]), np.full((H, W), z), sigma_z=0.05)
    tgt = _cam_at([b, 0, 0])
    s = compute_samples(Scene([src]), tgt, keep=("jac", "src_xy"))
    assert isinstance(s, Samples) and s.target_shape == (H, W)
    shift = F * b / z  # 4 px
    np.testing.assert_allclose(s.xy[:, 0], s.src_xy[:, 0] - shift, atol=1e-9)
    np.testing.assert_allclose(s.xy[:, 1], s.src_xy[:, 1], atol=1e-9)
    assert len(s) == H * (W - int(shift))  # the 4 leftmost columns land outside
    assert s.meta["counts"]["s"]["outside"] == H * int(shift)
    np.testing.assert_allclose(s.jac, np.broadcast_to(np.eye(2), (len(s), 2, 2)), atol=1e-7)
    np.testing.assert_allclose(s.inv_det, 1.0)
    # (the fields other than xy are float32)
    np.testing.assert_allclose(s.dtau_dz, np.broadcast_to([F * b / z**2, 0], (len(s), 2)), rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(s.sigma_z, 0.05)
    # colours and (default: forward-difference) gradients of the source at src_xy
    x, y = s.src_xy[:, 0], s.src_xy[:, 1]
    np.testing.assert_array_equal(s.colour, img[y, x])
    inner = (x < W - 1) & (y < H - 1)
    gx = img[y, np.minimum(x + 1, W - 1)] - img[y, x]
    gy = img[np.minimum(y + 1, H - 1), x] - img[y, x]
    np.testing.assert_allclose(s.grad[inner, :, 0], gx[inner], atol=1e-6)
    np.testing.assert_allclose(s.grad[inner, :, 1], gy[inner], atol=1e-6)
    # world points: depth z in the source frame, reproject onto src_xy
    np.testing.assert_allclose(s.X[:, 2], z)
    xy, _ = src.camera.project(s.X)
    np.testing.assert_allclose(xy, s.src_xy, atol=1e-5)  # X is float32
    assert s.view.dtype == np.int32 and s.src_xy.dtype == np.int32
    assert s.colour.dtype == np.float32 and s.grad.dtype == np.float32
    assert np.all((s.xy >= 0) & (s.xy <= [W - 1, H - 1]))


def test_unknown_depth_is_skipped_or_filled():
    img = np.full((H, W, 3), 0.5, np.float32)
    d = np.full((H, W), 2.0)
    d[10:13, 10:13] = np.nan
    sc = Scene([View("s", img, _cam_at([0, 0, 0]), d)])
    tgt = _cam_at([0, 0, 0])
    s = compute_samples(sc, tgt, keep="src_xy")
    assert len(s) == H * W - 9 and s.meta["counts"]["s"]["unknown"] == 9
    assert not np.any((s.src_xy[:, 0] == 11) & (s.src_xy[:, 1] == 11))
    s2 = compute_samples(sc, tgt, fill_holes=True)
    assert len(s2) == H * W


def test_default_sigma_z_and_map():
    d = np.full((H, W), 4.0)
    sc = Scene([View("s", _img(), _cam_at([0, 0, 0]), d)])
    s = compute_samples(sc, _cam_at([0, 0, 0]))
    np.testing.assert_allclose(s.sigma_z, 0.01 * 4.0)  # DEFAULT_SIGMA_Z_REL · median depth
    smap = np.arange(H * W, dtype=np.float32).reshape(H, W) * 1e-3
    sc2 = Scene([View("s", _img(), _cam_at([0, 0, 0]), d, sigma_z=smap)])
    s2 = compute_samples(sc2, _cam_at([0, 0, 0]), keep="src_xy")
    np.testing.assert_allclose(s2.sigma_z, smap[s2.src_xy[:, 1], s2.src_xy[:, 0]], rtol=1e-6)


def test_inv_det_is_capped():
    # a source with 3× the focal length sees the plane at 3× the target's resolution:
    # det = (1/3)² → 1/det = 9, capped at DEFAULT_MAX_INV_DET = 4 (or what is asked)
    d = np.full((H, W), 2.0)
    zoom = View("zoom", _img(), _cam_at([0, 0, 0], f=3 * F), d)
    s = compute_samples(Scene([zoom]), _cam_at([0, 0, 0]))
    np.testing.assert_allclose(s.inv_det, 4.0)
    np.testing.assert_allclose(compute_samples(Scene([zoom]), _cam_at([0, 0, 0]), max_inv_det=10.0).inv_det, 9.0)
    np.testing.assert_allclose(compute_samples(Scene([zoom]), _cam_at([0, 0, 0]), max_inv_det=1.0).inv_det, 1.0)
    # a grazing surface (det → 0) stays bounded too
    y, x = np.mgrid[0:H, 0:W].astype(float)
    steep = View("steep", _img(), _cam_at([0, 0, 0]), 2.0 + 5.0 * x)
    s2 = compute_samples(Scene([steep]), _cam_at([0.01, 0, 0]))
    assert np.all(s2.inv_det <= 4.0) and np.all(np.isfinite(s2.inv_det))


def test_no_view_sees_the_target_and_degenerate_sources():
    d = np.full((H, W), 2.0)
    sc = Scene([View("s", _img(), _cam_at([0, 0, 0]), d)])
    # target behind the plane and facing away from it
    away = Camera.from_centre(Camera.intrinsics(F, W, H), np.diag([-1.0, 1.0, -1.0]), [0, 0, 0], W, H,
                              source="target.json")
    with pytest.raises(VibrInputError, match="target.json.*no source view sees the target"):
        compute_samples(sc, away)
    # a source whose whole depth is behind the target camera yields zero samples, no crash
    behind = View("behind", _img(1), _cam_at([0, 0, 0.2]), np.full((H, W), 0.5))  # points at z = 0.7
    s = compute_samples(Scene([sc.views[0], behind]), _cam_at([0, 0, 1.0]))
    assert s.meta["counts"]["behind"]["visible"] == 0
    assert s.meta["counts"]["behind"]["behind"] == H * W
    assert np.all(s.view == 0) and len(s) > 0


def test_source_without_depth_is_an_input_error():
    sc = Scene([View("nodepth", _img(), _cam_at([0, 0, 0]), path="photos/nodepth.png")])
    with pytest.raises(VibrInputError, match="photos/nodepth.png"):
        compute_samples(sc, _cam_at([0, 0, 0]))


def test_occluder_hides_the_background():
    # background plane at z = 4 seen by the source, a foreground square at z = 2 in the middle
    d = np.full((H, W), 4.0)
    d[10:20, 15:25] = 2.0
    sc = Scene([View("s", _img(), _cam_at([0, 0, 0]), d)])
    s = compute_samples(sc, _cam_at([0.1, 0, 0]), keep="src_xy")  # foreground moves 2.5 px, background 1.25 px
    c = s.meta["counts"]["s"]
    assert c["occluded"] > 0
    # the occluded background pixels are just left of the square (covered by its shift)
    occl = np.ones((H, W), bool)
    occl[s.src_xy[:, 1], s.src_xy[:, 0]] = False
    occl[:, :2] = False  # outside
    ys, xs = np.nonzero(occl)
    assert np.all((ys >= 10) & (ys < 20)) and np.all((xs >= 13) & (xs < 15))


def test_samples_are_sorted_by_target_cell():
    """compute_samples returns the samples grouped by the target cell they land in
    (row-major), the same set as before the reordering: every source pixel once."""
    from vibr.synthetic import make_scene

    sc = make_scene("grid", width=48, height=40, seed=0, grid=(2, 2))
    src, tg = sc.split(0)
    s = compute_samples(src, tg.camera, keep=("jac", "src_xy"))
    H, W = s.target_shape
    x = np.minimum(np.floor(s.xy[:, 0]), W - 2)
    y = np.minimum(np.floor(s.xy[:, 1]), H - 2)
    key = y * (W - 1) + x
    assert len(s) > 1000 and np.all(np.diff(key) >= 0)
    pix = s.view.astype(np.int64) * (H * W) + s.src_xy[:, 1] * W + s.src_xy[:, 0]
    assert len(np.unique(pix)) == len(s)
    # stable: within a cell, the sources' order (view, then row-major pixel)
    assert np.array_equal(np.lexsort((pix, key)), np.arange(len(s)))
    for f in ("colour", "jac", "inv_det", "dtau_dz", "sigma_z", "X"):
        assert getattr(s, f).dtype == np.float32


@pytest.mark.parametrize("threads", [1, 2])
def test_fields_of_views_of_two_sizes(threads):
    """Views of different sizes (one at half resolution), one with a sigma_z map: each
    sample's fields are its source pixel's, from the warp (vibr.geometry.warp.warp_view), the
    image and its gradient (grad_image), with one thread or two."""
    import numba

    from vibr.geometry.depth import depth_derivatives
    from vibr.geometry.gradient import grad_image
    from vibr.geometry.resample import scaled_scene
    from vibr.geometry.warp import warp_view
    from vibr.synthetic import make_scene

    sc = make_scene("free", n_views=5, width=48, height=40, seed=1)
    views = list(sc.views)
    views[2] = scaled_scene(Scene([views[2]]), 0.5).views[0]
    views[3] = views[3].replace(sigma_z=np.full(views[3].depth.shape, 0.05, np.float32))
    src, tg = Scene(views[1:]), views[0]
    before = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        s = compute_samples(src, tg, keep=("jac", "src_xy"))
    finally:
        numba.set_num_threads(before)
    assert set(np.unique(s.view)) == {0, 1, 2, 3} and np.unique(s.sigma_z).size > 1
    assert all(v.sigma_z is not None for v in src.views)
    for k, v in enumerate(src.views):
        m = s.view == k
        x, y = s.src_xy[m, 0], s.src_xy[m, 1]
        assert m.sum() > 50 and x.max() < v.camera.width and y.max() < v.camera.height
        z = np.asarray(v.depth, np.float64)
        w = warp_view(v.camera, tg.camera, z, *depth_derivatives(z))
        np.testing.assert_allclose(s.xy[m], w["tau"][y, x], rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(s.jac[m], w["jac"][y, x], rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(s.dtau_dz[m], w["dtau_dz"][y, x], rtol=1e-5, atol=1e-9)
        np.testing.assert_array_equal(s.colour[m], v.image[y, x])
        g = grad_image(np.ascontiguousarray(v.image.transpose(2, 0, 1)))  # (3, 2, H, W)
        np.testing.assert_array_equal(s.grad[m], g[:, :, y, x].transpose(2, 0, 1))
        sz = np.broadcast_to(v.sigma_z, z.shape)  # a scalar or, for one view, a map
        np.testing.assert_array_equal(s.sigma_z[m], np.asarray(sz, np.float32)[y, x])
        xy, _ = v.camera.project(s.X[m])
        np.testing.assert_allclose(xy, s.src_xy[m], atol=2e-3)  # X is float32


def test_optional_fields_are_computed_only_when_kept():
    """jac and src_xy (no default render reads them) are None unless kept; the other fields
    are the same either way, and the footprint PSF asks for what it needs."""
    from vibr.errors import VibrInputError
    from vibr.render import render
    from vibr.render.api import render_samples
    from vibr.render.methods import sample_fields

    d = np.full((H, W), 4.0)
    d[10:20, 15:25] = 2.0
    sc = Scene([View("s", _img(), _cam_at([0, 0, 0]), d)])
    lean = compute_samples(sc, _cam_at([0.1, 0, 0]))
    full = compute_samples(sc, _cam_at([0.1, 0, 0]), keep=("jac", "src_xy"))
    assert lean.jac is None and lean.src_xy is None
    assert full.jac.shape == (len(full), 2, 2) and full.src_xy.shape == (len(full), 2)
    for f in ("xy", "colour", "grad", "inv_det", "dtau_dz", "sigma_z", "view", "X"):
        np.testing.assert_array_equal(getattr(lean, f), getattr(full, f))
    assert lean.select(lean.view == 0).jac is None
    assert sample_fields("gradient") == () and sample_fields("gradient", psf="footprint") == ("jac",)
    from vibr.paths.flythrough import FrameContext

    assert FrameContext(sc, [], "x", params={"psf": "footprint"}).geometry_kw["keep"] == ("jac",)
    assert FrameContext(sc, [], "x", geometry_kw={"keep": ("src_xy",)}).geometry_kw["keep"] == ("src_xy",)
    with pytest.raises(VibrInputError, match="keep"):
        compute_samples(sc, _cam_at([0.1, 0, 0]), keep=("normals",))
    with pytest.raises(VibrInputError, match="Jacobians"):
        render_samples(lean, "bvs", psf="footprint")
    # render() computes what its PSF reads
    a = render(sc, _cam_at([0.1, 0, 0]), "bvs", psf="footprint").image
    b = render_samples(full, "bvs", psf="footprint", source_centres=np.zeros((1, 3)),
                       target_centre=np.array([0.1, 0, 0])).image
    np.testing.assert_array_equal(a, b)


def test_a_target_one_pixel_high_is_refused_by_name():
    """(It read 'no source view sees the target': no bilinear cell fits in one row.)"""
    from vibr.synthetic import make_scene

    s = make_scene("grid", n_views=3, width=48, height=32, seed=1)
    c = s.views[1].camera
    with pytest.raises(VibrInputError, match="768x1: at least 2 pixels a side"):
        compute_samples(s.subset([0, 2]), Camera(Camera.intrinsics(50.0, 768, 1), c.R, c.t, 768, 1))


def test_georeferenced_coordinates_render_as_at_the_origin():
    """A scene half a million units from the origin (UTM-like coordinates, a metre-scale
    baseline): depth estimated from the sources and the render come out as for the same
    scene at the origin (an early shared-centre test measured the spread against the
    distance from the origin and took these cameras for one centre: 16.7 dB). The estimated
    depth differs at a few pixels (the matches that float rounding at 5e5 tips), which moves
    the render by up to about 0.2 dB from one (gamma, lam) to another."""
    from vibr.pipeline import prepare
    from vibr.render import render
    from vibr.synthetic import make_scene

    sc = make_scene("handheld", n_views=5, width=96, height=72, seed=2)
    sc = sc.replace(views=[v.replace(depth=None, sigma_z=None) for v in sc.views], points=None)
    off = np.array([5e5, -1.7e5, 7e4])
    far = sc.replace(views=[v.replace(camera=Camera.from_centre(v.camera.K, v.camera.R, v.camera.centre + off,
                                                               v.camera.width, v.camera.height))
                            for v in sc.views])
    psnr = []
    for s in (sc, far):
        src, t = prepare(s, 2, cache_dir=False)
        assert src.meta["depth_source"] == "estimated"
        psnr.append(render(src, t, "gradient").metrics["psnr"])
    assert psnr[0] > 28.0 and abs(psnr[1] - psnr[0]) < 0.3, psnr


def test_compute_samples_options_and_keywords():
    """compute_samples' options as a SampleOptions or as keywords over it: the same samples,
    field by field; a misspelt option is a TypeError, not a default."""
    from vibr.geometry import SampleOptions
    from vibr.synthetic import make_scene

    s = make_scene("grid", n_views=9, width=40, height=32, seed=0)
    src, tgt = s.split(4)
    a = compute_samples(src, tgt, vis_threshold=0.05, keep=("jac",), grad_scheme="central")
    b = compute_samples(src, tgt, options=SampleOptions(vis_threshold=0.05, keep=("jac",), grad_scheme="central"))
    c = compute_samples(src, tgt, options=SampleOptions(vis_threshold=0.5), vis_threshold=0.05, keep=("jac",),
                        grad_scheme="central")
    d = compute_samples(src, tgt)
    for other in (b, c):
        assert len(other) == len(a) and other.meta["vis_threshold"] == 0.05
        for f in ("xy", "colour", "grad", "inv_det", "view", "jac"):
            np.testing.assert_array_equal(getattr(other, f), getattr(a, f))
    assert d.jac is None and d.meta["grad_scheme"] != "central"
    with pytest.raises(TypeError, match="vis_treshold"):
        compute_samples(src, tgt, vis_treshold=0.05)
