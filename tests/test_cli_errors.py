"""Bad input: one line on stderr naming the file and the problem, exit status 2, no
traceback, no partial output (``vibr info`` / ``vibr convert``)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from vibr.cli import main
from vibr.io.depthfiles import write_pfm
from vibr.io.images import write_image


def run_cli(capsys, *args):
    code = main(list(map(str, args)) + ["-q"])
    err = capsys.readouterr().err.strip()
    return code, err


def assert_one_line_error(code, err, *words):
    assert code == 2
    assert "\n" not in err and "Traceback" not in err, err
    assert err.startswith("vibr ")
    for w in words:
        assert str(w) in err, (w, err)


def _img(path, w=16, h=12, seed=0):
    rng = np.random.default_rng(seed)
    write_image(path, (rng.integers(0, 256, (h, w, 3)) / 255).astype(np.float32))


def make_transforms(root, depth=None, matrix=None):
    """A one-frame nerfstudio scene; optional depth array written as .npy."""
    root.mkdir(exist_ok=True)
    _img(root / "a.png")
    fr = {"file_path": "a.png", "transform_matrix": matrix if matrix is not None else np.eye(4).tolist()}
    if depth is not None:
        np.save(root / "a_depth.npy", depth)
        fr["depth_file_path"] = "a_depth.npy"
    doc = {"fl_x": 20.0, "fl_y": 20.0, "cx": 8.0, "cy": 6.0, "w": 16, "h": 12, "frames": [fr]}
    (root / "transforms.json").write_text(json.dumps(doc))
    return root


def test_missing_path(capsys, tmp_path):
    code, err = run_cli(capsys, "info", tmp_path / "nope")
    assert_one_line_error(code, err, tmp_path / "nope", "not found")


def test_missing_image_of_a_frame(capsys, tmp_path):
    root = make_transforms(tmp_path / "s")
    os.remove(root / "a.png")
    code, err = run_cli(capsys, "info", root)
    assert_one_line_error(code, err, root / "a.png", "not found")


def test_unrecognised_folder(capsys, tmp_path):
    (tmp_path / "notes.txt").write_text("hello")
    code, err = run_cli(capsys, "info", tmp_path)
    assert_one_line_error(code, err, tmp_path, "no supported scene")
    assert "calibrate" not in err
    # a folder of photos without cameras: the error says how to get cameras
    write_image(tmp_path / "IMG_0001.png", np.zeros((8, 8, 3), np.float32))
    code, err = run_cli(capsys, "info", tmp_path)
    assert_one_line_error(code, err, tmp_path, "no supported scene", "vibr calibrate")

    # a Blender / NeRF-synthetic folder: its split files are named, and the way to use them
    root = make_transforms(tmp_path / "blender")
    (root / "transforms.json").rename(root / "transforms_train.json")
    code, err = run_cli(capsys, "info", root)
    assert_one_line_error(code, err, "found transforms_train.json", "give one of these files as SCENE")
    assert run_cli(capsys, "info", root / "transforms_train.json")[0] == 0


def test_garbage_png_in_light_field(capsys, tmp_path, cotton_dir):
    os.symlink(cotton_dir / "input_Cam040.png", tmp_path / "input_Cam040.png")
    (tmp_path / "input_Cam041.png").write_bytes(b"\x89PNG garbage bytes" * 10)
    code, err = run_cli(capsys, "info", tmp_path)
    assert_one_line_error(code, err, tmp_path / "input_Cam041.png", "cannot read image")


def test_garbage_png_in_transforms_scene(capsys, tmp_path):
    root = make_transforms(tmp_path / "s")
    (root / "a.png").write_bytes(os.urandom(300))
    code, err = run_cli(capsys, "info", root)
    assert_one_line_error(code, err, root / "a.png", "cannot read image")


def test_light_field_views_of_different_sizes(capsys, tmp_path, cotton_dir):
    os.symlink(cotton_dir / "input_Cam040.png", tmp_path / "input_Cam040.png")
    _img(tmp_path / "input_Cam041.png", 256, 256)
    code, err = run_cli(capsys, "info", tmp_path)
    assert_one_line_error(code, err, tmp_path / "input_Cam041.png", "same size", "256x256", "512x512")


@pytest.mark.parametrize("bad,word", [(np.nan, "NaN"), (np.inf, "infinite"), (-2.0, "negative")])
def test_bad_depth_values(capsys, tmp_path, bad, word):
    d = np.full((12, 16), 3.0, np.float32)
    d[4, 5] = bad
    root = make_transforms(tmp_path / "s", depth=d)
    code, err = run_cli(capsys, "info", root)
    assert_one_line_error(code, err, root / "a_depth.npy", word)


def test_nan_disparity_in_light_field(capsys, tmp_path, cotton_dir):
    for n in ("input_Cam040.png", "input_Cam080.png"):  # Cam080: the 9x9 grid is inferred
        os.symlink(cotton_dir / n, tmp_path / n)
    disp = np.zeros((512, 512), np.float32)
    disp[10, 10] = np.nan
    write_pfm(tmp_path / "gt_disp_lowres.pfm", disp)
    code, err = run_cli(capsys, "info", tmp_path)
    assert_one_line_error(code, err, tmp_path / "gt_disp_lowres.pfm", "NaN")


def test_non_orthonormal_rotation(capsys, tmp_path):
    """A shear is refused (a uniform scale is a scaled camera object: read as its rotation,
    tests/test_io_roundtrip.py)."""
    M = np.eye(4)
    M[0, 1] = 0.1
    root = make_transforms(tmp_path / "s", matrix=M.tolist())
    code, err = run_cli(capsys, "info", root)
    assert_one_line_error(code, err, root / "transforms.json", "not a rotation")


def test_malformed_json(capsys, tmp_path):
    root = make_transforms(tmp_path / "s")
    (root / "transforms.json").write_text('{"fl_x": 20, "frames": [{"file_path": "a.png",')
    code, err = run_cli(capsys, "info", root)
    assert_one_line_error(code, err, root / "transforms.json", "malformed JSON", "line 1")


def test_json_from_a_windows_editor_loads(capsys, tmp_path):
    """A UTF-8 byte-order mark and CRLF line ends (Notepad) were 'malformed JSON'."""
    root = make_transforms(tmp_path / "s")
    text = (root / "transforms.json").read_bytes()
    (root / "transforms.json").write_bytes(b"\xef\xbb\xbf" + text.replace(b"\n", b"\r\n"))
    assert run_cli(capsys, "info", root)[0] == 0


def _strecha(tmp_path, fountain_dir, names=("0000", "0001")):
    (tmp_path / "images").mkdir()
    (tmp_path / "gt_dense_cameras").mkdir()
    for n in names:
        os.symlink(fountain_dir / "images" / f"{n}.jpg", tmp_path / "images" / f"{n}.jpg")
        shutil.copy(fountain_dir / "gt_dense_cameras" / f"{n}.jpg.camera", tmp_path / "gt_dense_cameras")
    return tmp_path


def test_malformed_camera_file(capsys, tmp_path, fountain_dir):
    root = _strecha(tmp_path, fountain_dir)
    bad = root / "gt_dense_cameras" / "0001.jpg.camera"
    bad.write_text("\n".join(bad.read_text().splitlines()[:6]) + "\n")  # truncated
    code, err = run_cli(capsys, "info", root)
    assert_one_line_error(code, err, bad, "malformed .camera")


def test_camera_file_with_bad_rotation(capsys, tmp_path, fountain_dir):
    root = _strecha(tmp_path, fountain_dir)
    bad = root / "gt_dense_cameras" / "0000.jpg.camera"
    lines = bad.read_text().splitlines()
    lines[4] = "1 0 0"
    lines[5] = "1 0 0"
    bad.write_text("\n".join(lines) + "\n")
    code, err = run_cli(capsys, "info", root)
    assert_one_line_error(code, err, bad, "not a rotation")


def test_image_without_camera_file(capsys, tmp_path, fountain_dir):
    root = _strecha(tmp_path, fountain_dir)
    os.symlink(fountain_dir / "images" / "0002.jpg", root / "images" / "0002.jpg")
    code, err = run_cli(capsys, "info", root)
    assert_one_line_error(code, err, root / "images" / "0002.jpg", "no camera file")


def test_convert_leaves_no_partial_output(capsys, tmp_path):
    root = make_transforms(tmp_path / "s")
    (root / "a.png").write_bytes(b"junk")
    out = tmp_path / "out"
    code, err = run_cli(capsys, "convert", root, out)
    assert_one_line_error(code, err, root / "a.png")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]


def test_convert_refuses_existing_output_without_overwrite(capsys, tmp_path):
    root = make_transforms(tmp_path / "s")
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    code, err = run_cli(capsys, "convert", root, out)
    assert_one_line_error(code, err, out, "--overwrite")
    assert (out / "keep.txt").read_text() == "mine"
    # --overwrite (alias --force) never deletes a folder vibr did not write
    for flag in ("--overwrite", "--force"):
        code, err = run_cli(capsys, "convert", root, out, flag)
        assert_one_line_error(code, err, out, "not written by vibr")
        assert (out / "keep.txt").read_text() == "mine"


def test_exit_status_of_the_real_command(tmp_path):
    r = subprocess.run([sys.executable, "-m", "vibr", "info", str(tmp_path / "missing")],
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "missing" in r.stderr and "Traceback" not in r.stderr


# ----------------------------------------------------------------------------- sizes and lists
def test_scale_too_small_is_refused_at_load(capsys, temple_dir):
    """A --scale that shrinks the photos to a few pixels fails at load, naming the image and
    its size (it gave a traceback deep in the depth estimate)."""
    code, err = run_cli(capsys, "render", temple_dir, "--scale", "1e-9", "--target", "3", "-o", "x.png")
    assert_one_line_error(code, err, "templeSR0001.png", "640x480 is 1x1", "at least 8 pixels")
    code, err = run_cli(capsys, "info", temple_dir, "--scale", "0.01")
    assert_one_line_error(code, err, "6x5", "larger --scale")


@pytest.mark.slow
def test_a_view_too_small_to_measure(capsys, tmp_path, temple_dir):
    """eval refuses, before any work, a held-out view on which DSSIM is undefined; render
    writes the image and reports the PSNR, DSSIM n/a."""
    code, err = run_cli(capsys, "eval", temple_dir, "--scale", "0.025", "--target", "3",
                        "--json", tmp_path / "e.json")
    assert_one_line_error(code, err, "16x12", "at least 15 pixels")
    assert not (tmp_path / "e.json").exists()
    code = main(["render", str(temple_dir), "--scale", "0.025", "--target", "3", "-o", str(tmp_path / "x.png")])
    out = capsys.readouterr().out
    assert code == 0 and (tmp_path / "x.png").exists()
    assert "DSSIM n/a" in out and "PSNR" in out and "nan" not in out


@pytest.mark.parametrize("cmd", [
    ["info", "{scene}", "--only", ",,"],
    ["convert", "{scene}", "{tmp}/c", "--only", " , "],
    ["depth", "{scene}", "-o", "{tmp}/d", "--targets", ","],
    ["depth", "{scene}", "-o", "{tmp}/d", "--exclude", ","],
    ["path", "interpolate", "{scene}", "-o", "{tmp}/p.json", "--through", ",,"],
    ["render", "{scene}", "--target", "3", "--sources", ",", "-o", "{tmp}/x.png"],
    ["eval", "{scene}", "--target", "3", "--gamma", ",", "--json", "{tmp}/e.json"],
])
def test_an_empty_list_is_refused(capsys, tmp_path, temple_dir, cmd):
    """An option given with an empty comma list is a mistake, not "all" (vibr depth --targets ,
    wrote a scene with depth for no view)."""
    args = [a.format(scene=temple_dir, tmp=tmp_path) for a in cmd]
    with pytest.raises(SystemExit) as e:
        main(args + ["-q"])
    err = capsys.readouterr().err.strip()
    assert e.value.code == 2 and ("expected comma-separated" in err or "expected a comma-separated" in err), err
    assert list(tmp_path.iterdir()) == []


def test_a_path_too_large_for_memory_is_refused_before_the_depth(capsys, tmp_path, temple_dir):
    assert main(["path", "orbit", str(temple_dir), "--frames", "3", "--size", "100000x100000",
                 "-o", str(tmp_path / "p.json"), "-q"]) == 0
    capsys.readouterr()
    code, err = run_cli(capsys, "render", temple_dir, "--scale", "0.1", "--path", tmp_path / "p.json",
                        "-o", tmp_path / "v", "--no-cache")
    assert_one_line_error(code, err, "p.json", "100000x100000", "vibr path --size")
    assert not (tmp_path / "v").exists()


def test_one_source_with_estimated_depth_says_why(capsys, tmp_path, temple_dir):
    """(--views 1 read 'depth estimation needs at least two input views' of a 16-view scene.)"""
    code, err = run_cli(capsys, "render", temple_dir, "--scale", "0.1", "--target", "3", "--views", "1",
                        "-o", tmp_path / "x.png")
    assert_one_line_error(code, err, "one source is too few", "--views K")
    assert not (tmp_path / "x.png").exists()


def test_transforms_depth_at_another_resolution(capsys, tmp_path):
    """A depth_file_path map at half the image's size (depth networks, dense MVS at a lower
    resolution) was refused: maps of the image's aspect are resized; another aspect is named."""
    from vibr.io import load_scene

    d = np.full((6, 8), 2.0, np.float32)
    d[:1] = 0.0  # unknown: two rows at full size
    s = load_scene(make_transforms(tmp_path / "half", depth=d))
    assert s.views[0].depth.shape == (12, 16) and np.isnan(s.views[0].depth[:2]).all()
    root = make_transforms(tmp_path / "square", depth=np.full((5, 5), 2.0, np.float32))
    code, err = run_cli(capsys, "info", root)
    assert_one_line_error(code, err, "a_depth.npy", "depth is 5x5, frame 0's image is 16x12 (another aspect)")


def test_render_output_that_is_no_image_format(capsys, tmp_path):
    """(-o view.npy rendered, then wrote a TIFF under that name.)"""
    root = make_transforms(tmp_path / "s", depth=np.full((12, 16), 2.0, np.float32))
    code, err = run_cli(capsys, "render", root, "--target", "0", "-o", tmp_path / "v.npy")
    assert_one_line_error(code, err, "v.npy", ".npy is not an image format vibr writes")
    assert not (tmp_path / "v.npy").exists()
