"""Calibration from raw photos: a synthetic scene whose cameras are known is
photographed, calibrated through ``vibr calibrate`` (pycolmap, CPU) and compared with the
truth after a similarity alignment; plus the COLMAP → vibr camera conversion, the alignment
helpers and the error paths."""

from __future__ import annotations

import json

import imageio.v3 as iio
import numpy as np
import pycolmap
import pytest

from _helpers import rodrigues
from vibr.calib.colmap import (
    align_cameras,
    calibrate,
    calibrate_scene,
    camera_from_colmap,
    list_photos,
    pose_errors,
    similarity_align,
)
from vibr.camera import Camera  # noqa: E402
from vibr.errors import VibrInputError  # noqa: E402

pytestmark = pytest.mark.slow


def _write_png(path, img):
    iio.imwrite(path, (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8))


@pytest.fixture(scope="module")
def synthetic_photos(tmp_path_factory):
    """8 textured 320×240 views on an arc of the default synthetic world, as PNG files, plus
    one noise image that cannot register."""
    import vibr.synthetic as synthetic
    scene = synthetic.make_scene("arc", n_views=8, width=320, height=240, seed=0)
    d = tmp_path_factory.mktemp("photos")
    for v in scene.views:
        _write_png(d / f"{v.name}.png", v.image)
    rng = np.random.default_rng(1)
    _write_png(d / "zz_noise.png", rng.random((240, 320, 3)))
    (d / "notes.txt").write_text("not a photo")
    return d, scene


@pytest.fixture(scope="module")
def calibrated(synthetic_photos, tmp_path_factory):
    """The synthetic photos run through the CLI: ``vibr calibrate PHOTOS OUT --work W``."""
    from vibr.cli import main

    photos, truth = synthetic_photos
    out = tmp_path_factory.mktemp("calib") / "scene"
    rc = main(["calibrate", str(photos), str(out), "--quiet", "--work", str(out.parent / "work")])
    assert rc == 0
    return out, truth


def test_raw_colmap_model_loads_as_colmaps_undistorter_writes_it(calibrated):
    """The mapper's model (SIMPLE_RADIAL, distorted) loaded as it is, undistorted by vibr at
    load, is the scene COLMAP's image_undistorter wrote: the same cameras, images within
    8-bit rounding (the check of docs/explanation/calibration.md)."""
    from vibr.io import load_scene
    from vibr.metrics import psnr

    work = calibrated[0].parent / "work"
    a, b = load_scene(work), load_scene(work / "undistorted")
    assert a.meta["undistorted"].startswith(f"{len(a)} of {len(a)} views undistorted at load (SIMPLE_RADIAL")
    assert a.names == b.names
    for va, vb in zip(a.views, b.views):
        assert va.camera.shape == vb.camera.shape
        np.testing.assert_allclose(va.camera.K, vb.camera.K, rtol=1e-12)
        np.testing.assert_allclose(va.camera.R, vb.camera.R, atol=1e-12)
        assert psnr(va.image, vb.image, border=2) > 50


def test_calibrate_recovers_synthetic_cameras(calibrated):
    from vibr.io import load_scene

    out, truth = calibrated
    scene = load_scene(out)
    # Every rendered view registers; the noise image does not and is left out.
    assert sorted(scene.names) == sorted(truth.names)
    info = json.loads((out / "calibration.json").read_text())
    assert info["unregistered"] == ["zz_noise.png"]
    assert len(info["registered"]) == 8
    # On a level arc the principal point is not determined by the data (it trades off
    # against a common pitch): the covariance test of the auto mode keeps it at the centre.
    assert info["principal_point"].startswith("kept at the image centre"), info["principal_point"]
    ref = {v.name: v.camera for v in truth.views}
    est = [v.camera for v in scene.views]
    e = pose_errors(est, [ref[n] for n in scene.names])
    assert e["rot_deg"].max() < 1.0, e["rot_deg"]
    assert e["centre_rel"].max() < 0.02, e["centre_rel"]
    # Intrinsics: focal within 2 % of the truth (sizes may differ by the undistortion crop).
    f_true = truth.views[0].camera.K[0, 0]
    for v in scene.views:
        assert abs(v.camera.K[0, 0] / f_true - 1) < 0.02
        assert v.image.shape[:2] == v.camera.shape


def test_sparse_points_lie_on_the_true_surfaces(calibrated):
    """Sparse points, mapped into the true frame by the pose similarity, project onto the
    true depth maps (checks the world frame, the points and the depth range they give)."""
    from vibr.io import load_scene

    out, truth = calibrated
    scene = load_scene(out)
    assert scene.points is not None and len(scene.points) > 100
    zmin, zmax = scene.depth_range()
    assert 0 < zmin < zmax
    ref = {v.name: v for v in truth.views}
    est = [v.camera for v in scene.views]
    e = pose_errors(est, [ref[n].camera for n in scene.names])
    # The pose similarity X_ref = s Rs X_est + t.
    s, Rs, t = align_cameras(est, [ref[n].camera for n in scene.names])
    assert np.isclose(s, e["scale"])
    X = s * scene.points @ Rs.T + t
    tv = ref[scene.names[0]]
    xy, z = tv.camera.project(X)
    ij = np.round(xy[:, ::-1]).astype(int)
    ok = (z > 0) & np.all(ij >= 0, axis=1) & (ij[:, 0] < tv.camera.height) & (ij[:, 1] < tv.camera.width)
    d_true = tv.depth[ij[ok, 0], ij[ok, 1]]
    rel = np.abs(z[ok] - d_true) / d_true
    good = np.isfinite(rel)
    assert good.sum() > 50
    # Most points sit on the surface (depth edges and the pixel rounding make outliers).
    info = json.loads((out / "calibration.json").read_text())
    assert np.median(rel[good]) < 0.01, (np.median(rel[good]), info["principal_point"], e["rot_deg"])


def test_camera_from_colmap_matches_colmap_projection():
    """vibr's K is COLMAP's with the principal point moved by −½ px; the pose is kept."""
    cam = pycolmap.Camera.create_from_model_name(1, "PINHOLE", 500.0, 640, 480)
    cam.params = [500.0, 510.0, 320.0, 240.0]
    R = rodrigues([0.3, 1.0, 0.2], 25.0)
    t = np.array([0.1, -0.2, 2.0])
    rig = pycolmap.Rigid3d(pycolmap.Rotation3d(R), t)
    X = np.array([[0.2, 0.1, 1.0], [-0.3, 0.4, 2.5], [0.0, 0.0, 0.5]])
    colmap_xy = np.array([cam.img_from_cam(rig * x) for x in X])

    class _Im:  # the two attributes camera_from_colmap reads
        cam_from_world = rig

    vc = camera_from_colmap(cam, _Im())
    xy, z = vc.project(X)
    np.testing.assert_allclose(xy + 0.5, colmap_xy, atol=1e-9)
    np.testing.assert_allclose(vc.K[:2, 2], [319.5, 239.5])
    np.testing.assert_allclose(vc.R, R, atol=1e-12)


@pytest.mark.parametrize("align", ["poses", "centres"])
def test_pose_errors_zero_for_a_similar_copy(align):
    rng = np.random.default_rng(0)
    K = Camera.intrinsics(300.0, 320, 240)
    ref = [Camera.from_centre(K, rodrigues(rng.normal(size=3), rng.uniform(5, 40)), rng.normal(size=3), 320, 240)
           for _ in range(6)]
    # est world = similarity⁻¹ of ref world: X_ref = s Rs X_est + t.
    s, Rs, t = 2.5, rodrigues([1, 2, 3], 70.0), np.array([1.0, -4.0, 0.5])
    est = [Camera.from_centre(K, c.R @ Rs, Rs.T @ (c.centre - t) / s, 320, 240) for c in ref]
    e = pose_errors(est, ref, align=align)
    assert e["rot_deg"].max() < 1e-6
    assert e["centre_rel"].max() < 1e-9
    assert np.isclose(e["scale"], s)
    # A perturbed rotation of one view shows up as that view's error.
    bad = list(est)
    bad[2] = Camera.from_centre(K, rodrigues([0, 0, 1], 2.0) @ est[2].R, est[2].centre, 320, 240)
    e = pose_errors(bad, ref, align="centres")
    assert abs(e["rot_deg"][2] - 2.0) < 1e-6


def test_similarity_align_closed_form():
    rng = np.random.default_rng(3)
    X = rng.normal(size=(10, 3))
    R = rodrigues([0.2, -1, 0.5], 33.0)
    Y = 0.7 * X @ R.T + np.array([3.0, 2.0, 1.0])
    s, Rf, t = similarity_align(X, Y)
    assert np.isclose(s, 0.7) and np.allclose(Rf, R) and np.allclose(t, [3, 2, 1])


def test_missing_or_empty_folder(tmp_path):
    with pytest.raises(VibrInputError, match="not found"):
        list_photos(tmp_path / "nope")
    (tmp_path / "a.txt").write_text("x")
    with pytest.raises(VibrInputError, match="no photos found") as exc:
        calibrate(tmp_path, tmp_path / "out")
    assert str(tmp_path) in str(exc.value) and "HEIC" not in str(exc.value)
    assert not (tmp_path / "out").exists()
    (tmp_path / "IMG_0001.HEIC").write_bytes(b"\0")  # a phone's default format, not readable here
    with pytest.raises(VibrInputError, match="HEIC photos .* need converting to JPEG"):
        list_photos(tmp_path)
    _write_png(tmp_path / "b.png", np.zeros((8, 8, 3)))
    iio.imwrite(tmp_path / "c.webp", np.zeros((8, 8, 3), np.uint8))
    assert [p.name for p in list_photos(tmp_path)] == ["b.png", "c.webp"]
    (tmp_path / "clip.mp4").write_bytes(b"\0")  # a phone's folder: photos and a video
    import logging

    from _checks import messages_logged

    with messages_logged("vibr.calib.colmap", logging.INFO) as seen:
        assert [p.name for p in list_photos(tmp_path)] == ["b.png", "c.webp"]
    assert any("clip.mp4 in the folder: not used" in m for m in seen), seen
    (tmp_path / "clip.mp4").unlink()
    only_video = tmp_path / "only_video"
    only_video.mkdir()
    (only_video / "walk.MOV").write_bytes(b"\0")
    with pytest.raises(VibrInputError, match=r"no photos found .*; for the video, 'vibr calibrate .*walk.MOV OUT'"):
        list_photos(only_video)
    (tmp_path / "notes.txt").write_text("x")  # neither a folder nor a video: the error says what is read
    with pytest.raises(VibrInputError, match=r"not a folder of photos nor a video .*\.mp4, \.mov"):
        list_photos(tmp_path / "notes.txt")
    with pytest.raises(VibrInputError, match="video not found"):
        calibrate(tmp_path / "walk.MOV", tmp_path / "out")


def test_duplicate_stems_refused(tmp_path):
    _write_png(tmp_path / "a.png", np.zeros((8, 8, 3)))
    (tmp_path / "a.jpg").write_bytes((tmp_path / "a.png").read_bytes())
    with pytest.raises(VibrInputError, match="share a name stem"):
        list_photos(tmp_path)


def test_too_few_registered_names_them_and_leaves_no_output(tmp_path):
    """Featureless photos cannot register: the error names each one; nothing is written."""
    photos = tmp_path / "photos"
    photos.mkdir()
    for k in range(3):
        _write_png(photos / f"flat{k}.png", np.full((120, 160, 3), 0.2 * (k + 1)))
    out = tmp_path / "scene"
    with pytest.raises(VibrInputError) as exc:
        calibrate(photos, out, num_threads=1)
    msg = str(exc.value)
    assert "registered" in msg and "\n" not in msg
    for k in range(3):
        assert f"flat{k}.png" in msg
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["photos"]


def test_cli_error_is_one_line(tmp_path, capsys):
    from vibr.cli import main

    rc = main(["calibrate", str(tmp_path / "missing"), str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and "missing" in err and "not found" in err


def test_existing_output_refused(synthetic_photos, tmp_path):
    photos, _ = synthetic_photos
    (tmp_path / "out").mkdir()
    with pytest.raises(VibrInputError, match="already exists"):
        calibrate(photos, tmp_path / "out")


def test_bad_options(synthetic_photos):
    photos, _ = synthetic_photos
    with pytest.raises(VibrInputError, match="matcher"):
        calibrate_scene(photos, matcher="vocab")
    with pytest.raises(VibrInputError, match="scale"):
        calibrate_scene(photos, scale=0)
    # COLMAP's own checks raised a ValueError with a traceback for these
    for kw, word in ((dict(max_features=0), "max_features"), (dict(num_threads=-5), "num_threads"),
                     (dict(num_threads=0), "num_threads"),
                     # raised to 2 without a word; photos of 1x0 pixels failed in COLMAP's mapper
                     (dict(min_registered=0), "min_registered must be an integer >= 2"),
                     (dict(scale=0.001), "would be 0x0 pixels: SIFT needs at least 32")):
        with pytest.raises(VibrInputError, match=word):
            calibrate_scene(photos, **kw)
    # a misspelt option is an error, not a silent default
    with pytest.raises(TypeError, match="matchr"):
        calibrate_scene(photos, matchr="sequential")
    with pytest.raises(TypeError, match="matchr"):
        calibrate(photos, photos.parent / "never_written", matchr="sequential")
    assert not (photos.parent / "never_written").exists()


def test_calibrated_scene_runs_through_depth_estimation(calibrated):
    """A calibrated scene goes through ``vibr.stereo.estimate_depth`` unchanged; its depth
    range comes from the sparse points and the depths match the truth up to the scale."""
    import vibr.stereo as stereo
    from vibr.io import load_scene

    out, truth = calibrated
    scene = load_scene(out, scale=0.5)
    ref = {v.name: v for v in truth.views}
    e = pose_errors([v.camera for v in scene.views], [ref[n].camera for n in scene.names])
    i = len(scene) // 2
    est = stereo.estimate_depth(scene, views=[i], consistency=False)
    d = est.views[i].depth
    assert d is not None and d.shape == scene.views[i].camera.shape
    # Compare with the true depth, downsampled by 2 (2×2 means), in the true units.
    dt = ref[scene.names[i]].depth
    h, w = d.shape
    dt = dt[: 2 * h, : 2 * w].reshape(h, 2, w, 2).mean(axis=(1, 3))
    ok = np.isfinite(d) & np.isfinite(dt)
    assert ok.mean() > 0.3
    rel = np.abs(d[ok] * e["scale"] - dt[ok]) / dt[ok]
    assert np.median(rel) < 0.02, np.median(rel)


def test_importing_pycolmap_keeps_the_sigterm_handler():
    """pycolmap's glog replaces SIGTERM's handler on import (a stack trace, no cleanup);
    vibr imports it through vibr._runtime.pycolmap, which gives the handler back: `vibr calibrate`
    stopped by SIGTERM then exits 130 with its work folder removed."""
    import subprocess
    import sys

    code = ("import os, signal, time\n"
            "signal.signal(signal.SIGTERM, lambda *a: print('handler', flush=True))\n"
            "from vibr._runtime.pycolmap import import_pycolmap\n"
            "import_pycolmap()\n"
            "os.kill(os.getpid(), signal.SIGTERM)\n"
            "time.sleep(0.5)\n"
            "print('alive', flush=True)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.split() == ["handler", "alive"], r.stderr[-800:]


def test_the_registered_count_is_the_kept_models(temple_dir, tmp_path):
    """templeSparseRing's photos make COLMAP start a second model: the progress line counts
    the largest model's photos (it had summed the models: 'registered: 17/16'), and the
    report's count is the kept model's."""
    import io
    import logging
    import shutil

    from vibr.progress import configure_logging

    photos = tmp_path / "photos"
    photos.mkdir()
    for f in sorted(temple_dir.glob("*.png")):
        shutil.copy(f, photos / f.name)
    lg = logging.getLogger("vibr")
    saved = (list(lg.handlers), lg.level, lg.propagate)
    buf = io.StringIO()
    configure_logging(0, stream=buf)  # the CLI's lines, whatever earlier tests left
    try:
        _scene, report = calibrate_scene(photos, min_registered=3)
    finally:
        lg.handlers[:], lg.level, lg.propagate = saved
    lines = [ln for ln in buf.getvalue().splitlines() if ln.startswith("calibrate: registered:")]
    assert lines, "no progress line for the registration"
    done, total = map(int, lines[-1].split(":")[2].split()[0].split("/"))
    assert total == 16 and done <= total
    assert done == len(report.registered)


def test_photos_are_turned_upright_by_their_exif_orientation(tmp_path):
    """A phone stores a portrait photo sideways with EXIF orientation 6 (turn 90° clockwise
    to display): calibrate's copies, which COLMAP and the scene use, stand upright."""
    from PIL import Image

    from vibr.calib.colmap import _downscale_photos

    a = np.zeros((40, 60, 3), np.uint8)
    a[:, :30] = 255  # stored landscape, its left half white
    im = Image.fromarray(a)
    exif = im.getexif()
    exif[0x0112] = 6
    im.save(tmp_path / "p.jpg", exif=exif.tobytes(), quality=95)
    assert _downscale_photos([tmp_path / "p.jpg"], tmp_path / "out", 1.0) == [(40, 60)]
    up = iio.imread(tmp_path / "out" / "p.png").astype(float).mean(axis=(1, 2))
    assert up.shape == (60,) and up[:25].min() > 200 and up[35:].max() < 50  # the white half on top


def test_a_work_folder_without_room_is_refused_before_colmap(synthetic_photos, tmp_path, monkeypatch):
    """COLMAP aborts the process when its disk fills up (a C++ stack dump, exit 134, seen
    with a 3 MiB --work folder): too little free space is refused first, naming the folder."""
    import collections
    import shutil

    real = shutil.disk_usage
    usage = collections.namedtuple("usage", "total used free")

    def small(path):
        return usage(10 * 2**20, 9 * 2**20, 2**20) if str(path).startswith(str(tmp_path)) else real(path)

    photos, _ = synthetic_photos
    monkeypatch.setattr(shutil, "disk_usage", small)
    with pytest.raises(VibrInputError, match=r"1 MiB free, calibrating \d+ photos needs about \d+ MiB"):
        calibrate_scene(photos, work_dir=tmp_path / "w")
    assert list((tmp_path / "w").iterdir()) == []


def test_a_zoom_gets_one_camera_per_photo(tmp_path):
    """Photos of one size whose EXIF gives two focal lengths (a zoom): one camera per photo,
    each focal length recovered. With one shared camera (the copies COLMAP
    reads are PNGs without EXIF) both zooms would get one focal length, 17 % and 22 % off. The
    photos are :func:`vibr.synthetic.zoom_photos` (benchmarks/quality/calibrate_zoom.py's)."""
    from vibr.calib.colmap import _lens_keys, calibrate_scene
    from vibr.synthetic import zoom_photos

    truth = zoom_photos(tmp_path)
    assert sorted(set(_lens_keys(sorted(tmp_path.glob("*.jpg"))))) == [("Acme", "Zoomer", 24.0), ("Acme", "Zoomer", 36.0)]
    scene, report = calibrate_scene(tmp_path)
    assert len(scene) == 10 and report.mean_reprojection_error_px < 0.35
    for v in scene.views:
        assert abs(v.camera.K[0, 0] / (truth[v.name] * v.camera.width / 480.0) - 1) < 0.05, v.name
