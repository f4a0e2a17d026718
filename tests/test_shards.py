"""Shards (``--shard I/N`` then ``--assemble``) of a fly-through and of a leave-one-out
evaluation, run as separate processes, give what one process gives; the render's depth
(``--depth-out``) is the geometry's z-buffer, written in the formats vibr reads."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vibr.errors import VibrInputError

#: processes, fly-throughs and real encodes: seconds each (the fast subset leaves them out)
pytestmark = pytest.mark.slow

SRC = str(Path(__file__).resolve().parents[1] / "src")


@pytest.fixture(autouse=True)
def _cache_in_tmp(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("VIBR_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "vibr-cache"))


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    d = tmp_path_factory.mktemp("shards")
    save_scene(make_scene(width=64, height=64), d / "s")
    return d / "s"


@pytest.fixture(scope="module")
def path_json(scene_dir):
    from vibr.cli import main

    pj = scene_dir.parent / "p.json"
    assert main(["path", "interpolate", str(scene_dir), "-o", str(pj), "--frames", "6", "-q"]) == 0
    return pj


def _shards(args: list[str], n: int, cwd) -> None:
    """``vibr ARGS --shard i/n`` for i = 1..n, as n processes running at once (a job array)."""
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    procs = [subprocess.Popen([sys.executable, "-m", "vibr", *args, "--shard", f"{i}/{n}", "-q"], cwd=cwd, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(1, n + 1)]
    for i, p in enumerate(procs, 1):
        out, err = p.communicate(timeout=900)
        assert p.returncode == 0, f"shard {i}/{n}: {out}{err}"
        assert f"shard {i}/{n}" in out, out


def test_shard_of_interleaves_and_covers_every_task():
    from vibr.executor import parse_shard, shard_of

    parts = [shard_of(10, f"{i}/3") for i in (1, 2, 3)]
    assert parts == [[0, 3, 6, 9], [1, 4, 7], [2, 5, 8]]
    assert shard_of(2, (3, 3)) == [] and shard_of(4, None) == [0, 1, 2, 3]
    for bad in ("0/3", "4/3", "3", "a/b", "1/0", "-1/2"):
        with pytest.raises(VibrInputError, match="I/N"):
            parse_shard(bad)


def test_path_shards_assemble_to_the_one_process_video(scene_dir, path_json, tmp_path, capsys):
    """Three --shard processes then --assemble: frames and depth maps byte-identical to one
    process's, the video encoded from them; --assemble on an incomplete folder names the
    missing frames in one line and writes nothing."""
    import imageio_ffmpeg

    from vibr.cli import main
    from vibr.io.video import read_video_info

    one, sharded = tmp_path / "one.mp4", tmp_path / "sharded.mp4"
    common = ["render", str(scene_dir), "--path", str(path_json), "--views", "4"]
    assert main(common + ["-o", str(one), "--depth-out", str(tmp_path / "one_depth"), "-q"]) == 0
    _shards(common + ["-o", str(sharded), "--depth-out", str(tmp_path / "sharded_depth")], 3, tmp_path)
    assert not sharded.exists()  # a shard writes frames, never the video
    frames = sorted((tmp_path / "sharded_frames").glob("frame_*.png"))
    assert len(frames) == 6
    # one frame missing: refused, naming it
    frames[4].rename(tmp_path / "aside.png")
    capsys.readouterr()
    assert main(common + ["-o", str(sharded), "--assemble", "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "1 of 6 frames are missing" in err and ": 4;" in err, err
    assert not sharded.exists()
    (tmp_path / "aside.png").rename(frames[4])
    assert main(common + ["-o", str(sharded), "--assemble", "--depth-out", str(tmp_path / "sharded_depth")]) == 0
    assert "assembled 6 frames" in capsys.readouterr().out
    for name in [f"frame_{i:05d}.png" for i in range(6)]:
        assert (tmp_path / "one_frames" / name).read_bytes() == (tmp_path / "sharded_frames" / name).read_bytes()
    for name in [f"depth_{i:05d}.npy" for i in range(6)]:
        assert (tmp_path / "one_depth" / name).read_bytes() == (tmp_path / "sharded_depth" / name).read_bytes()
    assert read_video_info(sharded)[:3] == read_video_info(one)[:3] == (6, 64, 64)
    for a, b in zip(imageio_ffmpeg.read_frames(str(one)), imageio_ffmpeg.read_frames(str(sharded))):
        assert a == b


def test_eval_shards_assemble_to_the_one_process_report(scene_dir, tmp_path, capsys):
    """eval --target all in three --shard processes then --assemble: the numbers of one process."""
    from vibr.cli import main
    from vibr.eval.leave_one_out import results_only

    common = ["eval", str(scene_dir), "--target", "all", "--method", "ulr,gradient", "--gamma", "1", "--depth", "gt"]
    assert main(common + ["--json", str(tmp_path / "one.json"), "-q"]) == 0
    _shards(common + ["--json", str(tmp_path / "sharded.json")], 3, tmp_path)
    assert not (tmp_path / "sharded.json").exists()
    assert len(list((tmp_path / "sharded_views").glob("*.json"))) == 9
    (tmp_path / "sharded_views" / "view_007.json").rename(tmp_path / "aside.json")
    capsys.readouterr()
    assert main(common + ["--json", str(tmp_path / "sharded.json"), "--assemble", "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "1 of 9 targets" in err and "view_007" in err, err
    (tmp_path / "aside.json").rename(tmp_path / "sharded_views" / "view_007.json")
    assert main(common + ["--json", str(tmp_path / "sharded.json"), "--assemble"]) == 0
    assert "leave-one-out over 9 views" in capsys.readouterr().out
    one = json.loads((tmp_path / "one.json").read_text())
    sharded = json.loads((tmp_path / "sharded.json").read_text())
    a, b = results_only(one), results_only(sharded)
    assert a["per_view"] and a == b
    # the shards really split the targets: three worker processes wrote the reports
    assert len({r["worker_pid"] for r in sharded["per_view"].values()}) == 3


def test_shard_options_are_refused_where_they_do_not_apply(scene_dir, path_json, tmp_path, capsys):
    from vibr.cli import main

    cases = [
        ["render", str(scene_dir), "--target", "1", "-o", str(tmp_path / "a.png"), "--shard", "1/2"],
        ["render", str(scene_dir), "--path", str(path_json), "-o", str(tmp_path / "f"), "--assemble"],
        ["render", str(scene_dir), "--path", str(path_json), "-o", str(tmp_path / "a.mp4"), "--assemble",
         "--shard", "1/2"],
        ["render", str(scene_dir), "--path", str(path_json), "-o", str(tmp_path / "a.mp4"), "--shard", "3/2"],
        ["eval", str(scene_dir), "--target", "1", "--json", str(tmp_path / "e.json"), "--shard", "1/2"],
    ]
    for argv in cases:
        assert main(argv + ["-q"]) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "error:" in err, (argv, err)


# ----------------------------------------------------------------------------- depth
def test_depth_out_is_the_renders_depth_in_each_format(scene_dir, tmp_path, capsys):
    """--depth-out FILE.npy / .pfm / .png read back (vibr.io.read_depth) is the render's
    depth to the format's precision: float32 exactly, the PNG to half a level (0.5e-3)."""
    from vibr.cli import main
    from vibr.io import load_scene
    from vibr.io.depthfiles import read_depth
    from vibr.pipeline import prepare
    from vibr.render import render

    scene = load_scene(scene_dir)
    sources, target = prepare(scene, "view_004")
    ref = render(sources, target, "ulr").depth
    assert ref is not None and ref.shape == (64, 64) and np.isfinite(ref).mean() > 0.95
    for ext, tol in ((".npy", 0.0), (".pfm", 0.0), (".png", 0.5e-3 + 1e-6)):
        out = tmp_path / f"d{ext}"
        assert main(["render", str(scene_dir), "--target", "view_004", "--method", "ulr", "-o",
                     str(tmp_path / f"v{ext}.png"), "--depth-out", str(out), "-q"]) == 0
        back = read_depth(out)
        assert np.array_equal(np.isnan(back), np.isnan(ref)), ext
        ok = np.isfinite(ref)
        assert np.abs(back[ok] - ref[ok]).max() <= tol, ext
    assert main(["render", str(scene_dir), "--target", "1", "-o", str(tmp_path / "x.png"),
                 "--depth-out", str(tmp_path / "d.exr"), "-q"]) == 2
    assert "--depth-out must end in" in capsys.readouterr().err


def test_depth_at_a_source_camera_is_that_views_depth(scene_dir):
    """A render from a camera placed at a source view has that view's (exact, ray-cast)
    depth: from that view alone on every pixel it covers; from the others (it held out) on
    the pixels away from depth edges, to 1e-3 relative. At an edge the z-buffer holds the
    nearest surface any view's pixel quads reach, up to about a pixel past the edge."""
    from scipy import ndimage

    from vibr.io import load_scene
    from vibr.render import render

    scene = load_scene(scene_dir)
    view = scene["view_004"]
    truth = view.depth
    alone = render(scene.replace(views=[view]), view.camera, "ulr")
    cover = alone.coverage & np.isfinite(truth)
    assert cover.mean() > 0.99 and np.isfinite(alone.depth[cover]).all()
    assert (np.abs(alone.depth[cover] - truth[cover]) / truth[cover]).max() < 1e-3
    held = render(scene.replace(views=[v for v in scene.views if v.name != view.name]), view.camera, "ulr")
    t = np.nan_to_num(truth, nan=1e3)
    smooth = ndimage.maximum_filter(t, 5) / ndimage.minimum_filter(t, 5) < 1.02  # no edge within 2 px
    cover = held.coverage & np.isfinite(truth) & smooth
    assert cover.mean() > 0.3 and np.isfinite(held.depth[cover]).all()
    rel = np.abs(held.depth[cover] - truth[cover]) / truth[cover]
    assert rel.max() < 1e-3, rel.max()
