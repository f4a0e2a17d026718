"""Photograph masks (nerfstudio's ``mask_path``, :attr:`vibr.scene.View.mask`): masked
pixels give no sample and hide nothing, a held-out view is measured on its mask, and masks
survive saving, loading, ``--scale`` and undistortion."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibr.errors import VibrInputError
from vibr.io import load_scene, save_scene
from vibr.render import render
from vibr.synthetic import make_scene


@pytest.fixture(scope="module")
def grid96x72():
    return make_scene("grid", n_views=9, width=96, height=72)


def _with_intruder(scene, name="view_003", masked=True, paint=True):
    """``name``'s photograph with a saturated red block over a third of it (a passer-by),
    masked out or not (``paint=False``: the mask without the block)."""
    v = scene[name]
    img = v.image.copy()
    block = np.zeros(v.camera.shape, bool)
    block[10:50, 20:60] = True
    if paint:
        img[block] = [1.0, 0.0, 0.0]
    nv = v.replace(image=img, mask=~block if masked else None)
    return scene.replace(views=[nv if u.name == name else u for u in scene.views])


def _red(img):
    return float(np.mean(np.clip(img[..., 0] - img[..., 1:].mean(-1), 0, None)))


@pytest.mark.parametrize("method", ["ulr", "gradient"])
def test_masked_pixels_give_no_sample(grid96x72, method):
    """The red block, unmasked, bleeds into the render of the centre view; masked, its
    colours do not matter: the render equals, bit for bit, that of the clean photograph with
    the same mask (which, having a view fewer there, is 0.4-0.6 dB below the clean scene's,
    as dropping view_003 altogether is)."""
    tgt = grid96x72["view_004"]
    cases = (("clean", grid96x72), ("masked", _with_intruder(grid96x72)),
             ("unmasked", _with_intruder(grid96x72, masked=False)),
             ("clean, masked", _with_intruder(grid96x72, paint=False)))
    srcs = {k: s.replace(views=[v for v in s.views if v.name != "view_004"]) for k, s in cases}
    res = {k: render(s, tgt, method=method) for k, s in srcs.items()}
    psnr = {k: r.metrics["psnr"] for k, r in res.items()}
    assert psnr["unmasked"] < psnr["clean"] - 3.0
    np.testing.assert_array_equal(res["masked"].image, res["clean, masked"].image)
    assert _red(res["masked"].image) < _red(res["unmasked"].image) - 0.01


def test_masked_pixels_hide_nothing(grid96x72):
    """A masked pixel's depth is unknown to the geometry stage (no z-buffer entry, no
    sample): prepare_depth returns NaN there."""
    from vibr.geometry import prepare_depth

    v = _with_intruder(grid96x72)["view_003"]
    z, _, _ = prepare_depth(v)
    assert np.isnan(z[~v.mask]).all()
    assert np.isnan(z[9, 20:60]).all() and np.isfinite(z[8, 20:60]).all()  # one pixel more: ∇v reads it
    assert np.isfinite(z[:8]).all() and np.isfinite(z[51:]).all()


def test_held_out_view_is_measured_on_its_mask(grid96x72):
    """The red block in the held-out photograph is not an error of the render."""
    from vibr.eval.protocol import Setting, evaluate

    for masked, expect in ((True, lambda p: p > 35), (False, lambda p: p < 20)):
        sc = _with_intruder(grid96x72, "view_004", masked=masked)
        r = evaluate(sc, "view_004", [Setting("gradient")], use_lpips=False)
        assert expect(r["results"][0]["psnr"]), (masked, r["results"][0]["psnr"])
        if masked:
            assert r["evaluated_fraction"] < 1 - 40 * 40 / (96 * 72) + 1e-9


def test_masks_round_trip_through_transforms_json(grid96x72, tmp_path):
    sc = _with_intruder(grid96x72)
    save_scene(sc, tmp_path / "s")
    doc = json.loads((tmp_path / "s" / "transforms.json").read_text())
    paths = [f.get("mask_path") for f in doc["frames"]]
    assert paths.count(None) == 8 and "masks/view_003.png" in paths
    back = load_scene(tmp_path / "s")
    np.testing.assert_array_equal(back["view_003"].mask, sc["view_003"].mask)
    assert back["view_000"].mask is None
    half = load_scene(tmp_path / "s", scale=0.5)["view_003"].mask
    assert half.shape == (36, 48) and not half[5:25, 10:30].any() and half[30:, :].all()
    # a resized pixel over any masked pixel is masked: no masked colour leaks in
    from vibr.geometry.resample import resize_mask

    m = np.ones((72, 96), bool)
    m[11, 21] = False
    assert np.argwhere(~resize_mask(m, (36, 48))).tolist() == [[5, 10]]


def test_mask_file_errors_name_the_file(grid96x72, tmp_path):
    save_scene(_with_intruder(grid96x72), tmp_path / "s")
    from vibr.io.images import write_image

    write_image(tmp_path / "s" / "masks" / "view_003.png", np.zeros((72, 96), np.float32))
    with pytest.raises(VibrInputError, match=r"view_003.png: mask excludes every pixel"):
        load_scene(tmp_path / "s")
    write_image(tmp_path / "s" / "masks" / "view_003.png", np.ones((72, 72), np.float32))
    with pytest.raises(VibrInputError, match=r"view_003.png: mask is 72x72, frame 3's image is 96x72"):
        load_scene(tmp_path / "s")


def test_point_cloud_leaves_masked_pixels_out(grid96x72):
    from vibr.viewer.geometry import point_cloud

    sc = make_scene("grid", n_views=4, width=32, height=24)
    v = sc.views[0]
    m = np.ones(v.camera.shape, bool)
    m[:, :16] = False
    P0, _ = point_cloud(sc, max_points=10**6)
    P1, _ = point_cloud(sc.replace(views=[v.replace(mask=m)] + sc.views[1:]), max_points=10**6)
    assert len(P0) - len(P1) == int((~m & np.isfinite(v.depth)).sum())


def test_a_fly_through_frame_is_not_reused_across_masks(grid96x72):
    """A resumed fly-through reuses a frame only when its key matches: a mask added to a
    source photograph changes every frame."""
    from vibr.paths.flythrough import FrameContext, job_key

    def key(scene):
        return job_key(FrameContext(sources=scene, cameras=[grid96x72["view_004"].camera], frames_dir=None))

    # the key is the content: the same scene built again has it, the mask changes it
    assert key(grid96x72) == key(make_scene("grid", n_views=9, width=96, height=72))
    assert key(grid96x72) != key(_with_intruder(grid96x72, paint=False))


@pytest.mark.parametrize("layout", ["grid", "handheld"])
def test_estimated_depth_leaves_masked_pixels_unknown(layout):
    """Light field (grid) and multi-view stereo (hand-held): a masked pixel of a view gets
    no depth from the estimate."""
    from vibr.stereo import estimate_depth

    sc = make_scene(layout, n_views=9 if layout == "grid" else 5, width=64, height=48)
    v = sc.views[1]
    m = np.ones(v.camera.shape, bool)
    m[10:30, 20:40] = False
    sc = sc.replace(views=[u.replace(depth=None, sigma_z=None, mask=m if u.name == v.name else None)
                           for u in sc.views])
    d = estimate_depth(sc, views=[v.name])[v.name].depth
    assert np.isnan(d[~m]).all() and np.isfinite(d[m]).mean() > 0.3


def test_light_field_matching_reads_the_masks(grid96x72, monkeypatch):
    """The light-field estimate's plane sweep and slanted-plane refinement (coarse and full
    size) are given each source's mask, as the multi-view estimate's are: a masked sample
    does not match (``plane_sweep(src_masks=)``); views without a mask pass None."""
    import vibr.stereo.lightfield as L
    from vibr.stereo import estimate_depth

    seen = []
    for name in ("plane_sweep", "refine_planes"):
        real = getattr(L, name)

        def spy(*a, _real=real, _name=name, **kw):
            seen.append((_name, kw.get("src_masks"), [s.shape[:2] for s in a[2]]))
            return _real(*a, **kw)

        monkeypatch.setattr(L, name, spy)
    sc = _with_intruder(grid96x72)
    sc = sc.replace(views=[u.replace(depth=None, sigma_z=None) for u in sc.views])
    estimate_depth(sc, views=["view_004"])
    assert {n for n, _, _ in seen} == {"plane_sweep", "refine_planes"}
    for _, masks, shapes in seen:
        given = [m for m in masks if m is not None]
        assert len(masks) == len(shapes) and len(given) == 1  # view_003's, at each level's size
        assert given[0].shape in shapes and not given[0].all()
