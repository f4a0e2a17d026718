"""Image, depth-file and camera-JSON readers/writers."""

from __future__ import annotations

import numpy as np
import pytest

from vibr.camera import Camera
from vibr.errors import VibrInputError
from vibr.geometry.resample import quantise16, resize_depth
from vibr.io import (
    read_camera_json,
    read_depth,
    read_image,
    read_pfm,
    write_camera_json,
    write_depth,
    write_image,
    write_pfm,
)
from vibr.io.depthfiles import read_colmap_bin, write_colmap_bin
from vibr.io.images import decode_png16, image_bits, png_bit_depth


def _depth(h=5, w=7, seed=0):
    rng = np.random.default_rng(seed)
    d = rng.uniform(1, 10, (h, w)).astype(np.float32)
    d[1, 2] = np.nan
    d[4, 0] = np.nan
    return d


def test_pfm_rows_bottom_up_and_both_endiannesses(tmp_path):
    a = np.arange(6, dtype=np.float32).reshape(2, 3)
    for order, sc in (("<f4", b"-1.0"), (">f4", b"1.0")):
        p = tmp_path / f"x{sc.decode()}.pfm"
        # File stores the bottom row first.
        p.write_bytes(b"Pf\n3 2\n" + sc + b"\n" + a[::-1].astype(order).tobytes())
        np.testing.assert_array_equal(read_pfm(p), a)
    for le in (True, False):
        write_pfm(tmp_path / "w.pfm", a, little_endian=le)
        np.testing.assert_array_equal(read_pfm(tmp_path / "w.pfm"), a)


def test_colmap_bin_is_column_major(tmp_path):
    p = tmp_path / "d.bin"
    # W=3, H=2, 1 channel; column-major W×H means x varies fastest.
    p.write_bytes(b"3&2&1&" + np.array([1, 2, 3, 4, 5, 6], "<f4").tobytes())
    np.testing.assert_array_equal(read_colmap_bin(p), [[1, 2, 3], [4, 5, 6]])
    a = np.random.default_rng(1).random((4, 5)).astype(np.float32)
    write_colmap_bin(tmp_path / "e.bin", a)
    np.testing.assert_array_equal(read_colmap_bin(tmp_path / "e.bin"), a)


@pytest.mark.parametrize("ext", [".npy", ".pfm", ".bin"])
def test_depth_round_trip_keeps_holes(tmp_path, ext):
    d = _depth()
    p = tmp_path / f"d{ext}"
    write_depth(p, d)
    back = read_depth(p)
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, d)  # NaN == NaN for assert_array_equal


def test_depth_png16_scale(tmp_path):
    d = np.array([[1.0, 2.5], [np.nan, 0.001]], np.float32)
    write_depth(tmp_path / "d.png", d, scale=1e-3)
    np.testing.assert_allclose(read_depth(tmp_path / "d.png", scale=1e-3), d, rtol=1e-6)
    np.testing.assert_allclose(read_depth(tmp_path / "d.png", scale=1.0), d * 1000, rtol=1e-6)


@pytest.mark.parametrize("bad,word", [(np.nan, "NaN"), (np.inf, "infinite"), (-1.0, "negative")])
def test_bad_depth_values_raise(tmp_path, bad, word):
    d = np.ones((3, 4), np.float32)
    d[1, 1] = bad
    p = tmp_path / "bad.npy"
    np.save(p, d)
    with pytest.raises(VibrInputError, match=word) as ei:
        read_depth(p)
    assert str(p) in str(ei.value)


def test_depth_shape_checked(tmp_path):
    np.save(tmp_path / "d.npy", np.ones((3, 4), np.float32))
    with pytest.raises(VibrInputError, match="shape"):
        read_depth(tmp_path / "d.npy", shape=(4, 3))


def test_image_round_trip_8_and_16_bit(tmp_path):
    rng = np.random.default_rng(2)
    img8 = (rng.integers(0, 256, (6, 5, 3)).astype(np.float32) / np.float32(255))
    img16 = quantise16(rng.random((6, 5, 3)).astype(np.float32))
    assert image_bits(img8) == 8 and image_bits(img16) == 16
    for img, bits in ((img8, 8), (img16, 16)):
        write_image(tmp_path / f"i{bits}.png", img)
        assert png_bit_depth(tmp_path / f"i{bits}.png") == bits
        np.testing.assert_array_equal(read_image(tmp_path / f"i{bits}.png"), img)


def test_png16_decoder_handles_filtered_files(tmp_path):
    import imageio.v3 as iio

    # Pillow writes 16-bit grey PNGs with adaptive row filters: our decoder must undo them.
    y, x = np.mgrid[0:40, 0:50]
    q = ((x * 1000 + y * 37 + (x * y) % 251) % 65536).astype(np.uint16)
    iio.imwrite(tmp_path / "g16.png", q)
    raw = decode_png16(tmp_path / "g16.png")
    np.testing.assert_array_equal(raw, q)


def test_read_image_grey_and_rgba(tmp_path):
    import imageio.v3 as iio

    g = np.arange(12, dtype=np.uint8).reshape(3, 4)
    iio.imwrite(tmp_path / "g.png", g)
    im = read_image(tmp_path / "g.png")
    assert im.shape == (3, 4, 3) and im.dtype == np.float32
    rgba = np.zeros((3, 4, 4), np.uint8)
    rgba[..., 3] = 255
    iio.imwrite(tmp_path / "a.png", rgba)
    assert read_image(tmp_path / "a.png").shape == (3, 4, 3)


def test_read_image_cmyk_grey_alpha_and_float_range(tmp_path):
    """A CMYK JPEG read as its C, M, Y planes (mean error 0.78), grey + alpha was refused, and
    a float TIFF of 0..255 was clipped to a white image without a word."""
    from PIL import Image

    rng = np.random.default_rng(0)
    rgb = (rng.random((32, 48, 3)) * 255).astype(np.uint8)
    rgb = np.repeat(np.repeat(rgb[::8, ::8], 8, 0), 8, 1)[:32, :48]  # flat blocks: JPEG keeps them
    Image.fromarray(rgb).convert("CMYK").save(tmp_path / "c.jpg", quality=100)
    assert np.abs(read_image(tmp_path / "c.jpg") - rgb / 255.0).mean() < 0.02
    Image.fromarray(rgb[..., 0]).convert("LA").save(tmp_path / "la.png")
    np.testing.assert_allclose(read_image(tmp_path / "la.png")[..., 1], rgb[..., 0] / 255.0, atol=1e-6)
    Image.fromarray(rgb[..., 0].astype(np.float32)).save(tmp_path / "f255.tif")
    with pytest.raises(VibrInputError, match=r"f255.tif: float image values must lie in \[0, 1\], found \d+ .. \d+ \(8-bit values as floats"):
        read_image(tmp_path / "f255.tif")
    Image.fromarray(rgb[..., 0].astype(np.float32) / 255).save(tmp_path / "f1.tif")
    np.testing.assert_allclose(read_image(tmp_path / "f1.tif")[..., 2], rgb[..., 0] / 255.0, atol=1e-6)


def test_garbage_image_raises_naming_file(tmp_path):
    p = tmp_path / "junk.png"
    p.write_bytes(b"\x00garbage" * 20)
    with pytest.raises(VibrInputError, match="cannot read image") as ei:
        read_image(p)
    assert str(p) in str(ei.value) and "\n" not in str(ei.value)


def test_resize_depth_is_nearest_no_mixing():
    d = np.full((8, 8), 2.0, np.float32)
    d[:, 4:] = 9.0
    d[1, 1] = np.nan  # the source pixel of new pixel (0, 0) at half size
    r = resize_depth(d, (4, 4))
    assert set(np.unique(r[np.isfinite(r)])) <= {2.0, 9.0}
    assert np.isnan(r[0, 0])
    np.testing.assert_array_equal(r[:, 2:], 9.0)


def test_camera_json_round_trip_and_errors(tmp_path):
    R = Camera.look_at([1, 2, 3], [0, 0, 0], [0, 1, 0], Camera.intrinsics(100, 64, 48), 64, 48).R
    cam = Camera(np.array([[100.0, 0.3, 31.2], [0, 101.0, 23.9], [0, 0, 1]]), R, [0.1, -0.2, 3.0], 64, 48)
    write_camera_json(tmp_path / "c.json", cam)
    back = read_camera_json(tmp_path / "c.json")
    assert back.allclose(cam, atol=1e-12)
    (tmp_path / "bad.json").write_text('{"K": [[1,0,0],[0,1,0],[0,0,1]], "R": ')
    with pytest.raises(VibrInputError, match="malformed JSON"):
        read_camera_json(tmp_path / "bad.json")
    d = cam.to_dict()
    d["R"] = (2 * np.asarray(d["R"])).tolist()
    import json

    (tmp_path / "nr.json").write_text(json.dumps(d))
    with pytest.raises(VibrInputError, match="not a rotation"):
        read_camera_json(tmp_path / "nr.json")


@pytest.mark.parametrize("s", [0.25, 0.3, 0.5])
def test_resize_image_maps_pixel_centres_like_camera_scaled(s):
    from vibr.geometry.resample import resize_image

    H, W = 64, 128
    y, x = np.mgrid[0:H, 0:W].astype(np.float32)
    img = np.stack([x / 200, y / 100, 0.5 + 0 * x], axis=-1).astype(np.float32)  # linear ramps
    cam = Camera(Camera.intrinsics(100, W, H), np.eye(3), np.zeros(3), W, H).scaled(s)
    out = resize_image(img, cam.shape)
    assert out.shape[:2] == cam.shape
    # Interior pixel x' comes from x = (x' + ½)/s' − ½, with s' = w/W as in Camera.scaled.
    sx, sy = cam.width / W, cam.height / H
    yy, xx = np.mgrid[0:cam.height, 0:cam.width]
    ex, ey = ((xx + 0.5) / sx - 0.5) / 200, ((yy + 0.5) / sy - 0.5) / 100
    inner = (slice(3, -3), slice(3, -3))
    np.testing.assert_allclose(out[..., 0][inner], ex[inner], atol=2e-4)
    np.testing.assert_allclose(out[..., 1][inner], ey[inner], atol=2e-4)


def test_atomic_output_has_the_usual_file_mode(tmp_path):
    import os

    from vibr._runtime.atomic import atomic_path

    umask = os.umask(0o022)
    try:
        with atomic_path(tmp_path / "out.txt") as tmp:
            with open(tmp, "w") as f:
                f.write("x")
    finally:
        os.umask(umask)
    assert (os.stat(tmp_path / "out.txt").st_mode & 0o777) == 0o644


def test_saved_scene_folder_has_the_usual_folder_mode(tmp_path):
    """save_scene's folder was tempfile.mkdtemp's 0700 after the rename: a scene written for
    a group (a shared project folder, a web server) was unreadable to it."""
    import os

    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    umask = os.umask(0o022)
    try:
        save_scene(make_scene("grid", n_views=4, width=32, height=24), tmp_path / "scene")
    finally:
        os.umask(umask)
    assert (os.stat(tmp_path / "scene").st_mode & 0o777) == 0o755
    assert (os.stat(tmp_path / "scene" / "images").st_mode & 0o777) == 0o755


def test_write_image_formats(tmp_path):
    """-o out.npy wrote a TIFF under that name; WebP and PPM of a 16-bit image failed in Pillow."""
    from vibr.io.images import WRITE_EXTS

    img = np.random.default_rng(0).random((12, 16, 3)).astype(np.float32)
    for ext in WRITE_EXTS:
        write_image(tmp_path / f"w{ext}", img)
        back = read_image(tmp_path / f"w{ext}")
        assert back.shape == img.shape
        if ext in (".png", ".tif", ".tiff"):
            assert np.abs(back - img).max() < 1e-4  # 16-bit
    for ext in (".npy", ".exr", ".pgm"):
        with pytest.raises(VibrInputError, match=f"{ext} is not an image format vibr writes"):
            write_image(tmp_path / f"w{ext}", img)
        assert not (tmp_path / f"w{ext}").exists()
    # 16 bits asked for in an 8-bit format: refused (it was written in 8 without a word)
    with pytest.raises(VibrInputError, match="holds 8 bits per channel: 16 need .png or .tif"):
        write_image(tmp_path / "b16.jpg", img, bits=16)
    assert not (tmp_path / "b16.jpg").exists()
    write_image(tmp_path / "b16.tif", img, bits=16)


def test_lossy_outputs_keep_the_render(tmp_path):
    """JPEG and WebP outputs are written at quality 95, not Pillow's 75 / 80 (which kept about
    36 dB of the image)."""
    from vibr.io import read_image, write_image
    from vibr.metrics import psnr
    from vibr.synthetic import make_scene

    img = make_scene("grid", n_views=1, width=256, height=256).views[0].image
    for ext in ("jpg", "webp"):
        write_image(tmp_path / f"q.{ext}", img)
        assert psnr(read_image(tmp_path / f"q.{ext}"), img) > 40.0, ext
