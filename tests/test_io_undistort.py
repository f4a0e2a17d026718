"""Distorted cameras undistorted at load (vibr.io.undistort): transforms.json from
ns-process-data (OPENCV k1 k2 p1 p2, OPENCV_FISHEYE) and COLMAP models from the mapper."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibr.errors import VibrInputError
from vibr.io import load_scene
from vibr.io.images import write_image

W, H = 160, 120
FX, FY, CX, CY = 150.0, 152.0, 81.3, 58.9  # nerfstudio's convention: pixel centres at +0.5


def _distort(x, y, model, k):
    """nerfstudio's distortion of normalised coordinates, written out (not pycolmap's):
    OPENCV ``x d + 2 p1 x y + p2 (r² + 2x²)``, ``d = 1 + k1 r² + k2 r⁴ + k3 r⁶``; the
    fisheye ``θ (1 + k1 θ² + … + k4 θ⁸) / r`` with ``θ = atan r``."""
    r2 = x * x + y * y
    if model == "OPENCV_FISHEYE":
        r = np.sqrt(r2)
        th = np.arctan(r)
        s = th * (1 + k["k1"] * th**2 + k["k2"] * th**4 + k["k3"] * th**6 + k["k4"] * th**8) / r
        return x * s, y * s
    d = 1 + r2 * (k["k1"] + r2 * (k["k2"] + r2 * k.get("k3", 0.0)))
    xd = x * d + 2 * k["p1"] * x * y + k["p2"] * (r2 + 2 * x * x)
    yd = y * d + 2 * k["p2"] * x * y + k["p1"] * (r2 + 2 * y * y)
    return xd, yd


def _blob_scene(root, model, k, points, depth_z=None):
    """A one-frame transforms.json scene whose photograph has a Gaussian blob (σ 1 px) at
    the distorted projection of each camera-frame point; camera at the origin looking
    down +z (OpenCV axes: transform_matrix diag(1, −1, −1) in nerfstudio's GL axes)."""
    xd, yd = _distort(points[:, 0] / points[:, 2], points[:, 1] / points[:, 2], model, k)
    u, v = FX * xd + CX - 0.5, FY * yd + CY - 0.5  # array coordinates
    yy, xx = np.mgrid[0:H, 0:W]
    img = np.zeros((H, W), np.float64)
    for a, b in zip(u, v):
        img += np.exp(-((xx - a) ** 2 + (yy - b) ** 2) / 2.0)
    root.mkdir()
    write_image(root / "a.png", np.repeat(np.clip(img, 0, 1)[..., None], 3, 2).astype(np.float32), bits=16)
    frame = {"file_path": "a.png", "transform_matrix": np.diag([1.0, -1.0, -1.0, 1.0]).tolist()}
    if depth_z is not None:
        np.save(root / "d.npy", np.full((H, W), depth_z, np.float32))
        frame["depth_file_path"] = "d.npy"
    doc = {"camera_model": model, "fl_x": FX, "fl_y": FY, "cx": CX, "cy": CY, "w": W, "h": H, **k,
           "frames": [frame]}
    (root / "transforms.json").write_text(json.dumps(doc))


def _centroid(img, x, y, r=3):
    x0, y0 = int(round(x)), int(round(y))
    win = img[y0 - r:y0 + r + 1, x0 - r:x0 + r + 1, 0].astype(np.float64)
    yy, xx = np.mgrid[y0 - r:y0 + r + 1, x0 - r:x0 + r + 1]
    return (win * xx).sum() / win.sum(), (win * yy).sum() / win.sum()


@pytest.mark.parametrize("model, k", [
    ("OPENCV", {"k1": -0.12, "k2": 0.02, "p1": 0.003, "p2": -0.002}),
    ("OPENCV", {"k1": 0.08, "k2": -0.01, "k3": 0.004, "p1": 0.0, "p2": 0.0}),
    ("OPENCV_FISHEYE", {"k1": 0.05, "k2": -0.01, "k3": 0.002, "k4": 0.0}),
])
def test_undistorted_view_projects_as_its_pinhole_camera(tmp_path, model, k):
    """Each blob lies, after undistortion, where the loaded pinhole camera projects its
    point (to 0.05 px): the distortion formulas, COLMAP's and nerfstudio's half-pixel
    conventions and the undistorted camera agree."""
    gx, gy = np.meshgrid(np.linspace(-0.4, 0.4, 5), np.linspace(-0.3, 0.3, 4))
    pts = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)], 1) * 2.0
    _blob_scene(tmp_path / "s", model, k, pts)
    sc = load_scene(tmp_path / "s")
    v = sc.views[0]
    cam = v.camera
    expect = "OPENCV_FISHEYE" if model == "OPENCV_FISHEYE" else ("FULL_OPENCV" if "k3" in k else "OPENCV")
    assert sc.meta["undistorted"] == (f"1 of 1 views undistorted at load ({expect} {W}x{H} -> pinhole "
                                      f"{cam.width}x{cam.height})")
    assert v.image.shape[:2] == cam.shape and cam.shape != (H, W)  # COLMAP's size, no blank border
    uv = cam.project(pts)[0]  # world = camera frame here
    inside = (uv[:, 0] > 4) & (uv[:, 0] < cam.width - 5) & (uv[:, 1] > 4) & (uv[:, 1] < cam.height - 5)
    assert inside.sum() >= 8
    for (x, y) in uv[inside]:
        cx, cy = _centroid(v.image, x, y)
        assert abs(cx - x) < 0.1 and abs(cy - y) < 0.1, (model, x, y, cx, cy)


@pytest.mark.parametrize("model, k", [
    ("OPENCV", {"k1": -0.12, "k2": 0.02, "p1": 0.003, "p2": -0.002}),
    ("OPENCV", {"k1": 0.08, "k2": -0.01, "k3": 0.004, "p1": 0.001, "p2": 0.0}),
    ("OPENCV_FISHEYE", {"k1": 0.05, "k2": -0.01, "k3": 0.002, "k4": -0.001}),
])
def test_undistortion_map_is_nerfstudios_distortion(model, k):
    """Closed form: the photograph position the map gives a pinhole pixel is nerfstudio's
    distortion formula (written out above) of that pixel's ray, to 10⁻⁶ px."""
    from vibr.io.undistort import from_nerfstudio, pinhole, source_coords

    dist = from_nerfstudio(model, FX, FY, CX, CY, k, W, H, "test")
    K, w, h = pinhole(dist)
    xy = np.random.default_rng(1).uniform([0, 0], [w - 1, h - 1], (200, 2))
    rays = (xy - K[:2, 2]) / np.diag(K)[:2]
    xd, yd = _distort(rays[:, 0], rays[:, 1], model, {"k3": 0.0, "k4": 0.0, **k})
    expect = np.stack([FX * xd + CX - 0.5, FY * yd + CY - 0.5], 1)
    np.testing.assert_allclose(source_coords(dist, xy), expect, atol=1e-6)
    assert np.all((expect > -0.5) & (expect < [W - 0.5, H - 0.5]))  # no blank border


def test_depth_map_of_a_distorted_frame_is_resampled(tmp_path):
    pts = np.array([[0.0, 0.0, 2.0]])
    _blob_scene(tmp_path / "s", "OPENCV", {"k1": -0.1, "k2": 0.0, "p1": 0.0, "p2": 0.0}, pts, depth_z=2.5)
    v = load_scene(tmp_path / "s").views[0]
    assert v.depth.shape == v.camera.shape and np.all(v.depth == np.float32(2.5))


@pytest.mark.parametrize("extra, match", [
    ({"camera_model": "OPENCV", "k1": 0.1, "k4": 0.01}, "k4"),
    ({"camera_model": "OPENCV_FISHEYE", "k1": 0.1, "p1": 0.01}, "tangential"),
    ({"camera_model": "FISHEYE624", "k1": 0.1}, "FISHEYE624 is not one vibr reads"),
    ({"camera_model": "EQUIRECTANGULAR"}, "EQUIRECTANGULAR"),
    ({"camera_model": "OPENCV", "k1": "0.1"}, "k1 must be a number"),
    ({"camera_model": "OPENCV", "k1": -3.0}, "folds the image over itself"),  # r (1 - 3 r²) turns at 0.33
    ({"camera_model": "OPENCV", "k1": 1e10}, "outside the photograph"),  # COLMAP's size clamped
])
def test_distortions_vibr_cannot_undistort_are_refused(tmp_path, extra, match):
    write_image(tmp_path / "a.png", np.zeros((20, 30, 3), np.float32))
    doc = {"fl_x": 40.0, **extra, "frames": [{"file_path": "a.png", "transform_matrix": np.eye(4).tolist()}]}
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    with pytest.raises(VibrInputError, match=match):
        load_scene(tmp_path)


def test_zero_distortion_loads_the_file_as_it_is(tmp_path):
    img = np.random.default_rng(0).random((20, 30, 3)).astype(np.float32)
    write_image(tmp_path / "a.png", img, bits=16)
    doc = {"camera_model": "OPENCV", "fl_x": 40.0, "k1": 0.0, "p2": 0,
           "frames": [{"file_path": "a.png", "transform_matrix": np.eye(4).tolist()}]}
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    v = load_scene(tmp_path).views[0]
    assert v.camera.shape == (20, 30)
    np.testing.assert_array_equal(v.image, np.round(img * 65535) / np.float32(65535))


def test_a_lens_that_keeps_little_of_the_photograph_is_warned_once(tmp_path):
    """k1 = 50 is a valid, monotone model whose pinhole keeps a tenth of the photograph's
    pixels: loaded, with one warning for the camera all frames share."""
    import io
    import logging

    from vibr.progress import configure_logging

    frames = []
    for i in range(3):
        write_image(tmp_path / f"{i}.png", np.zeros((72, 96, 3), np.float32))
        frames.append({"file_path": f"{i}.png", "transform_matrix": np.eye(4).tolist()})
    doc = {"camera_model": "OPENCV", "fl_x": 90.0, "k1": 50.0, "frames": frames}
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    lg = logging.getLogger("vibr")
    saved = (list(lg.handlers), lg.level, lg.propagate)
    buf = io.StringIO()
    configure_logging(0, stream=buf)
    try:
        sc = load_scene(tmp_path)
    finally:
        lg.handlers[:], lg.level, lg.propagate = saved
    w, h = sc.views[0].camera.width, sc.views[0].camera.height
    assert w * h < 0.25 * 96 * 72
    assert buf.getvalue().count(f"96x72 photograph becomes a {w}x{h} pinhole") == 1


def test_a_distorted_scene_saves_as_its_pinhole_views(tmp_path):
    """vibr convert of a distorted scene writes the undistorted photographs and their
    pinhole cameras (no distortion keys): loaded again, the same views."""
    from vibr.io import save_scene

    pts = np.array([[0.0, 0.0, 2.0]])
    _blob_scene(tmp_path / "s", "OPENCV", {"k1": -0.1, "k2": 0.01, "p1": 0.0, "p2": 0.0}, pts, depth_z=2.5)
    a = load_scene(tmp_path / "s")
    save_scene(a, tmp_path / "t")
    doc = json.loads((tmp_path / "t" / "transforms.json").read_text())
    assert not any(k in doc or k in doc["frames"][0] for k in ("k1", "k2", "p1", "p2"))
    b = load_scene(tmp_path / "t")
    assert "undistorted" not in b.meta
    va, vb = a.views[0], b.views[0]
    np.testing.assert_allclose(vb.camera.K, va.camera.K, atol=1e-9)
    np.testing.assert_allclose(vb.image, va.image, atol=1 / 65535)
    np.testing.assert_array_equal(vb.depth, va.depth)


def test_compiled_remap_is_scipys_map_coordinates():
    """The compiled resampling equals scipy.ndimage.map_coordinates (mode "nearest"):
    bilinear to float32 rounding, nearest exactly (NaN depth kept)."""
    from scipy.ndimage import map_coordinates

    from vibr.io.undistort import _lookup, from_nerfstudio, undistort_array

    d = from_nerfstudio("OPENCV", 70.0, 72.0, 40.3, 29.8, {"k1": 0.12, "k2": -0.03, "p1": 0.002}, 80, 60, "t")
    rng = np.random.default_rng(3)
    img = rng.random((60, 80, 3), dtype=np.float32)
    dep = rng.random((60, 80)).astype(np.float32)
    dep[10:20, 30:50] = np.nan
    c = _lookup(d)
    ref = np.stack([map_coordinates(img[..., k], c, order=1, mode="nearest") for k in range(3)], -1)
    np.testing.assert_allclose(undistort_array(img, d), ref, atol=1e-6)
    np.testing.assert_array_equal(undistort_array(dep, d, nearest=True), map_coordinates(dep, c, order=0, mode="nearest"))
