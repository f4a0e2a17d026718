"""The viewer without a browser: camera conversion (closed form), the latest-request
worker, the point cloud, keyframes → camera_path.json → ``vibr render --path``, and the
CLI's errors and start/stop."""

from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from vibr.camera import Camera
from vibr.viewer import (
    CameraState,
    LatestRequestWorker,
    Viewer,
    ViewerOptions,
    ViewSettings,
    camera_from_viser,
    image_size,
    viser_pose_from_camera,
)
from vibr.viewer.browser import free_port
from vibr.viewer.convert import matrix_to_quat, quat_to_matrix
from vibr.viewer.geometry import point_cloud

_SRC = str(Path(__file__).resolve().parents[1] / "src")


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = _SRC + os.pathsep + env.get("PYTHONPATH", "")
    return env



@pytest.fixture(scope="module")
def tiny_scene():
    from vibr.synthetic import make_scene

    return make_scene("handheld", n_views=5, width=64, height=48)


# ------------------------------------------------------------------ conversion
def test_quaternions_match_viser():
    import viser.transforms as tf
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        R = quat_to_matrix(q)
        assert np.allclose(R, tf.SO3(q).as_matrix(), atol=1e-12)
        q2 = matrix_to_quat(R)
        assert np.allclose(quat_to_matrix(q2), R, atol=1e-12)
        assert np.allclose(q2, q if q[0] >= 0 else -q, atol=1e-9)


def test_camera_from_viser_closed_form():
    # identity orientation: OpenCV axes = world axes; fov 90°: f = H/2
    cam = camera_from_viser((1, 0, 0, 0), (1.0, 2.0, 3.0), math.pi / 2, 2.0, 200)
    assert (cam.width, cam.height) == (200, 100)
    assert np.allclose(cam.K, [[50, 0, 99.5], [0, 50, 49.5], [0, 0, 1]])
    assert np.allclose(cam.R, np.eye(3)) and np.allclose(cam.centre, [1, 2, 3])
    xy, z = cam.project(np.array([[1.0, 2.0, 8.0], [1.0, 2.0 - 5.0, 8.0], [1.0 + 5.0, 2.0, 8.0]]))
    # straight ahead: the image centre; 45° up: the top edge of the image (y = -0.5);
    # 45° right: 50 px right of the centre (square pixels)
    assert np.allclose(xy, [[99.5, 49.5], [99.5, -0.5], [149.5, 49.5]]) and np.allclose(z, 5.0)
    # a quarter turn about world y (z → x): the camera looks along world +x, image x = -z
    s = math.sqrt(0.5)
    cam = camera_from_viser((s, 0, s, 0), (0, 0, 0), math.pi / 2, 1.0, 100)
    assert np.allclose(cam.optical_axis, [1, 0, 0], atol=1e-12)
    xy, z = cam.project(np.array([[4.0, 0.0, 0.0], [4.0, 0.0, -4.0]]))
    assert np.allclose(xy, [[49.5, 49.5], [99.5, 49.5]]) and np.allclose(z, 4.0)
    # portrait canvas: the long side is the height
    assert image_size(0.5, 256) == (128, 256)


def test_viser_pose_round_trip(tiny_scene):
    for v in tiny_scene.views:
        wxyz, pos, fov, aspect = viser_pose_from_camera(v.camera)
        back = camera_from_viser(wxyz, pos, fov, aspect, max(v.camera.width, v.camera.height))
        assert back.allclose(v.camera, atol=1e-9)


# ------------------------------------------------------------------ worker
def test_latest_request_worker_drops_stale_requests():
    done = []
    release = threading.Event()

    def fn(req, kind):
        done.append((req.payload, kind))
        if req.payload == 0:
            release.wait(5)

    w = LatestRequestWorker(fn, settle_s=0.2)
    try:
        w.submit(0)
        time.sleep(0.1)  # the worker is busy with 0's preview
        for i in range(1, 20):
            w.submit(i)
        release.set()
        deadline = time.monotonic() + 5
        while (19, "full") not in done and time.monotonic() < deadline:
            time.sleep(0.02)
    finally:
        w.stop()
    # 0's preview, then only the newest: 19's preview, then its full render once settled;
    # 0's full render never happens (superseded), 1..18 were dropped unrendered
    assert done == [(0, "preview"), (19, "preview"), (19, "full")]
    assert w.dropped == 18 and w.submitted == 20


def test_full_render_waits_for_the_camera_to_settle():
    times = {}
    w = LatestRequestWorker(lambda req, kind: times.setdefault(kind, time.perf_counter() - req.t_update),
                            settle_s=0.3)
    try:
        w.submit("a")
        deadline = time.monotonic() + 3
        while "full" not in times and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        w.stop()
    assert times["preview"] < 0.2 and 0.3 <= times["full"] < 1.0


# ------------------------------------------------------------------ geometry
def test_point_cloud_lies_on_the_depth_maps(tiny_scene):
    P, C = point_cloud(tiny_scene, max_points=500)
    assert 0 < len(P) <= 500 and C.dtype == np.uint8 and C.shape == P.shape
    # every point is some view's pixel at that view's depth: reproject into view 0 and the
    # points it sees land at its depth (exact synthetic depth, float32 rounding)
    v = tiny_scene.views[0]
    xy, z = v.camera.project(P.astype(np.float64))
    ij = np.round(xy).astype(int)
    ok = (z > 0) & (ij[:, 0] >= 0) & (ij[:, 0] < v.camera.width) & (ij[:, 1] >= 0) & (ij[:, 1] < v.camera.height)
    on = np.isclose(v.depth[ij[ok, 1], ij[ok, 0]], z[ok], rtol=0.02)
    assert on.mean() > 0.5  # the others are hidden in view 0 or on depth edges
    # the pixels of a fallback proxy are no points: one view all proxy adds none
    views = list(tiny_scene.views)
    views[0] = v.replace(depth=v.depth, fallback=np.ones(v.shape, bool))
    n_all = len(point_cloud(tiny_scene.replace(views=views[1:]), max_points=10**6)[0])
    assert len(point_cloud(tiny_scene.replace(views=views), max_points=10**6)[0]) == n_all


# ------------------------------------------------------------------ keyframes → path
def test_georeferenced_scene_is_drawn_relative_to_its_centre(tiny_scene):
    """Half a million units from the origin, float32 (what the browser draws with) keeps
    0.03 units: the viewer sends positions relative to the cameras' mean centre and adds it
    back to the browser's camera, so points and cameras keep the scene's precision."""
    off = np.array([5e5, -1.7e5, 7e4])
    far = tiny_scene.replace(views=[v.replace(camera=Camera.from_centre(v.camera.K, v.camera.R, v.camera.centre + off,
                                                                      v.camera.width, v.camera.height))
                                    for v in tiny_scene.views])
    v = Viewer(far, ViewerOptions(warm_up=False))
    assert np.linalg.norm(v.origin - off) < 5.0
    assert not np.any(Viewer(tiny_scene, ViewerOptions(warm_up=False)).origin)  # near the origin: none
    P, _ = point_cloud(far, 5000, origin=v.origin)
    P0, _ = point_cloud(tiny_scene, 5000)
    np.testing.assert_allclose(P.astype(np.float64) + v.origin - off, P0, atol=1e-4)
    cam = far.views[1].camera
    wxyz, pos, fov, aspect = viser_pose_from_camera(cam)
    st = CameraState(tuple(wxyz), tuple(pos - v.origin), fov, aspect)
    assert max(abs(x) for x in st.position) < 10.0  # what the browser holds
    assert st.camera(cam.width, v.origin).allclose(cam, atol=1e-6)


def test_exported_path_renders_with_vibr_render(tiny_scene, tmp_path):
    import vibr.paths.camera_path as path_mod
    from vibr.io import save_scene

    scene_dir = tmp_path / "scene"
    save_scene(tiny_scene, scene_dir)
    viewer = Viewer(tiny_scene, ViewerOptions(fps=4.0, settings=ViewSettings(full_long_side=64)))
    for v in (tiny_scene.views[0], tiny_scene.views[2]):
        wxyz, pos, fov, aspect = viser_pose_from_camera(v.camera)
        viewer.add_keyframe(CameraState(tuple(wxyz), tuple(pos), fov, aspect))
    from vibr.errors import VibrInputError

    # an unwritable path file is a one-line error (shown in the panel), not an OSError
    for bad in (tmp_path / "no_such_folder" / "p.json", tmp_path):
        with pytest.raises(VibrInputError, match="path file|folder"):
            viewer.export_path(bad, seconds=1.0)
    # the panel's file name: a bare name in the folder of --path-out, never a path elsewhere
    from types import SimpleNamespace

    viewer.options.path_out = str(tmp_path / "camera_path.json")
    for typed in ("../evil.json", "/etc/evil.json", "sub/p.json", "p.txt", ".bashrc.json"):
        viewer.gui["path_out"] = SimpleNamespace(value=typed)
        with pytest.raises(VibrInputError, match="a file name ending in .json"):
            viewer.export_path(seconds=1.0)
    viewer.gui["path_out"] = SimpleNamespace(value="mine.json")
    assert viewer.export_path(seconds=1.0) == tmp_path / "mine.json"
    viewer.gui["path_out"] = SimpleNamespace(value="camera_path.json")  # what the panel starts with
    assert viewer.export_path(seconds=1.0) == tmp_path / "camera_path.json"
    out = viewer.export_path(tmp_path / "camera_path.json", seconds=1.0)
    cpath = path_mod.read_camera_path(out)
    assert len(cpath.cameras) == 4 and (cpath.width, cpath.height) == (64, 48)
    assert cpath.cameras[0].allclose(tiny_scene.views[0].camera, atol=1e-6)
    frames = tmp_path / "frames"
    from vibr.cli import main

    rc = main(["render", str(scene_dir), "--path", str(out), "-o", str(frames), "--views", "3", "-q"])
    assert rc == 0
    pngs = sorted(frames.glob("*.png"))
    assert len(pngs) == 4
    import imageio.v3 as iio

    from vibr.metrics import psnr

    first = iio.imread(pngs[0]).astype(np.float32) / 255.0
    assert psnr(first[..., :3], tiny_scene.views[0].image) > 25.0  # the first keyframe is view 0


# ------------------------------------------------------------------ CLI
def test_view_cli_port_in_use(tmp_path):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    port = s.getsockname()[1]
    try:
        r = subprocess.run([sys.executable, "-m", "vibr", "view", str(tmp_path), "--port", str(port)],
                           capture_output=True, text=True, timeout=60, env=_env())
    finally:
        s.close()
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and f"port {port}" in lines[0] and "Traceback" not in r.stderr


def test_view_cli_bad_scene(tmp_path):
    port = free_port()
    r = subprocess.run([sys.executable, "-m", "vibr", "view", str(tmp_path / "missing"), "--port", str(port)],
                       capture_output=True, text=True, timeout=60, env=_env())
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "missing" in lines[0] and "not found" in lines[0]
    # nothing left listening
    c = socket.socket()
    assert c.connect_ex(("127.0.0.1", port)) != 0
    c.close()


def test_view_cli_unwritable_path_out(tmp_path):
    """--path-out is checked at start (as every output), not at the first 'export path'."""
    port = free_port()
    bad = tmp_path / "no_such_folder" / "p.json"
    r = subprocess.run([sys.executable, "-m", "vibr", "view", str(tmp_path / "missing"), "--port", str(port),
                        "--path-out", str(bad)], capture_output=True, text=True, timeout=60, env=_env())
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "--path-out" in lines[0] and "does not exist" in lines[0]


@pytest.mark.slow
@pytest.mark.parametrize("host", ["127.0.0.1", "0.0.0.0"])
def test_view_cli_serves_and_stops(tiny_scene, tmp_path, host):
    """Serves its page, exits 0 on Ctrl-C with the port freed; on a non-loopback address it
    says who can reach it."""
    from vibr.io import save_scene

    save_scene(tiny_scene, tmp_path / "scene")
    port = free_port()
    env = {k: v for k, v in _env().items() if k not in ("NUMBA_NUM_THREADS", "OMP_WAIT_POLICY")}
    p = subprocess.Popen([sys.executable, "-m", "vibr", "-v", "view", str(tmp_path / "scene"), "--port", str(port),
                          "--host", host], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = ""
        deadline = time.monotonic() + 60
        while f"http://{host}:{port}" not in line:
            assert time.monotonic() < deadline and p.poll() is None, p.stderr.read() if p.poll() is not None else "timeout"
            line = p.stdout.readline()
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10) as resp:
            assert resp.status == 200 and b"<html" in resp.read().lower()
        p.send_signal(signal.SIGINT)
        assert p.wait(timeout=20) == 0
        from vibr._runtime.threads import cores

        err = p.stderr.read()
        assert f"renders on {2 * cores()} numba threads" in err  # vibr._runtime.threads
        assert ("listening on 0.0.0.0: anyone who reaches this machine" in err) == (host == "0.0.0.0")
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(5)
    c = socket.socket()
    assert c.connect_ex(("127.0.0.1", port)) != 0
    c.close()


@pytest.mark.parametrize("polls", [1, 2, 3, 4, 5, 6])
def test_stale_render_is_abandoned(tiny_scene, polls):
    """The request is checked before the render, after its geometry and between the solve's
    stages (before its first iteration): whichever poll says stop, the render stops there."""
    from vibr.render import RenderStopped
    from vibr.viewer import ViewRenderer

    r = ViewRenderer(tiny_scene)
    cam = tiny_scene.views[0].camera
    calls = []
    with pytest.raises(RenderStopped):
        r.render(cam, ViewSettings(n_views=3), should_stop=lambda: calls.append(1) or len(calls) >= polls)
    assert len(calls) == polls
    out = r.render(cam, ViewSettings(n_views=3), should_stop=lambda: False)
    assert out.image.shape == (48, 64, 3) and len(out.sources) == 3


def test_previews_render_from_views_at_their_scale(tiny_scene):
    from vibr.viewer import ViewRenderer

    r = ViewRenderer(tiny_scene)
    small = tiny_scene.views[0].camera.scaled(0.5)
    sc = r.scene_for(small)
    assert [v.shape for v in sc.views] == [(24, 32)] * len(tiny_scene)
    assert all(v.camera.allclose(w.camera.scaled(0.5)) for v, w in zip(sc.views, tiny_scene.views))
    assert r.scene_for(tiny_scene.views[0].camera) is tiny_scene  # full size: the views as they are
    out = r.render(small, ViewSettings(n_views=3))
    assert out.image.shape == (24, 32, 3)


def test_kept_depth_preparation_gives_the_per_request_image(tiny_scene, monkeypatch):
    """The per-source depth preparation the renderer keeps for the session (full size and
    each preview scale) renders exactly what preparing it per request renders."""
    import vibr.viewer.renderer as R
    from vibr.render import render

    r = R.ViewRenderer(tiny_scene)
    cams = [tiny_scene.views[0].camera, tiny_scene.views[2].camera.scaled(0.5)]
    kept = [r.render(c, ViewSettings(n_views=3)) for c in cams + cams]
    assert set(r._prepared) == {1.0, 0.5} and len(r._prepared[1.0]) >= 3
    for c, out in zip(cams + cams, kept):
        src = r.scene_for(c).subset(r.sources_for(c, 3))
        assert np.array_equal(out.image, render(src, c).image)  # ViewSettings(): the renderer's defaults
    monkeypatch.setattr(R, "PREPARED_BUDGET_BYTES", 0)  # nothing kept: prepared per request
    r0 = R.ViewRenderer(tiny_scene)
    assert np.array_equal(r0.render(cams[0], ViewSettings(n_views=3)).image, kept[0].image)
    assert r0._prepared_bytes == 0


def test_full_view_png_is_lossless():
    import io

    import imageio.v3 as iio

    from vibr.viewer.app import encode_png

    img = np.random.default_rng(0).integers(0, 256, (37, 53, 3), dtype=np.uint8)
    assert np.array_equal(iio.imread(io.BytesIO(encode_png(img))), img)


def test_identical_camera_echo_is_not_a_new_request(tiny_scene):
    """The browser reports one move several times: only a changed camera makes a request."""
    from types import SimpleNamespace

    from vibr.viewer import Viewer, ViewerOptions

    v = Viewer(tiny_scene, ViewerOptions(warm_up=False))
    got = []
    v._workers[7] = SimpleNamespace(submit=lambda payload, t_update=None: got.append(payload))
    v._hide_frustums_at = lambda pos: None
    cam = SimpleNamespace(wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.0, 0.0, 0.0), fov=0.8, aspect=1.5,
                          client=SimpleNamespace(client_id=7))
    v._on_camera(cam)
    v._on_camera(cam)
    assert len(got) == 1
    v._on_camera(SimpleNamespace(**dict(vars(cam), position=(0.0, 0.0, 0.1))))
    assert len(got) == 2


@pytest.mark.parametrize("mode", ["while moving", "always", "never"])
def test_point_cloud_shown_while_the_camera_moves(tiny_scene, monkeypatch, mode):
    """Default "while moving": the points appear with a camera move and go with the preview
    of a camera no newer update replaced (a stale preview leaves them), or when the
    full-size render starts; one visibility message per change; "always" / "never" do not
    follow the camera."""
    from types import SimpleNamespace

    from vibr.errors import VibrInputError
    from vibr.viewer import Viewer, ViewerOptions, ViewSettings, app
    from vibr.viewer.worker import Request

    monkeypatch.setattr(app, "send_background", lambda client, img, kind: None)
    v = Viewer(tiny_scene, ViewerOptions(warm_up=False, points=mode, settings=ViewSettings(full_long_side=32)))
    changes = []

    class Points:
        def __setattr__(self, name, value):
            changes.append(value)

    v._points = Points()
    v.gui = {"points": SimpleNamespace(value=mode), "status": SimpleNamespace(content=""),
             "show_sources": SimpleNamespace(value=False)}
    v._set_visible("points")
    newest = {"seq": 2}
    v._workers[7] = SimpleNamespace(submit=lambda payload, t_update=None: 1,
                                    is_stale=lambda req: req.seq != newest["seq"])
    v._hide_frustums_at = lambda pos: None
    client = SimpleNamespace(client_id=7, flush=lambda: None)
    wxyz, pos, fov, aspect = app.viser_pose_from_camera(tiny_scene.views[0].camera)
    cam = SimpleNamespace(wxyz=tuple(wxyz), position=tuple(pos), fov=fov, aspect=aspect, client=client)
    v._on_camera(cam)
    v._on_camera(SimpleNamespace(**dict(vars(cam), position=tuple(np.add(pos, 1e-3)))))
    moving = v._points_shown
    preview = app.ViewSettings(full_long_side=32, preview_long_side=16)
    state = app.CameraState.of(cam)
    v._render_for(client, Request(1, 0.0, (state, preview)), "preview")  # a newer camera came
    after_stale = v._points_shown
    v._render_for(client, Request(2, 0.0, (state, preview)), "preview")
    after_preview = v._points_shown
    v._on_camera(SimpleNamespace(**dict(vars(cam), position=tuple(np.add(pos, 2e-3)))))
    newest["seq"] = 3
    moving_again = v._points_shown
    v._render_for(client, Request(3, 0.0, (state, v.settings)), "full")  # no preview first
    still = v._points_shown
    want = {"while moving": (False, True, True, False, True, False), "always": (True,) * 6,
            "never": (False,) * 6}[mode]
    assert (changes[0], moving, after_stale, after_preview, moving_again, still) == want
    assert all(a != b for a, b in zip(changes, changes[1:]))  # a message only when it changes
    assert v.sent[7][-1].kind == "full"
    with pytest.raises(VibrInputError, match="points"):
        Viewer(tiny_scene, ViewerOptions(points="sometimes"))


# ------------------------------------------------------------------ render threads
_THREADS_PROBE = r"""
import json, os, threading
from vibr._runtime.threads import cores, oversubscribe_render_threads
if os.environ.get("PROBE_LAUNCH_FIRST"):
    import numba  # imported before the call: too late
n = oversubscribe_render_threads()
import numba, numpy as np
from vibr.synthetic import make_scene
from vibr.viewer import ViewRenderer, ViewSettings
scene = make_scene("handheld", n_views=4, width=96, height=80)
cam, st = scene.views[0].camera, ViewSettings(n_views=3)
seen = {}
def on_worker():  # as the viewer's render worker: numba's threads while its render solves
    seen["image"] = ViewRenderer(scene).render(cam, st, should_stop=lambda: bool(
        seen.setdefault("worker", numba.get_num_threads())) and False).image
t = threading.Thread(target=on_worker)
t.start(); t.join()
same = bool(np.array_equal(ViewRenderer(scene, threads=1).render(cam, st).image, seen["image"]))
print(json.dumps({"n": n, "cores": cores(), "config": numba.config.NUMBA_NUM_THREADS,
                  "main": numba.get_num_threads(), "worker": seen["worker"],
                  "wait": os.environ.get("OMP_WAIT_POLICY"), "same": same}))
"""


def _threads_probe(**env_changes):
    env = _env()
    for k in ("NUMBA_NUM_THREADS", "OMP_WAIT_POLICY", "PROBE_LAUNCH_FIRST"):
        env.pop(k, None)
    env.update(env_changes)
    r = subprocess.run([sys.executable, "-c", _THREADS_PROBE], capture_output=True, text=True, timeout=240, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    import json

    return json.loads(r.stdout.strip().splitlines()[-1])


def test_viewer_process_renders_on_two_threads_per_core():
    """``vibr view``'s setting (vibr._runtime.threads): numba starts two threads per core that
    wait passively, a render on the viewer's worker thread runs on all of them, and its
    image is the one-thread render's, bit for bit."""
    d = _threads_probe()
    assert d["n"] == d["config"] == d["main"] == d["worker"] == 2 * d["cores"]
    assert d["wait"] == "passive" and d["same"]


def test_render_threads_keep_the_users_setting_and_an_imported_numba():
    d = _threads_probe(NUMBA_NUM_THREADS="1")
    assert d["n"] == d["config"] == d["main"] == 1 and d["wait"] is None and d["same"]
    d = _threads_probe(PROBE_LAUNCH_FIRST="1")  # numba imported first: its own thread count
    assert d["n"] == d["config"] == d["cores"] and d["wait"] is None and d["same"]


def test_render_threads_must_be_positive(tiny_scene):
    from vibr import VibrInputError
    from vibr.viewer import ViewRenderer

    with pytest.raises(VibrInputError, match="threads"):
        ViewRenderer(tiny_scene, threads=0)


@pytest.mark.parametrize("size,hint", [((3072, 2048), "--scale 0.25"), ((3840, 2160), "--scale 0.25"),
                                       ((1920, 1080), None), ((768, 512), None)])
def test_view_hints_a_scale_for_large_views(size, hint):
    """Fountain's full-size photographs (3072×2048) take minutes per view to estimate and
    seconds per still render: `vibr view` says so and suggests a --scale near half a
    megapixel; 1080p and below get no hint."""
    import io
    import logging
    from types import SimpleNamespace

    from vibr.cli.view import _hint_large_views
    from vibr.progress import configure_logging

    scene = SimpleNamespace(views=[SimpleNamespace(camera=SimpleNamespace(width=size[0], height=size[1]))])
    lg = logging.getLogger("vibr")
    saved = (list(lg.handlers), lg.level, lg.propagate)
    buf = io.StringIO()
    configure_logging(0, stream=buf)
    try:
        _hint_large_views(scene, 1.0)
    finally:
        lg.handlers[:], lg.level, lg.propagate = saved
    text = buf.getvalue()
    assert (hint in text and f"{size[0]}x{size[1]}" in text) if hint else text == ""


def test_a_camera_that_sees_nothing_is_said_in_the_panel(tiny_scene, monkeypatch):
    """A camera turned away from the scene: the panel's status says so and nothing is sent;
    the worker logged a traceback for it before."""
    from types import SimpleNamespace

    from vibr.camera import Camera
    from vibr.viewer import Viewer, ViewerOptions, ViewSettings, app
    from vibr.viewer.worker import Request

    monkeypatch.setattr(app, "send_background", lambda client, img, kind: None)
    v = Viewer(tiny_scene, ViewerOptions(warm_up=False, settings=ViewSettings(full_long_side=32)))
    v.gui = {"points": SimpleNamespace(value="never"), "status": SimpleNamespace(content=""),
             "show_sources": SimpleNamespace(value=False)}
    v._points = SimpleNamespace(visible=False)
    client = SimpleNamespace(client_id=3, flush=lambda: None)
    c = tiny_scene.views[0].camera
    away = Camera.from_centre(c.K, np.diag([1.0, -1.0, -1.0]) @ c.R, c.centre, c.width, c.height)
    wxyz, pos, fov, aspect = app.viser_pose_from_camera(away)
    cam = SimpleNamespace(wxyz=tuple(wxyz), position=tuple(pos), fov=fov, aspect=aspect, client=client)
    v._render_for(client, Request(1, 0.0, (app.CameraState.of(cam), v.settings)), "full")
    assert v.gui["status"].content.startswith("nothing to render from here: ")
    assert not v.sent.get(3)


def test_the_viewer_shows_where_the_render_can_be_trusted(tiny_scene, monkeypatch):
    """show "sigma": the image sent is the render's σ map (vibr.render with uncertainty=True,
    the same camera and sources) through viridis on sigma_scale, the status line gives the
    scale; the render itself is the same with or without it."""
    from types import SimpleNamespace

    from vibr.eval.sigma_figures import colourise, sigma_scale
    from vibr.render import render
    from vibr.viewer import app
    from vibr.viewer.renderer import ViewRenderer
    from vibr.viewer.worker import Request

    sent = []
    monkeypatch.setattr(app, "send_background", lambda client, img, kind: sent.append(img))
    settings = ViewSettings(n_views=3, full_long_side=64, show="sigma")
    v = Viewer(tiny_scene, ViewerOptions(warm_up=False, settings=settings))
    v.gui = {"points": SimpleNamespace(value="never"), "status": SimpleNamespace(content=""),
             "show_sources": SimpleNamespace(value=False)}
    v._points = SimpleNamespace(visible=False)
    client = SimpleNamespace(client_id=4, flush=lambda: None)
    cam0 = tiny_scene.views[0].camera
    wxyz, pos, fov, aspect = app.viser_pose_from_camera(cam0)
    st = app.CameraState.of(SimpleNamespace(wxyz=tuple(wxyz), position=tuple(pos), fov=fov, aspect=aspect))
    v._render_for(client, Request(1, 0.0, (st, settings)), "full")
    cam = st.camera(64, v.origin)
    r = ViewRenderer(tiny_scene)
    src = tiny_scene.subset(r.sources_for(cam, 3))
    res = render(src, cam, uncertainty=True)
    vmax = sigma_scale(res.uncertainty)
    assert np.array_equal(sent[-1], colourise(np.where(np.isfinite(res.uncertainty), res.uncertainty, vmax), vmax))
    assert f"sigma 0 (dark) to {vmax:g} grey levels" in v.gui["status"].content
    assert np.array_equal(r.render(cam, settings).image, r.render(cam, settings.replace(show="image")).image)
    with pytest.raises(Exception, match="show must be one of image, sigma"):
        ViewSettings(show="depth")


@pytest.mark.slow
def test_a_click_on_a_rolled_photograph_moves_there_upright(data_dir):
    """templeSparseRing's photographs are rolled by ±90°: a click on one moves the browser's
    camera to its pose turned upright by quarter turns (as a path's keys), with the ring's
    normal as the orbit controls' up — before, the camera's own sideways up, so keyframes
    and exported paths came out sideways."""
    from types import SimpleNamespace

    from vibr.io import load_scene
    from vibr.paths.camera_path import scene_up
    from vibr.viewer.convert import camera_from_viser

    scene = load_scene(data_dir / "middlebury_templeSparseRing", views=[0, 3, 6, 9, 12, 14])
    scene = scene.replace(views=[v.replace(depth=np.full(v.shape, 0.6)) for v in scene.views])
    v = Viewer(scene, ViewerOptions(warm_up=False))
    up = scene_up([w.camera for w in scene.views])
    assert np.allclose(v.up, up)
    for w in scene.views:
        cam = SimpleNamespace()
        client = SimpleNamespace(camera=cam, atomic=lambda: __import__("contextlib").nullcontext(), flush=lambda: None)
        v.move_client(client, w.camera)
        assert np.allclose(cam.up_direction, up)
        got = camera_from_viser(cam.wxyz, np.add(cam.position, v.origin), cam.fov, 0.75, 640)
        assert np.allclose(got.centre, w.camera.centre, atol=1e-9)
        assert np.allclose(got.optical_axis, w.camera.optical_axis, atol=1e-9)
        assert -got.R[1] @ up > 0.98  # upright (the cameras look 8° down); the photograph's up is at 90°
        assert abs(w.camera.R[1] @ up) < 0.2


def test_a_preview_is_rendered_in_one_outer_pass(tiny_scene):
    """A preview of the methods that re-estimate their weights takes one outer pass (the
    image ``render(..., n_outer=1)`` gives, bit for bit); the full view keeps the method's
    passes; savsr and ulr make no more than one anyway."""
    import vibr.viewer.renderer as R
    from vibr.render import render

    r = R.ViewRenderer(tiny_scene)
    cam = tiny_scene.views[1].camera.scaled(0.5)
    src = r.scene_for(cam).subset(r.sources_for(cam, 3))
    for method in ("gradient", "bvs"):
        st = ViewSettings(method=method, n_views=3)
        preview, full = r.render(cam, st, preview=True), r.render(cam, st)
        kw = dict(gamma=st.gamma, lam=st.lam)  # the viewer's controls
        assert np.array_equal(preview.image, render(src, cam, method, n_outer=R.PREVIEW_OUTER, **kw).image)
        assert np.array_equal(full.image, render(src, cam, method, **kw).image)
        assert not np.array_equal(preview.image, full.image)
    for method in ("savsr", "ulr"):
        st = ViewSettings(method=method, n_views=3)
        assert np.array_equal(r.render(cam, st, preview=True).image, r.render(cam, st).image)


# ------------------------------------------------------------------ camera governor
def _orbit(P, L, axis, angle):
    """viser's orbit: the camera at ``P`` turned by ``angle`` about ``L`` (Rodrigues)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    v = P - L
    return L + v * np.cos(angle) + np.cross(a, v) * np.sin(angle) + a * (a @ v) * (1 - np.cos(angle))


def _bounds(spread, depth=1.0):
    from vibr.viewer.geometry import CameraBounds

    return CameraBounds(np.zeros(3), spread, depth, np.array([0.0, 0.0, depth]), 0.4)


@pytest.mark.parametrize("spread", [0.01, 0.05, 0.3])
def test_a_drag_moves_the_scene_as_far_as_the_cursor(spread):
    """A drag of 10 % of a 640 × 480 canvas (viser turns 2π per canvas height about its
    look-at point, kept at the scene's depth) moves the scene's centre by 10 % of the width
    whatever the baseline, and the camera by a fraction of the capture; a drag of the canvas
    height crosses the capture and stops at its edge (ROOM × spread)."""
    from vibr.viewer.geometry import ROOM, drag_gains, govern_move, look_at_wxyz

    b = _bounds(spread)
    fov, W, H = math.radians(50), 640, 480
    g = drag_gains(b, fov)
    assert 0 < g.orbit <= 1 and 0 < g.pan <= 1 and 0 < g.dolly <= 1
    up, P0, L0 = np.array([0.0, -1.0, 0.0]), np.zeros(3), np.array([0.0, 0.0, 1.0])

    def centre_x(P, f):
        cam = camera_from_viser(look_at_wxyz(P, P + f, up), P, fov, W / H, W)
        return cam.project(b.target[None])[0][0, 0]

    P1 = _orbit(P0, L0, up, 2 * np.pi * 0.1 * W / H)
    P, f, held = govern_move((P0, L0), (P1, L0), P0, L0, g, b)
    assert not held
    assert abs(abs(centre_x(P, f) - centre_x(P0, L0)) / W - 0.10) < 0.01
    assert 0.1 * spread < np.linalg.norm(P - P0) < 0.5 * spread
    # the canvas height in 100 reports: the camera goes across and stays at the edge
    raw, p, f = (P0, L0), P0, L0
    for _ in range(100):
        nxt = (_orbit(raw[0], raw[1], up, 2 * np.pi / 100), raw[1])
        p, f, held = govern_move(raw, nxt, p, f, g, b)
        raw = nxt
    assert held and np.linalg.norm(p) == pytest.approx(ROOM * spread)


def test_pan_and_dolly_move_at_the_capture_scale():
    """A pan of the canvas height (viser: 2 depth tan(fov/2) at its look-at point) moves
    the camera across the capture (2 × spread); a dolly all the way to the look-at point
    (depth) too; a wide capture keeps viser's own moves."""
    from vibr.viewer.geometry import drag_gains, govern_move

    b, fov = _bounds(0.02, depth=2.0), math.radians(40)
    g = drag_gains(b, fov)
    P0, L0, f0 = np.zeros(3), np.array([0.0, 0.0, 2.0]), np.array([0.0, 0.0, 1.0])
    shift = np.array([2 * 2.0 * math.tan(fov / 2) / 4, 0.0, 0.0])  # a quarter of the height
    P, f, held = govern_move((P0, L0), (P0 + shift, L0 + shift), P0, f0, g, b)
    assert np.allclose(P, [0.02 / 2, 0, 0]) and np.allclose(f, f0) and not held
    P, f, held = govern_move((P0, L0), (P0 + 0.25 * (L0 - P0), L0), P0, f0, g, b)
    assert np.allclose(P, [0, 0, 0.25 * 2 * 0.02]) and not held
    wide = drag_gains(_bounds(5.0), fov)
    assert (wide.orbit, wide.pan, wide.dolly) == (1.0, 1.0, 1.0)


def test_the_camera_is_kept_near_the_capture_and_facing_the_scene():
    """clamp_to_bounds puts a far position back on the ball of ROOM × spread and leaves one
    inside; clamp_turn turns a view that looks away back to max_turn from the scene's
    centre; look_at_wxyz poses a camera with no roll about up."""
    from vibr.viewer.convert import quat_to_matrix
    from vibr.viewer.geometry import ROOM, clamp_to_bounds, clamp_turn, look_at_wxyz

    b = _bounds(0.1)
    p, held = clamp_to_bounds([0.05, 0.0, 0.0], b)
    assert not held and np.allclose(p, [0.05, 0, 0])
    p, held = clamp_to_bounds([3.0, 4.0, 0.0], b)
    assert held and np.allclose(p, np.array([0.6, 0.8, 0.0]) * ROOM * 0.1)
    f, held = clamp_turn(np.zeros(3), np.array([0.0, 0.0, 1.0]), b)
    assert not held
    f, held = clamp_turn(np.zeros(3), np.array([1.0, 0.0, 0.0]), b)
    assert held and math.isclose(math.acos(f @ [0, 0, 1]), b.max_turn) and f[0] > 0
    up = np.array([0.0, -1.0, 0.0])
    R = quat_to_matrix(look_at_wxyz([0, 0, 0], [1.0, -0.5, 2.0], up))
    assert np.allclose(R[:, 2], np.array([1.0, -0.5, 2.0]) / np.linalg.norm([1.0, -0.5, 2.0]))
    assert abs(R[:, 0] @ up) < 1e-12 and R[:, 1] @ up < 0  # no roll, upright


def test_camera_bounds_of_a_scene(tiny_scene):
    """camera_bounds: the cameras' mean centre, their largest distance from it, the points'
    depth and median, and the input cameras' least half vertical field of view."""
    from vibr.viewer.geometry import camera_bounds, scene_scale

    P, _ = point_cloud(tiny_scene, 5000)
    b = camera_bounds(tiny_scene, P)
    C = np.array([v.camera.centre for v in tiny_scene.views])
    assert np.allclose(b.centre, C.mean(axis=0))
    assert b.spread == pytest.approx(np.max(np.linalg.norm(C - C.mean(axis=0), axis=1)))
    assert b.depth == scene_scale(tiny_scene, P)
    assert np.allclose(b.target, np.median(P.astype(np.float64), axis=0))
    cam = tiny_scene.views[0].camera
    assert b.max_turn == pytest.approx(math.atan2(cam.height / 2, cam.K[1, 1]))
    moved = camera_bounds(tiny_scene, P, origin=C.mean(axis=0))
    assert np.allclose(moved.centre, 0) and np.allclose(moved.target, b.target - C.mean(axis=0))


class _Handle:
    """viser's camera handle as the viewer meets it: ``_state`` is the newest report, replaced
    whole by the next one, and the server's camera writes change it in place."""

    def __init__(self, client, **state):
        self.client = client
        self._state = SimpleNamespace(**state)

    def __setattr__(self, name, value):
        if name in ("client", "_state"):
            object.__setattr__(self, name, value)
        else:  # a server write: viser's setters store it in the current report
            setattr(self._state, name, np.asarray(value, float) if name != "far" else float(value))


def _report_of(viewer, camera, far, width=640, height=480):
    from vibr.viewer import app

    (camera,), _ = app.orient_keys([camera], "snap", viewer.up)
    wxyz, pos, fov, _ = app.viser_pose_from_camera(camera)
    pos = pos - viewer.origin
    return dict(wxyz=np.asarray(wxyz), position=np.asarray(pos), fov=fov, image_width=width, image_height=height,
                look_at=pos + viewer._depth() * np.asarray(camera.optical_axis), up_direction=np.asarray(viewer.up),
                far=far)


def test_the_browser_reaches_the_first_view_however_late_it_applies_the_move(tiny_scene, monkeypatch):
    """On connection the viewer moves the browser to view 0. A browser still loading (no
    GPU, a busy machine) reports its own start camera for seconds before it applies the move;
    those reports are no drag: every render is of view 0, and once the browser reports the
    move's marker it is in step, with nothing more to correct (before: after 2 s the move
    was taken as lost and the browser's move to view 0 as a drag away from it). And a
    report is copied as it arrives: the server's write of a correction into viser's live
    camera state is not read as the browser's report of it."""
    import asyncio
    import contextlib

    from vibr.viewer import app
    from vibr.viewer.geometry import camera_bounds

    v = Viewer(tiny_scene, ViewerOptions(warm_up=False))
    P, _ = point_cloud(tiny_scene, 5000, origin=v.origin)
    v.bounds = camera_bounds(tiny_scene, P.astype(np.float64) + v.origin, v.origin)
    got = []
    v._workers[7] = SimpleNamespace(submit=lambda payload, t_update=None: got.append(payload[0]))
    v._hide_frustums_at = lambda pos: None
    v._set_visible = lambda what: None
    client = SimpleNamespace(client_id=7, atomic=contextlib.nullcontext, flush=lambda: None)
    start = tiny_scene.views[3].camera  # the browser's own start camera
    client.camera = _Handle(client, **_report_of(v, start, far=1000.0))
    clock = [100.0]
    monkeypatch.setattr(app.time, "perf_counter", lambda: clock[0])
    v.move_client(client, tiny_scene.views[0].camera)  # writes the marker into the live state
    marker = v._steers[7].pending
    assert client.camera._state.far == marker
    cam0 = v._states.get(7)
    for _ in range(3):  # the start camera, reported long after the move was sent
        clock[0] += 3.0
        client.camera._state = SimpleNamespace(**_report_of(v, start, far=1000.0))
        v._on_camera(app._Report.of(client.camera))
    view0 = app.CameraState.of(SimpleNamespace(**_report_of(v, tiny_scene.views[0].camera, far=marker)))
    assert cam0 is None and got and all(np.allclose(s.position, view0.position) for s in got)
    # the browser applied the move: in step at view 0, nothing to correct
    client.camera._state = SimpleNamespace(**_report_of(v, tiny_scene.views[0].camera, far=marker))
    sent = []
    v._send_pose = lambda c, correction: sent.append(correction)
    v._on_camera(app._Report.of(client.camera))
    assert not sent and np.allclose(v._states[7].position, view0.position, atol=1e-9)
    assert v._steers[7].pending is None

    # copied on arrival: the handle changed in place after the report is not what is handled
    v._report_threads[7] = app.ThreadPoolExecutor(max_workers=1)
    seen = []
    v._on_camera = lambda report, t=None: seen.append(report)
    moved = _report_of(v, tiny_scene.views[1].camera, far=marker)
    client.camera._state = SimpleNamespace(**moved)
    asyncio.run(v._on_report(client.camera))
    client.camera.far = marker * 2  # the server's next correction, written in place
    client.camera.position = (9.0, 9.0, 9.0)
    for i in range(2, 5):  # and reports are handled in the order they came
        client.camera._state = SimpleNamespace(**_report_of(v, tiny_scene.views[i].camera, far=marker))
        asyncio.run(v._on_report(client.camera))
    v._report_threads[7].shutdown(wait=True)
    assert seen[0].far == marker and np.allclose(seen[0].position, moved["position"])
    assert [r.position for r in seen[1:]] == [
        tuple(_report_of(v, tiny_scene.views[i].camera, far=marker)["position"]) for i in range(2, 5)]


@pytest.mark.slow
def test_a_preview_has_the_tone_of_the_full_view_on_a_real_scene(cotton_dir):
    """cotton at scale 0.25 (the full view 128², the preview 64²: sources resized by ½, one
    outer pass), at view 0 (where the viewer starts) and halfway to view 10 (no source
    there): the preview's mean and contrast are the full view's, resized to the preview's
    size (measured: means within 0.01 grey levels; standard deviation 27.87 against 27.76 at
    view 0, 29.81 against 27.83 halfway, where the preview keeps more of the ghosting)."""
    from skimage.transform import resize

    from vibr.io import load_scene
    from vibr.viewer import ViewRenderer, scene_with_depth
    from vibr.viewer.app import shown_image

    scene = scene_with_depth(load_scene(cotton_dir, scale=0.25), cache_dir=False)
    settings = ViewSettings(preview_long_side=64, full_long_side=128)
    r = ViewRenderer(scene)
    c0 = scene.views[0].camera
    half = Camera.from_centre(c0.K, c0.R, (c0.centre + scene.views[10].camera.centre) / 2, c0.width, c0.height)
    for cam in (c0, half):
        full = shown_image(r.render(cam, settings))[0] / 255.0
        preview = shown_image(r.render(cam.scaled(0.5), settings, preview=True))[0] / 255.0
        full = resize(full, preview.shape[:2], order=1, anti_aliasing=True)
        assert abs(preview.mean() - full.mean()) * 255 < 1.0, (preview.mean(), full.mean())
        assert abs(preview.std() / full.std() - 1) < 0.1, (preview.std(), full.std())
