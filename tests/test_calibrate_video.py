"""Calibration from a video (``vibr calibrate VIDEO``): the sharpest frame of each stretch
is kept, a phone's rotation is applied, and the frames of a synthetic walk calibrate to the
cameras that filmed them."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from scipy import ndimage

from _checks import messages_logged
from vibr.calib.colmap import pose_errors
from vibr.calib.video_frames import extract_frames, sharpness
from vibr.errors import VibrInputError
from vibr.io.video import open_video, write_video

pytestmark = pytest.mark.slow


def _texture(seed, h=120, w=160):
    rng = np.random.default_rng(seed)
    return ndimage.gaussian_filter(rng.random((h, w, 3)), (1, 1, 0))


def _motion_blur(img, px=9):
    return ndimage.uniform_filter1d(img, px, axis=1)


def test_sharpness_ranks_blur():
    img = _texture(0)
    s = [sharpness(img), sharpness(_motion_blur(img, 3)), sharpness(_motion_blur(img, 9))]
    assert s[0] > s[1] > s[2] > 0
    assert sharpness(np.full((40, 40, 3), 0.5)) == 0


def test_the_sharpest_frame_of_each_stretch_is_kept(tmp_path):
    """Three stretches of four frames, each with one sharp frame among motion-blurred ones
    (at the stretch's end in one of them): those three are kept, in time order, named by
    their frame number."""
    sharp = [1, 7, 8]
    frames = []
    for i in range(12):
        img = _texture(0)  # one scene, so that only the blur differs
        frames.append(img if i in sharp else _motion_blur(img, 9))
    video = tmp_path / "walk.mp4"
    write_video(video, frames, fps=12, crf=10)
    kept = extract_frames(video, tmp_path / "frames", 3)
    assert kept.indices == sharp
    assert [f.name for f in kept.files] == [f"frame_{i:06d}.bmp" for i in sharp]
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == [f.name for f in kept.files]
    assert kept.n_read == 12 and min(kept.sharpness) > 2 * kept.median_sharpness
    # Fewer frames than asked for: every one is kept.
    assert extract_frames(video, tmp_path / "all", 50).indices == list(range(12))


def test_equally_sharp_frames_are_kept_evenly_spaced(tmp_path):
    video = tmp_path / "still.mp4"
    write_video(video, [_texture(0)] * 24, fps=24, crf=10)
    kept = extract_frames(video, tmp_path / "frames", 6)
    assert np.all(np.diff(kept.indices) == 4), kept.indices  # the middles of the stretches


def test_a_phone_video_is_read_upright(tmp_path):
    """A phone stores a portrait video as landscape frames plus a display rotation: the
    frames come out turned (ffmpeg applies it), and their size says so."""
    import imageio_ffmpeg

    img = np.zeros((60, 80, 3))
    img[:10, :20] = 1.0  # a white block at the top left
    video, turned = tmp_path / "raw.mp4", tmp_path / "phone.mp4"
    write_video(video, [img] * 3, fps=10, crf=0)
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-display_rotation", "90", "-i",
                    str(video), "-c", "copy", str(turned)], check=True)
    with open_video(turned) as (info, frames):
        first = next(frames).astype(float) / 255
    assert (info.width, info.height, info.rotated) == (60, 80, True)
    assert first.shape == (80, 60, 3)
    # 90° anticlockwise: the block goes to the bottom left
    assert np.abs(first - np.rot90(img, 1)).mean() < 0.02


def test_bad_videos_are_refused_in_one_line(tmp_path, capsys):
    from vibr.cli import main

    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"not a video" * 50)
    rc = main(["calibrate", str(bad), str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "broken.mp4" in err and "cannot read the video" in err
    import imageio_ffmpeg

    sound = tmp_path / "voice.mp4"  # a phone's voice memo: an MP4 with sound only
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-f", "lavfi", "-i", "sine=duration=1",
                    "-c:a", "aac", str(sound)], check=True)
    rc = main(["calibrate", str(sound), str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "voice.mp4" in err and "no video stream" in err
    short = tmp_path / "short.mp4"
    write_video(short, [_texture(0)] * 2, fps=10)
    with pytest.raises(VibrInputError, match="the video has 2 frames, calibrate needs at least 3"):
        from vibr.calib.colmap import calibrate_scene
        calibrate_scene(short)
    rc = main(["calibrate", str(short), str(tmp_path / "out"), "--frames", "1"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "frames must be an integer >= 2" in err
    with pytest.raises(VibrInputError, match=r"frames \(2\) must be at least min_registered \(3\)"):
        calibrate_scene(short, frames=2)
    rc = main(["calibrate", str(tmp_path), str(tmp_path / "out"), "--frames", "10"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "--frames is for a video" in err and str(tmp_path) in err
    assert not (tmp_path / "out").exists()


def test_calibrate_a_video_of_a_walk(tmp_path, capsys):
    """24 frames along an arc of the synthetic world, as an H.264 video: ``vibr calibrate
    VIDEO --frames 8`` keeps one frame of each stretch of 3, matches them sequentially and
    recovers the cameras of those frames."""
    import vibr.synthetic as synthetic
    from vibr.cli import main
    from vibr.io import load_scene

    truth = synthetic.make_scene("arc", n_views=24, width=320, height=240, seed=0)
    video = tmp_path / "walk.mp4"
    write_video(video, [v.image for v in truth.views], fps=8, crf=12)
    out = tmp_path / "scene"
    assert main(["calibrate", str(video), str(out), "--frames", "8", "-q"]) == 0
    said = capsys.readouterr().out  # what to run next: a path along the walk, then the video
    assert f"next: vibr path interpolate {out} -o walk.json --smooth 2 && vibr render {out} --path" in said
    info = json.loads((out / "calibration.json").read_text())
    assert info["matcher"] == "sequential"
    # walking, not turned on the spot: COLMAP's mapper, the test stopped at its gate
    assert info["turned_on_the_spot"] is False and info["one_centre"]["taken"] is False
    assert "matches_px" not in info["one_centre"]
    assert info["one_centre"]["why"] == "the pairs are not related by homographies"
    kept = info["video"]["frames_kept"]
    assert [k // 3 for k in kept] == list(range(8)) and info["video"]["frames_read"] == 24
    assert len(info["registered"]) == 8 and not info["unregistered"]
    scene = load_scene(out)
    assert scene.names == [f"frame_{k:06d}" for k in kept]
    from vibr.cli.info import describe  # vibr info says where the cameras come from

    assert "calib    pycolmap" in describe(scene) and "from walk.mp4, 8 of its 24 frames" in describe(scene)
    # the views are the video's frames in time order, said in transforms.json
    assert scene.meta["capture"] == "video"
    assert json.loads((out / "transforms.json").read_text())["vibr_capture"] == "video"
    e = pose_errors([v.camera for v in scene.views], [truth.views[k].camera for k in kept])
    assert e["rot_deg"].max() < 1.0, e["rot_deg"]
    assert e["centre_rel"].max() < 0.02, e["centre_rel"]


def test_a_path_through_a_videos_frames_keeps_their_time_order():
    """A walk out and back along two close lines: by proximity the path zigzags between
    them; the frames of a video (``meta["capture"]``) are taken in time order."""
    from vibr.paths.camera_path import interpolate
    from vibr.scene import Scene, View
    from vibr.synthetic import walk_cameras

    out = walk_cameras(8, turn_deg=0)
    # back 0.05 beside the way out, half a step along: nearer the way out's keys than they are to each other
    back = [c.__class__.from_centre(c.K, c.R, c.centre + [0.05, 0, 0.05], c.width, c.height) for c in out[::-1]]
    views = [View(f"frame_{k:06d}", np.zeros((120, 160, 3), np.float32), c) for k, c in enumerate(out + back)]
    names = [v.name for v in views]
    plain = Scene(views)
    video = Scene(views, meta={"capture": "video"})
    assert interpolate(plain, n_frames=40).meta["views"] != names  # proximity reorders them
    assert interpolate(video, n_frames=40).meta["views"] == names
    assert interpolate(video, n_frames=40, order="proximity").meta["views"] != names


def test_a_video_cut_short_is_said(tmp_path):
    """A copy interrupted half-way decodes up to where it stops: the stretches are cut again
    for the frames it has (a second reading), so the frames asked for are kept, spread over
    them, and a warning says the video ended before the frames its header announces."""
    video = tmp_path / "walk.mp4"
    write_video(video, [_texture(k) for k in range(40)], fps=10, crf=18)
    data = video.read_bytes()
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(data[: len(data) // 2])  # faststart: the header, then the first half of the frames
    with messages_logged("vibr.calib.video_frames") as seen:
        kept = extract_frames(cut, tmp_path / "frames", 8)
    assert 8 <= kept.n_read < 40 and len(kept.files) == 8 and kept.total == kept.n_read
    assert kept.indices[-1] >= kept.n_read - kept.n_read // 8  # the last stretch ends where the video does
    assert any("ended after" in m and "of the 40 frames" in m for m in seen), seen
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == [f.name for f in kept.files]


def test_no_room_for_the_frames_is_said_before_reading(tmp_path, monkeypatch):
    import shutil
    from collections import namedtuple

    video = tmp_path / "walk.mp4"
    write_video(video, [_texture(k) for k in range(6)], fps=10)
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10 ** 9, 10 ** 9 - 100_000, 100_000))
    with pytest.raises(VibrInputError, match=r"0.1 MiB free, 6 frames of 160x120 need about 0.3 MiB"):
        extract_frames(video, tmp_path / "frames", 10)
    assert not any((tmp_path / "frames").iterdir())


def test_the_choice_stays_near_the_middle_of_a_long_stretch(tmp_path):
    """Two stretches of 3 s at 10 fps: a sharp frame 1.25 s from its stretch's middle is not
    taken (the views would bunch up at one end), one 0.05 s from it is."""
    from vibr.calib.video_frames import REACH_S

    frames = [_motion_blur(_texture(0), 5)] * 60
    frames = list(frames)
    frames[2] = frames[45] = _texture(0)
    video = tmp_path / "long.mp4"
    write_video(video, frames, fps=10, crf=10)
    assert REACH_S * 10 < 14.5 - 2
    assert extract_frames(video, tmp_path / "frames", 2).indices == [14, 45]
