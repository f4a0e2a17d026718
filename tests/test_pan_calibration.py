"""Photographs turned on the spot (:mod:`vibr.calib.pan`): the rotation-only model's
Jacobian, its fit, the starting values it is fitted from, the tracks, the choice against
COLMAP's mapper, and ``vibr calibrate`` on a video panned from one place."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pycolmap
import pytest
from scipy.spatial.transform import Rotation

import vibr.calib.pan as pc

W, H, F = 320, 240, 300.0


def _camera(f=F, k=0.0):
    c = pycolmap.Camera.create_from_model_name(1, "SIMPLE_RADIAL", f, W, H)
    c.params = [f, W / 2, H / 2, k]
    return c


def _rotations(n, seed=0):
    """``n`` cameras turning 40° about the vertical, tilted and rolled by up to 2°."""
    rng = np.random.default_rng(seed)
    yaw = np.radians(np.linspace(-20, 20, n))
    rv = np.c_[rng.uniform(-0.035, 0.035, n), yaw, rng.uniform(-0.035, 0.035, n)]
    return Rotation.from_rotvec(rv).as_matrix()


def _matches(cam, n):
    return pc.Matches(image_ids=np.arange(1, n + 1), names=[f"im{i}.png" for i in range(n)],
                      camera_of_image=np.zeros(n, np.int64), cameras=[cam], keypoints=[np.zeros((0, 2))] * n,
                      pairs=np.zeros((0, 2), np.int64), inliers=[], H=np.zeros((0, 3, 3)),
                      homography=np.zeros(0, bool))


def _tracks(R, cam, n_dirs=300, noise=0.0, seed=1):
    """Directions seen by every camera that has them in its image, observed (± noise px)."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n_dirs, 3))
    d[:, 2] = np.abs(d[:, 2]) * 2.5
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    img, trk, xy = [], [], []
    for t in range(n_dirs):
        Xc = R @ d[t]
        ok = Xc[:, 2] > 0.3
        p = cam.img_from_cam(Xc[ok])
        inside = (p[:, 0] > 0) & (p[:, 0] < W) & (p[:, 1] > 0) & (p[:, 1] < H)
        ids = np.flatnonzero(ok)[inside]
        if len(ids) >= 2:
            img += list(ids)
            trk += [t] * len(ids)
            xy += list(p[inside] + rng.normal(0, noise, (inside.sum(), 2)))
    img, trk, xy = np.array(img), np.array(trk), np.array(xy)
    _, trk = np.unique(trk, return_inverse=True)
    return pc.Tracks(img, np.zeros_like(img), trk, xy)


def test_the_jacobian_equals_finite_differences():
    """Rotations (through the projection and through the tracks' directions) and the
    intrinsics, at a point away from the start (rotation vectors of 0.05 rad, k = 0.05)."""
    R = _rotations(5)
    cam = _camera()
    tracks = _tracks(R, cam, 60)
    model = pc._Model(tracks, np.zeros(5, np.int64), [cam], R, np.arange(5))
    x = model.x0()
    x[:-2] += np.random.default_rng(2).normal(0, 0.05, len(x) - 2)
    x[-1] = 0.05
    J = model.jacobian(x)
    for c in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[c]))
        xp, xm = x.copy(), x.copy()
        xp[c] += h
        xm[c] -= h
        num = (model.residuals(xp) - model.residuals(xm)) / (2 * h)
        assert np.abs(J[:, c] - num).max() <= 1e-5 * max(1.0, np.abs(num).max()), c


def test_exact_tracks_give_the_rotations_and_the_focal_length():
    """Noise-free tracks, a start 30 % long in focal length and 2° off in every rotation:
    the fit ends on the truth (the first camera's rotation is the gauge)."""
    R = _rotations(6)
    truth = _camera(F, 0.02)
    tracks = _tracks(R, truth)
    start = Rotation.from_rotvec(np.random.default_rng(3).normal(0, np.radians(2), (6, 3))).as_matrix() @ R
    start[0] = R[0]
    fit = pc.fit_rotation_only(tracks, _matches(_camera(1.3 * F, 0.0), 6), start, np.arange(6))
    assert fit.params[0][0] == pytest.approx(F, rel=1e-6)
    assert fit.params[0][3] == pytest.approx(0.02, abs=1e-7)
    angle = Rotation.from_matrix(fit.rotations @ R.transpose(0, 2, 1)).magnitude()
    assert angle.max() < 1e-7 and fit.median_px < 1e-5


def test_the_fit_never_raises_its_cost_and_shrugs_off_outliers():
    """0.3 px of noise and one observation in ten moved by 40 px: the Huber cost falls at
    every step, and the focal length comes within 0.5 % of the truth."""
    R = _rotations(6)
    tracks = _tracks(R, _camera(), noise=0.3)
    bad = np.random.default_rng(4).random(len(tracks.xy)) < 0.1
    tracks.xy[bad] += 40.0
    model = pc._Model(tracks, np.zeros(6, np.int64), [_camera(1.2 * F)], R, np.arange(6))
    x, history = pc.robust_lm(model.residuals, model.jacobian, model.x0())
    assert len(history) > 3 and np.all(np.diff(history) < 0)
    assert x[-2] == pytest.approx(F, rel=0.005)


def _exact_homographies(R, cam):
    K = pc._calibration(cam)
    pairs = [(i, j) for i in range(len(R)) for j in range(i + 1, min(i + 3, len(R)))]
    Hs = [K @ R[j] @ R[i].T @ np.linalg.inv(K) for i, j in pairs]
    return np.array(pairs), np.array(Hs)


def test_the_focal_length_and_rotations_to_start_from_come_from_the_homographies():
    """Exact homographies ``K R_j R_iᵀ K⁻¹`` of a turn: the focal length's search finds the
    grid value of the truth, and the rotations chained along the pairs are the truth's up to
    one common rotation."""
    R = _rotations(7)
    scales = np.geomspace(0.25, 4.0, 49)
    true = _camera(1.2 * W * scales[19])
    pairs, Hs = _exact_homographies(R, true)
    m = _matches(_camera(1.2 * W), 7)
    m = replace(m, pairs=pairs, H=Hs, homography=np.ones(len(pairs), bool),
                   inliers=[np.zeros((100 + k, 2), np.int64) for k in range(len(pairs))])
    assert pc.focal_from_homographies(m, scales) == scales[19]
    R0, part = pc.chain_rotations(pc.with_focal_scaled(m, scales[19]))
    assert list(part) == list(range(7))
    common = R.transpose(0, 2, 1) @ R0  # R0_i = R_i C for one change of world axes C
    assert np.abs(common - common[0]).max() < 1e-9


def test_tracks_are_the_matches_connected_and_wrong_joins_are_left_out():
    """Keypoint 0 of image 0 matches keypoint 0 of image 1, which matches keypoint 5 of
    image 2; a wrong match also joins it to keypoint 3 of image 2: that track holds two
    keypoints of one image and is left out. Keypoints 1 ↔ 1 of images 0 and 1 are a track."""
    kp = [np.arange(20, dtype=float).reshape(10, 2) + 100 * i for i in range(3)]
    m = replace(_matches(_camera(), 3), keypoints=kp, pairs=np.array([[0, 1], [1, 2], [0, 2]]),
                   inliers=[np.array([[0, 0], [1, 1]]), np.array([[0, 5]]), np.array([[0, 3]])],
                   H=np.zeros((3, 3, 3)), homography=np.ones(3, bool))
    t = pc.tracks_from_matches(m)
    assert t.n_tracks == 1
    assert list(t.image) == [0, 1] and list(t.keypoint) == [1, 1]
    assert np.array_equal(t.xy, [kp[0][1], kp[1][1]])


class _Rec:
    """What :func:`prefer_one_centre` reads of a reconstruction."""

    def __init__(self, n, error):
        self.n, self.points3D = n, {i: type("P", (), {"error": error})() for i in range(3)}

    def num_reg_images(self):
        return self.n


@pytest.mark.parametrize("one, mapper, fit_px, taken", [
    ((20, 0.15), (20, 0.14), 0.15, True),    # the mapper's centres do no better: one centre
    ((20, 0.21), (20, 0.14), 0.21, False),   # they explain the points 1.5x better: parallax
    ((20, 0.32), (17, 0.07), 0.33, True),    # the mapper lost photos; one centre within 2x the pairs'
    ((20, 0.60), (10, 0.00), 0.60, False),   # ... but not where one centre is 3x worse than the pairs'
    ((20, 0.15), None, 0.15, True),          # the mapper made no model at all
])
def test_the_choice_against_the_mapper(one, mapper, fit_px, taken):
    o = pc.OneCentre(None, 69, 69, 0.2, pc.RotationFit(None, [], np.arange(20), fit_px, 5), _Rec(*one))
    choice = pc.prefer_one_centre(o, _Rec(*mapper) if mapper else None)
    assert choice.one_centre is taken, choice.why
    assert choice.registered[0] == one[0]


def test_no_fit_where_few_pairs_are_homographies(tmp_path, monkeypatch):
    m = replace(_matches(_camera(), 3), pairs=np.array([[0, 1], [1, 2], [0, 2]]),
                   inliers=[np.zeros((5, 2), np.int64)] * 3, H=np.repeat(np.eye(3)[None], 3, 0),
                   homography=np.array([True, False, False]),
                   keypoints=[np.zeros((5, 2))] * 3)
    monkeypatch.setattr(pc, "read_matches", lambda db: m)
    one = pc.fit_one_centre(tmp_path / "database.db")
    assert one.fit is None and one.reconstruction is None and (one.homography_pairs, one.pairs) == (1, 3)
    assert not pc.prefer_one_centre(one, None).one_centre


@pytest.mark.slow
def test_calibrate_a_video_panned_on_the_spot(tmp_path, capsys):
    """36 frames of the synthetic world turning 40° about one point, H.264: ``vibr calibrate
    VIDEO --frames 12`` gives every camera one centre, the focal length within 1 % of the
    truth and the rotations within 0.2°, says so in calibration.json and ``vibr info``."""
    import vibr.synthetic as syn
    from vibr.camera import shared_centre
    from vibr.cli import main
    from vibr.cli.info import describe
    from vibr.io import load_scene
    from vibr.io.video import write_video

    cams = syn.pan_cameras(36, pan_deg=40, width=W, height=H)
    world = syn.default_world(0)
    video = tmp_path / "pan.mp4"
    write_video(video, [syn.render_view(world, c)[0] for c in cams], fps=12, crf=18)
    out = tmp_path / "scene"
    assert main(["calibrate", str(video), str(out), "--frames", "12", "-q"]) == 0
    said = capsys.readouterr().out
    assert "calibrate: turned on the spot: one centre for every photo" in said
    assert f"next: vibr path interpolate {out} -o pan.json --smooth 2 && vibr render {out} --path pan.json" in said
    info = json.loads((out / "calibration.json").read_text())
    assert info["turned_on_the_spot"] is True and info["one_centre"]["taken"] is True
    assert info["principal_point"] == "fixed at the image centre (turned on the spot)"
    scene = load_scene(out)
    assert len(scene) == 12 and shared_centre([v.camera for v in scene.views], scene.points) is not None
    f_true = cams[0].K[0, 0]
    assert info["one_centre"]["focal_px"][0] == pytest.approx(f_true, rel=0.01)
    truth = [cams[k] for k in info["video"]["frames_kept"]]
    M = sum(t.R.T @ v.camera.R for v, t in zip(scene.views, truth))
    U, _, Vt = np.linalg.svd(M)
    align = U @ Vt
    err = [Rotation.from_matrix(t.R @ align @ v.camera.R.T).magnitude() for v, t in zip(scene.views, truth)]
    assert np.degrees(max(err)) < 0.2
    assert "turned on the spot: one centre for every photo" in describe(scene)


@pytest.mark.slow
def test_pan_yes_and_no_are_obeyed(tmp_path):
    """``--pan yes`` gives one centre to a walk without the test (and without the mapper);
    ``--pan no`` keeps the mapper's model without fitting one centre at all."""
    import vibr.synthetic as syn
    from vibr.camera import shared_centre
    from vibr.cli import main
    from vibr.io import load_scene
    from vibr.io.video import write_video

    truth = syn.make_scene("arc", n_views=24, width=W, height=H, seed=0)
    video = tmp_path / "walk.mp4"
    write_video(video, [v.image for v in truth.views], fps=8, crf=12)
    for pan in ("yes", "no"):
        out = tmp_path / pan
        assert main(["calibrate", str(video), str(out), "--frames", "8", "--pan", pan, "-q"]) == 0
        info = json.loads((out / "calibration.json").read_text())
        scene = load_scene(out)
        one = shared_centre([v.camera for v in scene.views], scene.points) is not None
        assert info["turned_on_the_spot"] is one is (pan == "yes")
        assert ("one_centre" in info) is (pan == "yes")
        assert ("mapping" in info["times_s"]) is (pan == "no")
        assert ("one_centre" in info["times_s"]) is (pan == "yes")


@pytest.mark.slow
def test_a_failed_fit_leaves_the_mapper_to_it(tmp_path, monkeypatch):
    """A numerical failure of the one-centre fit is a warning, not the end of the
    calibration: COLMAP's mapper calibrates the walk as before."""
    import vibr.calib.colmap as cal
    import vibr.synthetic as syn
    from _checks import messages_logged
    from vibr.io.video import write_video

    def broken(*a, **k):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(cal, "fit_one_centre", broken)
    truth = syn.make_scene("arc", n_views=12, width=W, height=H, seed=0)
    video = tmp_path / "walk.mp4"
    write_video(video, [v.image for v in truth.views], fps=8, crf=12)
    with messages_logged("vibr.calib.colmap") as said:
        scene, _ = cal.calibrate_scene(video, frames=6)
    assert len(scene) == 6 and scene.meta["calibration"]["turned_on_the_spot"] is False
    assert any("fit of one centre for every photo failed (Singular matrix)" in m for m in said)


def test_no_model_from_tracks_no_rotation_explains(tmp_path, monkeypatch):
    """Homography pairs whose matches are noise (the tracks that survive, ~150 px off):
    fewer than MIN_TRACKS tracks survive, and there is no model of one centre."""
    rng = np.random.default_rng(5)
    kp = [rng.uniform(0, [W, H], (200, 2)) for _ in range(4)]
    pairs = np.array([[0, 1], [1, 2], [2, 3], [0, 2]])
    inl = [np.c_[np.arange(200), rng.permutation(200)] for _ in pairs]
    m = replace(_matches(_camera(), 4), keypoints=kp, pairs=pairs, inliers=inl,
                H=np.repeat(np.eye(3)[None], 4, 0), homography=np.ones(4, bool))
    monkeypatch.setattr(pc, "read_matches", lambda db: m)
    one = pc.fit_one_centre(tmp_path / "database.db")
    assert one.fit is None and one.reconstruction is None
    assert not pc.prefer_one_centre(one, None).one_centre
