"""save_scene → load_scene round trips (synthetic and the three real scenes) and the
transforms.json reader's conventions."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibr.camera import Camera
from vibr.errors import VibrInputError
from vibr.geometry.resample import quantise16
from vibr.io import load_scene, save_scene
from vibr.scene import Scene, View


def synthetic_scene(seed=0) -> Scene:
    """Three free cameras (one with skew), 16-bit-grid images, depth with NaN holes,
    sigma_z as a map and as a scalar, sparse points, a grid."""
    rng = np.random.default_rng(seed)
    views = []
    for i in range(3):
        w, h = 40 + 4 * i, 30
        K = Camera.intrinsics(50.0 + i, w, h)
        K[0, 1] = 0.25 * (i == 1)
        cam = Camera.look_at(rng.normal(size=3) + [0, 0, -5], [0, 0, 0], [0, -1, 0], K, w, h)
        img = quantise16(rng.random((h, w, 3)).astype(np.float32)) if i else \
            (rng.integers(0, 256, (h, w, 3)) / 255).astype(np.float32)
        depth = rng.uniform(2, 8, (h, w)).astype(np.float32)
        depth[rng.random((h, w)) < 0.2] = np.nan
        sz = rng.uniform(0.01, 0.1, (h, w)).astype(np.float32) if i == 0 else (0.05 if i == 1 else None)
        views.append(View(f"v{i}", img, cam, depth=depth if i != 2 else None, sigma_z=sz))
    return Scene(views, name="synth", grid=(1, 3), points=rng.normal(size=(20, 3)),
                 meta={"grid_pos": {"v0": (0, 0), "v1": (0, 1), "v2": (0, 2)}})


def assert_same_scene(a: Scene, b: Scene):
    assert a.names == b.names
    for va, vb in zip(a.views, b.views):
        assert va.camera.allclose(vb.camera, atol=1e-9), va.name
        assert va.image.dtype == vb.image.dtype == np.float32
        np.testing.assert_array_equal(va.image, vb.image)  # bit for bit
        assert (va.depth is None) == (vb.depth is None)
        if va.depth is not None:
            np.testing.assert_array_equal(va.depth, vb.depth)  # NaN holes in the same places
        if va.sigma_z is None:
            assert vb.sigma_z is None
        else:
            np.testing.assert_array_equal(va.sigma_z, vb.sigma_z)
    assert a.grid == b.grid
    if a.meta.get("grid_pos"):
        assert {k: tuple(v) for k, v in a.meta["grid_pos"].items()} == b.meta["grid_pos"]
    if a.points is not None:
        np.testing.assert_array_equal(a.points, b.points)


def test_synthetic_round_trip(tmp_path):
    s = synthetic_scene()
    save_scene(s, tmp_path / "out")
    back = load_scene(tmp_path / "out")
    assert back.meta["format"] == "transforms.json"
    assert_same_scene(s, back)
    assert np.isnan(back["v0"].depth).any()


def test_save_refuses_existing_and_overwrites_atomically(tmp_path):
    s = synthetic_scene()
    out = tmp_path / "out"
    save_scene(s, out)
    with pytest.raises(VibrInputError, match="already exists"):
        save_scene(s, out)
    save_scene(s.subset(["v1"]), out, overwrite=True)
    assert load_scene(out).names == ["v1"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no temporary folders left


def test_save_failure_leaves_nothing(tmp_path, monkeypatch):
    import vibr.io.transforms as tr

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(tr, "write_depth", boom)
    with pytest.raises(OSError):
        save_scene(synthetic_scene(), tmp_path / "out")
    assert list(tmp_path.iterdir()) == []


def test_transforms_conventions(tmp_path):
    """A hand-written nerfstudio file: OpenGL c2w and the 0.5 px principal-point shift."""
    import imageio.v3 as iio

    iio.imwrite(tmp_path / "a.png", np.zeros((20, 30, 3), np.uint8))
    # Camera at (1, 2, 3) looking down world -z with y up (OpenGL identity rotation).
    M = [[1, 0, 0, 1], [0, 1, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]]
    doc = {"fl_x": 40.0, "fl_y": 41.0, "cx": 15.0, "cy": 10.0, "w": 30, "h": 20,
           "frames": [{"file_path": "a.png", "transform_matrix": M}]}
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    cam = load_scene(tmp_path).views[0].camera
    np.testing.assert_allclose(cam.K, [[40, 0, 14.5], [0, 41, 9.5], [0, 0, 1]])
    np.testing.assert_allclose(cam.centre, [1, 2, 3])
    np.testing.assert_allclose(cam.optical_axis, [0, 0, -1])  # looks along -z world
    xy, z = cam.project(np.array([1.0, 3.0, 0.0]))  # above the axis (world +y) → smaller row
    assert z == pytest.approx(3.0) and xy[1] < 9.5
    # camera_angle_x instead of fl_x, default centre.
    doc = {"camera_angle_x": 2 * np.arctan(15 / 40.0), "frames": [{"file_path": "a", "transform_matrix": M}]}
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    cam = load_scene(tmp_path / "transforms.json").views[0].camera
    np.testing.assert_allclose(cam.K, [[40, 0, 14.5], [0, 40, 9.5], [0, 0, 1]])


def test_transforms_windows_separators(tmp_path):
    """A transforms.json written on Windows names ``images\\a.png``: read on Linux as the
    file it means; a backslash path out of the folder is still refused."""
    import imageio.v3 as iio

    (tmp_path / "images").mkdir()
    iio.imwrite(tmp_path / "images" / "a.png", np.full((20, 30, 3), 200, np.uint8))
    M = np.eye(4).tolist()
    doc = {"fl_x": 40.0, "w": 30, "h": 20, "frames": [{"file_path": "images\\a.png", "transform_matrix": M}]}
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    sc = load_scene(tmp_path)
    assert sc.views[0].image.shape == (20, 30, 3) and sc.views[0].image.max() > 0.7
    doc["frames"][0]["file_path"] = "..\\outside\\a.png"
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    with pytest.raises(VibrInputError, match="outside"):
        load_scene(tmp_path)


def test_transforms_rotation_with_a_uniform_scale(tmp_path):
    """A camera object scaled in Blender writes s·R into transform_matrix: vibr refused it
    (not a rotation); the rays' lines do not depend on s, so the camera is R's. Shear is
    still refused."""
    save_scene(synthetic_scene(), tmp_path / "s")
    ref = load_scene(tmp_path / "s")
    doc = json.loads((tmp_path / "s" / "transforms.json").read_text())
    for f, s in zip(doc["frames"], (2.0, 0.01, 1.001)):
        M = np.array(f["transform_matrix"])
        M[:3, :3] *= s
        f["transform_matrix"] = M.tolist()
    (tmp_path / "s" / "transforms.json").write_text(json.dumps(doc))
    sc = load_scene(tmp_path / "s")
    for a, b in zip(sc.views, ref.views):
        np.testing.assert_allclose(a.camera.R, b.camera.R, atol=1e-12)
        np.testing.assert_allclose(a.camera.t, b.camera.t, atol=1e-12)
    M = np.array(doc["frames"][0]["transform_matrix"])
    M[:3, :3] = M[:3, :3] @ np.diag([1.0, 1.0, 1.5])
    doc["frames"][0]["transform_matrix"] = M.tolist()
    (tmp_path / "s" / "transforms.json").write_text(json.dumps(doc))
    with pytest.raises(VibrInputError, match="nor one with a uniform scale"):
        load_scene(tmp_path / "s")
    # a camera path's camera_to_world (vibr render --path) reads the same way
    from vibr.paths.camera_path import camera_from_c2w_opengl

    c2w = np.array(json.loads((tmp_path / "s" / "transforms.json").read_text())["frames"][1]["transform_matrix"])
    a = camera_from_c2w_opengl(c2w, 50.0, 32, 24)
    c2w[:3, :3] /= 0.01
    b = camera_from_c2w_opengl(c2w, 50.0, 32, 24)
    np.testing.assert_allclose(a.R, b.R, atol=1e-12)
    np.testing.assert_allclose(a.R, ref.views[1].camera.R, atol=1e-12)


def test_transforms_camera_rig_names(tmp_path):
    """A rig's frames share file stems (``images/cam0/0000.png``, ``images/cam1/0000.png``):
    the views are named by their paths below the shared folders (not refused as
    "duplicate view names"), and keep those names through a save."""
    import os

    from vibr.synthetic import make_scene

    save_scene(make_scene("arc", n_views=4, width=32, height=24), tmp_path / "s")
    d = json.loads((tmp_path / "s" / "transforms.json").read_text())
    for c in ("cam0", "cam1"):
        (tmp_path / "s" / "images" / c).mkdir()
    for i, f in enumerate(d["frames"]):
        new = f"images/cam{i % 2}/{i // 2:04d}.png"
        os.rename(tmp_path / "s" / f["file_path"], tmp_path / "s" / new)
        f["file_path"] = new
        del f["vibr_name"]
    (tmp_path / "s" / "transforms.json").write_text(json.dumps(d))
    sc = load_scene(tmp_path / "s")
    assert sc.names == ["cam0/0000", "cam1/0000", "cam0/0001", "cam1/0001"]
    save_scene(sc, tmp_path / "t")
    assert load_scene(tmp_path / "t").names == sc.names


# ----------------------------------------------------------------------------- real data
@pytest.mark.slow
def test_round_trip_cotton(cotton_dir, tmp_path):
    # Scaled (16-bit-grid images) subset with the depth-carrying centre view.
    s = load_scene(cotton_dir, scale=0.5, views=["input_Cam040", "input_Cam041", "input_Cam000"])
    save_scene(s, tmp_path / "c")
    back = load_scene(tmp_path / "c")
    assert_same_scene(s, back)
    assert back.grid == (9, 9) and back.meta["grid_pos"]["input_Cam041"] == (4, 5)


@pytest.mark.slow
def test_round_trip_temple(temple_dir, tmp_path):
    s = load_scene(temple_dir, views=[0, 5, 9])  # full resolution: 8-bit images
    save_scene(s, tmp_path / "t")
    import imageio.v3 as iio

    assert iio.imread(tmp_path / "t" / "images" / "templeSR0001.png").dtype == np.uint8
    assert_same_scene(s, load_scene(tmp_path / "t"))


@pytest.mark.slow
def test_round_trip_fountain(fountain_dir, tmp_path):
    s = load_scene(fountain_dir, scale=0.125, views=["0004", "0005"])
    assert s.views[0].camera.shape == (256, 384)
    save_scene(s, tmp_path / "f")
    assert_same_scene(s, load_scene(tmp_path / "f"))


def test_read_ply_points_formats_and_errors(tmp_path):
    """Binary (both byte orders, extra properties) and ascii PLY vertices read back exactly;
    a binary file cut short and ascii rows that are not numbers are one-line errors that say so."""
    from vibr.io.transforms import read_ply_points, write_ply_points

    pts = np.random.default_rng(3).normal(size=(50, 3))
    write_ply_points(tmp_path / "le.ply", pts)
    np.testing.assert_array_equal(read_ply_points(tmp_path / "le.ply"), pts)
    head = "ply\nformat {}\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n" \
           "property uchar red\nend_header\n"
    rec = np.zeros(2, dtype=[("x", ">f4"), ("y", ">f4"), ("z", ">f4"), ("red", "u1")])
    rec["x"], rec["y"], rec["z"], rec["red"] = [1, 4], [2, 5], [3, 6], [7, 8]
    (tmp_path / "be.ply").write_bytes(head.format("binary_big_endian 1.0", 2).encode() + rec.tobytes())
    np.testing.assert_array_equal(read_ply_points(tmp_path / "be.ply"), [[1, 2, 3], [4, 5, 6]])
    (tmp_path / "a.ply").write_text(head.format("ascii 1.0", 2) + "1 2 3 9\n4 5 6 9\n")
    np.testing.assert_array_equal(read_ply_points(tmp_path / "a.ply"), [[1, 2, 3], [4, 5, 6]])
    (tmp_path / "cut.ply").write_bytes(head.format("binary_little_endian 1.0", 3).encode() + bytes(20))
    with pytest.raises(VibrInputError, match="cut short: 3 vertices need 39 bytes, 20 follow"):
        read_ply_points(tmp_path / "cut.ply")
    (tmp_path / "bad.ply").write_text(head.format("ascii 1.0", 2) + "1 2 3 9\n4 x 6 9\n")
    with pytest.raises(VibrInputError, match="malformed PLY vertex data"):
        read_ply_points(tmp_path / "bad.ply")
