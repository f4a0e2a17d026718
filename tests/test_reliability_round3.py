"""Reliability, tried as a new user would and with malformed inputs: outputs vibr did not
write are kept, in-place updates keep the files they do not own, workers die with their
parent, memory and sizes are checked before the work, and inputs that would give a silent
wrong result are named (docs/reference/errors-and-limits.md)."""

from __future__ import annotations

import json
import logging
import os
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from test_cli_errors import assert_one_line_error, run_cli
from vibr.errors import VibrInputError
from vibr.io import load_scene, read_image, save_scene, write_image
from vibr.io.outputs import MARKER, read_marker
from vibr.synthetic import make_scene

SRC = str(Path(__file__).resolve().parents[1] / "src")


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    """A 3x3 synthetic scene of 64x64 views with depth, saved as transforms.json."""
    root = tmp_path_factory.mktemp("round3") / "scene"
    save_scene(make_scene(width=64, height=64), root)
    return root


@pytest.fixture(scope="module")
def path_file(scene_dir, tmp_path_factory):
    """A 6-frame orbit camera path of the scene (written by vibr path)."""
    from vibr.cli import main

    out = tmp_path_factory.mktemp("round3path") / "p.json"
    assert main(["path", "orbit", str(scene_dir), "-o", str(out), "--frames", "6", "-q"]) == 0
    return out


class _Warnings(logging.Handler):
    """The warnings vibr logs inside the block (the CLI stops the 'vibr' logger from
    propagating, so pytest's caplog does not see them once a command has run)."""

    def __init__(self, level=logging.WARNING):
        super().__init__(level)
        self.messages = []

    def emit(self, record):
        self.messages.append(record.getMessage())

    def __enter__(self):
        self._log = logging.getLogger("vibr")
        self._level = self._log.level
        self._log.addHandler(self)
        self._log.setLevel(min(self._level or logging.WARNING, self.level))
        return self

    def __exit__(self, *exc):
        self._log.removeHandler(self)
        self._log.setLevel(self._level)


def _png_header_only(path, w, h):
    """A PNG whose header declares w x h pixels (Pillow refuses to open it past its limit)."""
    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))


# ------------------------------------------------------------------ 1. outputs vibr did not write
def test_frames_folder_with_a_users_frame_is_refused(capsys, scene_dir, path_file, tmp_path):
    mine = tmp_path / "myframes"
    mine.mkdir()
    user = np.full((8, 8, 3), 0.5, np.float32)
    write_image(mine / "frame_00002.png", user)  # the user's own, no vibr key
    before = (mine / "frame_00002.png").read_bytes()
    code, err = run_cli(capsys, "render", scene_dir, "--path", path_file, "-o", mine, "--workers", "1")
    assert_one_line_error(code, err, "frame_00002.png", "--overwrite")
    code, err = run_cli(capsys, "render", scene_dir, "--path", path_file, "-o", tmp_path / "v.mp4",
                        "--frames-dir", mine)
    assert_one_line_error(code, err, "frame_00002.png")
    assert (mine / "frame_00002.png").read_bytes() == before
    assert sorted(p.name for p in mine.iterdir()) == ["frame_00002.png"]


def test_frames_folder_ownership_rule(tmp_path):
    """Frames with vibr's key chunk and files the marker lists are vibr's; others are not."""
    from vibr.io.outputs import check_frames_folder
    from vibr.paths.flythrough import FRAME_KEY, _owned_frame_file

    d = tmp_path / "f"
    d.mkdir()
    img = np.zeros((4, 4, 3), np.float32)
    write_image(d / "frame_00000.png", img, bits=8, text={FRAME_KEY: "k"})
    check_frames_folder(d, _owned_frame_file, overwrite=False)  # a frame vibr wrote: accepted
    (d / "notes.txt").write_text("mine")
    with pytest.raises(VibrInputError, match="notes.txt"):
        check_frames_folder(d, _owned_frame_file, overwrite=False)
    check_frames_folder(d, _owned_frame_file, overwrite=True)
    (d / MARKER).write_text(json.dumps({"written_by": "vibr", "files": ["notes.txt", "frame_00001.png"]}))
    check_frames_folder(d, _owned_frame_file, overwrite=False)  # listed by the marker
    write_image(d / "frame_00001.png", img)  # listed, but a frame without vibr's key: the user's
    with pytest.raises(VibrInputError, match="frame_00001.png"):
        check_frames_folder(d, _owned_frame_file, overwrite=False)


@pytest.mark.parametrize("overwrite", [False, True])
def test_a_file_in_the_place_of_the_frames_folder_is_refused(capsys, scene_dir, path_file, tmp_path, overwrite):
    """(benchmarks/tools/fuzz_outputs.py: `render --path P -o v.mp4` with a file, or a link to
    none, named v_frames gave a FileExistsError traceback once the scene was read.)"""
    (tmp_path / "v_frames").write_text("the user's file")
    (tmp_path / "dangling").symlink_to(tmp_path / "missing")
    for extra in ([], ["--frames-dir", tmp_path / "dangling"]):
        code, err = run_cli(capsys, "render", scene_dir, "--path", path_file, "-o", tmp_path / "v.mp4", *extra,
                            *(["--overwrite"] if overwrite else []))
        assert_one_line_error(code, err, "frames folder exists and is not a folder")
    assert (tmp_path / "v_frames").read_text() == "the user's file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling", "v_frames"]


def test_an_image_write_on_a_full_disk_prints_no_traceback(tmp_path):
    """(benchmarks/tools/fuzz_outputs.py: an 8-bit PNG frame on a full disk gave vibr's one
    line, then "Exception ignored in PluginV3.__del__" and a traceback: imageio closed its
    file again in its finaliser.) RLIMIT_FSIZE fails the write as a full disk does."""
    code = f"""
import gc, resource, signal, sys
import numpy as np
sys.path.insert(0, {SRC!r})
from vibr.errors import OutputFailed
from vibr.eval.sigma_figures import write_sigma
from vibr.io import write_image
from vibr.io.depthfiles import write_depth
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (1000, 1000))
img = np.random.default_rng(0).random((48, 48, 3))
for write in (lambda: write_image("a.png", img, bits=8), lambda: write_image("a.bmp", img),
              lambda: write_depth("d.png", 1 + img[..., 0]), lambda: write_sigma("s.png", 10 * img[..., 0])):
    try:
        write()
    except OutputFailed as exc:
        print("refused:", exc.problem)
    gc.collect()
"""
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert r.stdout.splitlines() == ["refused: cannot write: File too large"] * 4
    assert list(tmp_path.iterdir()) == []


def test_single_files_need_overwrite_unless_vibr_wrote_them(capsys, scene_dir, tmp_path):
    from vibr.io.outputs import written_by_vibr

    out = tmp_path / "p.json"
    out.write_text("my notes")
    code, err = run_cli(capsys, "path", "orbit", scene_dir, "-o", out, "--frames", "3")
    assert_one_line_error(code, err, out, "did not write", "--overwrite")
    assert out.read_text() == "my notes"
    assert run_cli(capsys, "path", "orbit", scene_dir, "-o", out, "--frames", "3", "--overwrite")[0] == 0
    assert written_by_vibr(out) and "p.json" in read_marker(tmp_path)
    assert run_cli(capsys, "path", "orbit", scene_dir, "-o", out, "--frames", "4")[0] == 0  # vibr's: replaced
    out.write_text(out.read_text().replace("4", "5", 1))  # edited by the user: no longer vibr's
    assert not written_by_vibr(out)
    code, err = run_cli(capsys, "path", "orbit", scene_dir, "-o", out, "--frames", "3")
    assert_one_line_error(code, err, "did not write")

    png = tmp_path / "photo.png"
    png.write_bytes(b"not vibr's")
    code, err = run_cli(capsys, "render", scene_dir, "--target", "4", "-o", png)
    assert_one_line_error(code, err, png, "did not write")
    rep = tmp_path / "report.json"
    rep.write_text("{}")
    code, err = run_cli(capsys, "eval", scene_dir, "--target", "4", "--json", rep)
    assert_one_line_error(code, err, rep, "did not write")
    assert png.read_bytes() == b"not vibr's" and rep.read_text() == "{}"

def test_a_users_link_to_nothing_is_not_replaced(capsys, scene_dir, tmp_path):
    """(benchmarks/tools/fuzz_outputs.py: a symbolic link to a missing file at -o did not
    "exist", and the output replaced it without --overwrite.)"""
    for name in ("p.json", "out"):
        (tmp_path / name).symlink_to(tmp_path / "missing")
    code, err = run_cli(capsys, "path", "orbit", scene_dir, "-o", tmp_path / "p.json", "--frames", "3")
    assert_one_line_error(code, err, "p.json", "did not write", "--overwrite")
    code, err = run_cli(capsys, "convert", scene_dir, tmp_path / "out", "--overwrite")
    assert_one_line_error(code, err, "exists and is not a folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "p.json"]
    assert all(os.readlink(tmp_path / n) == str(tmp_path / "missing") for n in ("out", "p.json"))
    assert run_cli(capsys, "path", "orbit", scene_dir, "-o", tmp_path / "p.json", "--frames", "3",
                   "--overwrite")[0] == 0  # asked: the link is replaced, never written through
    assert (tmp_path / "p.json").is_file() and not (tmp_path / "p.json").is_symlink()
    assert not (tmp_path / "missing").exists()


def test_an_output_named_as_the_marker_is_refused(capsys, scene_dir, tmp_path):
    """(benchmarks/tools/fuzz_outputs.py: `render -o .vibr-output` and `eval --json
    .vibr-output` wrote their output, then the marker over it, and said "wrote".)"""
    for cmd in (["render", scene_dir, "--target", "4", "-o", tmp_path / MARKER],
                ["eval", scene_dir, "--target", "4", "--method", "gradient", "--json", tmp_path / MARKER],
                ["convert", scene_dir, tmp_path / MARKER]):
        code, err = run_cli(capsys, *cmd, "--overwrite")
        assert_one_line_error(code, err, f"{MARKER} is the name of vibr's marker file")
    assert list(tmp_path.iterdir()) == []



def test_record_file_keeps_other_entries(tmp_path):
    from vibr.io.outputs import record_file, written_by_vibr

    for name in ("a.png", "b.png"):
        (tmp_path / name).write_bytes(name.encode())
        record_file(tmp_path / name)
    assert written_by_vibr(tmp_path / "a.png") and written_by_vibr(tmp_path / "b.png")
    assert read_marker(tmp_path) == {"a.png", "b.png"}
    assert not written_by_vibr(tmp_path / MARKER)


# ------------------------------------------------------------------ 2. in-place updates keep files
def test_in_place_update_keeps_calibration_json(capsys, tmp_path):
    from vibr.io.outputs import write_marker

    root = tmp_path / "scene"
    save_scene(make_scene(width=64, height=64), root)
    calib = {"photos": "/x/photos", "registered": ["a.jpg", "b.jpg"], "unregistered": [],
             "mean_reprojection_error_px": 0.5}
    (root / "calibration.json").write_text(json.dumps(calib))
    write_marker(root)  # as vibr calibrate does: the marker lists calibration.json
    scene = load_scene(root)
    save_scene(scene, root, overwrite=True, in_place=True)  # what 'vibr depth SCENE' does
    assert json.loads((root / "calibration.json").read_text()) == calib
    assert "calibration.json" in read_marker(root)
    from vibr.cli import main

    capsys.readouterr()
    assert main(["info", str(root), "-q"]) == 0
    assert "2 of 2 registered" in capsys.readouterr().out  # the calibration line of vibr info


# ------------------------------------------------------------------ 3. workers die with their parent
def _descendants(pid):
    try:
        import psutil
    except ImportError:  # /proc: every process whose parent chain reaches pid
        kids = {}
        for d in Path("/proc").iterdir():
            if d.name.isdigit():
                try:
                    ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
                except (OSError, IndexError, ValueError):
                    continue
                kids.setdefault(ppid, []).append(int(d.name))
        out, todo = [], [pid]
        while todo:
            for c in kids.get(todo.pop(), []):
                out.append(c)
                todo.append(c)
        return out
    try:
        return [c.pid for c in psutil.Process(pid).children(recursive=True)]
    except psutil.NoSuchProcess:
        return []


def _alive(pid):
    try:
        import psutil

        return psutil.pid_exists(pid) and psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except ImportError:
        try:
            return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
        except OSError:
            return False
    except Exception:  # noqa: BLE001 - gone between the two calls
        return False


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="kill -9 and /proc: Linux")
def test_workers_die_with_a_killed_parent(capsys, scene_dir, tmp_path):
    """kill -9 of a fly-through on 2 processes while its frames render: within 5 s no process
    it started is left (workers, and multiprocessing's resource tracker once they are gone)."""
    from vibr.cli import main

    long_path = tmp_path / "long.json"  # frames enough to be rendering still at the kill
    assert main(["path", "orbit", str(scene_dir), "-o", str(long_path), "--frames", "400", "-q"]) == 0
    frames = tmp_path / "frames"
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-m", "vibr", "render", str(scene_dir), "--path", str(long_path),
                             "-o", str(frames), "--workers", "2", "-q"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    kids = []
    try:
        deadline = time.time() + 600
        while time.time() < deadline and proc.poll() is None and not list(frames.glob("frame_*.png")):
            time.sleep(0.1)  # the workers render: past their start
        assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
        kids = _descendants(proc.pid)
        assert len([k for k in kids if "spawn_main" in _cmdline(k)]) == 2, [_cmdline(k) for k in kids]
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        gone_by = time.time() + 5.0  # the claim: all gone within 5 s (no need to wait them out)
        while any(_alive(k) for k in kids) and time.time() < gone_by:
            time.sleep(0.1)
        alive = [k for k in kids if _alive(k)]
        assert not alive, [(k, _cmdline(k)) for k in alive]
    finally:
        if proc.poll() is None:
            proc.kill()
        for k in kids:
            if _alive(k):
                os.kill(k, signal.SIGKILL)


def _cmdline(pid):
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


# ------------------------------------------------------------------ 4. memory before work
def test_scale_is_bounded(capsys, scene_dir, monkeypatch):
    import vibr.io.images as images

    def no_read(*a, **k):
        raise AssertionError("an image was read")

    monkeypatch.setattr(images, "read_image", no_read)
    code, err = run_cli(capsys, "render", scene_dir, "--target", "4", "-o", "/tmp/never.png", "--scale", "16")
    assert_one_line_error(code, err, "scale", "(0, 4]")


def test_memory_of_the_scale_checked_before_any_resize(scene_dir, monkeypatch):
    import vibr._runtime.memory as memory
    import vibr.io.images as images

    npx = 9 * 64 * 64
    monkeypatch.setattr(memory, "available_memory", lambda: int(16 * npx * 2))  # scale 1 fits, 2 does not

    def no_resize(*a, **k):
        raise AssertionError("an image was resized before the memory check")

    monkeypatch.setattr(images, "resize_image", no_resize)
    assert len(load_scene(scene_dir)) == 9
    with pytest.raises(VibrInputError, match="at scale 2"):
        load_scene(scene_dir, scale=2.0)


# ------------------------------------------------------------------ 5. sizes before the work
def test_calibrate_names_a_decompression_bomb(capsys, tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    rng = np.random.default_rng(0)
    for i in range(3):
        write_image(photos / f"p{i}.png", rng.random((64, 64, 3)).astype(np.float32), bits=8)
    _png_header_only(photos / "huge.png", 30000, 30000)
    code, err = run_cli(capsys, "calibrate", photos, tmp_path / "out")
    assert_one_line_error(code, err, "huge.png", "Mpixels")


def test_camera_path_frames_capped_before_cameras(capsys, scene_dir, path_file, tmp_path, monkeypatch):
    import vibr.paths.camera_path as cp

    d = json.loads(path_file.read_text())
    monkeypatch.setattr(cp, "MAX_FRAMES", len(d["camera_path"]) - 1)
    built = []
    real = cp.camera_from_c2w_opengl
    monkeypatch.setattr(cp, "camera_from_c2w_opengl", lambda *a, **k: built.append(1) or real(*a, **k))
    with pytest.raises(VibrInputError, match=f"more than the {len(d['camera_path']) - 1}"):
        cp.read_camera_path(path_file)
    assert not built
    code, err = run_cli(capsys, "render", scene_dir, "--path", path_file, "-o", tmp_path / "f")
    assert_one_line_error(code, err, path_file, "frames")


# ------------------------------------------------------------------ 6. silent wrong output
def test_two_frames_naming_one_image_refused(tmp_path):
    root = tmp_path / "s"
    save_scene(make_scene(width=64, height=64), root)
    doc = json.loads((root / "transforms.json").read_text())
    doc["frames"][2]["file_path"] = doc["frames"][1]["file_path"]
    (root / "transforms.json").write_text(json.dumps(doc))
    with pytest.raises(VibrInputError, match="frames 1 and 2 name the same image") as e:
        load_scene(root)
    assert "transforms.json" in str(e.value)


def test_scaled_rotation_in_a_camera_path_is_said(path_file, tmp_path):
    from vibr.paths.camera_path import read_camera_path

    d = json.loads(path_file.read_text())
    M = np.array(d["camera_path"][1]["camera_to_world"], float).reshape(4, 4)
    M[:3, :3] *= 2.0
    d["camera_path"][1]["camera_to_world"] = M.ravel().tolist()
    bad = tmp_path / "scaled.json"
    bad.write_text(json.dumps(d))
    with _Warnings() as w:
        read_camera_path(bad)
    msg = " ".join(w.messages)
    assert str(bad) in msg and "camera_path[1]" in msg and "rigid" in msg


def test_truncated_png_is_said(tmp_path):
    p = tmp_path / "a.png"
    write_image(p, np.random.default_rng(1).random((32, 32, 3)).astype(np.float32), bits=8)
    b = p.read_bytes()
    cut = tmp_path / "cut.png"
    cut.write_bytes(b[:-12])  # the IEND chunk lost: the pixels still decode
    with _Warnings() as w:
        a = read_image(cut)
    assert np.array_equal(a, read_image(p))
    assert any(str(cut) in m and "truncated" in m for m in w.messages), w.messages
    with _Warnings() as w:
        read_image(p)
    assert not w.messages


def _with_depth(tmp_path, fill):
    root = tmp_path / "s"
    save_scene(make_scene(width=64, height=64), root)
    for f in sorted((root / "depth").glob("*.npy")):
        np.save(f, np.full((64, 64), fill, np.float32))
    return root


@pytest.mark.parametrize("fill,level,words", [(0.0, logging.WARNING, ("all zero", "unknown")),
                                              (3.0, logging.INFO, ("constant",))])
def test_zero_or_constant_depth_is_said(tmp_path, fill, level, words):
    """All zero: a warning; constant: a note (a plane facing the camera has it too)."""
    root = _with_depth(tmp_path, fill)
    with _Warnings(level) as w:
        load_scene(root)
    msgs = w.messages
    hit = [m for m in msgs if "depth" in m and str(root / "depth") in m]
    assert len(hit) == 9, msgs
    for w in words:
        assert w in hit[0]


# ------------------------------------------------------------------ 7. messages
def test_all_zero_depth_render_says_so(tmp_path):
    from vibr.geometry import compute_samples

    scene = load_scene(_with_depth(tmp_path, 0.0))
    with pytest.raises(VibrInputError, match="depth is unknown") as e:
        compute_samples(scene.replace(views=scene.views[:4]), scene.views[4].camera)
    assert "no source view sees" not in str(e.value)


def test_empty_image_file_is_said(tmp_path):
    from vibr.io.images import image_size

    p = tmp_path / "empty.png"
    p.write_bytes(b"")
    for fn in (read_image, image_size):
        with pytest.raises(VibrInputError, match="empty") as e:
            fn(p)
        assert "backend" not in str(e.value) and str(p) in str(e.value)
