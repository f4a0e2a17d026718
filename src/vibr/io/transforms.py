"""nerfstudio / instant-NGP ``transforms.json`` scenes: loader and writer (vibr's save format).

Reading
-------
Intrinsics ``fl_x, fl_y, cx, cy, w, h`` (or ``camera_angle_x`` [, ``camera_angle_y``]) are
taken per frame, falling back to the top level. Each frame has ``file_path`` and
``transform_matrix``, a camera-to-world 4×4 in OpenGL axes (x right, y up, z backward);
vibr's OpenCV axes (x right, y down, z forward) are obtained by flipping the y and z axes::

    R_c2w = M[:3, :3] · diag(1, −1, −1),   R = R_c2wᵀ,   C = M[:3, 3],   t = −R C.

A rotation part that is a rotation times a uniform scale (Blender's ``matrix_world`` of a
scaled camera object) is read as its rotation, with one warning: the scale changes the
length of a ray's direction, not its line. Shear and per-axis scales are refused.

nerfstudio puts the centre of the top-left pixel at (0.5, 0.5): vibr ``cx = cx_ns − 0.5``
(same for y). Distorted frames (``OPENCV`` with non-zero k1, k2, k3, p1, p2, as
``ns-process-data`` writes them, and ``OPENCV_FISHEYE``) are undistorted at load onto
COLMAP's pinhole for them, their depth maps too (:mod:`vibr.io.undistort`); a k4 (r⁸) term,
a fisheye with p1/p2 and the other camera models (equirectangular, FISHEYE624) raise
:class:`VibrInputError`. ``depth_file_path`` (orthogonal depth, 0 =
unknown) is read by :func:`vibr.io.read_depth` and multiplied by ``depth_unit_scale_factor``
(default 1e-3 for 16-bit PNG, 1 otherwise). A path written on Windows (``images\\a.png``)
that names no file as it stands is read with ``/`` for its backslashes.

Views are named by their image's file stem; when two frames share one (a camera rig:
``images/cam0/0001.png``, ``images/cam1/0001.png``) by the path without its extension below
the folders every frame shares (``cam0/0001``).

``mask_path`` (nerfstudio's: an image, non-zero where the photograph is to be used, 0 where
not) gives :attr:`vibr.scene.View.mask`, resized and undistorted with the image.

vibr extras (ignored by other tools): top level ``vibr_grid: [rows, cols]``, ``vibr_name``
(scene name), ``vibr_capture: "video"`` (the frames of a video, in time order: ``vibr
calibrate VIDEO``; ``scene.meta["capture"]``), ``ply_file_path`` (sparse points, nerfstudio's key), ``sigma_z`` (scalar, may be
per frame); per frame ``vibr_name`` (view name), ``vibr_skew`` (K[0, 1]), ``vibr_grid_pos:
[row, col]``, ``sigma_z_file_path`` (.npy map).

Writing (:func:`save_scene`)
----------------------------
``OUT/transforms.json``, ``OUT/images/NAME.png`` (8-bit when exactly representable, else
16-bit), ``OUT/depth/NAME.npy`` (float32, 0 = unknown), ``OUT/sigma_z/NAME.npy``,
``OUT/sparse_pc.ply``. Everything is written into a temporary sibling folder that is renamed to
``OUT`` at the end, so a failure leaves no partial output.
"""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
from pathlib import Path

import numpy as np

from .._runtime.atomic import temporary_folder, write_failed
from ..camera import Camera
from ..errors import OutputExists, OutputFailed, VibrInputError
from ..progress import progress
from ..scene import Scene
from .camera_json import ROTATION_TOL, as_scaled_rotation, parse_json
from .depthfiles import fit_depth, read_depth, write_depth
from .entries import select_entries
from .formats import Format, register_format
from .images import build_views, image_size, read_mask, write_image
from .outputs import MARKER, check_not_input, check_replaceable, replace_folder, write_marker
from .undistort import NERFSTUDIO_FISHEYE, check_lens, from_nerfstudio, pinhole
from .undistort import summary as undistort_summary

logger = logging.getLogger(__name__)

_GL_TO_CV = np.diag([1.0, -1.0, -1.0])
_DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")
#: camera_model values read as a perspective camera (with k1, k2, k3, p1, p2) or a fisheye;
#: others (EQUIRECTANGULAR, FISHEYE624, the omnidirectional stereo models) are refused.
_PERSPECTIVE_MODELS = ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "PERSPECTIVE")


def find_transforms(path) -> Path | None:
    p = Path(path)
    if p.is_file() and p.suffix.lower() == ".json" and p.name != "cameras.json":
        return p
    if p.is_dir() and (p / "transforms.json").is_file():
        return p / "transforms.json"
    return None


# ----------------------------------------------------------------------------- PLY
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def read_ply_points(path) -> np.ndarray:
    """(N, 3) float64 vertex positions of a PLY file (ascii or binary; vertex element first)."""
    p = os.fspath(path)
    with open(p, "rb") as f:
        data = f.read()
    end = data.find(b"end_header")
    nl = data.find(b"\n", end) if end >= 0 else -1
    if not data.startswith(b"ply") or end < 0 or nl < 0:
        raise VibrInputError("not a PLY file (no 'ply' ... 'end_header' header)", p)
    fmt, n, props = _ply_header(data[:end].decode("ascii", "replace").splitlines(), p)
    cols = _ply_columns(data[nl + 1:], fmt, n, props, p)
    pts = np.stack([cols["x"], cols["y"], cols["z"]], axis=1).astype(np.float64)
    if not np.all(np.isfinite(pts)):
        raise VibrInputError(f"PLY file has {int((~np.isfinite(pts).all(axis=1)).sum())} non-finite vertices", p)
    return pts


def _ply_header(header: list, p: str):
    """``(format, vertex count, [(property, numpy type)])`` of a PLY header's lines, checked."""
    fmt, n, props, first, cur = None, None, [], None, None
    for ln in header:
        tok = ln.split()
        if not tok:
            continue
        if tok[0] == "format" and len(tok) >= 2:
            fmt = tok[1]
        elif tok[0] == "element" and len(tok) >= 3:
            first = first or tok[1]
            cur = tok[1]
            if cur == "vertex":
                if not tok[2].isdigit():
                    raise VibrInputError(f"PLY vertex count {tok[2]!r} is not a number", p)
                n = int(tok[2])
        elif tok[0] == "property" and cur == "vertex":
            if len(tok) >= 2 and tok[1] == "list":
                raise VibrInputError("PLY vertex element with list properties is not supported", p)
            if len(tok) < 3:
                raise VibrInputError(f"malformed PLY property line {ln!r}", p)
            props.append((tok[2], _PLY_TYPES.get(tok[1])))
    names = [q[0] for q in props]
    if n is None or first != "vertex" or not {"x", "y", "z"} <= set(names) or any(t is None for _, t in props):
        raise VibrInputError("PLY file needs a first 'vertex' element with x, y, z", p)
    if len(set(names)) != len(names):
        raise VibrInputError("PLY vertex properties are named twice", p)
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise VibrInputError(f"unknown PLY format {fmt!r}", p)
    return fmt, n, props


def _ply_columns(body: bytes, fmt: str, n: int, props: list, p: str) -> dict:
    """The first ``n`` vertices' properties by name, from the data after the header."""
    names = [q[0] for q in props]
    if fmt != "ascii":
        order = "<" if fmt == "binary_little_endian" else ">"
        dt = np.dtype([(nm, order + t) for nm, t in props])
        if n * dt.itemsize > len(body):  # outside the try below: VibrInputError is a ValueError
            raise VibrInputError(f"PLY file cut short: {n} vertices need {n * dt.itemsize} bytes, "
                                 f"{len(body)} follow the header", p)
        rec = np.frombuffer(body, dtype=dt, count=n)
        return {nm: rec[nm] for nm in names}
    try:
        rows = body.decode("ascii").split("\n")
        if len(rows) < n:
            raise ValueError
        arr = np.array([[float(v) for v in r.split()[: len(props)]] for r in rows[:n]], dtype=np.float64)
        arr = arr.reshape(n, len(props))
    except (ValueError, UnicodeDecodeError):
        raise VibrInputError("malformed PLY vertex data", p) from None
    return {nm: arr[:, i] for i, nm in enumerate(names)}


def write_ply_points(path, points: np.ndarray) -> None:
    """Write (N, 3) points as a binary little-endian PLY with double x, y, z (exact)."""
    pts = np.ascontiguousarray(np.asarray(points, dtype="<f8").reshape(-1, 3))
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"element vertex {len(pts)}\nproperty double x\nproperty double y\nproperty double z\n"
              "end_header\n").encode("ascii")
    with open(path, "wb") as f:
        f.write(header)
        f.write(pts.tobytes())


# ----------------------------------------------------------------------------- reading
def _get(frame: dict, meta: dict, key: str, default=None):
    return frame[key] if key in frame else meta.get(key, default)


def _frame_camera(frame: dict, meta: dict, img_path: Path, src: str, i: int):
    """``(camera, distortion, s)``: the frame's camera; for a distorted one its
    :class:`Distortion` (the camera is then the pinhole its image is undistorted onto at
    load), else None; the uniform scale its transform_matrix's rotation carried (1: none)."""
    model, dk = _frame_lens(frame, meta, src, i)
    w, h = _frame_size(frame, meta, img_path, src, i)
    fx, fy = _frame_focal(frame, meta, w, h, src, i)
    fi = f"frame {i}:"
    cx = _number(_get(frame, meta, "cx", w / 2.0), f"{fi} cx", src)
    cy = _number(_get(frame, meta, "cy", h / 2.0), f"{fi} cy", src)
    skew = _number(frame.get("vibr_skew", 0.0), f"{fi} vibr_skew", src)
    dist = from_nerfstudio(model, fx, fy, cx, cy, dk, w, h, f"{src} frame {i}")
    if dist is not None:
        check_lens(dist, f"{src} frame {i}")
    if dist is not None and skew:
        raise VibrInputError(f"{fi} vibr_skew with lens distortion is not supported", src)
    K = np.array([[fx, skew, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]])
    if dist is not None:
        K, w, h = pinhole(dist)
    M = _frame_pose(frame, src, i)
    R_gl, s = as_scaled_rotation(M[:3, :3], src, f"frame {i} transform_matrix rotation")
    R_c2w = R_gl @ _GL_TO_CV
    return Camera.from_centre(K, R_c2w.T, M[:3, 3], w, h, source=f"{src} frame {i}"), dist, s


def _frame_lens(frame: dict, meta: dict, src: str, i: int):
    """``(camera_model, distortion coefficients)`` of a frame (its own keys over the file's)."""
    model = str(_get(frame, meta, "camera_model", "OPENCV"))[:40].upper()
    if model not in _PERSPECTIVE_MODELS + NERFSTUDIO_FISHEYE:
        raise VibrInputError(f"frame {i}: camera_model {model} is not one vibr reads (it reads "
                             f"{', '.join(_PERSPECTIVE_MODELS + NERFSTUDIO_FISHEYE)})", src)
    dk = {}
    for k in _DISTORTION_KEYS:
        v = _get(frame, meta, k, 0.0)
        if isinstance(v, (list, dict, str, bool)):
            raise VibrInputError(f"frame {i}: distortion {k} must be a number, got {v!r}", src)
        dk[k] = 0.0 if v is None else _number(v, f"frame {i}: {k}", src)
    return model, dk


def _frame_size(frame: dict, meta: dict, img_path: Path, src: str, i: int):
    """``(w, h)`` of a frame: its keys, else the image file's header."""
    w, h = _get(frame, meta, "w"), _get(frame, meta, "h")
    if w is None or h is None:
        w, h = image_size(img_path)
    fi = f"frame {i}:"
    w, h = _number(w, f"{fi} w", src, positive=True), _number(h, f"{fi} h", src, positive=True)
    if w != int(w) or h != int(h) or max(w, h) > 1e6:
        raise VibrInputError(f"{fi} image size {w:g}x{h:g} must be whole numbers of at most 10^6 pixels", src)
    return int(w), int(h)


def _frame_focal(frame: dict, meta: dict, w: int, h: int, src: str, i: int):
    """``(fx, fy)`` in pixels: ``fl_x``/``fl_y``, else from ``camera_angle_x``/``_y``
    (``f = w / (2 tan(angle / 2))``); fy defaults to fx."""
    fi = f"frame {i}:"
    fx, fy = _get(frame, meta, "fl_x"), _get(frame, meta, "fl_y")
    if fx is None:
        ax = _get(frame, meta, "camera_angle_x")
        if ax is None:
            raise VibrInputError(f"{fi} no focal length (fl_x or camera_angle_x)", src)
        ax = _number(ax, f"{fi} camera_angle_x", src, positive=True)
        if not ax < math.pi:
            raise VibrInputError(f"{fi} camera_angle_x must be in (0, pi) radians, got {ax}", src)
        fx = 0.5 * w / math.tan(0.5 * ax)
    fx = _number(fx, f"{fi} fl_x", src, positive=True)
    if fy is None:
        ay = _get(frame, meta, "camera_angle_y")
        if ay is not None:
            ay = _number(ay, f"{fi} camera_angle_y", src, positive=True)
            if not ay < math.pi:
                raise VibrInputError(f"{fi} camera_angle_y must be in (0, pi) radians, got {ay}", src)
        fy = fx if ay is None else 0.5 * h / math.tan(0.5 * ay)
    return fx, _number(fy, f"{fi} fl_y", src, positive=True)


def _frame_pose(frame: dict, src: str, i: int):
    """The frame's checked ``transform_matrix`` (4×4 or 3×4, camera to world, OpenGL axes)."""
    fi = f"frame {i}:"
    if "transform_matrix" not in frame:
        raise VibrInputError(f"frame {i} is missing key 'transform_matrix'", src)
    try:
        M = np.asarray(frame["transform_matrix"], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise VibrInputError(f"{fi} transform_matrix must be a 4x4 array of numbers", src) from None
    if M.shape in ((4, 4), (3, 4)) and not np.all(np.isfinite(M)):
        raise VibrInputError(f"{fi} transform_matrix has non-finite values", src)
    if M.shape not in ((4, 4), (3, 4)):
        raise VibrInputError(f"frame {i}: transform_matrix must be 4x4, got shape {M.shape}", src)
    if M.shape == (4, 4) and not np.allclose(M[3], [0, 0, 0, 1]):
        raise VibrInputError(f"frame {i}: transform_matrix last row must be 0 0 0 1", src)
    return M


def _resolve(base: Path, rel: str, what: str, src: str, i: int, allow_outside: bool = False) -> Path:
    where = f"frame {i}: " if i >= 0 else ""
    if not isinstance(rel, str) or not rel or "\0" in rel:
        raise VibrInputError(f"{where}{what} must be a non-empty string", src)
    p = Path(rel)
    p = p if p.is_absolute() else base / p
    if "\\" in rel and not p.exists():  # written on Windows: "images\\frame_00001.png"
        p = base / Path(rel.replace("\\", "/"))
    if not allow_outside:
        try:
            inside = p.resolve().is_relative_to(base.resolve())
        except (OSError, RuntimeError, ValueError):
            inside = False
        if not inside:
            raise VibrInputError(f"{where}{what} {rel!r} is {'absolute' if Path(rel).is_absolute() else 'outside'} "
                                 "the scene folder: refused (load_scene(..., allow_outside=True) or "
                                 "vibr --allow-outside-paths to accept it)", src)
    if not p.exists() and what == "file_path" and not p.suffix:
        for ext in (".png", ".jpg", ".jpeg"):
            if p.with_suffix(ext).is_file():
                return p.with_suffix(ext)
    return p


def _frame_names(frames: list) -> list:
    """Default view names: the image file stems, or, when two frames share a stem (a camera
    rig: ``images/cam0/0001.png``, ``images/cam1/0001.png``), the paths without their
    extension and without the folders every frame shares (``cam0/0001``)."""
    paths = [Path(str(f.get("file_path", ""))) if isinstance(f, dict) else Path() for f in frames]
    stems = [p.stem for p in paths]
    if len(set(stems)) == len(stems):
        return stems
    parts = [p.with_suffix("").as_posix().removeprefix("./").split("/") for p in paths]
    k = 0
    while all(len(q) > k + 1 and q[k] == parts[0][k] for q in parts):
        k += 1
    return ["/".join(q[k:]) for q in parts]


def _ints(v, n: int, what: str, src: str) -> tuple[int, ...]:
    """``v`` as ``n`` non-negative integers (grid sizes and positions)."""
    if not isinstance(v, (list, tuple)) or len(v) != n or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and x == int(x)
            and 0 <= x < 2**31 for x in v):
        raise VibrInputError(f"{what} must be {n} non-negative integers, got {str(v)[:60]}", src)
    return tuple(int(x) for x in v)


def _number(v, what: str, src: str, *, positive: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, str)):
        raise VibrInputError(f"{what} must be a number, got {str(v)[:40]}", src)
    try:
        x = float(v)
    except ValueError:
        raise VibrInputError(f"{what} must be a number, got {v!r}", src) from None
    if not math.isfinite(x) or (positive and not x > 0):
        raise VibrInputError(f"{what} must be finite{' and > 0' if positive else ''}, got {x}", src)
    return x


def load_transforms(path, *, scale: float = 1.0, views=None, allow_outside: bool = False) -> Scene:
    """Load a ``transforms.json`` scene (a file or a folder holding ``transforms.json``).

    File paths (images, depth, sigma_z, points) must lie inside the scene folder: an
    absolute path or one escaping it (``../``) is refused unless ``allow_outside``.
    """

    tf = find_transforms(path)
    if tf is None:
        raise VibrInputError("no transforms.json found", path)
    src = str(tf)
    meta = parse_json(tf)
    if not isinstance(meta, dict) or not isinstance(meta.get("frames"), list) or not meta["frames"]:
        raise VibrInputError("transforms.json must be an object with a non-empty 'frames' list", src)
    base = tf.parent
    entries, grid_pos = _read_frames(meta["frames"], base, src, allow_outside)
    _refuse_shared_images(entries, base, src)
    entries = select_entries(entries, views, base)
    scaled = []
    for e in entries:
        fr, i = e.pop("frame"), e.pop("i")
        if not e["path"].is_file():
            raise VibrInputError(f"image of frame {i} not found" if e["path"].exists() is False else
                                 "image is not a file", e["path"])
        cam, dist, rot_scale = _frame_camera(fr, meta, e["path"], src, i)
        if abs(rot_scale - 1.0) > ROTATION_TOL:
            scaled.append((rot_scale, i))
        e["camera"] = cam
        if dist is not None:
            e["distortion"] = dist
        file_shape = cam.shape if dist is None else (dist.height, dist.width)  # depth and sigma_z files
        e.update(_frame_maps(fr, meta, i, file_shape, base, src, allow_outside))
    if scaled:  # a scaled camera object in 3-D software: the rays' lines are the same
        ss = [x for x, _ in scaled]
        logger.warning(f"{src}: the rotations of {len(scaled)} of {len(entries)} frames carry a uniform scale "
                       f"({min(ss):.4g}..{max(ss):.4g}, first frame {scaled[0][1]}), not a rigid motion; vibr uses "
                       "their rotation, as the scale changes the length of a ray's direction, not its line")
    undistorted = undistort_summary(entries)
    vs = build_views(entries, scale, desc="reading images")
    points = None
    if meta.get("ply_file_path"):
        ply = _resolve(base, meta["ply_file_path"], "ply_file_path", src, -1, allow_outside)
        if not ply.is_file():
            raise VibrInputError("sparse point file not found", ply)
        points = read_ply_points(ply)
    grid = _ints(meta["vibr_grid"], 2, "vibr_grid", src) if meta.get("vibr_grid") else None
    if grid is not None and min(grid) < 1:
        raise VibrInputError(f"vibr_grid must be positive, got {list(grid)}", src)
    names = {v.name for v in vs}
    smeta = {"format": "transforms.json", "scale": scale, "transforms": src}
    if undistorted:
        smeta["undistorted"] = undistorted
    if grid_pos:
        smeta["grid_pos"] = {n: p for n, p in grid_pos.items() if n in names}
    if meta.get("vibr_capture") == "video":
        smeta["capture"] = "video"
    name = meta.get("vibr_name", base.name)
    name = name if isinstance(name, str) and name else base.name
    return Scene(vs, name=name, root=base, grid=grid, points=points, meta=smeta)


def _read_frames(frames: list, base: Path, src: str, allow_outside: bool) -> tuple[list, dict]:
    """One entry per frame (name, image path, the frame's JSON, its index) and the grid
    positions frames give (``vibr_grid_pos``); the frames' keys checked."""
    entries, grid_pos = [], {}
    default_names = _frame_names(frames)
    for i, fr in enumerate(frames):
        if not isinstance(fr, dict):
            raise VibrInputError(f"frame {i} is not a JSON object", src)
        if "file_path" not in fr:
            raise VibrInputError(f"frame {i} is missing key 'file_path'", src)
        img = _resolve(base, fr["file_path"], "file_path", src, i, allow_outside)
        name = fr.get("vibr_name", default_names[i])
        if not isinstance(name, str) or not name.strip():
            raise VibrInputError(f"frame {i}: vibr_name must be a non-empty string", src)
        if "vibr_grid_pos" in fr:
            grid_pos[name] = _ints(fr["vibr_grid_pos"], 2, f"frame {i}: vibr_grid_pos", src)
        entries.append({"name": name, "path": img, "frame": fr, "i": i})
    return entries, grid_pos


def _frame_maps(fr: dict, meta: dict, i: int, file_shape, base: Path, src: str, allow_outside: bool) -> dict:
    """Frame ``i``'s per-pixel files and values: ``depth`` (``depth_file_path`` in the
    frame's ``depth_unit_scale_factor``), ``mask`` (``mask_path``), ``sigma_z`` (a
    ``sigma_z_file_path`` map or a number), each of ``file_shape``."""
    out = {}
    dp = _get(fr, {}, "depth_file_path")
    if dp is not None:
        dpath = _resolve(base, dp, "depth_file_path", src, i, allow_outside)
        fac = _get(fr, meta, "depth_unit_scale_factor")
        fac = None if fac is None else _number(fac, f"frame {i}: depth_unit_scale_factor", src, positive=True)
        out["depth"] = fit_depth(read_depth(dpath, fac), file_shape, dpath, f"frame {i}'s image")
    mp = fr.get("mask_path")
    if mp is not None:
        mpath = _resolve(base, mp, "mask_path", src, i, allow_outside)
        out["mask"] = read_mask(mpath, file_shape, f"frame {i}'s image")
    sz = _get(fr, meta, "sigma_z")
    szp = fr.get("sigma_z_file_path")
    if szp is not None:
        spath = _resolve(base, szp, "sigma_z_file_path", src, i, allow_outside)
        s = fit_depth(read_depth(spath, 1.0, what="sigma_z"), file_shape, spath, f"frame {i}'s image")  # finite, >= 0
        out["sigma_z"] = np.nan_to_num(s, nan=0.0)
    elif sz is not None:
        sz = _number(sz, f"frame {i}: sigma_z", src)
        if not sz >= 0:
            raise VibrInputError(f"frame {i}: sigma_z must be finite and >= 0, got {sz}", src)
        out["sigma_z"] = sz
    return out


# ----------------------------------------------------------------------------- writing
def _safe_name(name: str) -> str:
    bad = '<>:"/\\|?*'
    out = "".join("_" if (c in bad or ord(c) < 32) else c for c in name).strip(". ")
    return out or "view"


def _frame_entries(scene: Scene, files: list) -> list:
    """The transforms.json frame of each view (OpenGL camera-to-world, pixel corner at 0),
    its files named ``files`` (stems)."""
    frames = []
    for v, fn in zip(scene.views, files):
        cam = v.camera
        K = cam.K
        M = np.eye(4)
        M[:3, :3] = cam.R.T @ _GL_TO_CV
        M[:3, 3] = cam.centre
        fr = {"file_path": f"images/{fn}.png", "transform_matrix": M.tolist(),
              "fl_x": float(K[0, 0]), "fl_y": float(K[1, 1]),
              "cx": float(K[0, 2]) + 0.5, "cy": float(K[1, 2]) + 0.5,
              "w": cam.width, "h": cam.height, "vibr_name": v.name}
        if K[0, 1] != 0:
            fr["vibr_skew"] = float(K[0, 1])
        if v.depth is not None:
            fr["depth_file_path"] = f"depth/{fn}.npy"
            fr["depth_unit_scale_factor"] = 1.0
        if v.mask is not None:
            fr["mask_path"] = f"masks/{fn}.png"
        if v.sigma_z is not None:
            if np.ndim(v.sigma_z) == 2:
                fr["sigma_z_file_path"] = f"sigma_z/{fn}.npy"
            else:
                fr["sigma_z"] = float(v.sigma_z)
        gp = scene.meta.get("grid_pos", {}).get(v.name)
        if gp is not None:
            fr["vibr_grid_pos"] = [int(gp[0]), int(gp[1])]
        frames.append(fr)
    return frames


def save_scene(scene: Scene, out_dir, *, overwrite: bool = False, in_place: bool = False) -> Path:
    """Write ``scene`` as a nerfstudio ``transforms.json`` folder (see the module docstring).

    Parameters
    ----------
    scene : Scene
    out_dir : str or Path
        Created; if it exists, :class:`VibrInputError` unless ``overwrite``.
    overwrite : bool
        Replace an existing ``out_dir`` (only after the new one is complete), and only when
        vibr wrote it: it has the marker :data:`vibr.io.outputs.MARKER` and holds nothing
        but the files that marker lists (:func:`vibr.io.outputs.check_replaceable`).
    in_place : bool
        ``out_dir`` may be the scene's own folder (an in-place update; the scene's data is
        in memory). Otherwise an ``out_dir`` that is or contains the scene's folder or one
        of its files is refused.

    Returns the output folder. Views without an image cannot be saved. The folder gets a
    marker file listing what vibr wrote, so that a later ``overwrite`` can replace it.
    """
    from concurrent.futures import ThreadPoolExecutor



    out = Path(out_dir).absolute()
    _check_save(scene, out, overwrite, in_place)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(temporary_folder(out.parent, out.name))
    except OSError as exc:
        raise write_failed(exc, out) from exc
    try:
        files = _unique_stems(scene)
        for sub, needed in (("images", True), ("depth", any(v.depth is not None for v in scene.views)),
                            ("sigma_z", any(v.sigma_z is not None and np.ndim(v.sigma_z) == 2 for v in scene.views)),
                            ("masks", any(v.mask is not None for v in scene.views))):
            if needed:
                (tmp / sub).mkdir()
        frames = _frame_entries(scene, files)

        def write_one(args):
            v, fn = args
            write_image(tmp / "images" / f"{fn}.png", v.image)
            if v.depth is not None:
                write_depth(tmp / "depth" / f"{fn}.npy", v.depth)
            if v.sigma_z is not None and np.ndim(v.sigma_z) == 2:
                write_depth(tmp / "sigma_z" / f"{fn}.npy", np.asarray(v.sigma_z, dtype=np.float32))
            if v.mask is not None:
                write_image(tmp / "masks" / f"{fn}.png", v.mask.astype(np.float32), bits=8)

        with ThreadPoolExecutor(max_workers=min(8, (os.cpu_count() or 2) * 2)) as ex:
            list(progress(ex.map(write_one, zip(scene.views, files)), desc="writing views",
                          total=len(files), unit="view"))

        doc = _transforms_doc(scene, frames, tmp)
        with open(tmp / "transforms.json", "w", encoding="utf-8") as f:
            json.dump(doc, f, indent=2)
            f.write("\n")

        kept = _keep_other_files(out, tmp) if in_place else {}
        write_marker(tmp, sha256=kept)
        replace_folder(tmp, out, overwrite=overwrite)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(exc, OutputFailed):  # name the output, not its temporary folder
            raise OutputFailed(exc.problem, out) from exc
        if isinstance(exc, OSError) and not isinstance(exc, VibrInputError):
            raise write_failed(exc, out) from exc
        raise
    return out


def _refuse_shared_images(entries, base: Path, src) -> None:
    """Two frames naming the same image file are refused: one photograph has one camera
    (a copied frame whose ``file_path`` was not edited)."""
    seen = {}
    for e in entries:
        key = os.path.normcase(os.path.realpath(e["path"]))
        if key in seen:
            try:
                name = Path(e["path"]).relative_to(base)
            except ValueError:
                name = e["path"]
            raise VibrInputError(f"frames {seen[key]} and {e['i']} name the same image {name}: one photograph "
                                 "has one camera (give each frame its own file_path)", src)
        seen[key] = e["i"]


def _keep_other_files(old: Path, new: Path) -> dict:
    """An in-place update keeps every file of the old folder it does not write itself (a
    ``calibration.json`` from ``vibr calibrate``, a render vibr wrote there): each is linked
    (else copied) into the new folder before the swap. Returns the digests the old marker
    recorded for them (:func:`vibr.io.outputs.record_file`)."""
    if not old.is_dir():
        return {}
    for f in sorted(old.rglob("*")):
        rel = f.relative_to(old)
        dst = new / rel
        if f.name == MARKER or f.is_dir() or dst.exists() or dst.is_symlink():
            continue
        dst.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.link(f, dst, follow_symlinks=False)
        except OSError:
            shutil.copy2(f, dst, follow_symlinks=False)
    try:
        with open(old / MARKER, encoding="utf-8") as fh:
            sha = json.load(fh).get("sha256") or {}
        return {k: v for k, v in sha.items() if isinstance(k, str) and isinstance(v, str) and (new / k).is_file()}
    except (OSError, ValueError, AttributeError):
        return {}


def _check_save(scene: Scene, out: Path, overwrite: bool, in_place: bool) -> None:
    """Refuse a save to ``out`` before any work: into the scene's own files (unless an
    in-place update), over an output vibr did not write or without ``overwrite``, or of a
    view without an image."""

    if in_place:  # the scene is in memory; check_replaceable below guards its folder
        if scene.root is None or Path(scene.root).resolve() != out.resolve():
            raise VibrInputError("an in-place update must write to the scene's own folder", out)
    else:
        check_not_input(out, [scene.root] + [v.path for v in scene.views])
    if out.exists() and not overwrite:
        raise OutputExists("output folder already exists", out)
    if out.exists() and not out.is_dir():
        raise VibrInputError("output path exists and is not a folder", out)
    if out.exists():
        check_replaceable(out)  # before the work, and again at the swap
    for v in scene.views:
        if v.image is None:
            raise VibrInputError(f"view {v.name} has no image to save", v.path)


def _unique_stems(scene: Scene) -> list[str]:
    """A file stem per view: its name made safe for a file system, unique regardless of case."""
    files, used = [], set()
    for v in scene.views:
        fn = _safe_name(v.name)
        while fn.lower() in used:
            fn += "_"
        used.add(fn.lower())
        files.append(fn)
    return files


def _transforms_doc(scene: Scene, frames: list, tmp: Path) -> dict:
    """The transforms.json document: shared intrinsics when every frame has the same, the
    grid, the capture, the sparse points (written to ``tmp``) and the frames."""
    doc = {"camera_model": "OPENCV", "vibr_name": scene.name}
    keys = ("fl_x", "fl_y", "cx", "cy", "w", "h")
    if all(frames[0][k] == f[k] for f in frames for k in keys):
        doc.update({k: frames[0][k] for k in keys})
    if scene.grid is not None:
        doc["vibr_grid"] = [int(scene.grid[0]), int(scene.grid[1])]
    if scene.meta.get("capture") == "video":
        doc["vibr_capture"] = "video"
    if scene.points is not None and len(scene.points):
        write_ply_points(tmp / "sparse_pc.ply", scene.points)
        doc["ply_file_path"] = "sparse_pc.ply"
    doc["frames"] = frames
    return doc


def is_transforms(path: Path) -> bool:
    """A nerfstudio / instant-NGP scene: a ``.json`` file, or a folder with ``transforms.json``."""
    return path.suffix.lower() == ".json" if path.is_file() else find_transforms(path) is not None


register_format(Format("transforms", "nerfstudio/instant-NGP transforms.json", is_transforms, load_transforms,
                       looks_for="transforms.json", options=("allow_outside",), priority=10))
