"""Fuzz of vibr's command line over its outputs: vibr never overwrites or deletes a file it
did not write (docs/reference/errors-and-limits.md, vibr.io.outputs).

    PYTHONPATH=$PWD/src python3 benchmarks/tools/fuzz_outputs.py              # 500 cases
    PYTHONPATH=$PWD/src python3 benchmarks/tools/fuzz_outputs.py --cases 50 --seed 3
    PYTHONPATH=$PWD/src python3 benchmarks/tools/fuzz_outputs.py --case 17 --keep /tmp/c17

Each case copies a small synthetic scene (9 views of 48x48, saved by vibr.io.save_scene) and
two camera paths into a fresh folder, plants things at and around the output paths of one
command (user files with output-like names, user folders, symlinks, read-only files and
folders, forged .vibr-output markers, frames and folders a previous vibr run wrote, the
scene's own files named as outputs), then runs the command in this process through
vibr.cli.main, with or without --overwrite; a third of the cases run it as user nobody, so
that the read-only files and folders bind. Every file, link and folder is recorded
before and compared after:

* no traceback: main returns or exits 0, 2 or 130; an exit 2 prints one error line;
* without --overwrite no file vibr did not write changes or goes; with --overwrite only
  the outputs the command names may (a single output file, the frames in a frames folder);
  a folder output (convert OUT, depth -o OUT) never loses a file vibr did not write, and
  ``vibr depth SCENE`` in place keeps every file it does not write itself; the scene's own
  files are never outputs;
* a failure leaves no new output file or folder (a fly-through's frames may stay: a rerun
  resumes them), no half-written or temporary file anywhere;
* a success writes what it names.

The full-disk family (root only: it mounts a 2 MB tmpfs) runs cases whose scene and outputs
lie on a file system with 0 to 512 kB left: a failure must be exit 2 with one line on stderr
and no file lost. Prints one row per family (cases, passed, failures, the first failing
command) and the first failures in full; exit status 1 when any case failed.
"""

from __future__ import annotations

import argparse
import contextlib
import fnmatch
import gc
import hashlib
import io
import json
import os
import random
import shutil
import stat
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1] / "src"))

MARKER = ".vibr-output"  # vibr.io.outputs.MARKER (spelled out: the fuzz checks vibr, not itself)
FRAME_GLOBS = ("frame_[0-9][0-9][0-9][0-9][0-9].png", "sigma_[0-9][0-9][0-9][0-9][0-9].npz")
NOBODY = 65534
SCENE = "s"

FAMILIES = ("render", "render-path-dir", "render-path-video", "path", "eval", "convert", "depth-out",
            "depth-in-place", "full-disk")
#: relative frequency of each family
WEIGHTS = {"render": 4, "render-path-dir": 2, "render-path-video": 2, "path": 2, "eval": 2, "convert": 2,
           "depth-out": 2, "depth-in-place": 2, "full-disk": 2}


# ----------------------------------------------------------------------------- the command
@dataclass
class Spec:
    """One command and the outputs it names (paths relative to the case folder)."""

    family: str
    argv: list
    overwrite: bool = False
    files: list = field(default_factory=list)      # single output files
    frames: list = field(default_factory=list)     # frames folders (-o DIR, --frames-dir, V_frames)
    folders: list = field(default_factory=list)    # folder outputs (convert OUT, depth -o OUT)
    in_place: bool = False                          # vibr depth SCENE
    as_nobody: bool = False

    def line(self) -> str:
        return "vibr " + " ".join(self.argv)


def _pick(rng, options):
    return options[rng.randrange(len(options))]


def _render(rng) -> Spec:
    o = _pick(rng, ["out.png", "out.png", "sub/out.png", "a/b/out.png", "ro/out.png", "lnk_out.png",
                    "s/images/view_000.png", "s/transforms.json", "s/depth/view_001.npy", "frames", "out.tif",
                    MARKER, "sub/" + MARKER])
    argv = ["render", SCENE, "--target", _pick(rng, ["4", "view_004"]), "-o", o]
    files = [o]
    if rng.random() < 0.4:
        g = _pick(rng, ["sig.png", "sig.npy", "sub/sig.png", "ro/sig.png", o, "s/depth/view_002.npy"])
        argv += ["--uncertainty", g]
        files.append(g)
    return Spec("render", argv, files=files)


def _render_path_dir(rng) -> Spec:
    o = _pick(rng, ["frames", "frames/", "frames", "sub/frames", "user", "lnk_frames", "ro/frames", "s/images", "s",
                    "s/frames"])
    argv = ["render", SCENE, "--path", "cam.json", "-o", o]
    spec = Spec("render-path-dir", argv, frames=[o])
    if rng.random() < 0.2:
        spec.argv += ["--uncertainty", "sig.mp4"]
        spec.files.append("sig.mp4")
    return spec


def _render_path_video(rng) -> Spec:
    v = _pick(rng, ["fly.mp4", "fly.mp4", "sub/fly.mp4", "fly.gif", "ro/fly.mp4", "s/fly.mp4", "lnk_fly.mp4"])
    argv = ["render", SCENE, "--path", "cam.json", "-o", v]
    if rng.random() < 0.4:
        fd = _pick(rng, ["frames", "fly_frames", "user", "s/images", "s", "sub/frames", "lnk_frames"])
        argv += ["--frames-dir", fd]
    else:
        fd = str(Path(v).with_name(Path(v).stem + "_frames"))
    spec = Spec("render-path-video", argv, files=[v], frames=[fd])
    if rng.random() < 0.2:
        spec.argv += ["--uncertainty", _pick(rng, ["sig.mp4", v])]
        spec.files.append(spec.argv[-1])
    return spec


def _path(rng) -> Spec:
    o = _pick(rng, ["p.json", "p.json", "report.json", "sub/p.json", "s/transforms.json", "cam.json",
                    "a/b/p.json", "ro/p.json", "lnk_p.json"])
    kind = _pick(rng, ["orbit", "interpolate", "spiral"])
    return Spec("path", ["path", kind, SCENE, "-o", o, "--frames", "3"], files=[o])


def _eval(rng) -> Spec:
    j = _pick(rng, ["report.json", "report.json", "p.json", "sub/report.json", "s/transforms.json", "cam.json",
                    "ro/report.json", "lnk_p.json", MARKER])
    return Spec("eval", ["eval", SCENE, "--target", "4", "--method", "gradient", "--gamma", "1", "--json", j],
                files=[j])


def _folder_out(rng, family) -> Spec:
    out = _pick(rng, ["conv", "conv", "conv/", "sub/conv", "user", "s", "s/sub", "s/images", "out.png", "ro/conv",
                      "lnk_frames", MARKER])
    argv = ["convert", SCENE, out] if family == "convert" else ["depth", SCENE, "-o", out]
    return Spec(family, argv, folders=[out])


def _depth_in_place(rng) -> Spec:
    return Spec("depth-in-place", ["depth", _pick(rng, [SCENE, SCENE, "s/transforms.json"])], in_place=True)


BUILDERS = {"render": _render, "render-path-dir": _render_path_dir, "render-path-video": _render_path_video,
            "path": _path, "eval": _eval, "convert": lambda r: _folder_out(r, "convert"),
            "depth-out": lambda r: _folder_out(r, "depth-out"), "depth-in-place": _depth_in_place}


def draw_spec(rng, family: str) -> Spec:
    if family == "full-disk":
        spec = BUILDERS[_pick(rng, [f for f in BUILDERS if f != "depth-in-place"] + ["depth-in-place"])](rng)
        spec.family = "full-disk"
    else:
        spec = BUILDERS[family](rng)
    spec.overwrite = rng.random() < 0.5
    spec.argv = ["-q", *spec.argv] + (["--overwrite"] if spec.overwrite else [])
    spec.as_nobody = rng.random() < 0.33 and family != "full-disk" and os.geteuid() == 0
    return spec


# ----------------------------------------------------------------------------- running vibr
@dataclass
class Run:
    rc: object        # the exit status, or None after an exception
    out: str
    err: str
    exc: str = ""     # the traceback of an exception other than SystemExit


def run_vibr(argv, as_nobody=False) -> Run:
    """``vibr.cli.main(argv)`` in this process, stdout and stderr captured."""
    from vibr.cli import main

    out, err = io.StringIO(), io.StringIO()
    rc, exc = None, ""
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        if as_nobody:
            os.setegid(NOBODY)
            os.seteuid(NOBODY)
        try:
            rc = main(list(argv))
        except SystemExit as e:
            rc = 0 if e.code is None else e.code
        except BaseException:  # noqa: BLE001 - any other exception is a failure of the case
            exc = traceback.format_exc()
        finally:
            gc.collect()  # a finaliser's "Exception ignored" (a file closed again) goes to this case
            if as_nobody:
                os.seteuid(0)
                os.setegid(0)
    return Run(rc, out.getvalue(), err.getvalue(), exc)


# ----------------------------------------------------------------------------- the base folder
def _png_bytes(rng, with_text=None) -> bytes:
    """A small valid PNG (a user's picture), without vibr's frame key."""
    import numpy as np
    from PIL import Image

    a = (np.random.default_rng(rng.randrange(1 << 30)).random((8, 8, 3)) * 255).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(a).save(buf, format="PNG")
    return buf.getvalue()


def make_base(work: Path) -> Path:
    """The folder copied into every case: the scene ``s`` (vibr wrote it: its marker lists its
    files), two camera paths (the user's input files) and a folder ``user`` of user files
    (the targets of the symlinks)."""
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    base = work / "base"
    base.mkdir(parents=True)
    save_scene(make_scene("grid", width=48, height=48), base / SCENE)
    for name, kind in (("cam.json", "orbit"), ("cam2.json", "interpolate")):
        r = run_vibr(["-q", "path", kind, str(base / SCENE), "-o", str(base / name), "--frames", "3"])
        if r.rc != 0:
            raise SystemExit(f"fuzz_outputs: cannot make the camera path {name}: {r.err.strip() or r.exc}")
    (base / MARKER).unlink()  # the camera paths are the user's input files
    (base / "user").mkdir()
    (base / "user" / "photo.png").write_bytes(_png_bytes(random.Random(0)))
    (base / "user" / "notes.txt").write_text("the user's notes\n")
    (base / "user" / "fr").mkdir()
    (base / "user" / "fr" / "holiday.jpg").write_bytes(os.urandom(300))
    global _warmed
    if not _warmed:
        warm_up(base, work / "warm")
        _warmed = True
    return base


#: imports and compiled kernels last as long as the process: a second fuzz() (the tests
#: run two) has nothing left to warm, and the warm-up was half of its time
_warmed = False


def warm_up(base: Path, folder: Path) -> None:
    """Every command once as this user, in ``folder``: vibr's modules are imported and its
    kernels compiled before a case runs as nobody, who cannot read them where root keeps
    its Python (a lazy import failed there). Once per process (:func:`make_base`)."""
    shutil.copytree(base, folder, symlinks=True)
    here = os.getcwd()
    os.chdir(folder)
    try:
        for argv in (["render", SCENE, "--target", "4", "-o", "o.png", "--uncertainty", "u.png"],
                     ["render", SCENE, "--target", "4", "-o", "o.npy"],
                     ["render", SCENE, "--target", "4", "-o", "o.tif", "--uncertainty", "u.npy"],
                     ["render", SCENE, "--path", "cam.json", "-o", "v.mp4", "--uncertainty", "u.mp4"],
                     ["render", SCENE, "--path", "cam.json", "-o", "v.gif"],
                     ["path", "spiral", SCENE, "-o", "p.json", "--frames", "3"],
                     ["eval", SCENE, "--target", "4", "--method", "gradient", "--gamma", "1", "--json", "r.json"],
                     ["convert", SCENE, "c"], ["depth", SCENE, "-o", "d"], ["depth", "d"]):
            run_vibr(["-q", *argv])
    finally:
        os.chdir(here)
        shutil.rmtree(folder, ignore_errors=True)


# ----------------------------------------------------------------------------- snapshots
def _sha(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def snapshot(root: Path) -> dict:
    """Every entry under ``root`` (links not followed): relative path -> ("file", sha256,
    mode) / ("link", target) / ("dir", mode)."""
    snap = {}
    for d, dirs, files in os.walk(root):
        for name in dirs + files:
            p = os.path.join(d, name)
            rel = os.path.relpath(p, root)
            st = os.lstat(p)
            if stat.S_ISLNK(st.st_mode):
                snap[rel] = ("link", os.readlink(p))
            elif stat.S_ISDIR(st.st_mode):
                snap[rel] = ("dir", stat.S_IMODE(st.st_mode))
            else:
                snap[rel] = ("file", _sha(p), stat.S_IMODE(st.st_mode))
    return snap


# ----------------------------------------------------------------------------- planting
def _remove(p: Path) -> None:
    if p.is_symlink() or p.is_file():
        p.unlink()
    elif p.is_dir():
        shutil.rmtree(p)


def _write(case: Path, rel: str, data: bytes) -> None:
    p = case / rel
    p.parent.mkdir(parents=True, exist_ok=True)
    _remove(p)
    p.write_bytes(data)


def _user_content(rng, rel: str) -> bytes:
    if rel.endswith(".png"):
        return _png_bytes(rng)
    if rel.endswith(".json"):
        return json.dumps({"the user's": rel, "n": rng.randrange(1000)}).encode()
    return os.urandom(rng.randrange(1, 400))


def _forged_marker(rng, names) -> bytes:
    """A ``.vibr-output`` the user made: not JSON, naming other files, or naming the user's
    files without their digest or with a wrong one (a marker giving a user's file its true
    digest is vibr's word that it wrote it: not forged here)."""
    kind = rng.randrange(4)
    if kind == 0:
        return b"not json {"
    if kind == 1:
        return json.dumps({"written_by": "vibr", "files": ["something_else.png"]}).encode()
    files = sorted(set(names))
    doc = {"written_by": "vibr" if kind == 2 else "me", "files": files}
    doc["sha256"] = {Path(n).name: "0" * 64 for n in files}
    return json.dumps(doc).encode()


def _norm(rel: str) -> str:
    return os.path.normpath(rel)


def plant(rng, spec: Spec, case: Path) -> None:
    """Things at and around the outputs ``spec`` names: the user's files, folders, links,
    read-only modes, forged markers; decoys with output-like names elsewhere."""
    ro_dirs = []
    for name, target, p in (("lnk_out.png", _pick(rng, ["user/photo.png", "user/missing.png"]), 0.7),
                            ("lnk_fly.mp4", _pick(rng, ["user/notes.txt", "user/missing.mp4"]), 0.7),
                            ("lnk_p.json", _pick(rng, ["cam.json", "user/notes.txt", "user/missing.json"]), 0.7),
                            ("lnk_frames", _pick(rng, ["user/fr", "user/fr", "user/missing"]), 0.7)):
        # symlinks some commands name as outputs (to the user's files and folders, or to nothing)
        if rng.random() < p and not os.path.lexists(case / name):
            (case / name).symlink_to(target)
    if rng.random() < 0.7:
        (case / "ro").mkdir(exist_ok=True)
        if rng.random() < 0.5:
            _write(case, "ro/keep.txt", b"the user's file in a read-only folder\n")
        ro_dirs.append(case / "ro")
    for rel in map(_norm, spec.files):
        if rel.startswith(SCENE + "/") or (case / rel).is_symlink():
            continue
        parent = (case / rel).parent
        if not parent.exists() and rng.random() < 0.8:
            parent.mkdir(parents=True)
        if not parent.is_dir():
            continue
        r = rng.random()
        if r < 0.3:
            _write(case, rel, _user_content(rng, rel))
        elif r < 0.4:
            _write(case, rel, _user_content(rng, rel))
            (case / rel).chmod(0o444)
        elif r < 0.48:
            _remove(case / rel)
            (case / rel).mkdir()
            _write(case, rel + "/inside.txt", b"the user's file in a folder named as an output\n")
        elif r < 0.55:
            _remove(case / rel)
            (case / rel).symlink_to(os.path.relpath(case / "user" / "notes.txt", parent))
        elif r < 0.6:
            _remove(case / rel)
            (case / rel).symlink_to("a_users_link_to_nothing")
        if rng.random() < 0.2:
            _write(case, str(Path(rel).parent / MARKER), _forged_marker(rng, [Path(rel).name]))
    for rel in map(_norm, spec.frames + spec.folders):
        p = case / rel
        if rel == SCENE or rel.startswith(SCENE + "/images") or p.exists() or p.is_symlink():
            continue
        if not p.parent.is_dir():
            if rng.random() < 0.8:
                p.parent.mkdir(parents=True)
            else:
                continue
        r = rng.random()
        if r < 0.3:
            continue
        if r < 0.36:
            _write(case, rel, b"a file where a folder is expected\n")
            continue
        p.mkdir()
        names = []
        for name, data in (("frame_00002.png", _png_bytes(rng)), ("notes.txt", b"keep me\n"),
                           ("deep/x.txt", b"nested\n"), ("frame_00000.png", _png_bytes(rng)),
                           ("transforms.json", b"{}"), ("sigma_00001.npz", os.urandom(64))):
            if rng.random() < 0.4:
                _write(case, f"{rel}/{name}", data)
                names.append(name)
                if rng.random() < 0.2:
                    (p / name).chmod(0o444)
        if rng.random() < 0.2:
            (p / "frame_00001.png").symlink_to(os.path.relpath(case / "user" / "photo.png", p))
        if rng.random() < 0.3:
            _write(case, f"{rel}/{MARKER}", _forged_marker(rng, names or ["frame_00002.png"]))
        if rng.random() < 0.15:
            ro_dirs.append(p)
    if rng.random() < (0.5 if spec.in_place else 0.2):  # the user's files in the scene folder
        names = ["notes.txt", "calibration.json", "images/extra.png", "depth/readme.txt", "sub/x.txt", "out.png"]
        for name in rng.sample(names, rng.randint(1, 2)):
            _write(case, f"{SCENE}/{name}", _user_content(rng, name))
    for rel in ("frame_00002.png", "out.png", "p.json", "report.json", "fly.mp4", "fly_frames/frame_00002.png",
                "sub/out.png", "frames/notes.txt", "a/b/keep.txt", "conv/notes.txt"):
        if rng.random() < 0.15 and not (case / rel).exists() and not (case / rel).is_symlink():
            with contextlib.suppress(OSError):
                _write(case, rel, _user_content(rng, rel))
    if rng.random() < 0.15:
        _write(case, MARKER, _forged_marker(rng, ["out.png", "p.json", "report.json", "fly.mp4"]))
    if spec.as_nobody:
        for d, dirs, files in os.walk(case):
            for n in [*dirs, *files, None]:
                os.chown(os.path.join(d, n) if n else d, NOBODY, NOBODY, follow_symlinks=False)
    for d in ro_dirs:
        if d.is_dir() and not d.is_symlink():
            d.chmod(0o555)


def prior_run(rng, spec: Spec) -> list:
    """The argv of a vibr run before the case's (a render, a fly-through, a convert), so that
    the case meets outputs vibr wrote."""
    argv = [a for a in spec.argv if a != "--overwrite"]
    if spec.family in ("render-path-dir", "render-path-video") and rng.random() < 0.5:
        argv = [("cam2.json" if a == "cam.json" else a) for a in argv]  # other frames: other keys
    if spec.in_place:
        argv = ["-q", "render", SCENE, "--target", "3", "-o", f"{SCENE}/out.png"]
    return argv


# ----------------------------------------------------------------------------- the oracle
def _inside(rel: str, folder: str) -> bool:
    return rel == folder or rel.startswith(folder + "/")


def _real(case: Path, rel: str, follow_last: bool) -> str | None:
    """``rel`` with its links resolved (the last one only with ``follow_last``), relative to
    ``case``; None outside it."""
    p = case / rel
    r = p.resolve() if follow_last else p.parent.resolve() / p.name
    try:
        return str(r.relative_to(case.resolve()))
    except ValueError:
        return None


@dataclass
class Areas:
    files: set
    frames: set
    folders: set
    marker_dirs: set
    listed: dict  # folder output -> the files its marker listed before the run


def marker_lists(folder: Path) -> set:
    """The files a folder's marker lists (the documented format: a JSON object whose
    ``written_by`` is ``"vibr"`` and whose ``files`` is a list); none without one. Files so
    listed are vibr's by the folder rule, whoever wrote the marker."""
    try:
        doc = json.loads((folder / MARKER).read_text())
        return {str(f) for f in doc["files"]} if doc.get("written_by") == "vibr" and isinstance(
            doc["files"], list) else set()
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return set()


def areas(spec: Spec, case: Path) -> Areas:
    files = {r for r in (_real(case, f, False) for f in spec.files) if r}
    frames = {r for r in (_real(case, f, True) for f in spec.frames) if r}
    folders = {r for r in (_real(case, f, False) for f in spec.folders) if r}
    marker_dirs = {os.path.dirname(f) or "." for f in files} | frames | folders
    if spec.in_place:
        marker_dirs.add(SCENE)
    return Areas(files, frames, folders, marker_dirs, {f: marker_lists(case / f) for f in folders})


def _scene_written(rel: str) -> bool:
    """A file ``vibr depth SCENE`` writes in place."""
    return rel in (f"{SCENE}/transforms.json", f"{SCENE}/{MARKER}") or any(
        _inside(rel, f"{SCENE}/{d}") and rel != f"{SCENE}/{d}" for d in ("images", "depth", "sigma_z"))


def may_change(rel, before, spec: Spec, a: Areas, vibr_files: dict, scene_files: set) -> bool:
    """Whether the pre-existing entry ``rel`` may change or go in this case."""
    owned = before[0] == "file" and vibr_files.get(rel) == before[1]
    if os.path.basename(rel) == MARKER:
        return (os.path.dirname(rel) or ".") in a.marker_dirs or any(_inside(rel, f) for f in a.folders)
    if spec.in_place and _inside(rel, SCENE):
        return (owned or before[0] == "dir") and _scene_written(rel) and rel not in (
            f"{SCENE}/images", f"{SCENE}/depth")
    if rel in scene_files:
        return False
    if rel in a.files:
        return spec.overwrite or owned
    for fd in a.frames:
        if os.path.dirname(rel) == fd and (owned or (spec.overwrite and any(
                fnmatch.fnmatch(os.path.basename(rel), g) for g in FRAME_GLOBS))):
            return True
    for fo in a.folders:  # a folder vibr wrote is replaced whole: its marker lists names, not contents
        if _inside(rel, fo) and spec.overwrite and (rel in vibr_files or os.path.relpath(rel, fo) in a.listed[fo]
                                                    or before[0] == "dir"):  # a folder goes with its files
            return True
    return False


def may_appear(rel, ok: bool, spec: Spec, a: Areas) -> bool:
    """Whether the new entry ``rel`` may be there after the case (``ok``: it succeeded)."""
    name = os.path.basename(rel)
    if name == MARKER and ((os.path.dirname(rel) or ".") in a.marker_dirs):
        return True
    if rel in a.files:
        return ok
    for fd in a.frames:
        if rel == fd or (os.path.dirname(rel) == fd and any(fnmatch.fnmatch(name, g) for g in FRAME_GLOBS)):
            return True
        if _inside(fd, rel):  # a parent folder of the frames folder it created
            return True
    for fo in a.folders:
        if _inside(rel, fo) or _inside(fo, rel):
            return ok
        if not ok and _inside(rel, str(Path(fo).parent / f".{Path(fo).name}.vibr-resume")):
            return True  # a depth job's sweeps, kept for a rerun
    if spec.in_place:
        if _inside(rel, SCENE) and _scene_written(rel) or rel in (f"{SCENE}/sigma_z",):
            return ok
        if not ok and _inside(rel, f".{SCENE}.vibr-resume"):
            return True
    return False


#: the first bytes of each output format, by extension ("": vibr writes a PNG)
_MAGIC = {".png": [b"\x89PNG"], "": [b"\x89PNG"], ".tif": [b"II*\0", b"MM\0*"], ".npy": [b"\x93NUMPY"],
          ".gif": [b"GIF8"]}


def _holds_its_format(path: Path) -> bool:
    """Whether the output file ``path`` holds what its extension says (a report, not a
    marker written over it)."""
    data = path.read_bytes()
    ext = os.path.splitext(path.name)[1].lower() if not path.name.startswith(".") or path.name.count(".") > 1 else ""
    if ext == ".json":
        try:
            return "written_by" not in json.loads(data)
        except ValueError:
            return False
    if ext == ".mp4":
        return data[4:8] == b"ftyp"
    return any(data.startswith(m) for m in _MAGIC.get(ext, [b""]))


def check_case(spec: Spec, run: Run, before: dict, after: dict, a: Areas, case: Path, vibr_files: dict,
               scene_files: set) -> list:
    """The problems of one case (an empty list when it passed); ``a``: its output areas,
    taken before the run."""
    problems = []
    if run.exc:
        problems.append("traceback: " + run.exc.strip().splitlines()[-1])
    elif run.rc not in (0, 2, 130):
        problems.append(f"exit status {run.rc!r}")
    lines = [ln for ln in run.err.splitlines() if ln.strip()]
    if run.rc == 2:
        errors = [ln for ln in lines if ": error:" in ln]
        if len(errors) != 1:
            problems.append(f"exit 2 with {len(errors)} error lines: {run.err.strip()[-300:]!r}")
        if spec.family == "full-disk" and len(lines) != 1:
            problems.append(f"full disk: {len(lines)} lines on stderr: {run.err.strip()[-300:]!r}")
    if "Traceback" in run.err or "Traceback" in run.out:
        problems.append("a traceback printed")
    ok = run.rc == 0
    for rel, b in sorted(before.items()):
        now = after.get(rel)
        if now == b or may_change(rel, b, spec, a, vibr_files, scene_files):
            continue
        owner = "vibr's" if rel in vibr_files and vibr_files[rel] == (b[1] if b[0] == "file" else None) else "user's"
        what = "lost" if now is None else "changed" if now[0] == b[0] else f"became a {now[0]}"
        problems.append(f"{owner} {b[0]} {rel} {what}")
    for rel in sorted(set(after) - set(before)):
        if not may_appear(rel, ok, spec, a):
            problems.append(f"{'partial output' if not ok and _names_output(rel, a) else 'stray new'} "
                            f"{after[rel][0]} {rel}")
    if ok:
        for f in a.files:
            if after.get(f, ("?",))[0] != "file":
                problems.append(f"exit 0 but {f} is not a file")
            elif not _holds_its_format(case / f):
                problems.append(f"exit 0 but {f} does not hold what its name says")
        for fd in a.frames:
            if f"{fd}/frame_00000.png" not in after:
                problems.append(f"exit 0 but no frames in {fd}")
        for fo in a.folders:
            if f"{fo}/transforms.json" not in after:
                problems.append(f"exit 0 but no {fo}/transforms.json")
    return problems


def _names_output(rel, a: Areas) -> bool:
    return rel in a.files or any(_inside(rel, f) for f in a.folders | a.frames)


# ----------------------------------------------------------------------------- the cases
@dataclass
class Result:
    index: int
    spec: Spec
    problems: list
    rc: object
    seconds: float
    err: str = ""


def _clear(folder: Path) -> None:
    for p in list(folder.iterdir()):
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink()


def _fill(folder: Path, leave: int) -> None:
    """A user's file filling the file system of ``folder`` but ``leave`` bytes."""
    st = os.statvfs(folder)
    free = st.f_bavail * st.f_frsize
    with open(folder / "user" / "filler.bin", "wb") as f:
        f.write(b"\0" * max(0, free - leave - 8192))


def run_case(i: int, seed: int, family: str, base: Path, work: Path, disk: Path | None,
             keep: Path | None = None) -> Result:
    rng = random.Random(f"{seed}:{i}")
    spec = draw_spec(rng, family)
    if family == "full-disk":
        _clear(disk)
        case = disk / "c"
    else:
        case = work / "cases" / f"c{i}"
    shutil.copytree(base, case, symlinks=True)
    scene_files = {f"{SCENE}/{p.relative_to(case / SCENE).as_posix()}" for p in (case / SCENE).rglob("*")
                   if p.is_file() and p.name != MARKER}
    vibr_files = {rel: e[1] for rel, e in snapshot(case).items() if e[0] == "file" and rel in scene_files}
    vibr_files.update({rel: None for rel in ("s", "s/images", "s/depth")})  # folders vibr wrote
    here = os.getcwd()
    os.chdir(case)
    try:
        if rng.random() < 0.35:  # outputs of an earlier vibr run, some edited by the user since
            pre = snapshot(case)
            run_vibr(prior_run(rng, spec))
            post = snapshot(case)
            for rel, e in post.items():
                if rel not in pre or pre[rel] != e:
                    vibr_files[rel] = e[1] if e[0] == "file" else None
            mine = [rel for rel, e in post.items() if e[0] == "file" and rel not in pre
                    and os.path.basename(rel) != MARKER]
            if mine and rng.random() < 0.3:
                edited = _pick(rng, sorted(mine))
                if any(fnmatch.fnmatch(os.path.basename(edited), g) for g in FRAME_GLOBS):
                    # a frame is vibr's by the key in it (docs/reference/errors-and-limits.md): the
                    # user's frame is one without it
                    _write(case, edited, _png_bytes(rng) if edited.endswith(".png") else os.urandom(64))
                else:  # a single file is vibr's while its content is the one vibr recorded
                    with open(edited, "ab") as f:
                        f.write(b"the user's edit")
        plant(rng, spec, case)
        if family == "full-disk":
            _fill(case, _pick(rng, [0, 4096, 8192, 16384, 32768, 65536, 131072, 262144, 524288]))
        before, a = snapshot(case), areas(spec, case)
        t0 = time.perf_counter()
        run = run_vibr(spec.argv, spec.as_nobody)
        seconds = time.perf_counter() - t0
        after = snapshot(case)
        problems = check_case(spec, run, before, after, a, case, vibr_files, scene_files)
    finally:
        os.chdir(here)
    if keep is not None:
        shutil.copytree(case, keep, symlinks=True, dirs_exist_ok=True)
        print(f"case {i}: {spec.line()}{' (as nobody)' if spec.as_nobody else ''}\n  exit {run.rc}\n"
              f"  stdout: {run.out.strip()!r}\n  stderr: {run.err.strip()!r}\n{run.exc}"
              f"  kept in {keep}")
    shutil.rmtree(case, ignore_errors=True)
    return Result(i, spec, problems, run.rc, seconds, run.err)


@contextlib.contextmanager
def small_disk(work: Path, size: str = "2m"):
    """A tmpfs of ``size`` mounted in ``work`` (None when mounting is not permitted)."""
    d = work / "disk"
    d.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(d)], capture_output=True,
                       text=True)
    if r.returncode != 0:
        yield None, (r.stderr.strip() or f"mount exited {r.returncode}")
        return
    try:
        yield d, None
    finally:
        subprocess.run(["umount", str(d)], capture_output=True)


def fuzz(cases: int, seed: int = 0, families=None, only=None, keep=None, progress=None) -> tuple[list, str | None]:
    """Run ``cases`` cases (or case ``only``); returns the results and why the full-disk
    family was left out (None when it ran)."""
    families = list(families or FAMILIES)
    work = Path(tempfile.mkdtemp(prefix="vibr-fuzz-outputs-"))
    work.chmod(0o755)  # the cases run as nobody walk through it
    old_cache = os.environ.get("VIBR_CACHE_DIR")
    os.environ["VIBR_CACHE_DIR"] = str(work / "cache")  # never the user's cache
    (work / "cache").mkdir(mode=0o777)
    (work / "cache").chmod(0o777)
    (work / "cases").mkdir()
    (work / "cases").chmod(0o755)
    results, skipped = [], None
    # each case's gc.collect() then walks only what was made since: in a test session's heap a
    # full walk cost more than many a case
    gc.collect()
    gc.freeze()
    try:
        base = make_base(work)
        with small_disk(work) if "full-disk" in families and os.geteuid() == 0 else \
                contextlib.nullcontext((None, "not root")) as (disk, why):
            if disk is None and "full-disk" in families:
                skipped = f"full-disk family left out: cannot mount a tmpfs ({why})"
                families.remove("full-disk")
            if os.geteuid() != 0:
                print("fuzz_outputs: not root: every case runs as this user (no nobody cases)", file=sys.stderr)
            if disk is not None:
                disk.chmod(0o755)
            draw = random.Random(seed)
            order = [draw.choices(families, [WEIGHTS[f] for f in families])[0] for _ in range(cases)]
            for i, family in enumerate(order):
                if only is not None and i != only:
                    continue
                r = run_case(i, seed, family, base, work, disk, keep)
                results.append(r)
                if progress:
                    progress(r)
    finally:
        gc.unfreeze()
        if old_cache is None:
            os.environ.pop("VIBR_CACHE_DIR", None)
        else:
            os.environ["VIBR_CACHE_DIR"] = old_cache
        shutil.rmtree(work, ignore_errors=True)
    return results, skipped


def summary(results, skipped) -> str:
    rows = ["family                 cases  passed  failures  first failing command",
            "-" * 100]
    for fam in FAMILIES:
        rs = [r for r in results if r.spec.family == fam]
        if not rs:
            continue
        bad = [r for r in rs if r.problems]
        first = f"#{bad[0].index} {bad[0].spec.line()}" if bad else ""
        rows.append(f"{fam:<22} {len(rs):>5} {len(rs) - len(bad):>7} {len(bad):>9}  {first}")
    bad = [r for r in results if r.problems]
    rows.append("-" * 100)
    rows.append(f"{'all':<22} {len(results):>5} {len(results) - len(bad):>7} {len(bad):>9}")
    if skipped:
        rows.append(skipped)
    for r in bad[:10]:
        who = " (as nobody)" if r.spec.as_nobody else ""
        rows.append(f"\ncase {r.index}: {r.spec.line()}{who} -> exit {r.rc}")
        rows += [f"  {p}" for p in r.problems[:8]]
    return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", type=int, default=500, help="number of cases (default 500)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the draw (default 0): the same cases every run")
    ap.add_argument("--families", default=None, help=f"comma-separated families (default all: {','.join(FAMILIES)})")
    ap.add_argument("--case", type=int, default=None, help="run only case N of the draw and print its output")
    ap.add_argument("--keep", type=Path, default=None, help="with --case: copy the case folder here after the run")
    args = ap.parse_args(argv)
    families = args.families.split(",") if args.families else None
    if families and set(families) - set(FAMILIES):
        ap.error(f"unknown families {sorted(set(families) - set(FAMILIES))}; choose among {', '.join(FAMILIES)}")
    t0 = time.perf_counter()

    def tick(r):
        if r.problems or (r.index + 1) % 50 == 0:
            print(f"  case {r.index}: {'FAIL' if r.problems else 'ok'} {r.spec.line()}", file=sys.stderr, flush=True)

    results, skipped = fuzz(args.cases, args.seed, families, args.case, args.keep, tick)
    print(f"fuzz_outputs: {len(results)} cases, seed {args.seed}, {time.perf_counter() - t0:.0f} s")
    print(summary(results, skipped))
    return 1 if any(r.problems for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
