"""Fly-throughs: camera paths (nerfstudio schema), path generators, depth cache,
``vibr path`` / ``vibr render --path``, MP4 output."""

import json
import math
import os

import numpy as np
import pytest

from vibr.camera import Camera
from vibr.errors import VibrInputError


@pytest.fixture(autouse=True)
def _cache_in_tmp(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("VIBR_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "vibr-cache"))


@pytest.fixture(scope="module")
def grid_dir(tmp_path_factory):
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    d = tmp_path_factory.mktemp("fly")
    save_scene(make_scene("grid", n_views=9, width=64, height=64, seed=1), d / "s")
    return d / "s"


@pytest.fixture(scope="module")
def arc_scene():
    from vibr.synthetic import make_scene

    return make_scene("arc", n_views=6, width=64, height=48, seed=0)


def _same_cameras(a, b, tol=1e-9):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert (x.width, x.height) == (y.width, y.height)
        for m, n in ((x.K, y.K), (x.R, y.R), (x.t, y.t)):
            assert np.abs(m - n).max() <= tol


# ----------------------------------------------------------------------------- schema
def test_opengl_camera_closed_form():
    """nerfstudio's camera at the origin with identity camera_to_world looks down -z with y
    up: a point 5 units in front projects to the centre, +x to the right, +y upwards."""
    from vibr.paths.camera_path import c2w_opengl_from_camera, camera_from_c2w_opengl

    W, H, fov = 80, 60, 50.0
    cam = camera_from_c2w_opengl(np.eye(4), fov, W, H)
    f = (H / 2) / math.tan(math.radians(fov) / 2)
    assert np.allclose(cam.K, [[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]], atol=1e-12)
    assert np.allclose(cam.R, np.diag([1, -1, -1])) and np.allclose(cam.centre, 0)
    xy, z = cam.project(np.array([[0, 0, -5.0], [1, 0, -5.0], [0, 1, -5.0]]))
    assert np.allclose(z, 5) and np.allclose(xy[0], [(W - 1) / 2, (H - 1) / 2])
    assert xy[1, 0] > xy[0, 0] and xy[2, 1] < xy[0, 1]
    assert np.allclose(c2w_opengl_from_camera(cam), np.eye(4), atol=1e-15)


@pytest.mark.parametrize("kind", ["interpolate", "orbit", "spiral"])
def test_round_trip_nerfstudio_schema(arc_scene, tmp_path, kind):
    from vibr.paths import camera_path as P

    p = getattr(P, kind)(arc_scene, n_frames=17)
    f = tmp_path / "p.json"
    P.write_camera_path(f, p)
    d = json.loads(f.read_text())
    assert d["camera_type"] == "perspective" and (d["render_width"], d["render_height"]) == (64, 48)
    assert len(d["camera_path"]) == 17 and d["fps"] == 24.0 and abs(d["seconds"] - 17 / 24) < 1e-12
    fr = d["camera_path"][0]
    assert len(fr["camera_to_world"]) == 16 and fr["aspect"] == 64 / 48 and 0 < fr["fov"] < 180
    q = P.read_camera_path(f)
    _same_cameras(p.cameras, q.cameras)
    assert q.fps == 24.0 and (q.width, q.height) == (64, 48)


def test_dataparser_transforms_map_back(arc_scene, tmp_path):
    """A path written in nerfstudio's normalised frame (x_n = s (T_R x + T_t)) reads back in
    the scene's frame with --dataparser-transforms."""
    from scipy.spatial.transform import Rotation

    from vibr.paths import camera_path as P

    p = P.orbit(arc_scene, n_frames=5)
    T = np.hstack([Rotation.from_rotvec([0.9, -0.4, 1.2]).as_matrix(), [[5.0], [-8.0], [3.0]]])
    s = 0.2
    frames = []
    for c in p.cameras:
        M = P.c2w_opengl_from_camera(c)
        M[:3, :3] = T[:, :3] @ M[:3, :3]
        M[:3, 3] = s * (T[:, :3] @ M[:3, 3] + T[:, 3])
        frames.append({"camera_to_world": M.ravel().tolist(), "fov": P.fov_from_focal(c.K[1, 1], c.height),
                       "aspect": c.width / c.height})
    f = tmp_path / "ns.json"
    f.write_text(json.dumps({"camera_type": "perspective", "render_width": 64, "render_height": 48,
                             "seconds": 1.0, "fps": 5, "camera_path": frames}))
    (tmp_path / "dp.json").write_text(json.dumps({"transform": T.tolist(), "scale": s}))
    _same_cameras(p.cameras, P.read_camera_path(f, dataparser_transforms=tmp_path / "dp.json").cameras)
    from vibr.paths.flythrough import check_path_sees_scene

    with pytest.raises(VibrInputError, match="nowhere near.*dataparser"):
        check_path_sees_scene(arc_scene, P.read_camera_path(f).cameras)


def _nerfstudio_normalised(cameras, T_saved, sf, A, applied_scale, tmp_path):
    """nerfstudio's data parser on poses saved in transforms.json: ``poses = T @ poses``,
    positions × sf; its dataparser_transforms.json holds ``T @ A`` and ``sf · applied_scale``
    (nerfstudio_dataparser.py). Returns the camera path file and that json."""
    from vibr.paths import camera_path as P

    frames = []
    for c in cameras:
        M = P.c2w_opengl_from_camera(c)
        M[:3, :3] = T_saved[:, :3] @ M[:3, :3]
        M[:3, 3] = sf * (T_saved[:, :3] @ M[:3, 3] + T_saved[:, 3])
        frames.append({"camera_to_world": M.ravel().tolist(), "fov": P.fov_from_focal(c.K[1, 1], c.height)})
    f = tmp_path / "ns_path.json"
    f.write_text(json.dumps({"camera_type": "perspective", "render_width": cameras[0].width,
                             "render_height": cameras[0].height, "fps": 5, "camera_path": frames}))
    A4 = np.vstack([A, [0, 0, 0, 1]])
    T4 = np.vstack([T_saved, [0, 0, 0, 1]])
    dp = tmp_path / "dataparser_transforms.json"
    dp.write_text(json.dumps({"transform": (T4 @ A4)[:3].tolist(), "scale": sf * applied_scale}))
    return f, dp


@pytest.mark.parametrize("legacy", [False, True])
def test_dataparser_transforms_with_applied_transform_and_scale(arc_scene, tmp_path, legacy):
    """A transforms.json scene processed with an ``applied_transform`` and an ``applied_scale``
    (or, legacy, with neither recorded but a colmap/sparse/0 folder beside it, for which
    nerfstudio assumes a fixed axis swap): the path maps back to the file's own frame."""
    from scipy.spatial.transform import Rotation

    from vibr.io.transforms import save_scene as save_scene_transforms
    from vibr.paths import camera_path as P

    scene_dir = tmp_path / "scene"
    save_scene_transforms(arc_scene, scene_dir)
    tj = scene_dir / "transforms.json"
    d = json.loads(tj.read_text())
    if legacy:
        (scene_dir / "colmap" / "sparse" / "0").mkdir(parents=True)
        A, a_s = np.array(P.LEGACY_COLMAP_APPLIED), 1.0
    else:
        A = np.hstack([Rotation.from_rotvec([0.3, 1.1, -0.2]).as_matrix(), [[0.5], [2.0], [-1.0]]])
        a_s = 2.5
        d.update(applied_transform=A.tolist(), applied_scale=a_s)
    tj.write_text(json.dumps(d))
    T = np.hstack([Rotation.from_rotvec([0.9, -0.4, 1.2]).as_matrix(), [[5.0], [-8.0], [3.0]]])
    p = P.orbit(arc_scene, n_frames=5)
    f, dp = _nerfstudio_normalised(p.cameras, T, 0.2, A, a_s, tmp_path)
    got_A, got_scale = P.scene_processing_transform(scene_dir)
    assert np.array_equal(got_A, A) and got_scale == a_s
    back = P.read_camera_path(f, dataparser_transforms=dp, applied_transform=got_A, applied_scale=got_scale)
    _same_cameras(p.cameras, back.cameras, tol=1e-8)
    if not legacy:  # without the scale the positions land elsewhere
        off = P.read_camera_path(f, dataparser_transforms=dp, applied_transform=got_A)
        assert max(np.linalg.norm(a.centre - b.centre) for a, b in zip(p.cameras, off.cameras)) > 0.1
        from vibr.cli import main

        frames = tmp_path / "frames"
        assert main(["render", str(scene_dir), "--path", str(f), "--dataparser-transforms", str(dp),
                     "-o", str(frames), "--method", "ulr", "--workers", "1", "-q"]) == 0
        assert len(list(frames.glob("*.png"))) == 5
    # the other way: a vibr path written in nerfstudio's frame (for ns-render) is the file
    # nerfstudio's forward map gives, and reads back
    out = tmp_path / "for_ns.json"
    P.write_camera_path(out, p, dataparser_transforms=dp, applied_transform=got_A, applied_scale=got_scale)
    want = json.loads(f.read_text())["camera_path"]
    for a, b in zip(json.loads(out.read_text())["camera_path"], want):
        np.testing.assert_allclose(a["camera_to_world"], b["camera_to_world"], atol=1e-9)
    back = P.read_camera_path(out, dataparser_transforms=dp, applied_transform=got_A, applied_scale=got_scale)
    _same_cameras(p.cameras, back.cameras, tol=1e-8)
    from vibr.cli import main

    cli_out = tmp_path / "cli_ns.json"
    assert main(["path", "orbit", str(scene_dir), "-o", str(cli_out), "--frames", "5",
                 "--dataparser-transforms", str(dp), "-q"]) == 0
    for a, b in zip(json.loads(cli_out.read_text())["camera_path"], want):
        np.testing.assert_allclose(a["camera_to_world"], b["camera_to_world"], atol=1e-9)


def test_scene_processing_transform_refuses_bad_values(tmp_path, arc_scene):
    from vibr.io.transforms import save_scene as save_scene_transforms
    from vibr.paths.camera_path import scene_processing_transform

    assert scene_processing_transform(tmp_path) == (None, 1.0)  # not a transforms.json scene
    save_scene_transforms(arc_scene, tmp_path / "s")
    tj = tmp_path / "s" / "transforms.json"
    assert scene_processing_transform(tmp_path / "s") == (None, 1.0)
    d = json.loads(tj.read_text())
    for bad in ({"applied_transform": [[1, 0, 0]]}, {"applied_scale": 0}, {"applied_scale": "x"}):
        tj.write_text(json.dumps(dict(d, **bad)))
        with pytest.raises(VibrInputError, match="applied_"):
            scene_processing_transform(tj)


# ----------------------------------------------------------------------------- generators
def _second_third_differences(P, n):
    d2 = np.diff(P, 2, axis=0)
    d3 = np.diff(P, 3, axis=0)
    return np.abs(d2).max(), np.abs(d3).max()


def test_interpolate_is_c2_and_passes_through_the_keys(arc_scene):
    """C²: third differences shrink like h³ (second derivative continuous across the key
    cameras; a C¹ spline's would jump and leave third differences ~h²). The keys are on the
    curve, the first and last frames are the end cameras and no frame repeats."""
    from vibr.paths.camera_path import interpolate

    ratios = []
    for n in (400, 800):
        p = interpolate(arc_scene, n_frames=n)
        C = np.array([c.centre for c in p.cameras])
        Z = np.array([c.optical_axis for c in p.cameras])
        d2, d3 = _second_third_differences(C, n)
        e2, e3 = _second_third_differences(Z, n)
        ratios.append((d3 / d2, e3 / e2))
        assert np.linalg.norm(np.diff(C, axis=0), axis=1).min() > 0
    # halving the step halves the ratio of third to second differences (O(h)); a jump of
    # the second derivative would keep it constant
    for k in range(2):
        assert ratios[1][k] < 0.6 * ratios[0][k]
    p = interpolate(arc_scene, n_frames=11)
    assert p.cameras[0].allclose(arc_scene.views[0].camera.with_size(64, 48), atol=1e-9)
    assert np.allclose(p.cameras[-1].centre, arc_scene.views[-1].camera.centre, atol=1e-9)
    knots = np.array(p.meta["knots"])
    from scipy.interpolate import CubicSpline

    spline = CubicSpline(knots, [v.camera.centre for v in arc_scene.views], bc_type="natural")
    assert np.allclose(spline(knots), [v.camera.centre for v in arc_scene.views])


def test_interpolate_order_and_views(arc_scene):
    from vibr.paths.camera_path import interpolate

    names = arc_scene.names
    p = interpolate(arc_scene, [names[3], names[0], names[5], names[1]], order="proximity", n_frames=4)
    assert p.meta["views"][0] in (names[0], names[5]) and set(p.meta["views"]) == {names[i] for i in (0, 1, 3, 5)}
    with pytest.raises(VibrInputError):
        interpolate(arc_scene, [names[0], names[0]], n_frames=4)


def _cameras_only(views):
    from vibr.scene import Scene, View

    return Scene([View(n, None, c) for n, c in views])


def _fountain_cameras(d):
    from vibr.io.strecha import read_strecha_camera

    files = sorted((d / "gt_dense_cameras").glob("*.camera"))
    return _cameras_only([(f.name.split(".")[0], read_strecha_camera(f).scaled(0.25)) for f in files])


def _temple_cameras(d):
    from vibr.io.middlebury import read_par

    return _cameras_only([(n, Camera(K, R, t, 640, 480)) for n, K, R, t in read_par(d / "templeSR_par.txt")])


@pytest.mark.slow
def test_interpolate_through_a_ring_goes_round_it(data_dir):
    """templeSparseRing's file order jumps across the ring: a path in that order crosses the
    ring's inside (where the temple stands). Through all the views the default order is by
    proximity, and the path stays near the ring; the view with the same pose as its
    neighbour by proximity (templeSR0011, templeSR0001's) is left out with a warning."""
    from _checks import messages_logged
    from vibr.paths.camera_path import interpolate, scene_centre

    scene = _temple_cameras(data_dir / "middlebury_templeSparseRing")
    X = scene_centre([v.camera for v in scene.views])
    ring = np.median([np.linalg.norm(v.camera.centre - X) for v in scene.views])

    def closest(p):
        return min(np.linalg.norm(c.centre - X) for c in p.cameras) / ring

    with messages_logged("vibr.paths.camera_path") as seen:
        p = interpolate(scene, n_frames=200)
    assert any("templeSR0011.png (after templeSR0001.png) left out" in m for m in seen)
    assert len(p.meta["views"]) == 15 and closest(p) > 0.8
    assert closest(interpolate(scene, order="given", n_frames=200)) < 0.5


def _up_angles(cameras, up):
    """Degrees between each camera's image up (−y axis) and ``up``."""
    return np.degrees(np.arccos(np.clip([-c.R[1] @ up for c in cameras], -1, 1)))


@pytest.mark.slow
def test_interpolate_through_rolled_photographs_does_not_spin(data_dir):
    """templeSparseRing's photographs are rolled by +90° or −90° (the temple lies on its
    side, upside down from one half of the ring to the other): a path keeping their
    orientations spins by up to 180° between neighbours. The default turns each key by
    quarter turns to the ring's up: every frame upright within the cameras' 8° look down,
    the frame portrait (the photographs turned); "level" makes every key's horizon level."""
    from vibr.paths.camera_path import interpolate, scene_up

    scene = _temple_cameras(data_dir / "middlebury_templeSparseRing")
    up = scene_up([v.camera for v in scene.views])
    kept = interpolate(scene, n_frames=120, roll="keep")
    assert _up_angles(kept.cameras, up).max() > 150 and (kept.width, kept.height) == (640, 480)
    snap = interpolate(scene, n_frames=120)
    assert snap.meta["roll"] == "snap" and (snap.width, snap.height) == (480, 640)
    assert _up_angles(snap.cameras, up).max() < 12
    # the step between frames: no spin left (the kept path turns 10 times faster somewhere)
    from scipy.spatial.transform import Rotation

    def steps(p):
        r = Rotation.from_matrix(np.array([c.R for c in p.cameras]))
        return np.degrees((r[:-1].inv() * r[1:]).magnitude())
    assert steps(snap).max() < 3.0 < steps(kept).max()
    level = interpolate(scene, n_frames=120, roll="level")
    keys = np.round(np.array(level.meta["knots"]) / level.meta["knots"][-1] * 119).astype(int)
    assert max(abs(level.cameras[k].R[0] @ up) for k in keys) < 0.02  # x axis level at the keys


def test_interpolate_snap_turns_a_rolled_key_back(arc_scene):
    """A view whose camera was turned by a quarter turn (a portrait photograph among
    landscape ones) makes, by default, the path of the scene without the turn; the
    cameras of an upright capture are not touched (the same path as roll="keep")."""
    from vibr.paths.camera_path import interpolate
    from vibr.scene import Scene, View

    plain = interpolate(arc_scene, n_frames=30)
    _same_cameras(plain.cameras, interpolate(arc_scene, n_frames=30, roll="keep").cameras, tol=0)
    views = [View(v.name, None, v.camera.turned(1) if i == 2 else v.camera) for i, v in enumerate(arc_scene.views)]
    rolled = Scene(views)
    _same_cameras(interpolate(rolled, n_frames=30).cameras, plain.cameras, tol=1e-9)
    spun = interpolate(rolled, n_frames=30, roll="keep").cameras
    assert max(np.abs(a.R - b.R).max() for a, b in zip(spun, plain.cameras)) > 0.5
    with pytest.raises(VibrInputError, match="roll must be one of"):
        interpolate(arc_scene, n_frames=3, roll="upright")


def test_interpolate_through_a_portrait_photograph_keeps_the_focal(arc_scene):
    """A portrait photograph among landscape ones, taken with the same lens (the same focal
    in pixels, the phone turned): the path keeps that focal; relative to each photograph's
    height it zoomed out by 4:3 at that key and back in (fy / H: 0.75 f there)."""
    from vibr.paths.camera_path import interpolate
    from vibr.scene import Scene, View

    def portrait(c):
        K = Camera.intrinsics(c.K[0, 0], c.height, c.width)
        return Camera(K, c.R, c.t, c.height, c.width)

    views = [View(v.name, None, portrait(v.camera) if i == 2 else v.camera) for i, v in enumerate(arc_scene.views)]
    p = interpolate(Scene(views), n_frames=60)
    f = [c.K[1, 1] for c in p.cameras]
    assert (p.width, p.height) == (64, 48)
    assert np.allclose(f, arc_scene.views[0].camera.K[1, 1], rtol=1e-9)


@pytest.mark.parametrize("layout", ["arc", "handheld"])
def test_scene_up_with_portrait_photographs_stored_sideways(layout):
    """Half of the cameras rolled by a quarter turn (a phone's portrait photographs stored
    sideways, no EXIF turn applied): the scene's up is that of the upright capture — the
    plain mean of the −y axes leaned 27° with 2 of 6 rolled, 45° with 3 (where a quarter
    turn is a tie) — and a path through them is the upright capture's."""
    from vibr.paths.camera_path import interpolate, scene_up
    from vibr.scene import Scene, View
    from vibr.synthetic import make_scene

    s = make_scene(layout, n_views=6, width=64, height=48, seed=0)
    cams = [v.camera for v in s.views]
    u0 = scene_up(cams)
    for k in (1, 2, 3):
        rolled = [c.turned(1 if i % 2 else 3) if i < k else c for i, c in enumerate(cams)]
        assert np.degrees(np.arccos(min(1.0, scene_up(rolled) @ u0))) < 1e-6
    rolled = Scene([View(v.name, None, v.camera.turned(1) if i in (1, 4) else v.camera) for i, v in enumerate(s.views)])
    _same_cameras(interpolate(rolled, n_frames=20).cameras, interpolate(s, n_frames=20).cameras, tol=1e-9)


def _turns_and_speeds(p):
    C = np.array([c.centre for c in p.cameras])
    if p.meta.get("closed"):
        C = np.vstack([C, C[:1]])
    V = np.diff(C, axis=0)
    cos = np.sum(V[1:] * V[:-1], 1) / np.linalg.norm(V[1:], axis=1) / np.linalg.norm(V[:-1], axis=1)
    return np.degrees(np.arccos(np.clip(cos, -1, 1))).max(), np.linalg.norm(V, axis=1)


@pytest.mark.slow
def test_interpolate_round_a_light_field_grid(data_dir):
    """Through all of cotton's 81 views in proximity order the path scans the grid row by
    row, the camera turning back by up to 116° between frames; by default it loops round the
    grid through its corners and the middles of its sides, closed (the video loops: its last
    frame leads to its first at the pace of the others), turning by at most 19° a frame."""
    from vibr.io import load_scene
    from vibr.paths.camera_path import interpolate

    scene = load_scene(data_dir / "hci2016_cotton", scale=0.125)
    loop = interpolate(scene, n_frames=96)
    assert loop.meta["closed"] and loop.meta["views"] == [
        "input_Cam000", "input_Cam004", "input_Cam008", "input_Cam044", "input_Cam080", "input_Cam076",
        "input_Cam072", "input_Cam036", "input_Cam000"]
    turn, speed = _turns_and_speeds(loop)
    assert turn < 19 and speed.max() < 2.2 * speed.min()
    scan = interpolate(scene, n_frames=96, order="proximity")
    assert not scan.meta["closed"] and len(scan.meta["views"]) == 81 and _turns_and_speeds(scan)[0] > 100


def test_grid_loop_passes_over_missing_positions():
    """A light field with missing views: the loop takes the border views nearest to the
    corners and the middles of the sides; a grid of 2 rows has no loop (proximity order)."""
    from vibr.paths.camera_path import grid_loop, interpolate
    from vibr.synthetic import make_scene

    s = make_scene("grid", width=32, height=32, grid=(5, 5), seed=0)
    assert [s.names[i] for i in grid_loop(s)] == [s.names[i] for i in (0, 2, 4, 14, 24, 22, 20, 10)]
    gone = {0, 2, 14}  # a corner and two side middles
    sub = s.replace(views=[v for i, v in enumerate(s.views) if i not in gone],
                    meta=dict(s.meta, grid_pos={v.name: (i // 5, i % 5) for i, v in enumerate(s.views)
                                                if i not in gone}))
    got = [sub.names[i] for i in grid_loop(sub)]
    assert got[0] in (s.names[1], s.names[5]) and s.names[4] in got and s.names[0] not in got
    assert interpolate(sub, n_frames=10).meta["closed"]
    two = make_scene("grid", width=32, height=32, grid=(2, 5), seed=0)
    assert grid_loop(two) is None and not interpolate(two, n_frames=10).meta["closed"]


def test_interpolate_level_needs_an_up():
    """Cameras whose up directions cancel out (half of them upside down, side by side): the
    default keeps them; "level" says why it cannot."""
    from vibr.paths.camera_path import interpolate

    K = Camera.intrinsics(50.0, 64, 48)
    cams = [Camera.look_at([x, 0, 0], [x, 0, 5], [0, -1 if i % 2 else 1, 0], K, 64, 48) for i, x in enumerate(range(4))]
    scene = _cameras_only([(f"c{i}", c) for i, c in enumerate(cams)])
    assert interpolate(scene, n_frames=5).meta["roll"] == "snap"
    with pytest.raises(VibrInputError, match="roll 'level' needs the scene's up"):
        interpolate(scene, n_frames=5, roll="level")


@pytest.mark.slow
@pytest.mark.parametrize("which", ["fountain", "temple"])
@pytest.mark.parametrize("kind", ["orbit", "spiral"])
def test_orbit_and_spiral_look_at_the_object(data_dir, which, kind):
    """The scene's centre (where the cameras' axes meet) projects within the middle third
    of every frame, in front of the camera; an orbit stays at the cameras' mean distance.
    The frame is the photographs' turned upright: templeSparseRing's, rolled by 90°, portrait
    with the photographs' horizontal field of view as its vertical one."""
    from vibr.camera import axes_meeting_point
    from vibr.paths import camera_path as P

    scene = _fountain_cameras(data_dir / "strecha_fountain-P11") if which == "fountain" \
        else _temple_cameras(data_dir / "middlebury_templeSparseRing")
    cams = [v.camera for v in scene.views]
    X = axes_meeting_point(cams)
    assert X is not None
    p = getattr(P, kind)(scene, n_frames=60)
    c0 = cams[0]
    if which == "temple":
        assert (p.width, p.height) == (c0.height, c0.width)
        assert p.cameras[0].K[1, 1] / p.height == pytest.approx(c0.K[0, 0] / c0.width)
    else:
        assert (p.width, p.height) == (c0.width, c0.height)
    for c in p.cameras:
        xy, z = c.project(X)
        assert z > 0
        assert c.width / 3 <= xy[0] <= 2 * c.width / 3 and c.height / 3 <= xy[1] <= 2 * c.height / 3
    if kind == "orbit":
        up = P.scene_up(cams)
        hd = lambda C: np.linalg.norm((C - X) - ((C - X) @ up) * up)  # noqa: E731
        mean_h = np.mean([hd(c.centre) for c in cams])
        assert p.meta["full"] == (which == "temple")
        d = [hd(c.centre) for c in p.cameras]
        assert 0.7 * mean_h < np.min(d) and np.max(d) < 1.3 * mean_h


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("out,extra,msg", [
    ("v.mp4", ["--fps", "nan"], "fps must be in (0, 1000]"),  # checked only after the frames, before
    ("v.mp4", ["--fps", "0"], "fps must be in (0, 1000]"),  # fell back to the path's rate silently
    ("v.mp4", ["--fps", "24000"], "fps must be in (0, 1000]"),
    ("v.mp4", ["--crf", "99"], "crf must be in 0..51"),
    ("v.gif", ["--crf", "30"], "--crf does not apply to a GIF"),  # was ignored without a word
    ("v.avi", [], "-o is a video (.mp4, .mov, .mkv, .webm, .gif) or a folder"),
    ("frames", ["--uncertainty", "u.png"], "with --path, --uncertainty is a video (.mp4, .mov, .mkv, .webm, .gif)"),
    ("v.mp4", ["--uncertainty", "v.mp4"], "the σ video must not be the frames' video"),
    ("v.mp4", ["--uncertainty", "u.mp4", "--crf", "60"], "crf must be in 0..51"),
    ("frames", ["--bit-depth", "16"], "--bit-depth does not apply to --path"),
    ("v.mp4", ["--grad-consistency", "-1"], "grad_consistency must be >= 0"),  # every render parameter
])
def test_bad_render_path_options_are_refused_before_any_frame(grid_dir, tmp_path, capsys, out, extra, msg):
    from vibr.cli import main

    pj = tmp_path / "p.json"
    assert main(["path", "orbit", str(grid_dir), "-o", str(pj), "--frames", "2", "-q"]) == 0
    capsys.readouterr()
    extra = [str(tmp_path / a) if a.endswith((".mp4", ".png")) else a for a in extra]
    assert main(["render", str(grid_dir), "--path", str(pj), "-o", str(tmp_path / out), "-q", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err
    assert not (tmp_path / out).exists() and not (tmp_path / "v_frames").exists()


@pytest.mark.parametrize("extra,msg", [(["--fps", "nan"], "fps must be positive and finite"),
                                       (["--seconds", "-1"], "the duration must be positive"),
                                       (["--seconds", "inf"], "the duration must be positive"),
                                       (["--seconds", "1e9"], "is more than the 100000 frames"),
                                       (["--frames", "100000000"], "is more than the 100000 frames")])
def test_bad_path_timing_is_one_line(grid_dir, tmp_path, capsys, extra, msg):
    """(--fps nan was a traceback; --seconds -1 read 'at least one frame, got -24'; --seconds
    1e9 was a MemoryError traceback and --frames 100000000 ran until killed.)"""
    from vibr.cli import main

    pj = tmp_path / "p.json"
    capsys.readouterr()
    assert main(["path", "orbit", str(grid_dir), "-o", str(pj), "-q", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err and "Traceback" not in err
    assert not pj.exists()


@pytest.mark.parametrize("content,msg", [
    ("{not json", "malformed JSON"),
    ('{"render_width": 8, "render_height": 8, "fps": 24}', "camera_path"),
    ('{"render_width": 8, "render_height": 8, "fps": 24, "camera_path": []}', "no frames"),
    ('{"render_width": 8, "render_height": 8, "fps": 24, "camera_path": [{"camera_to_world": '
     '[2,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], "fov": 50}]}', "not a rotation matrix"),
    ('{"render_width": 8, "render_height": 8, "fps": 24, "camera_path": [{"camera_to_world": '
     '[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], "fov": 0}]}', "fov"),
    ('{"render_width": 8, "render_height": 8, "fps": 24, "camera_path": [{"camera_to_world": '
     '[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], "fov": -30}]}', "fov"),
    ('{"render_width": 8.5, "render_height": 8, "fps": 24, "camera_path": [{"camera_to_world": '
     '[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], "fov": 30}]}', "render_width must be an integer"),
])
def test_bad_path_files_exit_2_one_line_no_output(grid_dir, tmp_path, capsys, content, msg):
    from vibr.cli import main

    f = tmp_path / "bad.json"
    f.write_text(content)
    out = tmp_path / "out.mp4"
    assert main(["render", str(grid_dir), "--path", str(f), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err and str(f) in err
    assert not out.exists() and not (tmp_path / "out_frames").exists()


@pytest.mark.parametrize("extra,msg", [
    (["--crf", "30", "--workers", "2"], "--crf, --workers apply to --path only"),
    (["--exclude", "view_003"], "--exclude applies to --path only; with --target, choose the sources"),
    (["--dask", "local"], "--dask applies to --path only"),
])
def test_path_options_with_a_target_are_refused(grid_dir, tmp_path, capsys, extra, msg):
    """The fly-through's options are refused with --target, not silently ignored (an
    --exclude'd view would otherwise have been used as a source)."""
    from vibr.cli import main

    out = tmp_path / "v.png"
    capsys.readouterr()
    assert main(["render", str(grid_dir), "--target", "view_004", "-o", str(out), "-q", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err
    assert not out.exists()


@pytest.mark.parametrize("kind,extra,msg", [
    ("orbit", ["--through", "view_001,view_002"], "--through applies to 'vibr path interpolate' only"),
    ("spiral", ["--order", "given"], "--order applies to 'vibr path interpolate' only"),
    ("interpolate", ["--full"], "--full applies to 'vibr path orbit' only"),
    ("orbit", ["--roll", "level"], "--roll applies to 'vibr path interpolate' only"),
])
def test_path_options_of_another_kind_are_refused(grid_dir, tmp_path, capsys, kind, extra, msg):
    from vibr.cli import main

    pj = tmp_path / "p.json"
    capsys.readouterr()
    assert main(["path", kind, str(grid_dir), "-o", str(pj), "-q", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err
    assert not pj.exists()


@pytest.mark.slow
def test_path_cli_turns_rolled_photographs_and_says_so(data_dir, tmp_path, capsys):
    """``vibr path interpolate`` on templeSparseRing: the keys turned (a line says how many),
    a portrait frame; ``--roll keep`` the photographs' landscape orientation."""
    from vibr.cli import main

    ring = str(data_dir / "middlebury_templeSparseRing")
    capsys.readouterr()
    assert main(["path", "interpolate", ring, "-o", str(tmp_path / "a.json"), "--frames", "8"]) == 0
    err = capsys.readouterr().err
    assert "16 of 16 key cameras turned to the scene's up" in err
    a = json.loads((tmp_path / "a.json").read_text())
    assert (a["render_width"], a["render_height"]) == (480, 640) and a["vibr"]["roll"] == "snap"
    assert main(["path", "interpolate", ring, "-o", str(tmp_path / "b.json"), "--frames", "8", "--roll", "keep"]) == 0
    assert "turned" not in capsys.readouterr().err
    b = json.loads((tmp_path / "b.json").read_text())
    assert (b["render_width"], b["render_height"]) == (640, 480) and b["vibr"]["roll"] == "keep"


# ----------------------------------------------------------------------------- rendering
def _psnr_png(a, b):
    from vibr.metrics import psnr

    return psnr(a, b, border=2)


def test_frame_at_held_out_view_matches_render_target(grid_dir, tmp_path, capsys):
    """A path frame exactly at view_004 with view_004 excluded renders what
    `vibr render --target view_004` renders: same PSNR (within 0.05 dB)."""
    from vibr.cli import main
    from vibr.io import load_scene, read_image
    from vibr.paths.camera_path import write_camera_path

    scene = load_scene(grid_dir)
    write_camera_path(tmp_path / "p.json", [scene["view_004"].camera], fps=1.0)
    assert main(["render", str(grid_dir), "--target", "view_004", "-o", str(tmp_path / "t.png"), "-q"]) == 0
    assert main(["render", str(grid_dir), "--path", str(tmp_path / "p.json"), "-o", str(tmp_path / "fr"),
                 "--exclude", "view_004", "-q"]) == 0
    capsys.readouterr()
    truth = scene["view_004"].image
    # the single view is written at 16 bits when it needs them, video frames at 8
    t8 = np.rint(read_image(tmp_path / "t.png") * 255) / 255
    fr = read_image(tmp_path / "fr" / "frame_00000.png")
    a, b = _psnr_png(t8, truth), _psnr_png(fr, truth)
    assert a > 30 and abs(a - b) <= 0.05
    assert np.abs(t8 - fr).max() <= 1 / 255 + 1e-6


def test_a_frame_that_sees_nothing_stops_with_one_line(grid_dir, tmp_path, capsys):
    """A path whose third camera looks away from the scene: exit 2, one line naming the frame
    and what is wrong, the other frames kept; every such frame is named at once, after the
    others are rendered (it used to stop at the first)."""
    from vibr.camera import Camera
    from vibr.cli import main
    from vibr.io import load_scene
    from vibr.paths.camera_path import write_camera_path

    scene = load_scene(grid_dir)
    c = scene["view_004"].camera
    away = Camera.from_centre(c.K, np.diag([1.0, -1.0, -1.0]) @ c.R, c.centre, c.width, c.height)
    write_camera_path(tmp_path / "p.json", [scene["view_003"].camera, c, away], fps=1.0)
    capsys.readouterr()
    code = main(["render", str(grid_dir), "--path", str(tmp_path / "p.json"), "-o", str(tmp_path / "fr"),
                 "--workers", "1", "-q"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "Traceback" not in err
    assert "frame 2: " in err and "no photograph looked" in err
    assert sorted(p.name for p in (tmp_path / "fr").glob("frame_*.png")) == ["frame_00000.png", "frame_00001.png"]
    # two runs of such frames among seven: all named in one line, the others rendered, no video
    cams = [away, away, scene["view_003"].camera, away, c, scene["view_005"].camera, scene["view_001"].camera]
    write_camera_path(tmp_path / "q.json", cams, fps=1.0)
    code = main(["render", str(grid_dir), "--path", str(tmp_path / "q.json"), "-o", str(tmp_path / "q.mp4"),
                 "--workers", "2", "-q"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "3 of 7 frames saw nothing: frames 0-1, 3 (frame 0: " in err
    assert sorted(int(p.stem[6:]) for p in (tmp_path / "q_frames").glob("frame_*.png")) == [2, 4, 5, 6]
    assert not (tmp_path / "q.mp4").exists()


def test_hand_written_nerfstudio_camera_renders_like_camera_json(grid_dir, tmp_path, capsys):
    """A camera written by hand in nerfstudio's convention (OpenGL axes: the grid looks down
    world +z, so camera_to_world = diag(1, -1, -1) at the centre) renders the same image as
    the equivalent vibr camera JSON (R = I, t = -C)."""
    from vibr.cli import main
    from vibr.io import load_scene, read_image

    scene = load_scene(grid_dir)
    C = scene["view_004"].camera.centre + np.array([0.03, -0.02, 0.0])
    f = scene["view_004"].camera.K[1, 1]
    fov = math.degrees(2 * math.atan(32 / f))
    ns = {"camera_type": "perspective", "render_width": 64, "render_height": 64, "seconds": 1, "fps": 1,
          "camera_path": [{"camera_to_world": [1, 0, 0, C[0], 0, -1, 0, C[1], 0, 0, -1, C[2], 0, 0, 0, 1],
                           "fov": fov, "aspect": 1.0}]}
    (tmp_path / "ns.json").write_text(json.dumps(ns))
    cam = {"K": [[f, 0, 31.5], [0, f, 31.5], [0, 0, 1]], "R": np.eye(3).tolist(), "t": (-C).tolist(),
           "width": 64, "height": 64}
    (tmp_path / "cam.json").write_text(json.dumps(cam))
    assert main(["render", str(grid_dir), "--target", str(tmp_path / "cam.json"), "-o", str(tmp_path / "c.png"),
                 "-q"]) == 0
    assert main(["render", str(grid_dir), "--path", str(tmp_path / "ns.json"), "-o", str(tmp_path / "fr"),
                 "--views", "9", "-q"]) == 0
    capsys.readouterr()
    a = read_image(tmp_path / "c.png")
    b = read_image(tmp_path / "fr" / "frame_00000.png")
    assert np.abs(a - b).max() <= 1 / 255 + 1e-6


def test_path_uncertainty_video_on_one_scale(grid_dir, tmp_path, capsys):
    """``--uncertainty fly_sigma.mp4`` with a path: a video of every frame's σ map, each
    frame colour-mapped on the one scale of the whole path (decoded back: the σ frame of
    a frame is its map through that scale, within H.264's rounding); the colour frames are
    the ones rendered without it (bit for bit); a rerun renders nothing, but frames written
    without σ are rendered again for it."""
    import imageio.v3 as iio

    from vibr.cli import main
    from vibr.eval.sigma_figures import sigma_figure
    from vibr.io.video import read_video_info
    from vibr.paths.flythrough import sigma_name

    pj = tmp_path / "o.json"
    assert main(["path", "orbit", str(grid_dir), "-o", str(pj), "--frames", "6", "--size", "48x32", "-q"]) == 0
    plain = tmp_path / "plain.mp4"
    assert main(["render", str(grid_dir), "--path", str(pj), "-o", str(plain), "--views", "4", "-q"]) == 0
    out, sig = tmp_path / "o.mp4", tmp_path / "o_sigma.mp4"
    args = ["render", str(grid_dir), "--path", str(pj), "-o", str(out), "--views", "4", "--uncertainty", str(sig)]
    capsys.readouterr()
    assert main(args) == 0
    txt = capsys.readouterr().out
    vmax = float(txt.split("(sigma of every frame, 0 to ")[1].split(" grey levels")[0])
    n, w, h = read_video_info(sig)[:3]
    assert (n, w) == (6, 48) and h > 32  # the map above its scale bar
    fdir = tmp_path / "o_frames"
    for i in range(6):
        a, b = iio.imread(fdir / f"frame_{i:05d}.png"), iio.imread(tmp_path / "plain_frames" / f"frame_{i:05d}.png")
        assert np.array_equal(a, b)
    decoded = iio.imread(sig, index=None)
    maps = [np.load(fdir / sigma_name(i))["sigma"].astype(np.float32) for i in range(6)]
    for i in (0, 3, 5):
        want = sigma_figure(maps[i], vmax)[:32].astype(float)
        assert np.abs(decoded[i][:32].astype(float) - want).mean() < 10.0  # 4:2:0 chroma on 48×32
    assert main(args) == 0
    assert "rendered 0 frames (6 already there)" in capsys.readouterr().out
    # the plain run's frames have no σ: asked for it, they are rendered again
    assert main(["render", str(grid_dir), "--path", str(pj), "-o", str(plain), "--views", "4", "-q",
                 "--uncertainty", str(tmp_path / "p_sigma.webm")]) == 0
    assert "rendered 6 frames (0 already there)" in capsys.readouterr().out


def test_sigma_video_has_one_scale_for_all_frames(tmp_path):
    """Three σ maps of different ranges: every frame of the video is drawn on the scale of
    all of them (0 to the 99th percentile of every frame's values, rounded up), not on its
    own, so that a colour means the same σ in every frame; NaN (no value) as the top."""
    import imageio.v3 as iio

    from vibr.eval.sigma_figures import sigma_figure
    from vibr.paths.flythrough import _write_sigma_frame, write_sigma_video

    ramp = np.linspace(0, 1, 64 * 48).reshape(48, 64)
    maps = [ramp * 1.0, ramp * 5.0, ramp * 20.0]
    maps[0][:4, :4] = np.nan
    paths = []
    for i, m in enumerate(maps):
        paths.append(tmp_path / f"s{i}.npz")
        _write_sigma_frame(paths[-1], m, "k")
    n, w, h, vmax = write_sigma_video(paths, tmp_path / "s.mp4", fps=24)
    assert (n, w) == (3, 64) and vmax == 20.0  # 99th percentile of all: 19.6 → 20
    decoded = iio.imread(tmp_path / "s.mp4", index=None)
    for i, m in enumerate(maps):
        want = sigma_figure(m.astype(np.float16).astype(np.float32), 20.0)[:48].astype(float)
        own = sigma_figure(m.astype(np.float16).astype(np.float32))[:48].astype(float)
        err = np.abs(decoded[i][:48].astype(float) - want).mean()
        assert err < 4.0, err
        if i < 2:  # its own scale would have drawn it otherwise
            assert np.abs(own - want).mean() > 4 * err


@pytest.mark.slow
def test_path_to_mp4_resume_and_decode(grid_dir, tmp_path, capsys):
    """vibr path -> vibr render --path -> MP4 with the right frame count and size (decoded
    back); a rerun skips the frames written, but not those of another path or other
    settings (each frame carries its key); an odd size is padded to even."""
    from vibr.cli import main
    from vibr.io.video import read_video_info

    # 3 frames (a first, a middle one deleted and resumed, a last) keep every check below at 3/5 of the renders
    pj = tmp_path / "o.json"
    assert main(["path", "orbit", str(grid_dir), "-o", str(pj), "--frames", "3", "--size", "47x33", "-q"]) == 0
    out = tmp_path / "o.mp4"
    assert main(["render", str(grid_dir), "--path", str(pj), "-o", str(out), "--views", "4", "-q"]) == 0
    txt = capsys.readouterr().out
    assert "rendered 3 frames (0 already there)" in txt
    assert "in this process" in txt  # executor auto: 3 small frames are not worth a process
    assert read_video_info(out)[:3] == (3, 48, 34)
    frames = sorted((tmp_path / "o_frames").glob("frame_*.png"))
    assert len(frames) == 3
    (frames[1]).unlink()
    mtime = frames[0].stat().st_mtime_ns
    assert main(["render", str(grid_dir), "--path", str(pj), "-o", str(out), "--views", "4"]) == 0
    cap = capsys.readouterr()
    assert "rendered 1 frame (2 already there)" in cap.out
    assert "frames: 1/1 in" in cap.err  # the progress counts only the frame still to render
    assert frames[0].stat().st_mtime_ns == mtime and frames[1].exists()
    assert read_video_info(out)[:3] == (3, 48, 34)
    # the video is the one the PNGs on disk give (the resumed run's included)
    import imageio_ffmpeg

    from vibr.io import read_image, write_image
    from vibr.io.video import read_video_info, write_video

    ref = tmp_path / "ref.mp4"
    write_video(ref, (read_image(f) for f in frames), fps=24)
    for a, b in zip(imageio_ffmpeg.read_frames(str(out)), imageio_ffmpeg.read_frames(str(ref))):
        assert a == b

    # frames of another path or other settings are rendered again, never reused; so is a
    # frame without its key (written by something else)
    pj2 = tmp_path / "s.json"
    assert main(["path", "spiral", str(grid_dir), "-o", str(pj2), "--frames", "3", "--size", "47x33", "-q"]) == 0
    assert main(["render", str(grid_dir), "--path", str(pj2), "-o", str(out), "--views", "4", "-q"]) == 0
    assert "rendered 3 frames (0 already there)" in capsys.readouterr().out
    fresh = tmp_path / "fresh"
    assert main(["render", str(grid_dir), "--path", str(pj2), "-o", str(fresh), "--views", "4", "-q"]) == 0
    for a, b in zip(frames, sorted(fresh.glob("frame_*.png"))):
        assert np.array_equal(read_image(a), read_image(b))
    assert main(["render", str(grid_dir), "--path", str(pj2), "-o", str(out), "--views", "3", "-q"]) == 0
    assert "rendered 3 frames (0 already there)" in capsys.readouterr().out
    assert main(["render", str(grid_dir), "--path", str(pj2), "-o", str(out), "--views", "3", "-q"]) == 0
    txt = capsys.readouterr().out
    assert "rendered 0 frames (3 already there)" in txt and "per frame" not in txt  # nothing to divide
    write_image(frames[1], read_image(frames[1]), bits=8)  # the same pixels, no key: not vibr's
    before = frames[1].read_bytes()
    assert main(["render", str(grid_dir), "--path", str(pj2), "-o", str(out), "--views", "3", "-q"]) == 2
    assert "which vibr did not write" in capsys.readouterr().err and frames[1].read_bytes() == before
    assert main(["render", str(grid_dir), "--path", str(pj2), "-o", str(out), "--views", "3", "-q",
                 "--overwrite"]) == 0  # asked for: every frame rendered again
    assert "rendered 3 frames (0 already there)" in capsys.readouterr().out


def test_view_weights_soft_and_continuous(arc_scene):
    """Far from a rank swap the K best have weight 1 and the others 0 (select_views' set);
    along a path the weights change continuously (no jump larger than the path's step
    warrants)."""
    from vibr.geometry.selection import select_views
    from vibr.paths.camera_path import interpolate
    from vibr.paths.flythrough import _source_points, view_weights

    pts = _source_points(arc_scene)
    p = interpolate(arc_scene, n_frames=200, width=32, height=24)
    W = np.array([view_weights(arc_scene, c, 3, view_points=pts) for c in p.cameras])
    assert np.abs(np.diff(W, axis=0)).max() < 0.35
    hard = [i for i in range(len(W)) if set(np.unique(W[i])) <= {0.0, 1.0}]
    assert len(hard) > len(W) / 3
    for i in hard[::10]:
        assert sorted(np.flatnonzero(W[i])) == select_views(arc_scene, p.cameras[i], 3)


def test_depth_cache_estimates_once(tmp_path, monkeypatch):
    """Without depth, the first call estimates and writes the cache; the second loads it
    (estimate_depth not called) and gives the same maps."""
    import vibr.stereo.cache as stereo  # where the cache calls the estimator
    from vibr.scene import Scene
    from vibr.stereo.cache import scene_with_depth
    from vibr.synthetic import make_scene

    s = make_scene("arc", n_views=4, width=48, height=40, seed=3)
    bare = Scene([v.replace(depth=None, sigma_z=None) for v in s.views], s.name, None, None, None, {})
    calls = []
    truth = {v.name: v.depth for v in s.views}

    def fake(scene, **kw):  # the cache is under test, not the estimator: the true depth, noised
        calls.append(kw)
        rng = np.random.default_rng(len(calls))
        return Scene([v.replace(depth=truth[v.name] * (1 + 0.01 * rng.random(v.shape)).astype(np.float32),
                                sigma_z=0.01) for v in scene.views], scene.name, scene.root, None, None, {})

    monkeypatch.setattr(stereo, "estimate_depth", fake)
    a = scene_with_depth(bare, cache_dir=tmp_path, exclude=[s.names[0]])
    assert a.meta["depth_source"] == "estimated" and len(calls) == 1 and a.names == s.names[1:]
    b = scene_with_depth(bare, cache_dir=tmp_path, exclude=[s.names[0]])
    assert b.meta["depth_source"] == "cache" and len(calls) == 1
    for u, v in zip(a.views, b.views):
        assert np.array_equal(u.depth, v.depth, equal_nan=True)
    scene_with_depth(bare, cache_dir=tmp_path)  # other views: another key
    assert len(calls) == 2
    # a newer estimator (its results changed) does not take an older one's maps
    monkeypatch.setattr(stereo, "ESTIMATOR_VERSION", stereo.ESTIMATOR_VERSION + 1)
    c = scene_with_depth(bare, cache_dir=tmp_path, exclude=[s.names[0]])
    assert c.meta["depth_source"] == "estimated" and len(calls) == 3
    assert scene_with_depth(s, cache_dir=tmp_path).meta["depth_source"] == "scene"


@pytest.mark.parametrize("ext", [".mp4", ".mov", ".mkv", ".webm"])
def test_video_colours_are_bt709_tagged(tmp_path, ext):
    """The video's colours as a player shows them: players read HD video as BT.709 (untagged
    or tagged), so the frames are converted and tagged BT.709. Decoding with the BT.709
    matrix forced (what an untagged file got in a browser: pure green came back as 215)
    gives the colours back; every YUV format (H.264 in MP4, QuickTime, Matroska; VP9 in
    WebM) alike."""
    import subprocess

    import imageio_ffmpeg

    from vibr.io.video import read_video_info, write_video

    cols = [(255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 255, 0), (200, 120, 60), (128, 128, 128)]
    img = np.zeros((96, 96 * len(cols), 3), np.uint8)
    for i, c in enumerate(cols):
        img[:, 96 * i:96 * (i + 1)] = c
    out = tmp_path / f"c{ext}"
    write_video(out, [img] * 3, fps=24)
    ff = imageio_ffmpeg.get_ffmpeg_exe()
    info = subprocess.run([ff, "-i", str(out)], capture_output=True, text=True).stderr
    assert "yuv420p(tv, bt709, progressive)" in info
    raw = subprocess.run([ff, "-i", str(out), "-vf", "scale=in_color_matrix=bt709", "-f", "rawvideo",
                          "-pix_fmt", "rgb24", "-v", "error", "-"], capture_output=True, check=True).stdout
    dec = np.frombuffer(raw, np.uint8)[:img.size].reshape(img.shape).astype(int)
    for i, c in enumerate(cols):
        assert np.abs(dec[48, 96 * i + 48] - np.array(c)).max() <= 4, (c, dec[48, 96 * i + 48])
    assert read_video_info(out) == (3, img.shape[1], img.shape[0], 24.0)


def test_gif_keeps_colours_and_odd_sizes(tmp_path):
    """A GIF (one 256-colour palette, no YUV: no even padding) decodes to the frames'
    colours; its frame duration is whole hundredths of a second (24 fps plays at 25)."""
    from vibr.io.video import read_video_info, write_video

    rng = np.random.default_rng(0)
    frames = [np.repeat(np.repeat(rng.integers(0, 256, (5, 7, 3), dtype=np.uint8), 9, 0), 9, 1)[:-1, :-2]
              for _ in range(4)]  # 44x61: odd sizes
    out = tmp_path / "a.gif"
    assert write_video(out, frames, fps=24) == (4, 61, 44)
    assert read_video_info(out) == (4, 61, 44, 25.0)
    import imageio.v3 as iio

    dec = iio.imread(out, index=None)[..., :3]
    assert np.abs(dec.astype(int) - np.array(frames, int)).max() <= 8


def test_video_extension_must_be_known(tmp_path):
    from vibr.errors import VibrInputError
    from vibr.io.video import write_video

    with pytest.raises(VibrInputError, match=r"not a video extension \(one of .mp4, .mov, .mkv, .webm, .gif\)"):
        write_video(tmp_path / "a.avi", [np.zeros((8, 8, 3), np.uint8)], fps=24)


@pytest.mark.slow
def test_depth_only_for_the_views_the_path_uses(tmp_path):
    """A scene of many views without depth: the fly-through estimates depth for the views
    its frames may use (each frame's 2·n_views best, ranked before depth), not for all."""
    from vibr.paths.camera_path import interpolate
    from vibr.paths.flythrough import render_path, views_for_path
    from vibr.synthetic import make_scene

    s = make_scene("handheld", n_views=16, width=64, height=48, seed=2)
    s = s.replace(views=[v.replace(depth=None, sigma_z=None) for v in s.views])
    p = interpolate(s, views=["view_003", "view_004"], n_frames=3)
    assert views_for_path(s, p.cameras, None) is None and views_for_path(s, p.cameras, 8) is None
    need = views_for_path(s, p.cameras, 2)
    assert need is not None and {"view_003", "view_004"} <= set(need) and len(need) < 16
    r = render_path(s, p, tmp_path / "f", n_views=2, cache_dir=tmp_path / "cache", executor=None, progress=False)
    assert r.rendered == 3
    from vibr.stereo.cache import scene_with_depth

    got = scene_with_depth(s, cache_dir=tmp_path / "cache", views=need)
    assert got.meta["depth_source"] == "cache" and got.names == need
    targets = [n for n, st in got.meta["depth_estimation"]["views"].items() if st["role"] == "target"]
    assert targets == need


def test_orient_keys_property():
    """For any camera and up (hypothesis): "snap" keeps the centre, the optical axis and the
    focal in pixels, and leaves the image up the nearest of the four quarter turns to ``up``
    (its cosine to up's projection on the image plane at least cos 45°); "level" puts it at
    0° (x axis perpendicular to up); a camera within 15° of ±up is kept."""
    from hypothesis import given, settings
    from hypothesis import strategies as st
    from scipy.spatial.transform import Rotation

    from vibr.paths.camera_path import orient_keys

    unit = st.lists(st.floats(-1, 1, allow_nan=False), min_size=3, max_size=3).filter(
        lambda v: np.linalg.norm(v) > 0.1)

    @settings(max_examples=150, deadline=None)
    @given(q=st.lists(st.floats(-1, 1, allow_nan=False), min_size=4, max_size=4).filter(
        lambda v: np.linalg.norm(v) > 0.1), up=unit, w=st.integers(8, 64), h=st.integers(8, 64))
    def check(q, up, w, h):
        up = np.asarray(up) / np.linalg.norm(up)
        R = Rotation.from_quat(q).as_matrix()
        cam = Camera.from_centre(Camera.intrinsics(40.0, w, h, fy=44.0), R, [1.0, 2.0, 3.0], w, h)
        (snap,), (k,) = orient_keys([cam], "snap", up)
        (lev,), _ = orient_keys([cam], "level", up)
        assert np.allclose(snap.centre, cam.centre) and np.allclose(snap.optical_axis, cam.optical_axis)
        assert np.allclose(lev.centre, cam.centre) and np.allclose(lev.optical_axis, cam.optical_axis)
        proj = up - (up @ cam.optical_axis) * cam.optical_axis
        if np.linalg.norm(proj) < np.sin(np.radians(15.0)) - 1e-9:
            assert k == 0 and snap is cam and lev is cam
            return
        c = -snap.R[1] @ proj / np.linalg.norm(proj)
        assert c >= np.cos(np.radians(45.0)) - 1e-9
        assert abs(lev.R[0] @ up) < 1e-9 and -lev.R[1] @ up > 0
        assert sorted([snap.K[0, 0], snap.K[1, 1]]) == [40.0, 44.0]
        assert (snap.width, snap.height) == ((w, h) if k % 2 == 0 else (h, w))

    check()


def _walk(n=40, jitter=0.02, deg=2.0, seed=0):
    """A steady walk and the same shaken by a hand (:func:`vibr.synthetic.walk_cameras`)."""
    from vibr.synthetic import walk_cameras

    return walk_cameras(n, seed), walk_cameras(n, seed, jitter=jitter, jitter_deg=deg)


def _rms_off(cams, ref):
    """RMS distance and angle (degrees) of ``cams`` from ``ref``, key by key."""
    d = [np.linalg.norm(a.centre - b.centre) for a, b in zip(cams, ref)]
    ang = [np.degrees(np.arccos(np.clip((np.trace(a.R @ b.R.T) - 1) / 2, -1, 1))) for a, b in zip(cams, ref)]
    return float(np.sqrt(np.mean(np.square(d)))), float(np.sqrt(np.mean(np.square(ang))))


def test_smooth_keys_keeps_a_steady_walk_and_calms_a_shaken_one():
    from vibr.paths.camera_path import smooth_keys

    steady, shaken = _walk()
    same = smooth_keys(steady, 2.0)
    d, a = _rms_off(same, steady)
    assert d < 1e-12 and a < 1e-4  # a steady motion (and its ends) is left as it is
    for sigma in (1.0, 2.0):
        calm = smooth_keys(shaken, sigma)
        d0, a0 = _rms_off(shaken, steady)
        d1, a1 = _rms_off(calm, steady)
        assert d1 < 0.7 * d0 and a1 < 0.7 * a0, (sigma, d0, d1, a0, a1)
        assert np.allclose(calm[0].centre, shaken[0].centre) and np.allclose(calm[-1].centre, shaken[-1].centre)
    # a loop wraps round: a ring of 12 keys smoothed stays a ring, every key shrunk alike
    K = Camera.intrinsics(100, 160, 120)
    ring = [Camera.look_at([3 * math.cos(a), 0, 3 * math.sin(a)], [0, 0, 0], [0, -1, 0], K, 160, 120)
            for a in np.linspace(0, 2 * math.pi, 12, endpoint=False)]
    r1 = [np.linalg.norm(c.centre) for c in smooth_keys(ring, 1.0, closed=True)]
    assert np.ptp(r1) < 1e-9 and abs(r1[0] / 3 - 0.872) < 0.001  # Σ g_j cos(30° j) / Σ g_j
    with pytest.raises(VibrInputError, match="smooth must be a positive number of keys"):
        smooth_keys(steady, -1)


def test_interpolate_smooth_through_a_shaken_walk():
    """``interpolate(smooth=...)``: the path of a shaken walk is nearer the steady one and
    turns less from frame to frame; 0 leaves the path through the cameras unchanged."""
    from vibr.paths.camera_path import interpolate
    from vibr.scene import Scene, View

    steady, shaken = _walk()
    scene = Scene([View(f"f{k:03d}", np.zeros((120, 160, 3), np.float32), c) for k, c in enumerate(shaken)])
    ref = Scene([View(f"f{k:03d}", np.zeros((120, 160, 3), np.float32), c) for k, c in enumerate(steady)])
    truth = interpolate(ref, order="given", n_frames=200).cameras
    raw = interpolate(scene, order="given", n_frames=200)
    calm = interpolate(scene, order="given", n_frames=200, smooth=2.0)
    assert calm.meta["smooth"] == 2.0 and raw.meta["smooth"] == 0.0

    def turn(cams):  # mean rotation between consecutive frames, degrees
        return np.mean([np.degrees(np.arccos(np.clip((np.trace(a.R @ b.R.T) - 1) / 2, -1, 1)))
                        for a, b in zip(cams, cams[1:])])

    assert turn(calm.cameras) < 0.6 * turn(raw.cameras)
    assert _rms_off(calm.cameras, truth)[1] < 0.7 * _rms_off(raw.cameras, truth)[1]
    assert all(a.allclose(b) for a, b in zip(interpolate(scene, order="given", n_frames=50, smooth=0).cameras,
                                              interpolate(scene, order="given", n_frames=50).cameras))


def test_cli_smooth(tmp_path, arc_scene, capsys):
    from vibr.cli import main
    from vibr.io.transforms import save_scene as save_scene_transforms

    save_scene_transforms(arc_scene, tmp_path / "s")
    out = tmp_path / "p.json"
    assert main(["path", "interpolate", str(tmp_path / "s"), "-o", str(out), "--frames", "8", "--smooth", "1",
                 "-q"]) == 0
    assert json.loads(out.read_text())["vibr"]["smooth"] == 1.0
    capsys.readouterr()
    for args, said in ((["orbit", "--smooth", "1"], "--smooth applies to 'vibr path interpolate' only"),
                       (["interpolate", "--smooth", "-1"], "--smooth must be a number of keys >= 0")):
        rc = main(["path", args[0], str(tmp_path / "s"), "-o", str(tmp_path / "q.json"), *args[1:]])
        err = capsys.readouterr().err.strip()
        assert rc == 2 and said in err and len(err.splitlines()) == 1
    assert not (tmp_path / "q.json").exists()


def test_smooth_keys_property():
    """For any steady motion (hypothesis: centres on a line at a constant speed, a constant
    turn per key about any axis, any σ and number of keys) ``smooth_keys`` leaves every key
    where it is; for any shaken sequence the end keys stay, and every smoothed centre lies
    within the hull of the window's keys and their reflections."""
    from hypothesis import given, settings
    from hypothesis import strategies as st
    from scipy.spatial.transform import Rotation

    from vibr.paths.camera_path import smooth_keys

    vec = st.lists(st.floats(-1, 1, allow_nan=False), min_size=3, max_size=3)
    K = Camera.intrinsics(100, 160, 120)

    @settings(max_examples=80, deadline=None)
    @given(n=st.integers(2, 25), sigma=st.floats(0.3, 4.0), start=vec, step=vec, axis=vec,
           turn=st.floats(-3.0, 3.0), seed=st.integers(0, 2**16))
    def check(n, sigma, start, step, axis, turn, seed):
        a = np.asarray(axis) / (np.linalg.norm(axis) or 1.0)
        R0 = Rotation.from_rotvec([0.1, -0.2, 0.3])
        cams = [Camera.from_centre(K, (Rotation.from_rotvec(a * np.radians(turn * i)) * R0).as_matrix().T,
                                   np.asarray(start) + i * np.asarray(step), 160, 120) for i in range(n)]
        for c, s in zip(cams, smooth_keys(cams, sigma)):
            assert np.allclose(s.centre, c.centre, atol=1e-9)
            assert np.allclose(s.R, c.R, atol=1e-6) and np.allclose(s.K, c.K)
        rng = np.random.default_rng(seed)
        shaken = [Camera.from_centre(K, c.R, c.centre + rng.normal(0, 0.1, 3), 160, 120) for c in cams]
        sm = smooth_keys(shaken, sigma)
        assert np.allclose(sm[0].centre, shaken[0].centre) and np.allclose(sm[-1].centre, shaken[-1].centre)
        C = np.array([c.centre for c in shaken])
        lo, hi = (2 * C.min(0) - C.max(0)) - 1e-9, (2 * C.max(0) - C.min(0)) + 1e-9  # reflections included
        assert all(np.all((s.centre >= lo) & (s.centre <= hi)) for s in sm)

    check()


def test_render_path_options_and_keywords(tmp_path):
    """render_path's options as a FlyOptions or as keywords over it give the same frames; a
    misspelt option is a TypeError, not a default."""
    from vibr.io import read_image
    from vibr.paths.camera_path import interpolate
    from vibr.paths.flythrough import FlyOptions, render_path
    from vibr.synthetic import make_scene

    s = make_scene("grid", n_views=9, width=48, height=40, seed=0)
    p = interpolate(s, views=["view_003", "view_004"], n_frames=2)
    common = dict(cache_dir=False, executor=None, progress=False)
    a = render_path(s, p, tmp_path / "a", method="ulr", n_views=3, **common)
    b = render_path(s, p, tmp_path / "b", options=FlyOptions(method="ulr", n_views=3, **common))
    c = render_path(s, p, tmp_path / "c", options=FlyOptions(method="gradient", n_views=8), method="ulr", n_views=3,
                    **common)
    assert a.rendered == b.rendered == c.rendered == 2
    pngs = sorted(f for f in os.listdir(tmp_path / "a") if f.endswith(".png"))
    assert len(pngs) == 2
    for f in pngs:
        np.testing.assert_array_equal(read_image(tmp_path / "a" / f), read_image(tmp_path / "b" / f))
        np.testing.assert_array_equal(read_image(tmp_path / "a" / f), read_image(tmp_path / "c" / f))
    with pytest.raises(TypeError, match="n_veiws"):
        render_path(s, p, tmp_path / "d", n_veiws=3, **common)
