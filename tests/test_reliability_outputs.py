"""--overwrite never deletes what vibr did not write, and outputs
are checked before the work (one line, exit 2, nothing written)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from test_cli_errors import assert_one_line_error, make_transforms, run_cli
from vibr.cli import main
from vibr.errors import VibrInputError
from vibr.io import save_scene
from vibr.io.outputs import check_output, read_marker


def _tree(p):
    return sorted(str(f.relative_to(p)) for f in p.rglob("*"))


def test_convert_overwrite_refuses_an_ancestor_of_the_scene(capsys, tmp_path):
    (tmp_path / "data").mkdir()
    root = make_transforms(tmp_path / "data" / "s")
    (tmp_path / "data" / "notes.txt").write_text("mine")
    before = _tree(tmp_path)
    for out in (tmp_path / "data", tmp_path, root):
        code, err = run_cli(capsys, "convert", root, out, "--overwrite")
        assert_one_line_error(code, err, "input")
        assert _tree(tmp_path) == before


def test_convert_overwrite_replaces_only_its_own_folder(capsys, tmp_path):
    root = make_transforms(tmp_path / "s")
    out = tmp_path / "out"
    assert run_cli(capsys, "convert", root, out)[0] == 0
    listed = read_marker(out)
    assert "transforms.json" in listed and "images/a.png" in listed
    assert run_cli(capsys, "convert", root, out, "--overwrite")[0] == 0   # vibr's own: replaced
    assert run_cli(capsys, "convert", root, out, "--force")[0] == 0       # the old name still works
    (out / "images" / "my_edit.png").write_bytes(b"user file")
    code, err = run_cli(capsys, "convert", root, out, "--overwrite")
    assert_one_line_error(code, err, out, "images/my_edit.png")
    assert (out / "images" / "my_edit.png").read_bytes() == b"user file"


def test_convert_refuses_an_output_holding_an_input(capsys, tmp_path):
    """OUT inside SCENE is fine when new, but never replaces a folder of the input."""
    root = make_transforms(tmp_path / "s")
    assert run_cli(capsys, "convert", root, root / "converted")[0] == 0
    (root / "sub").mkdir()
    code, err = run_cli(capsys, "convert", root, root, "--overwrite")
    assert_one_line_error(code, err, "input")
    assert (root / "a.png").is_file() and (root / "transforms.json").is_file()


def test_save_scene_library_refuses_input_folder(tmp_path):
    from vibr.io import load_scene

    root = make_transforms(tmp_path / "s")
    scene = load_scene(root)
    with pytest.raises(VibrInputError, match="input"):
        save_scene(scene, tmp_path, overwrite=True)
    assert (root / "a.png").is_file()


def test_depth_in_place_only_on_a_folder_vibr_wrote(capsys, tmp_path):
    root = make_transforms(tmp_path / "s")
    (root / "notes.txt").write_text("mine")
    before = _tree(root)
    code, err = run_cli(capsys, "depth", root)
    assert_one_line_error(code, err, root, "-o OUT")
    assert _tree(root) == before
    # --overwrite on a user folder: refused too
    other = tmp_path / "o"
    other.mkdir()
    (other / "x.txt").write_text("mine")
    code, err = run_cli(capsys, "depth", root, "-o", other, "--overwrite")
    assert_one_line_error(code, err, other, "not written by vibr")
    assert (other / "x.txt").read_text() == "mine"


# ----------------------------------------------------------------------------- item 3
def test_check_output_cases(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "f.txt").write_text("x")
    assert check_output(tmp_path / "r.png") == tmp_path / "r.png"
    for path, kind, word in [("", "file", "empty"), (tmp_path / "d", "file", "folder"),
                             (tmp_path / "f.txt", "dir", "not a folder"),
                             (tmp_path / "missing" / "r.png", "file", "does not exist"),
                             (tmp_path / "f.txt" / "r.png", "file", "not a folder"),
                             ("/proc/vibr_test_out.png", "file", "cannot write")]:
        with pytest.raises(VibrInputError, match=word):
            check_output(path, kind)


def _tiny_scene(tmp_path):
    from vibr.synthetic import make_scene

    s = make_scene("grid", n_views=4, width=32, height=24, seed=1)
    return save_scene(s, tmp_path / "scene")


@pytest.mark.parametrize("bad", ["dir", "missing_parent", "empty", "readonly"])
def test_outputs_checked_before_the_work(capsys, tmp_path, bad):
    """render -o / eval --json / eval --figures / convert OUT / depth -o: refused in
    well under a second (before loading or computing), one line, nothing written."""
    src = _tiny_scene(tmp_path)
    (tmp_path / "adir").mkdir()
    target = {"dir": tmp_path / "adir", "missing_parent": tmp_path / "no" / "such" / "x.png",
              "empty": "", "readonly": "/proc/vibr_test/x.png"}[bad]
    cmds = [["render", src, "--target", "0", "-o", target],
            ["eval", src, "--target", "0", "--method", "ulr", "--json", target],
            ["eval", src, "--target", "0", "--method", "ulr", "--json", tmp_path / "r.json",
             "--figures", target if bad != "dir" else tmp_path / "scene" / "transforms.json"],
            ["demo", "--size", "16", "-o", target]]
    if bad != "dir":
        cmds += [["convert", src, target], ["depth", src, "-o", target]]
    for cmd in cmds:
        before = _tree(tmp_path)
        t0 = time.perf_counter()
        code, err = run_cli(capsys, *cmd)
        assert_one_line_error(code, err)
        assert time.perf_counter() - t0 < 5.0, cmd
        assert _tree(tmp_path) == before, cmd


def test_atomic_path_registers_its_temporary_file_before_creating_it(tmp_path, monkeypatch):
    """A SIGTERM handler (``remove_partial``) that runs right after the temporary file is
    created finds it: the name is registered first (a pool worker terminated in that window
    used to leave a ``.part`` file behind)."""
    import contextlib
    import os

    import vibr._runtime.atomic as atomic

    seen = []
    real_close = os.close

    def close_then_handler(fd):
        real_close(fd)
        atomic.remove_partial()  # what the worker's SIGTERM handler does at this moment
        seen.append(sorted(p.name for p in tmp_path.glob(".*.part*")))

    cm = atomic.atomic_path(tmp_path / "x.txt")
    with monkeypatch.context() as m:
        m.setattr(atomic.os, "close", close_then_handler)
        cm.__enter__()
    assert seen == [[]]
    with contextlib.suppress(BaseException):  # its file is gone: leaving the write fails
        cm.__exit__(None, None, None)
    assert not list(tmp_path.glob(".*.part*")) and not (tmp_path / "x.txt").exists()


# ----------------------------------------------------------------------------- a full disk
def _start_with_file_limit(args, limit_bytes, cwd):
    """``python -m vibr ARGS`` started (a Popen) with its files (and ffmpeg's) not allowed to
    grow past ``limit_bytes`` (RLIMIT_FSIZE: a write past it fails with EFBIG, as on a full
    disk with ENOSPC)."""
    import os
    import resource
    import signal
    import subprocess
    import sys

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails instead of killing
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    env = dict(os.environ, VIBR_CACHE_DIR=str(cwd / "cache"))
    return subprocess.Popen([sys.executable, "-m", "vibr", "-q", *map(str, args)], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=limit)


def _finished(proc):
    """The process's return code, stdout and stderr (as subprocess.run's result), once it ends."""
    import subprocess

    try:
        out, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


@pytest.mark.slow
def test_a_write_that_fails_is_one_line_and_leaves_nothing(tmp_path):
    """A full disk gave a traceback (PNG, .npy, scene folders) or, for the video, exit 0
    with a truncated file (ffmpeg's status was not read)."""
    from vibr.synthetic import make_scene

    scene = save_scene(make_scene("grid", n_views=4, width=64, height=48, seed=1), tmp_path / "s")
    # without a limit first: numba's kernel cache is then written (a cold cache is a file
    # the limit stops too: 'vibr render: error: cannot write: File too large', no name)
    assert main(["render", str(scene), "--target", "1", "-o", str(tmp_path / "warm.png"), "-q"]) == 0
    cases = ((["render", scene, "--target", "1", "-o", "x.png", "--bit-depth", "16"], "x.png"),
             (["convert", scene, "c"], "c"))
    started = [_start_with_file_limit(args, 2000, tmp_path) for args, _ in cases]  # both at once
    for (args, out), proc in zip(cases, started):
        r = _finished(proc)
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        assert r.stderr.strip().splitlines()[-1].startswith(f"vibr {args[0]}: error: ")
        assert "cannot write: File too large" in r.stderr and not (tmp_path / out).exists()
    assert not list(tmp_path.glob(".*part*"))
    # the frames are written (no limit), then the video cannot be: one line, no video
    assert main(["path", "orbit", str(scene), "--frames", "4", "-o", str(tmp_path / "p.json"), "-q"]) == 0
    assert main(["render", str(scene), "--path", str(tmp_path / "p.json"), "-o", str(tmp_path / "f"), "-q"]) == 0
    r = _finished(_start_with_file_limit(["render", scene, "--path", "p.json", "-o", "v.mp4", "--frames-dir", "f"],
                                         1500, tmp_path))
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.strip().splitlines()[-1].startswith("vibr render: error: v.mp4: cannot write the video: ffmpeg:")
    assert not (tmp_path / "v.mp4").exists()


# ----------------------------------------------------------------------------- inputs as outputs
@pytest.mark.parametrize("args,what", [
    (["eval", "{s}", "--target", "0", "--method", "ulr", "--json", "{s}/transforms.json"], "--json"),
    (["render", "{s}", "--target", "0", "-o", "{s}/a.png"], "-o"),
    (["render", "{s}", "--target", "0", "-o", "{t}/x.png", "--uncertainty", "{s}/a_depth.npy"], "--uncertainty"),
    (["path", "orbit", "{s}", "--frames", "3", "-o", "{s}/transforms.json"], "-o"),
])
def test_an_output_that_is_a_file_of_the_scene_is_refused(capsys, tmp_path, args, what):
    """`vibr eval SCENE --json SCENE/transforms.json` replaced the scene's cameras with the
    report (the scene was lost). Every file output is checked against the scene's files, even
    with --overwrite (without it, a file vibr did not write is refused first)."""
    root = make_transforms(tmp_path / "s", depth=np.full((12, 16), 2.0, np.float32))
    before = {f.name: f.read_bytes() for f in root.iterdir()}
    code, err = run_cli(capsys, *[a.format(s=root, t=tmp_path) for a in args], "--overwrite")
    assert_one_line_error(code, err, f"{what} would overwrite a file of the input scene")
    assert {f.name: f.read_bytes() for f in root.iterdir()} == before
    assert not (tmp_path / "x.png").exists()


def test_fly_through_frames_are_not_written_among_the_photographs(capsys, tmp_path):
    """(`vibr render SCENE --path P -o SCENE/images` put frame_*.png among the photographs: in
    an image-folder scene they would be views without cameras on the next load.)"""
    root = make_transforms(tmp_path / "s", depth=np.full((12, 16), 2.0, np.float32))
    assert main(["path", "orbit", str(root), "--frames", "2", "-o", str(tmp_path / "p.json"), "-q"]) == 0
    capsys.readouterr()
    for out in (root, tmp_path):
        code, err = run_cli(capsys, "render", root, "--path", tmp_path / "p.json", "-o", out)
        assert_one_line_error(code, err, "the output folder contains the input")
    assert sorted(f.name for f in root.iterdir()) == ["a.png", "a_depth.npy", "transforms.json"]
    assert run_cli(capsys, "render", root, "--path", tmp_path / "p.json", "-o", root / "frames")[0] == 0
