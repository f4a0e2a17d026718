"""Sources finer or coarser than the target: the pixel size of a source in the target (closed
forms), the grid a target is rendered on (supersampling, source reduction, a coarser grid
enlarged), and what it buys (docs/explanation/renderer.md, "Sources finer than the target", "Sources
coarser than the target")."""

import math

import numpy as np
import pytest

from _helpers import pinhole
from vibr.camera import Camera
from vibr.errors import VibrInputError
from vibr.render.methods import DEFAULTS
from vibr.scene import View


@pytest.fixture(autouse=True)
def _cache_in_tmp(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("VIBR_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "vibr-cache"))


@pytest.fixture(scope="module")
def grid128():
    from vibr.synthetic import make_scene

    return make_scene("grid", n_views=9, width=128, height=128, seed=3)


def _plane_view(cam, z0=5.0):
    return View("v", np.zeros(cam.shape + (3,), np.float32), cam, depth=np.full(cam.shape, z0, np.float32))


def _front_cam(W=64, H=48, f=60.0, C=(0.0, 0.0, 0.0)):
    """A camera looking down +z (at a fronto-parallel plane, :func:`_plane_view`)."""
    return pinhole(f, W, H, C=C)


# ------------------------------------------------------------------ closed forms
def test_pixel_size_closed_forms():
    """A fronto-parallel plane: the same camera → 1; the camera for images half the size
    → 0.5; the same camera twice as far from the plane → 0.5 (f/z halves); 4× the focal
    length → 4; a target looking away → NaN (nothing to measure)."""
    from vibr.geometry.resolution import source_pixel_size

    src = _front_cam()
    v = _plane_view(src)
    assert source_pixel_size(v, src) == pytest.approx(1.0, abs=1e-12)
    assert source_pixel_size(v, src.scaled(0.5)) == pytest.approx(0.5, abs=1e-12)
    assert source_pixel_size(v, _front_cam(C=(0, 0, -5.0))) == pytest.approx(0.5, abs=1e-12)
    assert source_pixel_size(v, _front_cam(f=240.0)) == pytest.approx(4.0, abs=1e-12)
    away = Camera.from_centre(src.K, np.diag([1.0, -1.0, -1.0]), np.zeros(3), 64, 48)
    assert math.isnan(source_pixel_size(v, away))
    assert math.isnan(source_pixel_size(View("n", v.image, src), src))  # no depth


def test_reduction_scale_and_plan():
    """Reductions are powers of 1/√2 never below the pixel size; "auto" supersamples by
    round(1/size) up to 4 and reduces only what stays more than twice finer than the grid."""
    from vibr.geometry.resolution import reduction_scale, resolution_plan

    assert [reduction_scale(s) for s in (1.0, 0.8, 0.7, 0.5, 0.4, 0.25, math.nan)] == \
        [1.0, 1.0, pytest.approx(2 ** -0.5), 0.5, 0.5, 0.25, 1.0]
    for s in (0.01, 0.13, 0.3, 0.49, 0.6):
        r = reduction_scale(s)
        assert s <= r < s * math.sqrt(2) + 1e-12
    src = _front_cam(W=160, H=128)
    scene = _scene([_plane_view(src)])
    for f, k, scales in ((1.0, 1, {}), (0.5, 2, {}), (0.25, 4, {}), (0.125, 4, {}), (0.0625, 4, {"v": 0.25})):
        plan = resolution_plan(scene, src.scaled(f))
        assert plan.supersample == k and plan.scales == pytest.approx(scales)
        assert plan.sizes["v"] == pytest.approx(f, rel=1e-9)
    assert resolution_plan(scene, src.scaled(0.25), supersample=1).scales == {"v": 0.25}
    assert resolution_plan(_scene([_plane_view(_front_cam(W=40, H=32))]), _front_cam(W=40, H=32).scaled(0.125),
                           supersample=1).scales == {}  # 8 px would be too small to warp
    assert resolution_plan(scene, src.scaled(0.5), supersample=3).supersample == 3


def _scene(views):
    from vibr.scene import Scene

    return Scene(views, "t", None, None, None, {})


@pytest.mark.parametrize("bad", [0, -1, 1.5, "two", True, None, float("nan")])
def test_bad_supersample_is_refused(bad):
    from vibr.geometry.resolution import check_supersample

    with pytest.raises(VibrInputError, match="supersample must be 'auto' or an integer >= 1"):
        check_supersample(bad)
    assert check_supersample("AUTO") == "auto" and check_supersample("2") == 2 and check_supersample(3.0) == 3


def test_box_reduced_means_blocks():
    from vibr.render import RenderResult

    img = np.arange(4 * 6 * 3, dtype=np.float32).reshape(4, 6, 3)
    cov = np.ones((4, 6), bool)
    cov[0, 0] = False
    sig = np.full((4, 6), 2.0, np.float32)
    sig[0, 1] = 4.0
    r = RenderResult(img, cov, uncertainty=sig).box_reduced(2)
    assert r.image.shape == (2, 3, 3) and np.allclose(r.image[1, 2], img[2:4, 4:6].mean(axis=(0, 1)))
    assert r.coverage.tolist() == [[False, True, True], [True, True, True]]
    assert r.uncertainty[0, 0] == pytest.approx(math.sqrt((3 * 4 + 16) / 4)) and r.uncertainty[1, 1] == 2.0
    assert RenderResult(img, cov).box_reduced(1).image is img


# ------------------------------------------------------------------ renders
def _reference(view, f):
    from skimage.transform import downscale_local_mean

    return downscale_local_mean(view.image.astype(np.float64), (f, f, 1)).astype(np.float32)


@pytest.mark.parametrize("method", ["gradient", "ulr"])
def test_supersampled_render_beats_the_target_grid(grid128, method):
    """The centre view at half the sources' resolution, against the photograph averaged
    over 2×2 blocks (a pixel-integrating sensor): "auto" renders on the sources' grid and
    averages, and is at least 3 dB closer than rendering on the target's own grid (the
    bilinear PSF reads every fine source pixel as a point sample: aliasing)."""
    from vibr.metrics import psnr
    from vibr.render import render

    tgt = grid128.views[4]
    src = grid128.subset([v.name for v in grid128.views if v.name != tgt.name])
    cam = tgt.camera.scaled(0.5)
    ref = _reference(tgt, 2)
    auto = render(src, cam, method)
    own = render(src, cam, method, supersample=1)
    assert auto.params["supersample"] == 2 and own.params["supersample"] == 1
    assert auto.image.shape == own.image.shape == ref.shape
    both = auto.coverage & own.coverage
    assert psnr(auto.image, ref, mask=both, border=2) > psnr(own.image, ref, mask=both, border=2) + 3.0
    # the same as rendering the fine grid by hand (lam / 2 there) and averaging
    fine = render(src, cam.scaled(2), method, supersample=1, grid_factor=2)
    assert np.array_equal(auto.image, fine.box_reduced(2).image)
    if method == "gradient":
        assert auto.params["grid_factor"] == 2
        half = render(src, cam.scaled(2), method, supersample=1, lam=DEFAULTS["lam"] / 2)
        assert np.array_equal(fine.image, half.image)


def test_the_target_at_the_sources_resolution_is_unchanged(grid128):
    """Supersampling never applies to a target at its sources' resolution: the render is
    bit-identical to the target's own grid."""
    from vibr.render import render

    src = grid128.subset([v.name for v in grid128.views if v.name != "view_004"])
    a = render(src, grid128["view_004"].camera)
    b = render(src, grid128["view_004"].camera, supersample=1)
    assert a.params["supersample"] == 1 and a.params["reduced_sources"] == {}
    assert np.array_equal(a.image, b.image)


def test_footprint_psf_keeps_the_target_grid(grid128):
    """The footprint PSF models fine sources itself: "auto" leaves it on the target's grid
    with the sources as they are; an explicit factor still applies, and so does the coarser
    grid for coarser sources (the footprint model shrinks their footprints to a pixel)."""
    from vibr.render import render

    src = grid128.subset([v.name for v in grid128.views if v.name != "view_004"])
    cam = grid128["view_004"].camera.scaled(0.25)
    r = render(src, cam, psf="footprint")
    assert r.params["supersample"] == 1 and r.params["reduced_sources"] == {}
    assert render(src, cam, psf="footprint", supersample=2).params["supersample"] == 2
    near = grid128["view_004"].camera.scaled(4)  # sources coarser: its footprints shrink to 1 px, a coarser grid
    r = render(src, near, psf="footprint")
    assert r.params["coarsen"] == pytest.approx(2 * math.sqrt(2.0)) and r.image.shape[:2] == near.shape


def test_far_finer_sources_are_reduced(grid128):
    """A thumbnail of 8×8 from sources of 128²: the grid is 4× finer (the cap) and the
    sources, still 4× finer than it, are reduced to a quarter of their size first."""
    from vibr.render import render

    src = grid128.subset([v.name for v in grid128.views if v.name != "view_004"])
    r = render(src, grid128["view_004"].camera.scaled(1 / 16))
    assert r.params["supersample"] == 4 and r.image.shape == (8, 8, 3)
    assert set(r.params["reduced_sources"]) == set(src.names)
    assert all(s == pytest.approx(0.25) for s in r.params["reduced_sources"].values())


def test_flythrough_frame_at_half_size_matches_render(grid128, tmp_path):
    """A fly-through frame at half the photographs' size is supersampled as `vibr render`
    renders it: the same image within a grey level (the frame is 8-bit); the frame's record
    says so, and the job's key (resumed frames) depends on the factor."""
    from vibr.io import read_image
    from vibr.paths.camera_path import CameraPath
    from vibr.paths.flythrough import FrameContext, job_key, render_path
    from vibr.render import render

    src = grid128.subset([v.name for v in grid128.views if v.name != "view_004"])
    cam = grid128["view_004"].camera.scaled(0.5)
    res = render_path(src, CameraPath([cam], fps=1.0), tmp_path / "fr", n_views=None, executor=None,
                      progress=False, check_scene=False)
    assert res.frames[0]["supersample"] == 2
    fr = read_image(tmp_path / "fr" / "frame_00000.png")
    ref = render(src, cam).image
    assert np.abs(fr - np.rint(np.clip(ref, 0, 1) * 255) / 255).max() <= 1 / 255 + 1e-6
    keys = {job_key(FrameContext(src, [cam], "d", supersample=k)) for k in ("auto", 1, 2)}
    assert len(keys) == 3
    big = grid128["view_004"].camera.scaled(4)  # a frame four times the photographs' size: a coarser grid
    res = render_path(src, CameraPath([big], fps=1.0), tmp_path / "big", n_views=None, executor=None,
                      progress=False, check_scene=False)
    assert res.frames[0]["coarsen"] == pytest.approx(2 * math.sqrt(2.0)) and res.frames[0]["supersample"] == 1
    fr = read_image(tmp_path / "big" / "frame_00000.png")
    assert np.abs(fr - np.rint(render(src, big).image * 255) / 255).max() <= 1 / 255 + 1e-6


def test_cli_supersample_option(tmp_path, capsys):
    """`--supersample 0` is refused in one line (exit 2); `--supersample 1` renders."""
    from vibr.cli import main
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    save_scene(make_scene("grid", n_views=9, width=48, height=48, seed=1), tmp_path / "s")
    for bad in ("0", "1.5", "x"):
        with pytest.raises(SystemExit) as e:
            main(["render", str(tmp_path / "s"), "--target", "view_004", "-o", str(tmp_path / "o.png"),
                  "--supersample", bad])
        assert e.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()[-1]
        assert "supersample must be 'auto' or an integer >= 1" in err
    assert main(["render", str(tmp_path / "s"), "--target", "view_004", "-o", str(tmp_path / "o.png"),
                 "--supersample", "1", "-q"]) == 0
    assert not (tmp_path / "o.png.tmp").exists() and (tmp_path / "o.png").exists()


def test_cli_path_says_when_frames_are_supersampled(tmp_path, capsys):
    """`vibr render --path` with frames half the photographs' size says it rendered them on
    a finer grid (and how to turn it off), with frames four times their size on a coarser
    one; at the photographs' size it says nothing."""
    from vibr.cli import main
    from vibr.io import load_scene, save_scene
    from vibr.paths.camera_path import write_camera_path
    from vibr.synthetic import make_scene

    save_scene(make_scene("grid", n_views=9, width=64, height=64, seed=1), tmp_path / "s")
    cam = load_scene(tmp_path / "s")["view_004"].camera
    for name, c, said in (("half", cam.scaled(0.5), "finer"), ("full", cam, None), ("four", cam.scaled(4), "coarser")):
        write_camera_path(tmp_path / f"{name}.json", [c], fps=1.0)
        capsys.readouterr()
        assert main(["render", str(tmp_path / "s"), "--path", str(tmp_path / f"{name}.json"), "-o",
                     str(tmp_path / name), "--workers", "1", "-q"]) == 0
        out = capsys.readouterr().out
        assert ("rendered on a grid 2x finer and averaged back (--supersample 1" in out) == (said == "finer")
        assert ("the photographs are coarser than the frames: rendered on a grid 2.83x coarser and enlarged "
                "(--supersample 1" in out) == (said == "coarser")


# ------------------------------------------------------------------ the gradient's frame
def test_chain_gradient_is_the_jacobian_transposed_inverse(grid128):
    """``grad_model="chain"`` gives every sample ``J⁻ᵀ ∇v`` (J the warp's Jacobian, kept
    with ``keep=("jac",)``), where 1/|det J| is under the cap; "translation" gives ``∇v``
    as it is. Closed form: the target camera for half-size images has J = ½ I, so the
    chain gradients are twice the translation ones."""
    from vibr.geometry import compute_samples

    src = grid128.subset([v.name for v in grid128.views if v.name != "view_004"])
    cam = grid128["view_004"].camera
    a = compute_samples(src, cam, keep=("jac",))
    b = compute_samples(src, cam, keep=("jac",), grad_model="chain")
    assert a.meta["grad_model"] == "translation" and b.meta["grad_model"] == "chain"
    assert np.array_equal(a.xy, b.xy) and np.array_equal(a.colour, b.colour)
    det = np.linalg.det(a.jac.astype(np.float64))
    ok = np.abs(det) * 4.0 > 1.0
    want = np.einsum("nji,ncj->nci", np.linalg.inv(a.jac[ok].astype(np.float64)), a.grad[ok].astype(np.float64))
    assert ok.mean() > 0.9 and np.allclose(b.grad[ok], want, rtol=1e-4, atol=1e-5)
    v = src.views[0]
    one = src.subset([v.name])
    h = compute_samples(one, v.camera.scaled(0.5), grad_model="chain")
    t = compute_samples(one, v.camera.scaled(0.5))
    assert np.allclose(h.grad, 2.0 * t.grad, rtol=1e-5, atol=1e-6)
    with pytest.raises(VibrInputError, match="grad_model"):
        compute_samples(one, v.camera, grad_model="affine")


# ------------------------------------------------------------------ coarser sources
def test_coarser_sources_weigh_their_gradients_less():
    """Sources at half the target's resolution (a camera closer than the photographs): the
    median source pixel is 2 pixels of the grid, gamma is divided by 4 (bit for bit the render
    with gamma / 4 on the target's grid), and the render is at least 0.3 dB closer to the
    photograph than with gamma as it is (the coarse gradients pull the image toward their
    blur)."""
    from vibr.geometry import compute_samples
    from vibr.geometry.resolution import resolution_plan
    from vibr.metrics import psnr
    from vibr.render import render, render_samples
    from vibr.synthetic import make_scene

    lo = make_scene("grid", n_views=9, width=64, height=64, seed=3)
    hi = make_scene("grid", n_views=9, width=128, height=128, seed=3)
    tgt = hi.views[4]
    src = lo.subset([v.name for v in lo.views if v.name != tgt.name])
    plan = resolution_plan(src, tgt.camera, supersample=1)  # the target's grid (auto: a coarser one, below)
    assert plan.supersample == 1 and plan.grid_source_size == pytest.approx(2.0, rel=1e-6)
    auto = render(src, tgt.camera, supersample=1)
    assert auto.params["grid_source_size"] == pytest.approx(2.0, rel=1e-6)
    S = compute_samples(src, tgt.camera)
    quarter = render_samples(S, gamma=auto.params["gamma"] / plan.grid_source_size ** 2)
    before = render_samples(S)
    assert np.array_equal(auto.image, quarter.image)
    both = auto.coverage & before.coverage
    # 0.44 dB with the defaults (more than 0.5 without lam_density)
    assert psnr(auto.image, tgt.image, mask=both, border=2) > psnr(before.image, tgt.image, mask=both, border=2) + 0.3


def test_coarsen_factor_rule():
    """The coarser grid: a power of √2 near size / √2, none below 2^0.75, never under 16 px."""
    from vibr.geometry.resolution import coarsen_factor

    r2 = math.sqrt(2.0)
    assert coarsen_factor(1.0, (64, 64)) == 1.0 and coarsen_factor(1.6, (64, 64)) == 1.0
    assert coarsen_factor(1.7, (64, 64)) == pytest.approx(r2)
    assert coarsen_factor(2.0, (64, 64)) == pytest.approx(r2)
    assert coarsen_factor(4.0, (64, 64)) == pytest.approx(2 * r2)
    assert coarsen_factor(8.0, (480, 640)) == pytest.approx(4 * r2)
    assert coarsen_factor(8.0, (40, 64)) == pytest.approx(2.0)  # 40 / 2.83 < 16: one step less
    assert coarsen_factor(float("nan"), (64, 64)) == 1.0


def test_sources_much_coarser_render_on_a_coarser_grid():
    """Sources at a quarter of the target's resolution: on the target's grid fewer than 60 %
    of its pixels receive a sample (the rest is the TV prior's fill); "auto" renders on a grid
    2√2 times coarser, where a source pixel is √2 of its pixels, and enlarges it: that render
    done by hand (to 1e-6), more than 90 % covered, and at least 0.2 dB closer to the
    photograph over all pixels (the target's grid fills its holes by push-pull)."""
    from vibr.geometry.resolution import resolution_plan
    from vibr.metrics import psnr
    from vibr.render import render
    from vibr.synthetic import make_scene

    lo = make_scene("grid", n_views=9, width=32, height=32, seed=3)
    hi = make_scene("grid", n_views=9, width=128, height=128, seed=3)
    tgt = hi.views[4]
    src = lo.subset([v.name for v in lo.views if v.name != tgt.name])
    plan = resolution_plan(src, tgt.camera)
    assert plan.supersample == 1 and plan.coarsen == pytest.approx(2 * math.sqrt(2.0))
    assert plan.grid_source_size == pytest.approx(4 * 45 / 128)  # the grid is 45 px wide: 128 / 2√2, rounded
    auto = render(src, tgt.camera)
    assert auto.image.shape == tgt.image.shape and auto.params["coarsen"] == plan.coarsen
    grid = tgt.camera.scaled(1.0 / plan.coarsen)
    by_hand = render(src, grid, supersample=1).enlarged(tgt.camera.shape)
    # the pixel size the hand-made render measures on that grid equals the plan's to one ulp
    np.testing.assert_allclose(auto.image, by_hand.image, atol=1e-6)
    assert np.array_equal(auto.coverage, by_hand.coverage)
    own = render(src, tgt.camera, supersample=1)
    assert own.coverage.mean() < 0.6 and auto.coverage.mean() > 0.9
    # 0.34 dB since the holes take the push-pull fill (more than 0.7 with the TV fill before)
    assert psnr(auto.image, tgt.image, border=2) > psnr(own.image, tgt.image, border=2) + 0.2


def test_enlarged_result_maps_pixel_centres_like_the_camera():
    """A smooth image rendered on a grid and enlarged lands where the finer camera's pixels
    are: a linear ramp in x comes back as the same ramp (the cubic spline is exact on it away
    from the border; a shifted mapping would be off by 1/96 per pixel), coverage conservative
    at a hole's edge."""
    from vibr.render import RenderResult

    H, W, h, w = 64, 96, 16, 24
    x = (np.arange(w) + 0.5) * (W / w) - 0.5  # the fine pixel coordinate of each grid centre
    ramp = np.repeat(np.repeat((x / W)[None, :, None], h, 0), 3, 2).astype(np.float32)
    cov = np.ones((h, w), bool)
    cov[5, 7] = False
    res = RenderResult(image=ramp, coverage=cov).enlarged((H, W))
    assert res.image.shape == (H, W, 3) and res.coverage.shape == (H, W)
    want = np.arange(W) / W
    # the spline's edge condition disturbs the ramp within 5 grid pixels of the border
    np.testing.assert_allclose(res.image[H // 2, 20:-20, 0], want[20:-20], atol=2e-5)
    assert not res.coverage[5 * 4 + 1, 7 * 4 + 1] and res.coverage[H - 1, 0] and res.coverage.mean() > 0.95


def test_spline_enlargement_equals_scipys_spline():
    """The separable cubic spline of `resize_image(..., order=3)` (a target enlarged from a
    coarser grid) is scipy's cubic-spline zoom with the same pixel-centre mapping, to 2e-5
    away from the border (where the two extend the image differently)."""
    from scipy import ndimage as ndi

    from vibr.geometry.resample import resize_image

    rng = np.random.default_rng(0)
    img = ndi.gaussian_filter(rng.random((30, 41, 3)), (1.5, 1.5, 0)).astype(np.float32)
    out = resize_image(img, (85, 116), order=3, quantise=False)
    ref = np.stack([ndi.zoom(img[..., c].astype(np.float64), (85 / 30, 116 / 41), order=3, mode="nearest",
                             grid_mode=True) for c in range(3)], axis=-1)
    assert out.shape == (85, 116, 3) and out.dtype == np.float32
    np.testing.assert_allclose(out[12:-12, 12:-12], ref[12:-12, 12:-12], atol=2e-5)
    grey = resize_image(img[..., 0], (85, 116), order=3, quantise=False)
    np.testing.assert_array_equal(grey, out[..., 0])
