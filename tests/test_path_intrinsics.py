"""Camera paths keep the photographs' intrinsics at their keys: a frame at a key camera has
that photograph's K (focal lengths and principal point, at the frame's size), camera_path.json
carries it (vibr's optional fl_x, fl_y, cx, cy), and the frame renders what a render at that
camera renders."""

import json
import math

import numpy as np
import pytest

from vibr.camera import Camera
from vibr.errors import VibrInputError


@pytest.fixture(autouse=True)
def _cache_in_tmp(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("VIBR_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "vibr-cache"))


def _off_centre(cam: Camera, i: int) -> Camera:
    """The camera with a principal point a few pixels off the centre and fx != fy (as a
    calibrated photograph has), different for every view."""
    K = cam.K.copy()
    K[0, 0] *= 1.0 + 0.01 * (i + 1)
    K[0, 2] += 2.5 - i
    K[1, 2] -= 1.5 + 0.5 * i
    return Camera(K, cam.R, cam.t, cam.width, cam.height)


@pytest.fixture(scope="module")
def calibrated_arc():
    """An arc of 5 views of the synthetic world rendered through off-centre cameras."""
    from vibr.scene import Scene, View
    from vibr.synthetic import arc_cameras, default_world, render_view

    world = default_world(0)
    views = []
    for i, cam in enumerate(arc_cameras(5, width=64, height=48)):
        cam = _off_centre(cam, i)
        img, depth = render_view(world, cam)
        views.append(View(f"view_{i:03d}", img, cam, depth=depth, sigma_z=0.01))
    return Scene(views, name="calibrated-arc")


def test_key_frames_have_the_photographs_k(calibrated_arc):
    """At every key the frame's camera is the photograph's (K, pose), at the photograph's
    size and resized (scale 0.5: Camera.scaled's K); between keys the focal lengths and the
    principal point stay between the neighbouring keys'."""
    from vibr.paths.camera_path import interpolate

    names = calibrated_arc.names
    p = interpolate(calibrated_arc, names, n_frames=2)
    assert p.cameras[0].allclose(calibrated_arc.views[0].camera, atol=1e-9)
    assert p.cameras[1].allclose(calibrated_arc.views[-1].camera, atol=1e-9)
    half = interpolate(calibrated_arc, names, n_frames=2, scale=0.5)
    assert (half.width, half.height) == (32, 24)
    for cam, v in zip(half.cameras, (calibrated_arc.views[0], calibrated_arc.views[-1])):
        assert np.abs(cam.K - v.camera.scaled(0.5).K).max() <= 1e-9
    # a frame at every key: n − 1 = 4 · 20 steps, knots where t is the key's
    q = interpolate(calibrated_arc, names, n_frames=81)
    knots = np.array(q.meta["knots"])
    ts = np.linspace(knots[0], knots[-1], 81)
    for i, v in enumerate(calibrated_arc.views):
        j = int(np.argmin(np.abs(ts - knots[i])))
        if abs(ts[j] - knots[i]) < 1e-12 * knots[-1]:
            assert np.abs(q.cameras[j].K - v.camera.K).max() <= 1e-9
    Ks = np.array([c.K for c in q.cameras])
    keys = np.array([v.camera.K for v in calibrated_arc.views])
    for a, b in ((0, 0), (1, 1), (0, 2), (1, 2)):
        lo, hi = keys[:, a, b].min(), keys[:, a, b].max()
        span = hi - lo
        assert Ks[:, a, b].min() >= lo - 0.2 * span and Ks[:, a, b].max() <= hi + 0.2 * span
    # smooth: no step of the principal point much larger than the path's steps warrant
    assert np.abs(np.diff(Ks[:, 0, 2])).max() < 0.5


def test_centred_pinholes_stay_centred(tmp_path):
    """A path through centred square-pixel cameras (every synthetic scene's, a viewer's
    keyframes) has centred square-pixel frames, exactly, and its file no intrinsics keys."""
    from vibr.paths.camera_path import interpolate, write_camera_path
    from vibr.synthetic import make_scene

    s = make_scene("arc", n_views=4, width=40, height=30, seed=0)
    p = interpolate(s, n_frames=9)
    for c in p.cameras:
        assert c.K[0, 0] == c.K[1, 1] == s.views[0].camera.K[1, 1]
        assert (c.K[0, 2], c.K[1, 2]) == (19.5, 14.5)
    write_camera_path(tmp_path / "p.json", p)
    frames = json.loads((tmp_path / "p.json").read_text())["camera_path"]
    assert all(set(fr) == {"camera_to_world", "fov", "aspect"} for fr in frames)


def test_camera_path_file_carries_the_intrinsics(calibrated_arc, tmp_path):
    """fl_x, fl_y, cx, cy (transforms.json's pixel convention, + 0.5) are written for an
    off-centre camera and read back exactly; the fov beside them is fl_y's (what nerfstudio
    reads); a centred pinhole's frame has only its fov, as every nerfstudio file."""
    from vibr.paths.camera_path import interpolate, read_camera_path, write_camera_path

    p = interpolate(calibrated_arc, n_frames=7)
    f = tmp_path / "p.json"
    write_camera_path(f, p)
    d = json.loads(f.read_text())
    fr = d["camera_path"][0]
    K = p.cameras[0].K
    assert (fr["fl_x"], fr["fl_y"], fr["cx"], fr["cy"]) == (K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5)
    assert abs((48 / 2) / math.tan(math.radians(fr["fov"]) / 2) - K[1, 1]) < 1e-9
    q = read_camera_path(f)
    for a, b in zip(p.cameras, q.cameras):
        assert a.allclose(b, atol=1e-9)
    centred = Camera(Camera.intrinsics(50.0, 64, 48), np.eye(3), np.zeros(3), 64, 48)
    write_camera_path(tmp_path / "c.json", [centred], fps=1.0)
    assert set(json.loads((tmp_path / "c.json").read_text())["camera_path"][0]) == {"camera_to_world", "fov", "aspect"}


def _frame(fov=50.0, **extra):
    return {"camera_type": "perspective", "render_width": 64, "render_height": 48, "fps": 24,
            "camera_path": [{"camera_to_world": np.eye(4).ravel().tolist(), "fov": fov, **extra}]}


def test_old_files_and_partial_intrinsics(tmp_path):
    """A frame without the keys is the centred pinhole of its fov (today's meaning); with
    some of them the others default (fl_x to fl_y, the principal point to the centre); an
    fl_y that disagrees with the fov, a focal that is not positive or a value that is not a
    number is one line naming the frame."""
    from vibr.paths.camera_path import focal_from_fov, read_camera_path

    f = tmp_path / "p.json"
    f.write_text(json.dumps(_frame()))
    K = read_camera_path(f).cameras[0].K
    fy = focal_from_fov(50.0, 48)
    assert np.allclose(K, [[fy, 0, 31.5], [0, fy, 23.5], [0, 0, 1]], atol=1e-12)
    f.write_text(json.dumps(_frame(cx=30.0)))
    K = read_camera_path(f).cameras[0].K
    assert np.allclose(K, [[fy, 0, 29.5], [0, fy, 23.5], [0, 0, 1]], atol=1e-12)
    for extra, msg in (({"fl_y": fy * 1.01}, "disagree"), ({"fl_x": -3}, "positive"),
                       ({"cy": "middle"}, "must be a number"), ({"cx": float("nan")}, "finite")):
        f.write_text(json.dumps(_frame(**extra)))
        with pytest.raises(VibrInputError, match=msg) as exc:
            read_camera_path(f)
        assert "camera_path[0]" in str(exc.value)


def test_path_frame_at_a_source_is_its_render(calibrated_arc, tmp_path):
    """A fly-through frame at a source's camera (the path's first key, read back from its
    camera_path.json) renders what vibr.render renders at that camera from the same sources
    (above 50 dB against it), and gives the photograph back (above 40 dB)."""
    from vibr.io import read_image
    from vibr.metrics import psnr
    from vibr.paths.camera_path import interpolate, read_camera_path, write_camera_path
    from vibr.paths.flythrough import render_path
    from vibr.render import render

    s = calibrated_arc
    p = interpolate(s, [s.names[1], s.names[3]], n_frames=2)
    write_camera_path(tmp_path / "p.json", p)
    q = read_camera_path(tmp_path / "p.json")
    assert q.cameras[0].allclose(s.views[1].camera, atol=1e-9)
    res = render_path(s, q, tmp_path / "f", cache_dir=False, executor=None, progress=False)
    assert res.frames[0]["views"] == s.names  # every source, the photograph's own among them
    fr = read_image(tmp_path / "f" / "frame_00000.png")
    ref = render(s, s.views[1].camera, "gradient").image
    # the fly-through blends its sources with soft weights: a few edge pixels differ (58.7 dB)
    assert psnr(fr, ref, border=2) > 50
    assert psnr(fr, s.views[1].image, border=2) > 40
