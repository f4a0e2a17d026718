"""Property-based fuzzing of vibr's loaders, shared by tests/test_fuzz_loaders.py
(fast profile, part of ``pytest -q``) and benchmarks/tools/fuzz_long.py (long profile).

Each *seed* writes a small valid input (a scene folder or one file). A hypothesis strategy
draws a mutation of one of its files: truncation at an offset of some class (0, 1, a word
boundary ± 1, the middle, the end − 1, anywhere), byte flips, a huge or negative count
written over 4 or 8 bytes, junk appended, and for structured files a token or JSON value
replaced by a wrong type, NaN/inf, a huge or negative number, a path outside the folder, or a
line deleted/duplicated; images and depth arrays are also replaced by valid files of the
wrong size, type or shape. The property (:func:`run_case`): the loader returns a valid result
(finite cameras, images in [0, 1], depth NaN or > 0) or raises
:class:`vibr.errors.VibrInputError`; never another exception, never longer than the time
budget, never more memory than the budget. Each case runs in a forked child with
``RLIMIT_AS`` (address space) set to what the parent maps plus the memory budget, and is
killed at the time budget.
"""

from __future__ import annotations

import json
import logging
import os
import pickle
import re
import resource
import select
import shutil
import signal
import struct
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from hypothesis import strategies as st

from vibr.errors import VibrInputError

# ----------------------------------------------------------------------------- seeds
W, H = 12, 8


def _img(path, w=W, h=H, seed=0, bits=None):
    from vibr.io.images import write_image

    rng = np.random.default_rng(seed)
    write_image(path, (rng.integers(0, 256, (h, w, 3)) / 255).astype(np.float32), bits=bits)


def _seed_transforms(d: Path):
    from vibr.io.transforms import write_ply_points

    (d / "images").mkdir()
    (d / "depth").mkdir()
    frames = []
    for i in range(2):
        _img(d / "images" / f"v{i}.png", seed=i)
        np.save(d / "depth" / f"v{i}.npy", np.full((H, W), 2.0 + i, np.float32))
        M = np.eye(4)
        M[0, 3] = 0.1 * i
        frames.append({"file_path": f"images/v{i}.png", "transform_matrix": M.tolist(),
                       "depth_file_path": f"depth/v{i}.npy", "depth_unit_scale_factor": 1.0,
                       "sigma_z": 0.01, "vibr_grid_pos": [0, i]})
    write_ply_points(d / "sparse_pc.ply", np.array([[0, 0, 2.0], [0.1, 0.1, 2.5]]))
    doc = {"camera_model": "OPENCV", "fl_x": 10.0, "fl_y": 10.0, "cx": 6.0, "cy": 4.0, "w": W, "h": H,
           "vibr_grid": [1, 2], "ply_file_path": "sparse_pc.ply", "frames": frames}
    (d / "transforms.json").write_text(json.dumps(doc, indent=1))


_CFG = """[intrinsics]
focal_length_mm = 100.0
image_resolution_x_px = {w}
image_resolution_y_px = {h}
sensor_size_mm = 35.0

[extrinsics]
num_cams_x = 3
num_cams_y = 3
baseline_mm = 25.0
focus_distance_m = 4.25
center_cam_x_m = -2.4
center_cam_rx_rad = 1.3
"""


def _seed_hci(d: Path, cfg: bool):
    from vibr.io.depthfiles import write_pfm

    for i in (0, 1, 3, 4, 5, 7):
        _img(d / f"input_Cam{i:03d}.png", seed=i)
    write_pfm(d / "gt_disp_lowres.pfm", np.linspace(-0.1, 0.1, W * H, dtype=np.float32).reshape(H, W))
    if cfg:
        (d / "parameters.cfg").write_text(_CFG.format(w=W, h=H))


def _seed_strecha(d: Path):
    (d / "images").mkdir()
    (d / "gt_dense_cameras").mkdir()
    for i in range(2):
        _img(d / "images" / f"000{i}.png", seed=i)
        (d / "gt_dense_cameras" / f"000{i}.png.camera").write_text(
            f"10 0 6\n0 10 4\n0 0 1\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n{0.1 * i} 0 0\n{W} {H}\n")


def _seed_middlebury(d: Path):
    lines = ["2"]
    for i in range(2):
        _img(d / f"t{i}.png", seed=i)
        lines.append(f"t{i}.png 10 0 6 0 10 4 0 0 1 1 0 0 0 1 0 0 0 1 {0.1 * i} 0 1")
    (d / "t_par.txt").write_text("\n".join(lines) + "\n")


def _seed_colmap(d: Path, text: bool):
    from _colmap_model import write_colmap_model

    write_colmap_model(d, text=text, size=(W, H))


def _seed_depth(d: Path, ext: str):
    from vibr.io import write_depth

    a = np.linspace(0.5, 3, W * H, dtype=np.float32).reshape(H, W)
    a[0, 0] = np.nan
    write_depth(d / f"depth{ext}", a, scale=1e-3 if ext == ".png" else None)


def _seed_camera(d: Path):
    from vibr.camera import Camera
    from vibr.io import write_camera_json

    write_camera_json(d / "cam.json", Camera(np.array([[10, 0, 6], [0, 10, 4], [0, 0, 1.0]]), np.eye(3),
                                             np.zeros(3), W, H))


def _load_scene(d: Path):
    from vibr.io import load_scene

    return load_scene(d)


def _load_depth(name, scale=None):
    def f(d: Path):
        from vibr.io import read_depth

        return read_depth(d / name, scale, shape=(H, W))
    return f


def _load_camera(d: Path):
    from vibr.io import read_camera_json

    return read_camera_json(d / "cam.json")


@dataclass
class Seed:
    name: str
    build: Callable[[Path], None]
    load: Callable[[Path], object]
    files: dict = field(default_factory=dict)  # relative path -> kind (json, text, binary, png, npy)


def _colmap_files(text: bool) -> dict:
    ext = "txt" if text else "bin"
    kind = "text" if text else "binary"
    out = {f"sparse/0/{n}.{ext}": kind for n in ("cameras", "images", "points3D", "frames", "rigs")}
    out["images/im1.png"] = "png"
    return out


SEEDS = {s.name: s for s in [
    Seed("transforms", _seed_transforms, _load_scene,
         {"transforms.json": "json", "images/v0.png": "png", "depth/v1.npy": "npy", "sparse_pc.ply": "binary"}),
    Seed("hci_cfg", lambda d: _seed_hci(d, True), _load_scene,
         {"parameters.cfg": "text", "gt_disp_lowres.pfm": "binary", "input_Cam004.png": "png"}),
    Seed("hci_nocfg", lambda d: _seed_hci(d, False), _load_scene,
         {"gt_disp_lowres.pfm": "binary", "input_Cam004.png": "png", "input_Cam000.png": "png"}),
    Seed("strecha", _seed_strecha, _load_scene,
         {"gt_dense_cameras/0000.png.camera": "text", "gt_dense_cameras/0001.png.camera": "text",
          "images/0001.png": "png"}),
    Seed("middlebury", _seed_middlebury, _load_scene, {"t_par.txt": "text", "t0.png": "png"}),
    Seed("colmap_bin", lambda d: _seed_colmap(d, False), _load_scene, _colmap_files(False)),
    Seed("colmap_txt", lambda d: _seed_colmap(d, True), _load_scene, _colmap_files(True)),
    Seed("depth_pfm", lambda d: _seed_depth(d, ".pfm"), _load_depth("depth.pfm"), {"depth.pfm": "binary"}),
    Seed("depth_npy", lambda d: _seed_depth(d, ".npy"), _load_depth("depth.npy"), {"depth.npy": "npy"}),
    Seed("depth_png16", lambda d: _seed_depth(d, ".png"), _load_depth("depth.png", 1e-3),
         {"depth.png": "png16"}),
    Seed("camera_json", _seed_camera, _load_camera, {"cam.json": "json"}),
]}


def add_camera_path_seed() -> bool:
    """Add developer B's camera_path.json loader (vibr.paths.camera_path.read_camera_path) when present."""
    try:
        from vibr.paths.camera_path import read_camera_path, write_camera_path
    except ImportError:
        return False

    def build(d: Path):
        from vibr.camera import Camera

        K = np.array([[10, 0, (W - 1) / 2], [0, 10, (H - 1) / 2], [0, 0, 1.0]])  # a centred pinhole
        cams = [Camera(K, np.eye(3), np.array([0.1 * i, 0, 0]), W, H) for i in range(3)]
        write_camera_path(d / "camera_path.json", cams, fps=24.0)

    def load(d: Path):
        return read_camera_path(d / "camera_path.json")

    SEEDS["camera_path"] = Seed("camera_path", build, load, {"camera_path.json": "json"})
    return True


def build_seed(seed: Seed, folder: Path) -> Path:
    """Write the seed's valid files into ``folder`` (made) and check that they load."""
    logging.getLogger("vibr").setLevel(logging.WARNING)  # no status lines from the loaders
    folder.mkdir(parents=True, exist_ok=True)
    seed.build(folder)
    check_result(seed.load(folder))
    return folder


# ----------------------------------------------------------------------------- mutations
_BAD_VALUES = [None, "x", "", [], {}, [[]], float("nan"), float("inf"), -float("inf"), -1, 0, 1e308,
               -1e308, 2**63, 2**31, 10**30, True, "../../../etc/passwd", "/etc/passwd", [1, 2, 3],
               [[1, 0], [0, 1]], [[float("nan")] * 4] * 4, "NaN", 1e-300]
_BAD_TOKENS = ["nan", "inf", "-inf", "-1", "0", "1e308", "-1e308", "99999999999999999999", "4294967296",
               "abc", "", "1.5", "0x10", "CAMERA", "PINHOLE", "\x00", "1e-320", "18446744073709551615"]
_HUGE = [0xFFFFFFFF, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFFFFFFFFFF, 2**40, 2**32, 1 << 62, 1000000]


def _offset(data: st.DataObject, n: int) -> int:
    cls = data.draw(st.sampled_from(["zero", "one", "word", "middle", "end", "any"]), "offset class")
    if n == 0:
        return 0
    if cls == "zero":
        return 0
    if cls == "one":
        return min(1, n)
    if cls == "word":
        w = data.draw(st.sampled_from([4, 8]))
        k = data.draw(st.integers(0, max(0, n // w)))
        return int(np.clip(k * w + data.draw(st.integers(-1, 1)), 0, n))
    if cls == "middle":
        return n // 2
    if cls == "end":
        return max(0, n - 1)
    return data.draw(st.integers(0, n))


def _mutate_bytes(data, raw: bytes) -> bytes:
    kind = data.draw(st.sampled_from(["truncate", "flip", "huge", "append", "zero_run"]), "byte mutation")
    b = bytearray(raw)
    if kind == "truncate":
        return bytes(b[:_offset(data, len(b))])
    if kind == "flip":
        for _ in range(data.draw(st.integers(1, 8))):
            if b:
                i = _offset(data, len(b) - 1)
                b[i] ^= data.draw(st.integers(1, 255))
        return bytes(b)
    if kind == "huge":
        v = data.draw(st.sampled_from(_HUGE))
        size = data.draw(st.sampled_from([4, 8]))
        i = _offset(data, max(0, len(b) - size))
        b[i:i + size] = struct.pack("<Q", v & 0xFFFFFFFFFFFFFFFF)[:size]
        return bytes(b)
    if kind == "zero_run":
        i = _offset(data, len(b))
        n = data.draw(st.integers(1, 64))
        b[i:i + n] = bytes(min(n, max(0, len(b) - i)))
        return bytes(b)
    return bytes(b) + data.draw(st.binary(min_size=1, max_size=64))


def _json_paths(x, prefix=()):
    yield prefix
    if isinstance(x, dict):
        for k, v in x.items():
            yield from _json_paths(v, prefix + (k,))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from _json_paths(v, prefix + (i,))


def _mutate_json(data, raw: bytes) -> bytes:
    doc = json.loads(raw)
    paths = [p for p in _json_paths(doc) if p]
    p = data.draw(st.sampled_from(paths), "json path")
    parent = doc
    for k in p[:-1]:
        parent = parent[k]
    action = data.draw(st.sampled_from(["replace", "delete", "deep"]))
    if action == "delete":
        del parent[p[-1]]
    elif action == "deep":
        v = 0
        for _ in range(data.draw(st.integers(1, 200))):
            v = [v]
        parent[p[-1]] = v
    else:
        parent[p[-1]] = data.draw(st.sampled_from(_BAD_VALUES), "json value")
    return json.dumps(doc, allow_nan=True).encode()


_TOKEN = re.compile(rb"[^\s]+")


def _mutate_text(data, raw: bytes) -> bytes:
    lines = raw.split(b"\n")
    action = data.draw(st.sampled_from(["token", "token", "delete_line", "dup_line", "insert_token"]))
    li = data.draw(st.integers(0, max(0, len(lines) - 1)), "line")
    if action == "delete_line":
        del lines[li]
    elif action == "dup_line":
        lines.insert(li, lines[li])
    else:
        toks = list(_TOKEN.finditer(lines[li]))
        new = data.draw(st.sampled_from(_BAD_TOKENS)).encode()
        if not toks:
            lines[li] = new
        else:
            m = toks[data.draw(st.integers(0, len(toks) - 1))]
            s = lines[li]
            if action == "insert_token":
                lines[li] = s[:m.end()] + b" " + new + s[m.end():]
            else:
                lines[li] = s[:m.start()] + new + s[m.end():]
    return b"\n".join(lines)


def _mutate_png(data, path: Path, bits16: bool = False) -> None:
    from vibr.io.images import write_image

    kind = data.draw(st.sampled_from(["size", "grey", "rgba", "bits", "bytes"]))
    w, h = data.draw(st.sampled_from([(1, 1), (W + 1, H), (W, H - 1), (2 * W, 2 * H), (H, W)]))
    if kind == "bytes":
        path.write_bytes(_mutate_bytes(data, path.read_bytes()))
        return
    import imageio.v3 as iio

    rng = np.random.default_rng(0)
    if kind == "size":
        if bits16:
            iio.imwrite(path, rng.integers(1, 65535, (h, w)).astype(np.uint16))
        else:
            write_image(path, rng.random((h, w, 3)).astype(np.float32))
    elif kind == "grey":
        iio.imwrite(path, rng.integers(0, 255, (H, W)).astype(np.uint8))
    elif kind == "rgba":
        iio.imwrite(path, rng.integers(0, 255, (H, W, 4)).astype(np.uint8))
    else:
        write_image(path, rng.random((H, W, 3)).astype(np.float32), bits=16)


def _mutate_npy(data, path: Path) -> None:
    kind = data.draw(st.sampled_from(["shape", "dtype", "values", "object", "bytes"]))
    if kind == "bytes":
        path.write_bytes(_mutate_bytes(data, path.read_bytes()))
        return
    if kind == "shape":
        shp = data.draw(st.sampled_from([(H, W, 3), (H + 1, W), (W, H), (0,), (), (H * W,), (0, 0), (1, H, W)]))
        np.save(path, np.ones(shp, np.float32))
    elif kind == "dtype":
        dt = data.draw(st.sampled_from(["int64", "uint8", "complex64", "bool", "float16", "U3", "<M8[s]"]))
        np.save(path, np.ones((H, W)).astype(dt))
    elif kind == "values":
        v = data.draw(st.sampled_from([np.nan, np.inf, -np.inf, -1.0, 0.0, 1e38, 1e-45]))
        a = np.ones((H, W), np.float32)
        a[data.draw(st.integers(0, H - 1)), :] = v
        np.save(path, a)
    else:
        np.save(path, np.array([{"a": 1}], dtype=object), allow_pickle=True)


def mutate(data: st.DataObject, seed: Seed, folder: Path) -> str:
    """Apply one drawn mutation to one of the seed's files in ``folder``; returns a label."""
    rel = data.draw(st.sampled_from(sorted(seed.files)), "file")
    kind = seed.files[rel]
    p = folder / rel
    if not p.exists():
        return f"{rel}: absent"
    if data.draw(st.integers(0, 19), "remove?") == 0:
        p.unlink()
        return f"{rel}: removed"
    if kind == "png" or kind == "png16":
        _mutate_png(data, p, kind == "png16")
    elif kind == "npy":
        _mutate_npy(data, p)
    else:
        raw = p.read_bytes()
        how = data.draw(st.sampled_from(["structure", "structure", "bytes"]), "structured?")
        if how == "bytes" or kind == "binary":
            new = _mutate_bytes(data, raw)
        elif kind == "json":
            new = _mutate_json(data, raw)
        else:
            new = _mutate_text(data, raw)
        p.write_bytes(new)
    return f"{rel} ({kind})"


# ----------------------------------------------------------------------------- the property
def check_result(x) -> None:
    """A loader's result must be valid: raise AssertionError (not VibrInputError) otherwise."""
    from vibr.camera import Camera
    from vibr.scene import Scene

    def cam_ok(c: Camera):
        assert c.width >= 1 and c.height >= 1
        for a in (c.K, c.R, c.t):
            assert np.all(np.isfinite(a)), "non-finite camera"
        assert abs(np.linalg.det(c.R) - 1) < 1e-6, "R is not a rotation"
        assert c.K[0, 0] > 0 and c.K[1, 1] > 0, "focal length <= 0"

    if isinstance(x, Scene):
        assert len(x.views) >= 1
        for v in x.views:
            cam_ok(v.camera)
            if v.image is not None:
                assert v.image.shape == (v.camera.height, v.camera.width, 3)
                assert np.all(np.isfinite(v.image)) and v.image.min() >= 0 and v.image.max() <= 1
            if v.depth is not None:
                d = v.depth[np.isfinite(v.depth)]
                assert v.depth.shape == v.camera.shape and np.all(d > 0) and not np.any(np.isinf(v.depth))
            if v.sigma_z is not None:
                s = np.asarray(v.sigma_z)
                assert np.all(np.isfinite(s)) and np.all(s >= 0)
        if x.points is not None:
            assert np.all(np.isfinite(x.points))
    elif isinstance(x, Camera):
        cam_ok(x)
    elif isinstance(x, np.ndarray):
        assert x.dtype == np.float32 and x.shape == (H, W)
        assert not np.any(np.isinf(x)) and np.all(x[np.isfinite(x)] > 0)
    elif hasattr(x, "cameras"):  # a CameraPath
        assert len(x.cameras) >= 1
        for c in x.cameras:
            cam_ok(c)
    else:
        raise AssertionError(f"unexpected result type {type(x).__name__}")


@dataclass
class Outcome:
    status: str  # ok | vibr_error | unexpected | invalid | timeout | crashed
    message: str
    seconds: float
    mem_bytes: int  # the child's peak resident memory above its resident memory at the start

    @property
    def passed(self) -> bool:
        return self.status in ("ok", "vibr_error")


def _rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _vm_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")


def _child(fn, folder, mem_budget, w):
    logging.getLogger("vibr").setLevel(logging.WARNING)  # no status lines from the loaders
    status, msg = "ok", ""
    rss0 = _rss_bytes()
    try:
        resource.setrlimit(resource.RLIMIT_AS, (_vm_bytes() + mem_budget, resource.RLIM_INFINITY))
        check_result(fn(folder))
    except VibrInputError as exc:
        status, msg = "vibr_error", str(exc)
        if "\n" in msg or "Traceback" in msg:
            status = "unexpected"
    except AssertionError as exc:
        status, msg = "invalid", f"invalid result: {exc}"
    except BaseException as exc:  # noqa: BLE001 - the property: nothing else escapes
        status, msg = "unexpected", "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))[-3000:]
    grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - rss0
    os.write(w, pickle.dumps((status, msg, grown)))


def run_case(fn, folder: Path, *, time_budget: float = 10.0, mem_budget: int = 2 << 30) -> Outcome:
    """Run ``fn(folder)`` in a forked child under the budgets; see the module docstring."""
    r, w = os.pipe()
    rss0 = _rss_bytes()
    t0 = time.perf_counter()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - child
        try:
            os.close(r)
            _child(fn, folder, mem_budget, w)
        finally:
            os._exit(0)
    os.close(w)
    chunks, timed_out = [], False
    while True:
        left = time_budget - (time.perf_counter() - t0)
        if left <= 0:
            timed_out = True
            break
        ready, _, _ = select.select([r], [], [], left)
        if ready:
            b = os.read(r, 1 << 16)
            if not b:
                break
            chunks.append(b)
    if timed_out:
        os.kill(pid, signal.SIGKILL)
    _, status, ru = os.wait4(pid, 0)
    os.close(r)
    secs = time.perf_counter() - t0
    mem = max(0, ru.ru_maxrss * 1024 - rss0)
    if timed_out:
        return Outcome("timeout", f"over {time_budget:g} s", secs, mem)
    try:
        st_, msg, grown = pickle.loads(b"".join(chunks))
    except Exception:  # noqa: BLE001
        return Outcome("crashed", f"child died (status {status})", secs, mem)
    return Outcome(st_, msg, secs, max(0, grown))


def fresh_copy(seed_dir: Path, work: Path) -> Path:
    if work.exists():
        shutil.rmtree(work)
    shutil.copytree(seed_dir, work)
    return work
