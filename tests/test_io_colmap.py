"""COLMAP sparse models written with pycolmap's own API (there is no real COLMAP data here)."""

from __future__ import annotations

import numpy as np
import pycolmap
import pytest

from _helpers import rot_about
from vibr.errors import VibrInputError
from vibr.io import load_scene
from vibr.io.depthfiles import write_colmap_bin
from vibr.io.images import write_image


def write_model(root, *, model="PINHOLE", params=(100.0, 110.0, 32.0, 24.0), sparse="sparse/0", depth=True):
    """Two images (one camera of ``model``, one SIMPLE_PINHOLE), three points, a depth map."""
    rec = pycolmap.Reconstruction()
    cam1 = pycolmap.Camera.create_from_model_name(1, model, 100.0, 64, 48)
    cam1.params = list(params)
    cam2 = pycolmap.Camera.create_from_model_name(2, "SIMPLE_PINHOLE", 90.0, 64, 48)
    cam2.params = [90.0, 31.5, 23.0]
    poses = {}
    for cam in (cam1, cam2):
        rec.add_camera_with_trivial_rig(cam)
    poses_in = [(1, rot_about(1, 0.1), [0.1, -0.2, 2.0]), (2, rot_about(0, -0.05) @ rot_about(2, 0.2), [0.3, 0.0, 2.5])]
    for iid, (cid, R, t) in enumerate(poses_in, 1):
        name = f"img{iid}.png"
        im = pycolmap.Image(name=name, camera_id=cid, image_id=iid)
        rec.add_image_with_trivial_frame(im, pycolmap.Rigid3d(pycolmap.Rotation3d(np.asarray(R)), np.asarray(t, float)))
        poses[f"img{iid}"] = (np.asarray(R), np.asarray(t, float))
    pts = np.array([[0.0, 0.0, 1.0], [0.2, -0.1, 0.5], [-0.3, 0.2, 0.8]])
    for p in pts:
        rec.add_point3D(p, pycolmap.Track())
    (root / sparse).mkdir(parents=True)
    rec.write(str(root / sparse))
    (root / "images").mkdir()
    rng = np.random.default_rng(0)
    for n in ("img1", "img2"):
        write_image(root / "images" / f"{n}.png", (rng.integers(0, 256, (48, 64, 3)) / 255).astype(np.float32))
    d = np.full((48, 64), 2.0, np.float32)
    d[:5] = 0.0  # unknown
    if depth:
        (root / "stereo" / "depth_maps").mkdir(parents=True)
        write_colmap_bin(root / "stereo" / "depth_maps" / "img1.png.geometric.bin", d)
    return poses, pts


def test_colmap_model_loads(tmp_path):
    poses, pts = write_model(tmp_path)
    s = load_scene(tmp_path)
    assert s.meta["format"] == "COLMAP" and s.names == ["img1", "img2"]
    c1, c2 = s["img1"].camera, s["img2"].camera
    # COLMAP's pixel centres are at +0.5: vibr's principal point is shifted by -0.5.
    np.testing.assert_allclose(c1.K, [[100, 0, 31.5], [0, 110, 23.5], [0, 0, 1]])
    np.testing.assert_allclose(c2.K, [[90, 0, 31.0], [0, 90, 22.5], [0, 0, 1]])
    for v in s.views:
        R, t = poses[v.name]
        np.testing.assert_allclose(v.camera.R, R, atol=1e-12)
        np.testing.assert_allclose(v.camera.t, t, atol=1e-12)
    np.testing.assert_allclose(np.sort(s.points, axis=0), np.sort(pts, axis=0))
    d = s["img1"].depth
    assert np.isnan(d[:5]).all() and np.all(d[5:] == 2.0)
    assert s["img2"].depth is None
    # The model folder itself and the image_undistorter layout (root/sparse) load too.
    assert load_scene(tmp_path / "sparse" / "0").names == ["img1", "img2"]


def test_colmap_undistorter_layout_and_zero_distortion(tmp_path):
    write_model(tmp_path, model="OPENCV", params=(100.0, 110.0, 32.0, 24.0, 0, 0, 0, 0), sparse="sparse", depth=False)
    s = load_scene(tmp_path)
    np.testing.assert_allclose(s["img1"].camera.K[0], [100, 0, 31.5])


def test_colmap_distorted_camera_is_undistorted_at_load(tmp_path):
    """The mapper's models are distorted (SIMPLE_RADIAL by default): loaded as COLMAP's
    undistorted pinhole (image_undistorter's camera), where vibr refused them before."""
    params = (100.0, 110.0, 32.0, 24.0, 0.1, 0, 0, 0)
    write_model(tmp_path, model="OPENCV", params=params)
    s = load_scene(tmp_path)
    cam = pycolmap.Camera.create_from_model_name(1, "OPENCV", 1.0, 64, 48)
    cam.params = list(params)
    u = pycolmap.undistort_camera(pycolmap.UndistortCameraOptions(), cam)
    v = s["img1"]
    assert v.camera.shape == (u.height, u.width) != (48, 64) and v.image.shape[:2] == v.camera.shape
    np.testing.assert_allclose(v.camera.K, [[u.params[0], 0, u.params[2] - 0.5], [0, u.params[1], u.params[3] - 0.5],
                                            [0, 0, 1]])
    assert v.depth.shape == v.camera.shape and np.nanmax(v.depth) == 2.0 and np.isnan(v.depth[0]).all()
    assert s["img2"].camera.shape == (48, 64)  # its SIMPLE_PINHOLE as it is


def test_colmap_dense_depth_at_its_max_image_size_is_resized(tmp_path):
    """COLMAP's dense maps at a max_image_size below the images' (a common setting) made
    the whole scene fail to load: maps of the image's aspect are resized (nearest)."""
    write_model(tmp_path)
    d = np.full((24, 32), 2.0, np.float32)
    d[:3] = 0.0  # unknown: the top 6 rows at full size
    write_colmap_bin(tmp_path / "stereo" / "depth_maps" / "img1.png.geometric.bin", d)
    depth = load_scene(tmp_path)["img1"].depth
    assert depth.shape == (48, 64) and np.isnan(depth[:6]).all() and np.all(depth[6:] == 2.0)
    write_colmap_bin(tmp_path / "stereo" / "depth_maps" / "img1.png.geometric.bin", np.ones((24, 24), np.float32))
    with pytest.raises(VibrInputError, match="img1.png.geometric.bin: depth is 24x24, image img1 is 64x48"):
        load_scene(tmp_path)


def test_other_colmap_reconstructions_are_named(tmp_path):
    """The mapper writes sparse/0, sparse/1, ... for disconnected parts of a capture; vibr
    loaded sparse/0 without a word, though sparse/1 may hold most of the photographs."""
    import io
    import logging

    from vibr.progress import configure_logging

    write_model(tmp_path)
    rec = pycolmap.Reconstruction(str(tmp_path / "sparse" / "0"))
    im = pycolmap.Image(name="img3.png", camera_id=1, image_id=3)
    rec.add_image_with_trivial_frame(im, pycolmap.Rigid3d(pycolmap.Rotation3d(np.eye(3)), np.zeros(3)))
    (tmp_path / "sparse" / "1").mkdir()
    rec.write(str(tmp_path / "sparse" / "1"))
    write_image(tmp_path / "images" / "img3.png", np.zeros((48, 64, 3), np.float32))
    lg = logging.getLogger("vibr")
    saved = (list(lg.handlers), lg.level, lg.propagate)
    buf = io.StringIO()
    configure_logging(0, stream=buf)
    try:
        assert load_scene(tmp_path).names == ["img1", "img2"]
        said = buf.getvalue()
        buf.truncate(0)
        buf.seek(0)
        load_scene(tmp_path / "sparse" / "1")  # chosen by the user: nothing to say
    finally:
        lg.handlers[:], lg.level, lg.propagate = saved
    assert "2 reconstructions; loading 0 (2 images), not 1 (3 images)" in said
    assert "the largest is " + str(tmp_path / "sparse" / "1") in said
    assert "reconstructions" not in buf.getvalue()
