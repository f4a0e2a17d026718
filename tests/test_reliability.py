"""Truncated COLMAP models, parameters checked at the API
boundary, memory and coverage limits, paths kept inside the scene, messages without
internals, bit-identical renders."""

from __future__ import annotations

import json
import os
import re
import shutil

import numpy as np
import pytest

from _colmap_model import write_colmap_model
from _fuzz import run_case
from vibr.camera import Camera
from vibr.errors import VibrInputError
from vibr.io import load_scene, save_scene


# ----------------------------------------------------------------------------- item 2
@pytest.fixture(scope="module")
def colmap_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("colmap") / "m"
    write_colmap_model(root)
    return root


# the cases (pycolmap alone: points3D.bin > 8 GB, frames.bin 40-80 s, images.bin
# > 2 min, cameras.bin silently wrong) and one cut at each record of every file
@pytest.mark.parametrize("name,cut", [("points3D.bin", 20), ("points3D.bin", 60), ("frames.bin", 20),
                                      ("frames.bin", 24), ("frames.bin", 28), ("images.bin", 75),
                                      ("cameras.bin", 40), ("rigs.bin", 12)])
def test_truncated_colmap_file_is_refused_quickly(colmap_root, tmp_path, name, cut):
    root = tmp_path / "m"
    shutil.copytree(colmap_root, root)
    os.truncate(root / "sparse" / "0" / name, cut)
    out = run_case(load_scene, root, time_budget=20.0, mem_budget=1 << 30)
    assert out.status == "vibr_error", out
    assert name in out.message and re.search(r"\(byte \d+\)", out.message), out.message
    assert out.seconds < 10


def test_every_truncation_of_every_colmap_file(colmap_root, tmp_path):
    """In process (the validation bounds every read): every cut of every file is refused."""
    model = colmap_root / "sparse" / "0"
    from vibr.io.colmap_check import check_colmap_model

    d = tmp_path / "cut"
    shutil.copytree(model, d)
    for f in sorted(model.iterdir()):
        raw = f.read_bytes()
        for n in range(len(raw)):
            (d / f.name).write_bytes(raw[:n])
            with pytest.raises(VibrInputError, match=re.escape(f.name)):
                check_colmap_model(d)
        (d / f.name).write_bytes(raw)


def test_colmap_text_model_errors_name_the_line(tmp_path):
    root = tmp_path / "t"
    model = write_colmap_model(root, text=True)
    assert len(load_scene(root)) == 3
    cams = (model / "cameras.txt").read_text().replace("PINHOLE 12 8 40 41", "PINHOLE 12 8 40", 1)
    lines = (model / "cameras.txt").read_text().splitlines()
    lines = [ln if ln.startswith("#") or " PINHOLE " not in ln else " ".join(ln.split()[:-1]) for ln in lines]
    (model / "cameras.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(VibrInputError, match=r"cameras.txt: line \d+: PINHOLE has 4 parameters, got 3"):
        load_scene(root)
    del cams


def test_colmap_reference_errors_have_no_cpp_internals(colmap_root, tmp_path):
    root = tmp_path / "m"
    shutil.copytree(colmap_root, root)
    p = root / "sparse" / "0" / "images.bin"
    b = bytearray(p.read_bytes())
    b[8:12] = (77).to_bytes(4, "little")  # the first image's id: no frame lists it
    p.write_bytes(bytes(b))
    with pytest.raises(VibrInputError) as e:
        load_scene(root)
    assert "image 77" in str(e.value) and "unordered_map" not in str(e.value)


# ----------------------------------------------------------------------------- item 4
@pytest.mark.parametrize("kw,word", [({"lam": float("nan")}, "lam"), ({"alpha": float("inf")}, "alpha"),
                                     ({"max_iter": 0}, "iterations"), ({"sigma_s": 0.0}, "sigma_s"),
                                     ({"gamma": -1.0}, "gamma"), ({"scale": 0.0}, "intensity_scale"),
                                     ({"sigma_z": -0.1}, "sigma_z"), ({"n_outer": -1}, "n_outer")])
def test_render_parameters_checked(kw, word):
    from vibr.render.methods import method_params

    with pytest.raises(VibrInputError, match=word):
        method_params("gradient", **kw)
    method_params("gradient", lam=0.0, alpha=0.0, max_iter=1)  # edges of the ranges are fine


@pytest.mark.parametrize("kw,word", [({"step_px": 0.0}, "step_px"), ({"max_planes": 0}, "max_planes"),
                                     ({"median_radius": -1}, "median_radius"),
                                     ({"depth_range": (1.0, float("nan"))}, "depth_range"),
                                     ({"refine_iter": -2}, "refine_iter")])
def test_depth_parameters_checked(kw, word):
    from vibr.stereo import estimate_depth
    from vibr.synthetic import make_scene

    s = make_scene("free", n_views=3, width=32, height=24, seed=2)
    with pytest.raises(VibrInputError, match=word):
        estimate_depth(s, views=[0], **kw)


def test_negative_view_index_is_an_error():
    from vibr.synthetic import make_scene

    s = make_scene("grid", n_views=4, width=16, height=16, seed=0)
    for k in (-1, "-1"):
        with pytest.raises(VibrInputError, match="no view -1"):
            s.index(k)


# ----------------------------------------------------------------------------- item 5
def test_render_memory_refused_before_allocating(monkeypatch):
    from vibr.render import render
    from vibr.render.checks import render_memory
    from vibr.synthetic import make_scene

    s = make_scene("grid", n_views=4, width=32, height=32, seed=0)
    c = s[0].camera
    huge = Camera(c.K * np.array([[600.0], [600.0], [1.0]]), c.R, c.t, 20000, 20000)
    need = render_memory([v.camera.shape for v in s.views], huge.shape)
    assert need > 100 * 2**30
    monkeypatch.setenv("VIBR_MEMORY_LIMIT_GB", "4")
    with pytest.raises(VibrInputError, match=r"rendering 20000x20000 from 4 views needs about .* GB.*--scale"):
        render(s, huge, "gradient")


def test_huge_source_image_refused_at_load(tmp_path, monkeypatch):
    from test_cli_errors import make_transforms

    root = make_transforms(tmp_path / "s")
    doc = json.loads((root / "transforms.json").read_text())
    doc.update(w=13000, h=13000, cx=6500.0, cy=6500.0)
    (root / "transforms.json").write_text(json.dumps(doc))
    monkeypatch.setenv("VIBR_MEMORY_LIMIT_GB", "1")
    with pytest.raises(VibrInputError, match=r"loading 1 images \(169 Mpixels\) needs about 2.5 GB"):
        load_scene(root)
    monkeypatch.setenv("VIBR_MEMORY_LIMIT_GB", "64")
    with pytest.raises(VibrInputError, match="image is 16x12 but its camera says 13000x13000"):
        load_scene(root)


def test_camera_that_sees_nothing_is_an_error(capsys, tmp_path):
    from vibr.cli import main
    from vibr.io import write_camera_json
    from vibr.synthetic import make_scene

    s = make_scene("grid", n_views=4, width=32, height=32, seed=0)
    src = save_scene(s, tmp_path / "s")
    c = s[0].camera
    away = Camera.from_centre(c.K, np.diag([1.0, -1.0, -1.0]) @ c.R, c.centre, 32, 32)  # looks backwards
    write_camera_json(tmp_path / "away.json", away)
    out = tmp_path / "o.png"
    capsys.readouterr()
    assert main(["-q", "render", str(src), "--target", str(tmp_path / "away.json"), "-o", str(out),
                 "--depth", "gt"]) == 2
    err = capsys.readouterr().err
    assert "sees" in err and len(err.strip().splitlines()) == 1 and not out.exists()
    # samples that land but cover no pixel (one sample between pixel centres, the hole
    # threshold at 1): an error before the solve, not a grey image
    from vibr.geometry import compute_samples
    from vibr.render.api import render_samples

    sources, tv = s.split(0)
    smp = compute_samples(sources, tv.camera)
    frac = np.abs(smp.xy - np.round(smp.xy)).min(axis=1) > 0.1
    one = smp.select(np.arange(len(smp)) == int(np.argmax(frac)))
    with pytest.raises(VibrInputError, match="coverage 0 %"):
        render_samples(one, "bvs", hole_threshold=1.0, max_iter=2)


# ----------------------------------------------------------------------------- item 6
@pytest.mark.parametrize("path", ["../outside.png", "/etc/hostname", "images/../../outside.png"])
def test_transforms_paths_stay_inside_the_scene(tmp_path, capsys, path):
    from test_cli_errors import _img, make_transforms

    root = make_transforms(tmp_path / "s")
    _img(tmp_path / "outside.png")
    (root / "images").mkdir()
    doc = json.loads((root / "transforms.json").read_text())
    doc["frames"][0]["file_path"] = path
    (root / "transforms.json").write_text(json.dumps(doc))
    with pytest.raises(VibrInputError, match="scene folder: refused"):
        load_scene(root)
    if path != "/etc/hostname":
        assert len(load_scene(root, allow_outside=True)) == 1
        from vibr.cli import main

        assert main(["-q", "info", str(root)]) == 2
        assert main(["-q", "--allow-outside-paths", "info", str(root)]) == 0


# ----------------------------------------------------------------------------- item 7
def test_hci_cfg_messages_have_no_exception_names(tmp_path):
    from _fuzz import _seed_hci

    _seed_hci(tmp_path, True)
    cfg = (tmp_path / "parameters.cfg").read_text()
    for text, word in [(cfg.replace("[extrinsics]", "[extr]"), "no [extrinsics] section"),
                       (cfg.replace("baseline_mm = 25.0", "baseline_mm = abc"), "is not a number"),
                       (cfg.replace("num_cams_x = 3", ""), "has no num_cams_x"),
                       ("garbage without a section", "malformed parameters.cfg")]:
        (tmp_path / "parameters.cfg").write_text(text)
        with pytest.raises(VibrInputError, match=re.escape(word)) as e:
            load_scene(tmp_path)
        assert not re.search(r"\b[A-Z][a-z]+Error\b", str(e.value)), str(e.value)


# ----------------------------------------------------------------------------- item 8
def test_twenty_renders_are_bit_identical():
    """The kernels' results did depend on the arrays' addresses (FMA contraction in the
    vectorised body only): 3 distinct images in 12 renders of cotton at 256²."""
    from vibr.render import render
    from vibr.synthetic import make_scene

    s = make_scene("grid", n_views=9, width=64, height=64, seed=3)
    sources, target = s.split(4)
    first = render(sources, target, "gradient").image
    for _ in range(19):
        assert np.array_equal(render(sources, target, "gradient").image, first)


# ----------------------------------------------------------------------------- item 9
def test_depth_killed_midway_resumes(tmp_path, capsys, monkeypatch):
    """A `vibr depth` interrupted after its first view keeps it: the rerun sweeps only the
    others, reads back nothing damaged, and writes the same maps as an uninterrupted run."""
    import vibr.stereo.api as sapi
    from vibr._runtime.checkpoint import resume_folder
    from vibr.cli import main
    from vibr.synthetic import make_scene

    s = make_scene("free", n_views=4, width=40, height=32, seed=2)
    src = save_scene(s.replace(views=[v.replace(depth=None, sigma_z=None) for v in s.views]), tmp_path / "s")
    args = ["-q", "depth", str(src), "--targets", "view_000,view_001,view_002", "--refine-iter", "1",
            "--sweep-scale", "1"]
    assert main(args + ["-o", str(tmp_path / "ref")]) == 0
    ref = load_scene(tmp_path / "ref")

    real, calls = sapi.plane_sweep, []

    def killed(*a, **k):
        if k.get("desc") == "depth view_001":
            raise KeyboardInterrupt  # killed while sweeping the second view
        return real(*a, **k)

    out = tmp_path / "out"
    monkeypatch.setattr(sapi, "plane_sweep", killed)
    assert main(args + ["-o", str(out)]) == 130
    assert not out.exists() and len(list(resume_folder(out).glob("*.npz"))) == 1
    (resume_folder(out) / "junk.npz.tmp").write_bytes(b"half")  # a stray partial file: ignored
    calls.clear()
    monkeypatch.setattr(sapi, "plane_sweep", lambda *a, **k: calls.append(k.get("desc")) or real(*a, **k))
    assert main(args + ["-o", str(out)]) == 0
    assert "depth view_000" not in calls and "depth view_001" in calls  # the first view was not redone
    assert "kept from an interrupted run" in capsys.readouterr().out
    assert not resume_folder(out).exists()
    got = load_scene(out)
    for a, b in zip(ref.views, got.views):
        assert (a.depth is None) == (b.depth is None)


def test_depth_cache_killed_midway_resumes(tmp_path, monkeypatch):
    """The depth a fly-through, eval or the viewer estimates (vibr.stereo.cache) resumes as
    `vibr depth` does: killed in its second view, the rerun keeps the first, writes the same
    maps as an uninterrupted run, and removes its checkpoint folder once the cache is written."""
    import vibr.stereo.api as sapi
    from vibr._runtime.checkpoint import resume_folder
    from vibr.scene import Scene
    from vibr.stereo.cache import scene_with_depth
    from vibr.synthetic import make_scene

    s = make_scene("free", n_views=3, width=40, height=32, seed=2)
    bare = Scene([v.replace(depth=None, sigma_z=None) for v in s.views], s.name, None, None, None, {})
    kw = dict(refine_iter=1, sweep_scale=1)
    ref = scene_with_depth(bare, cache_dir=tmp_path / "ref", estimate_kw=kw)
    real, calls = sapi.plane_sweep, []

    def killed(*a, **k):
        if k.get("desc") == "depth view_001":
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(sapi, "plane_sweep", killed)
    with pytest.raises(KeyboardInterrupt):
        scene_with_depth(bare, cache_dir=tmp_path / "c", estimate_kw=kw)
    (resume,) = [p for p in (tmp_path / "c").iterdir() if p.name.endswith(".vibr-resume")]
    assert len(list(resume.glob("*.npz"))) == 1
    monkeypatch.setattr(sapi, "plane_sweep", lambda *a, **k: calls.append(k.get("desc")) or real(*a, **k))
    got = scene_with_depth(bare, cache_dir=tmp_path / "c", estimate_kw=kw)
    assert "depth view_000" not in calls and "depth view_001" in calls
    assert not resume.exists() and resume == resume_folder(got.meta["depth_cache"])
    for a, b in zip(ref.views, got.views):
        assert np.array_equal(a.depth, b.depth, equal_nan=True)
        if a.depth is not None:
            np.testing.assert_array_equal(a.depth, b.depth)


def test_strecha_infinite_image_size_is_refused(tmp_path):
    """Found by the long fuzz profile: 'inf 8' as the size line raised OverflowError."""
    from vibr.io.strecha import read_strecha_camera

    p = tmp_path / "a.camera"
    for wh in ("inf 8", "nan 8", "0 8", "1e300 8"):
        p.write_text("10 0 6\n0 10 4\n0 0 1\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n0 0 0\n" + wh + "\n")
        with pytest.raises(VibrInputError, match="image size"):
            read_strecha_camera(p)


def test_eval_and_render_estimate_depth_once_through_the_cache(tmp_path, capsys, monkeypatch):
    """`vibr eval` and `vibr render` estimate their sources' depth through the depth cache: a
    second run on the same sources loads it (the same numbers, the estimator's statistics
    kept in the report); --no-cache estimates again and writes nothing; other code (vibr's
    code fingerprint) does not take the maps."""
    import json

    import vibr.stereo.cache as dc
    from vibr.cli import main
    from vibr.synthetic import make_scene

    s = make_scene("free", n_views=4, width=40, height=32, seed=2)
    src = save_scene(s.replace(views=[v.replace(depth=None, sigma_z=None) for v in s.views]), tmp_path / "s")
    cache = tmp_path / "cache"
    args = ["eval", str(src), "--target", "view_000", "--method", "gradient", "--gamma", "0.2", "--depth",
            "estimated", "--cache-dir", str(cache)]
    reports = []
    for k in range(2):
        assert main(args + ["--json", str(tmp_path / f"e{k}.json")]) == 0
        reports.append(json.loads((tmp_path / f"e{k}.json").read_text()))
    err = capsys.readouterr().err
    assert err.count("estimating depth for 3 views") == 1 and "loaded from the cache" in err
    assert len(list(cache.glob("depth-*.npz"))) == 1 and not list(cache.glob(".*vibr-resume"))
    a, b = (r["results"][0]["psnr"] for r in reports)
    assert a == b and reports[1]["depth_estimation"] == reports[0]["depth_estimation"]
    assert reports[0]["depth_estimation"]["views"]  # the estimator's per-view statistics
    # `vibr render` of the same target from the same sources: the same cache entry
    assert main(["render", str(src), "--target", "view_000", "-o", str(tmp_path / "r.png"), "--depth",
                 "estimated", "--cache-dir", str(cache)]) == 0
    assert "loaded from the cache" in capsys.readouterr().err
    assert main(args[:-2] + ["--no-cache", "--json", str(tmp_path / "e2.json")]) == 0
    assert "estimating depth for 3 views" in capsys.readouterr().err
    assert len(list(cache.glob("depth-*.npz"))) == 1
    bare = load_scene(src).subset(["view_001", "view_002", "view_003"])
    key = dc.depth_cache_key(bare)
    monkeypatch.setattr(dc, "code_fingerprint", lambda: "other code")
    assert dc.depth_cache_key(bare) != key


def test_a_cache_folder_that_cannot_be_written(tmp_path, capsys):
    """--cache-dir that is, or lies under, a file: one line, exit 2, before any work. A
    checkpoint folder that cannot be made (a read-only cache) only costs the resumption."""
    from vibr._runtime.checkpoint import ViewCheckpoint
    from vibr.cli import main
    from vibr.synthetic import make_scene

    s = make_scene("free", n_views=3, width=40, height=32, seed=2)
    src = save_scene(s.replace(views=[v.replace(depth=None, sigma_z=None) for v in s.views]), tmp_path / "s")
    afile = tmp_path / "afile"
    afile.write_text("x")
    capsys.readouterr()  # only what the commands below write
    for bad, why in ((afile, "is a file, a folder is expected"), (afile / "sub", "cannot be made")):
        assert main(["eval", str(src), "--target", "view_000", "--method", "ulr", "--json", str(tmp_path / "e.json"),
                     "--cache-dir", str(bad)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert why in err[-1] and "Traceback" not in "".join(err)
    assert not (tmp_path / "e.json").exists()
    ck = ViewCheckpoint(afile / "resume", {})
    for _ in range(2):
        ck.save("view_000", "k", {"depth": np.zeros((2, 2), np.float32)}, {})
    assert ck.unwritable and ck.load("view_000", "k") is None


def test_the_cache_keeps_under_its_bound_least_recently_used_first(tmp_path, monkeypatch):
    """prune_cache removes the entries used longest ago until the rest fit; a cache hit counts
    as a use; the entry just written is never removed; other files are left alone."""
    import os

    import vibr.stereo.cache as dc

    names = ["depth-a.npz", "depth-b.npz", "scene-c.pkl", "depth-d.npz"]
    for k, n in enumerate(names):
        (tmp_path / n).write_bytes(bytes(100))
        os.utime(tmp_path / n, (1000 + k, 1000 + k))
    (tmp_path / "notes.txt").write_bytes(bytes(500))
    dc.mark_used(tmp_path / "depth-a.npz")  # a hit: now the most recent
    assert dc.prune_cache(tmp_path, keep=[tmp_path / "depth-b.npz"], max_bytes=250) == 200
    assert sorted(p.name for p in tmp_path.iterdir()) == ["depth-a.npz", "depth-b.npz", "notes.txt"]
    monkeypatch.setenv("VIBR_CACHE_MAX_GB", "0")
    assert dc.prune_cache(tmp_path, keep=[tmp_path / "depth-a.npz"]) == 100
    assert sorted(p.name for p in tmp_path.iterdir()) == ["depth-a.npz", "notes.txt"]


def test_a_leave_one_out_keeps_depth_in_the_cache_only_when_asked(tmp_path, monkeypatch):
    """`vibr eval --target all` estimates each target's sources once (the per-view reports
    make a rerun resume): no cache entry by default, one per target with --cache-dir."""
    from vibr.cli import main
    from vibr.synthetic import make_scene

    s = make_scene("free", n_views=3, width=40, height=32, seed=2)
    src = save_scene(s.replace(views=[v.replace(depth=None, sigma_z=None) for v in s.views]), tmp_path / "s")
    default = tmp_path / "default"
    monkeypatch.setenv("VIBR_CACHE_DIR", str(default))
    argv = ["-q", "eval", str(src), "--target", "all", "--method", "ulr", "--depth", "estimated"]
    assert main(argv + ["--json", str(tmp_path / "a.json")]) == 0
    assert not list(default.glob("depth-*.npz"))
    asked = tmp_path / "asked"
    assert main(argv + ["--json", str(tmp_path / "b.json"), "--cache-dir", str(asked)]) == 0
    assert len(list(asked.glob("depth-*.npz"))) == 3
