"""``vibr.eval.protocol`` and ``vibr eval``: samples computed once, identical numbers to a direct
render, the intensity scale reaching the renderer, the JSON report, unseen scene folders."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

FAST = {"max_iter": 8, "n_outer": 2}


@pytest.fixture(scope="module")
def scene():
    from vibr.synthetic import make_scene

    return make_scene("grid", n_views=9, width=48, height=40, seed=2)


def test_evaluate_computes_samples_once_and_matches_a_direct_render(scene, monkeypatch):
    import vibr.render.api as render_api
    from vibr.eval.protocol import Setting, evaluate
    from vibr.metrics import psnr
    from vibr.pipeline import prepare
    from vibr.render import render

    calls = []
    real = render_api.compute_samples  # the name shared_geometry calls

    def counting(*a, **kw):
        calls.append(1)
        time.sleep(0.05)  # samples_seconds must include this
        return real(*a, **kw)

    monkeypatch.setattr(render_api, "compute_samples", counting)
    settings = [Setting("ulr"), Setting("bvs", {"lam": 0.2}), Setting("gradient", {"gamma": 1.0}),
                Setting("gradient", {"gamma": 2.0})]
    t0 = time.perf_counter()
    rep = evaluate(scene, "view_004", settings, depth="gt", render_kw=FAST, use_lpips=False)
    wall = time.perf_counter() - t0
    assert len(calls) == 1  # one geometry for the four settings
    # the time of the samples, in seconds: the call above, within the whole evaluation
    assert rep["n_samples"] > 0 and 0.05 <= rep["samples_seconds"] <= wall + 1e-3

    # the same numbers as rendering directly, geometry recomputed by render itself. Not to
    # the last bit: the solver's fastmath reductions may sum in another order from one call
    # to the next (up to 3.6e-7 dB apart, measured); a different geometry moves PSNR by far
    # more than the 1e-5 dB allowed here.
    src, tview = prepare(scene, "view_004", depth="gt")
    for s, entry in zip(settings, rep["results"]):
        res = render(src, tview, method=s.method, **FAST, **s.params)
        # and by the same rule as render's own metrics (reconstructed pixels, 2-px border)
        assert entry["psnr"] == pytest.approx(res.metrics["psnr"], abs=1e-5)
        assert entry["psnr"] == pytest.approx(psnr(res.image, tview.image, mask=res.coverage, border=2), abs=1e-5)
        assert entry["params"]["scale"] == 255.0 and entry["intensity_scale"] == 255.0
    assert len(calls) == 1 + len(settings)


def test_intensity_scale_reaches_the_renderer(scene, monkeypatch):
    import vibr.render.api as vr  # evaluate renders through vibr.render.shared_geometry
    from vibr.eval.protocol import Setting, evaluate

    seen = []
    real = vr.render

    def spy(*a, **kw):
        seen.append(kw["params"].scale)  # a RenderParams
        return real(*a, **kw)

    monkeypatch.setattr(vr, "render", spy)
    rep = evaluate(scene, "view_004", [Setting("savsr"), Setting("bvs", {"scale": 255.0})], depth="gt",
                   intensity_scale=1.0, render_kw=FAST, use_lpips=False)
    assert seen == [1.0, 255.0]  # the default, then a setting's own scale wins
    assert rep["intensity_scale"] == 1.0
    assert [r["intensity_scale"] for r in rep["results"]] == [1.0, 255.0]
    # and the scale matters: lambda read on [0, 1] is 255x stronger relative to the data
    assert rep["results"][0]["psnr"] != rep["results"][1]["psnr"]


def test_cli_eval_json_on_an_unseen_scene_folder(grid_scene_dir, tmp_path, capsys):
    from vibr.cli import main

    out = tmp_path / "r.json"
    figs = tmp_path / "figs"
    code = main(["eval", str(grid_scene_dir), "--target", "view_004", "--method", "ulr,savsr,gradient",
                 "--gamma", "0,1", "--lam", "0.2", "--intensity-scale", "100", "--border", "2",
                 "--json", str(out), "--figures", str(figs), "-q"])
    assert code == 0
    txt = capsys.readouterr().out
    assert "PSNR" in txt and "intensity scale 100" in txt
    rep = json.loads(out.read_text())
    for k in ("scene", "target", "sources", "scale", "intensity_scale", "size", "depth", "mask",
              "results", "machine", "geometry_seconds"):
        assert k in rep
    assert rep["target"] == "view_004" and "view_004" not in rep["sources"] and len(rep["sources"]) == 8
    assert rep["scale"] == 1.0 and rep["intensity_scale"] == 100.0
    assert [r["label"] for r in rep["results"]] == [
        "ulr", "savsr(lam=0.2)", "gradient(gamma=0,lam=0.2)", "gradient(gamma=1,lam=0.2)"]
    # measured on this scene (PSNR dB, DSSIM): ulr 38.08 / 160, savsr 36.67 / 167,
    # gamma 0 36.68 / 167, gamma 1 39.16 / 111; floors 1.5 dB below, DSSIM bounds 1.4x above
    measured = {"ulr": (38.08, 160), "savsr(lam=0.2)": (36.67, 167), "gradient(gamma=0,lam=0.2)": (36.68, 167),
                "gradient(gamma=1,lam=0.2)": (39.16, 111)}
    for r in rep["results"]:
        for k in ("method", "params", "depth", "psnr", "dssim", "seconds"):
            assert k in r
        assert r["params"]["scale"] == 100.0
        p, d = measured[r["label"]]
        assert r["psnr"] > p - 1.5 and 0 <= r["dssim"] < 1.4 * d, (r["label"], r["psnr"], r["dssim"])
    cols = rep["figures"]["columns"]
    assert cols[0] == "reference" and len(cols) == 5
    from vibr.io import read_image

    fig = read_image(rep["figures"]["compare"])
    assert fig.shape[0] == 2 * (14 + 40) + 4 and fig.shape[1] == 5 * 48 + 4 * 4  # rows under 14-px labels
    assert read_image(rep["figures"]["crops"]).shape[0] == 14 + 4 * 16


def test_cli_eval_image_scale_and_planar(grid_scene_dir, tmp_path, capsys):
    from vibr.cli import main

    out = tmp_path / "p.json"
    assert main(["eval", str(grid_scene_dir), "--target", "2", "--scale", "0.5", "--depth", "planar",
                 "--method", "bvs", "--json", str(out), "-q"]) == 0
    rep = json.loads(out.read_text())
    assert rep["scale"] == 0.5 and rep["size"] == [24, 20] and rep["intensity_scale"] == 255.0
    assert rep["depth"] == "planar" and rep["proxy"]["depth"] > 0
    # errors are one line, exit status 2
    assert main(["eval", str(grid_scene_dir), "--target", "view_004", "--intensity-scale", "0",
                 "--json", str(tmp_path / "x.json"), "-q"]) == 2
    assert "intensity-scale" in capsys.readouterr().err


def test_planar_proxy_when_only_the_target_has_depth(scene):
    """A light field whose only depth is the held-out centre's: the plane's depth comes
    from it (two scalars), the sources' own depth stays unused."""
    from vibr.pipeline import prepare
    from vibr.scene import Scene

    views = [v if v.name == "view_004" else v.replace(depth=None) for v in scene.views]
    lf = Scene(views, scene.name, None, scene.grid, None, dict(scene.meta))
    src, tview = prepare(lf, "view_004", depth="planar")
    assert src.meta["proxy"]["from_views"] == ["view_004"]
    from vibr.geometry import planar_proxy

    t = scene["view_004"]
    ref = planar_proxy(Scene([t], scene.name), t.camera).meta["proxy"]
    assert src.meta["proxy"]["depth"] == ref["depth"] and src.meta["proxy"]["sigma_z"] == ref["sigma_z"]
    assert float(t.depth.min()) < ref["depth"] < float(t.depth.max())
    assert all(v.depth is not None and v.name != "view_004" for v in src.views)


def test_eval_on_a_middlebury_layout_folder(scene, tmp_path, capsys):
    """A scene folder in the Middlebury *_par.txt layout that vibr never saw (no depth in
    the format): depth from files; planar without depth or points is a one-line error."""
    from vibr.cli import main
    from vibr.io import write_image

    d = tmp_path / "mvs_unseen"
    (d / "depth").mkdir(parents=True)
    lines = [str(len(scene))]
    for i, v in enumerate(scene.views):
        name = f"obj{i + 1:04d}"
        write_image(d / f"{name}.png", v.image)
        np.save(d / "depth" / f"{name}.npy", v.depth.astype(np.float32))
        c = v.camera
        lines.append(" ".join([f"{name}.png"] + [f"{x:.12g}" for x in (*c.K.ravel(), *c.R.ravel(), *c.t.ravel())]))
    (d / "obj_par.txt").write_text("\n".join(lines) + "\n")
    out = tmp_path / "m.json"
    assert main(["eval", str(d), "--target", "obj0005", "--depth", "files", "--depth-files", str(d / "depth"),
                 "--method", "ulr,bvs", "--json", str(out), "-q"]) == 0
    rep = json.loads(out.read_text())
    assert rep["target"] == "obj0005" and len(rep["sources"]) == 8
    # measured (2-px border, the metric rule): ulr 38.08 dB / DSSIM 160, bvs 36.36 / 202 (the
    # depth files are the exact depth)
    assert all(r["psnr"] > 34.8 and r["dssim"] < 280 for r in rep["results"]), rep["results"]
    capsys.readouterr()
    assert main(["eval", str(d), "--target", "obj0005", "--depth", "planar", "--method", "ulr,bvs",
                 "--json", str(tmp_path / "m2.json"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "planar" in err and len(err.strip().splitlines()) == 1
    # depth files at the photographs' size serve a scene loaded at --scale 0.5 (resized,
    # nearest neighbour; they were refused), and give nearly the same result
    out2 = tmp_path / "m3.json"
    assert main(["eval", str(d), "--target", "obj0005", "--depth", "files", "--depth-files", str(d / "depth"),
                 "--method", "ulr", "--scale", "0.5", "--json", str(out2), "-q"]) == 0
    assert json.loads(out2.read_text())["results"][0]["psnr"] > 30
    # a map of another aspect, or a file that is no .npy, is one line naming the file
    np.save(d / "depth" / "obj0001.npy", np.ones((10, 10), np.float32))
    (d / "depth" / "obj0002.npy").write_bytes(b"garbage")
    for view, msg in (("obj0001", "another aspect"), ("obj0002", "not a .npy file")):
        capsys.readouterr()
        assert main(["render", str(d), "--target", "obj0005", "--sources", view, "--depth", "files",
                     "--depth-files", str(d / "depth"), "-o", str(tmp_path / "r.png"), "-q"]) == 2
        err = capsys.readouterr().err.strip()
        assert msg in err and f"{view}.npy" in err and len(err.splitlines()) == 1, err


def test_figures_downscale_and_crop_inside_mask(tmp_path):
    from vibr.eval.figures import downscale_image, most_different_window, write_figures
    from vibr.io import read_image

    rng = np.random.default_rng(0)
    ref = rng.random((32, 48, 3)).astype(np.float32)
    a = ref.copy()
    b = ref.copy()
    b[:10, :10] = 0  # the largest difference, but outside the mask
    b[20:30, 30:40] += 0.3
    mask = np.ones((32, 48), bool)
    mask[:12, :12] = False
    r, c = most_different_window([a, b], 8, mask)
    assert 20 - 8 < r <= 30 and 30 - 8 < c <= 40
    assert downscale_image(np.ones((5, 7, 3), np.float32), 2).shape == (2, 3, 3)
    info = write_figures(tmp_path, ref, {"a": a, "b": b}, mask, prefix="t", downscale=2)
    fig = read_image(info["compare"])
    assert fig.shape == ((2 * (32 + 14) + 4) // 2, (3 * 48 + 2 * 4) // 2, 3)  # two rows, each under a 14-px label
    crops = read_image(info["crops"])
    strip = crops[:14, : crops.shape[1] // 3]  # the reference panel's label
    assert (strip < 0.5).any() and (strip > 0.9).mean() > 0.5  # dark text on white


def test_label_panel_writes_text_above_the_image():
    from vibr.eval.figures import label_panel

    img = np.zeros((10, 60, 3), np.float32)
    out = label_panel(img, "bvs")
    assert out.shape == (24, 60, 3) and np.array_equal(out[14:], img)
    assert (out[:14] < 0.5).any() and not (label_panel(img, "")[:14] < 0.5).any()


def test_view_counts_closed_form():
    """view_counts: distinct source views per target pixel, a sample counted at the pixel
    its landing point rounds to (clipped to the image)."""
    from vibr.geometry.samples import view_counts

    class _S:  # the three fields view_counts reads
        def __init__(self, xy, view, shape):
            self.xy, self.view, self.target_shape = np.asarray(xy, float), np.asarray(view), shape

        def __len__(self):
            return len(self.xy)

    xy = [[1.4, 0.2], [1.2, -0.3],   # view 0 twice in pixel (row 0, col 1): counted once
          [1.0, 0.0],                # view 1, same pixel
          [1.6, 0.0],                # view 2, rounds to col 2
          [-3.0, 9.0], [4.4, 2.6]]   # view 3 clipped to (2, 0); view 0 at (row 3, col 4)
    c = view_counts(_S(xy, [0, 0, 1, 2, 3, 0], (4, 5)))
    want = np.zeros((4, 5), int)
    want[0, 1], want[0, 2], want[3, 0], want[3, 4] = 2, 1, 1, 1
    np.testing.assert_array_equal(c, want)
    assert view_counts(_S(np.zeros((0, 2)), np.zeros(0, int), (2, 3))).shape == (2, 3)


def test_evaluation_writes_nothing_figures_are_separate(scene, tmp_path):
    """run_evaluation measures and returns the images; only vibr.eval.figures writes files."""
    from vibr.eval.figures import write_evaluation_figures
    from vibr.eval.protocol import Setting, evaluate, run_evaluation

    with pytest.raises(TypeError):
        evaluate(scene, "view_004", [Setting("ulr")], figures=tmp_path)
    ev = run_evaluation(scene, "view_004", [Setting("ulr")], depth="gt", use_lpips=False)
    assert list(tmp_path.iterdir()) == [] and "figures" not in ev.report
    assert ev.images["ulr"].shape == ev.reference.shape and ev.mask.shape == ev.reference.shape[:2]
    info = write_evaluation_figures(ev, tmp_path / "figs")
    assert info["columns"] == ["reference", "ulr"] and (tmp_path / "figs" / "view_004_gt_compare.png").is_file()


def test_run_evaluation_options_and_keywords(scene):
    """run_evaluation's options as an EvalOptions or as keywords over it: the same report
    (timings aside); a misspelt option is a TypeError, not a default."""
    from vibr.eval.protocol import EvalOptions, Setting, run_evaluation

    settings = [Setting("ulr"), Setting("gradient")]
    a = run_evaluation(scene, "view_004", settings, depth="gt", border=3, use_lpips=False)
    b = run_evaluation(scene, "view_004", settings, options=EvalOptions(depth="gt", border=3, use_lpips=False))
    c = run_evaluation(scene, "view_004", settings, options=EvalOptions(depth="gt", border=0, mask="all"),
                       border=3, mask="reconstructed", use_lpips=False)
    for ev in (b, c):
        assert ev.report["border"] == 3 and ev.report["mask"] == "reconstructed"
        assert [r["psnr"] for r in ev.report["results"]] == [r["psnr"] for r in a.report["results"]]
        np.testing.assert_array_equal(ev.images["gradient"], a.images["gradient"])
    with pytest.raises(TypeError, match="boarder"):
        run_evaluation(scene, "view_004", settings, depth="gt", boarder=3)
