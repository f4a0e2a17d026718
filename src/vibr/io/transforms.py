"""nerfstudio / instant-NGP ``transforms.json`` scenes: loader and writer (vibr's save format).

Reading
-------
Intrinsics ``fl_x, fl_y, cx, cy, w, h`` (or ``camera_angle_x`` [, ``camera_angle_y``]) are
taken per frame, falling back to the top level. Each frame has ``file_path`` and
``transform_matrix``, a camera-to-world 4×4 in OpenGL axes (x right, y up, z backward);
vibr's OpenCV axes (x right, y down, z forward) are obtained by flipping the y and z axes::

    R_c2w = M[:3, :3] · diag(1, −1, −1),   R = R_c2wᵀ,   C = M[:3, 3],   t = −R C.

nerfstudio puts the centre of the top-left pixel at (0.5, 0.5): vibr ``cx = cx_ns − 0.5``
(same for y). Non-zero distortion (k1..k4, p1, p2) or a fisheye / equirectangular
``camera_model`` raise :class:`VibrInputError`. ``depth_file_path`` (orthogonal depth, 0 =
unknown) is read by :func:`vibr.io.read_depth` and multiplied by ``depth_unit_scale_factor``
(default 1e-3 for 16-bit PNG, 1 otherwise).

vibr extras (ignored by other tools): top level ``vibr_grid: [rows, cols]``, ``vibr_name``
(scene name), ``ply_file_path`` (sparse points, nerfstudio's key), ``sigma_z`` (scalar, may be
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
import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..camera import Camera
from ..errors import OutputExists, VibrInputError
from ..scene import Scene
from .camera_json import as_rotation, parse_json
from .depthfiles import read_depth, write_depth
from .images import build_views, image_size, write_image

_GL_TO_CV = np.diag([1.0, -1.0, -1.0])
_DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")
_BAD_MODELS = ("OPENCV_FISHEYE", "FISHEYE", "EQUIRECTANGULAR", "OMNIDIRECTIONALSTEREO_L",
               "OMNIDIRECTIONALSTEREO_R", "VR180_L", "VR180_R")


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
    if not data.startswith(b"ply") or end < 0:
        raise VibrInputError("not a PLY file", p)
    header = data[:end].decode("ascii", "replace").splitlines()
    body = data[data.index(b"\n", end) + 1:]
    fmt, n, props, first = None, None, [], None
    for ln in header:
        tok = ln.split()
        if not tok:
            continue
        if tok[0] == "format":
            fmt = tok[1]
        elif tok[0] == "element":
            first = first or tok[1]
            cur = tok[1]
            if cur == "vertex":
                n = int(tok[2])
        elif tok[0] == "property" and cur == "vertex":
            if tok[1] == "list":
                raise VibrInputError("PLY vertex element with list properties is not supported", p)
            props.append((tok[2], _PLY_TYPES.get(tok[1])))
    names = [q[0] for q in props]
    if n is None or first != "vertex" or not {"x", "y", "z"} <= set(names) or any(t is None for _, t in props):
        raise VibrInputError("PLY file needs a first 'vertex' element with x, y, z", p)
    try:
        if fmt == "ascii":
            rows = body.decode("ascii").split("\n")[:n]
            arr = np.array([[float(v) for v in r.split()[: len(props)]] for r in rows], dtype=np.float64)
            arr = arr.reshape(n, len(props))
            cols = {nm: arr[:, i] for i, nm in enumerate(names)}
        else:
            order = "<" if fmt == "binary_little_endian" else ">"
            dt = np.dtype([(nm, order + t) for nm, t in props])
            rec = np.frombuffer(body, dtype=dt, count=n)
            cols = {nm: rec[nm] for nm in names}
    except (ValueError, UnicodeDecodeError):
        raise VibrInputError("malformed PLY vertex data", p) from None
    return np.stack([cols["x"], cols["y"], cols["z"]], axis=1).astype(np.float64)


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


def _frame_camera(frame: dict, meta: dict, img_path: Path, src: str, i: int) -> Camera:
    model = str(_get(frame, meta, "camera_model", "OPENCV")).upper()
    if model in _BAD_MODELS:
        raise VibrInputError(f"frame {i}: camera_model {model} is not a pinhole; vibr needs undistorted "
                             "pinhole images", src)
    for k in _DISTORTION_KEYS:
        v = _get(frame, meta, k, 0.0)
        if v not in (0, 0.0, None):
            raise VibrInputError(f"frame {i}: non-zero distortion {k} = {v}: undistort the images first "
                                 "(vibr handles pinhole cameras only)", src)
    w, h = _get(frame, meta, "w"), _get(frame, meta, "h")
    if w is None or h is None:
        w, h = image_size(img_path)
    try:
        w, h = int(w), int(h)
        fx, fy = _get(frame, meta, "fl_x"), _get(frame, meta, "fl_y")
        if fx is None:
            ax = _get(frame, meta, "camera_angle_x")
            if ax is None:
                raise VibrInputError(f"frame {i}: no focal length (fl_x or camera_angle_x)", src)
            fx = 0.5 * w / math.tan(0.5 * float(ax))
        if fy is None:
            ay = _get(frame, meta, "camera_angle_y")
            fy = fx if ay is None else 0.5 * h / math.tan(0.5 * float(ay))
        cx = float(_get(frame, meta, "cx", w / 2.0)) - 0.5
        cy = float(_get(frame, meta, "cy", h / 2.0)) - 0.5
        skew = float(frame.get("vibr_skew", 0.0))
        K = np.array([[float(fx), skew, cx], [0.0, float(fy), cy], [0.0, 0.0, 1.0]])
        M = np.asarray(frame["transform_matrix"], dtype=np.float64)
    except KeyError as exc:
        raise VibrInputError(f"frame {i} is missing key {exc}", src) from None
    except (TypeError, ValueError) as exc:
        if isinstance(exc, VibrInputError):
            raise
        raise VibrInputError(f"frame {i}: bad camera values ({exc})", src) from None
    if M.shape not in ((4, 4), (3, 4)):
        raise VibrInputError(f"frame {i}: transform_matrix must be 4x4, got shape {M.shape}", src)
    if M.shape == (4, 4) and not np.allclose(M[3], [0, 0, 0, 1]):
        raise VibrInputError(f"frame {i}: transform_matrix last row must be 0 0 0 1", src)
    R_c2w = as_rotation(M[:3, :3], src, f"frame {i} transform_matrix rotation") @ _GL_TO_CV
    return Camera.from_centre(K, R_c2w.T, M[:3, 3], w, h, source=f"{src} frame {i}")


def _resolve(base: Path, rel: str, what: str, src: str, i: int) -> Path:
    if not isinstance(rel, str) or not rel:
        raise VibrInputError(f"frame {i}: {what} must be a non-empty string", src)
    p = Path(rel)
    p = p if p.is_absolute() else base / p
    if not p.exists() and what == "file_path" and not p.suffix:
        for ext in (".png", ".jpg", ".jpeg"):
            if p.with_suffix(ext).is_file():
                return p.with_suffix(ext)
    return p


def load_transforms(path, *, scale: float = 1.0, views=None) -> Scene:
    """Load a ``transforms.json`` scene (a file or a folder holding ``transforms.json``)."""
    from . import select_entries

    tf = find_transforms(path)
    if tf is None:
        raise VibrInputError("no transforms.json found", path)
    src = str(tf)
    meta = parse_json(tf)
    if not isinstance(meta, dict) or not isinstance(meta.get("frames"), list) or not meta["frames"]:
        raise VibrInputError("transforms.json must be an object with a non-empty 'frames' list", src)
    base = tf.parent
    entries, grid_pos = [], {}
    for i, fr in enumerate(meta["frames"]):
        if not isinstance(fr, dict):
            raise VibrInputError(f"frame {i} is not a JSON object", src)
        if "file_path" not in fr:
            raise VibrInputError(f"frame {i} is missing key 'file_path'", src)
        img = _resolve(base, fr["file_path"], "file_path", src, i)
        name = str(fr.get("vibr_name", Path(str(fr["file_path"])).stem))
        e = {"name": name, "path": img, "frame": fr, "i": i}
        if "vibr_grid_pos" in fr:
            grid_pos[name] = tuple(int(v) for v in fr["vibr_grid_pos"])
        entries.append(e)
    entries = select_entries(entries, views, base)
    for e in entries:
        fr, i = e.pop("frame"), e.pop("i")
        if not e["path"].is_file():
            raise VibrInputError(f"image of frame {i} not found" if e["path"].exists() is False else
                                 "image is not a file", e["path"])
        cam = _frame_camera(fr, meta, e["path"], src, i)
        e["camera"] = cam
        dp = _get(fr, {}, "depth_file_path")
        if dp is not None:
            dpath = _resolve(base, dp, "depth_file_path", src, i)
            fac = _get(fr, meta, "depth_unit_scale_factor")
            e["depth"] = read_depth(dpath, None if fac is None else float(fac), shape=cam.shape)
        sz = _get(fr, meta, "sigma_z")
        szp = fr.get("sigma_z_file_path")
        if szp is not None:
            spath = _resolve(base, szp, "sigma_z_file_path", src, i)
            s = read_depth(spath, 1.0, shape=cam.shape)  # same validation: finite, >= 0
            e["sigma_z"] = np.nan_to_num(s, nan=0.0)
        elif sz is not None:
            try:
                sz = float(sz)
            except (TypeError, ValueError):
                raise VibrInputError(f"frame {i}: sigma_z must be a number", src) from None
            if not (np.isfinite(sz) and sz >= 0):
                raise VibrInputError(f"frame {i}: sigma_z must be finite and >= 0, got {sz}", src)
            e["sigma_z"] = sz
    vs = build_views(entries, scale, desc="reading images")
    points = None
    if meta.get("ply_file_path"):
        ply = _resolve(base, meta["ply_file_path"], "ply_file_path", src, -1)
        if not ply.is_file():
            raise VibrInputError("sparse point file not found", ply)
        points = read_ply_points(ply)
    grid = tuple(int(v) for v in meta["vibr_grid"]) if meta.get("vibr_grid") else None
    names = {v.name for v in vs}
    smeta = {"format": "transforms.json", "scale": scale, "transforms": src}
    if grid_pos:
        smeta["grid_pos"] = {n: p for n, p in grid_pos.items() if n in names}
    name = str(meta.get("vibr_name", base.name))
    return Scene(vs, name=name, root=base, grid=grid, points=points, meta=smeta)


# ----------------------------------------------------------------------------- writing
def _safe_name(name: str) -> str:
    bad = '<>:"/\\|?*'
    out = "".join("_" if (c in bad or ord(c) < 32) else c for c in name).strip(". ")
    return out or "view"


def save_scene(scene: Scene, out_dir, *, overwrite: bool = False) -> Path:
    """Write ``scene`` as a nerfstudio ``transforms.json`` folder (see the module docstring).

    Parameters
    ----------
    scene : Scene
    out_dir : str or Path
        Created; if it exists, :class:`VibrInputError` unless ``overwrite``.
    overwrite : bool
        Replace an existing ``out_dir`` (only after the new one is complete).

    Returns the output folder. Views without an image cannot be saved.
    """
    from concurrent.futures import ThreadPoolExecutor

    from ..progress import progress

    out = Path(out_dir).absolute()
    if out.exists() and not overwrite:
        raise OutputExists("output folder already exists", out)
    if out.exists() and not out.is_dir():
        raise VibrInputError("output path exists and is not a folder", out)
    for v in scene.views:
        if v.image is None:
            raise VibrInputError(f"view {v.name} has no image to save", v.path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".part", dir=out.parent))
    try:
        files, used = [], set()
        for v in scene.views:
            fn = _safe_name(v.name)
            while fn.lower() in used:
                fn += "_"
            used.add(fn.lower())
            files.append(fn)
        (tmp / "images").mkdir()
        if any(v.depth is not None for v in scene.views):
            (tmp / "depth").mkdir()
        if any(v.sigma_z is not None and np.ndim(v.sigma_z) == 2 for v in scene.views):
            (tmp / "sigma_z").mkdir()

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
            if v.sigma_z is not None:
                if np.ndim(v.sigma_z) == 2:
                    fr["sigma_z_file_path"] = f"sigma_z/{fn}.npy"
                else:
                    fr["sigma_z"] = float(v.sigma_z)
            gp = scene.meta.get("grid_pos", {}).get(v.name)
            if gp is not None:
                fr["vibr_grid_pos"] = [int(gp[0]), int(gp[1])]
            frames.append(fr)

        def write_one(args):
            v, fn = args
            write_image(tmp / "images" / f"{fn}.png", v.image)
            if v.depth is not None:
                write_depth(tmp / "depth" / f"{fn}.npy", v.depth)
            if v.sigma_z is not None and np.ndim(v.sigma_z) == 2:
                write_depth(tmp / "sigma_z" / f"{fn}.npy", np.asarray(v.sigma_z, dtype=np.float32))

        with ThreadPoolExecutor(max_workers=min(8, (os.cpu_count() or 2) * 2)) as ex:
            list(progress(ex.map(write_one, zip(scene.views, files)), desc="writing views",
                          total=len(files), unit="view"))

        doc = {"camera_model": "OPENCV", "vibr_name": scene.name}
        same = all(frames[0][k] == f[k] for f in frames for k in ("fl_x", "fl_y", "cx", "cy", "w", "h"))
        if same:
            doc.update({k: frames[0][k] for k in ("fl_x", "fl_y", "cx", "cy", "w", "h")})
        if scene.grid is not None:
            doc["vibr_grid"] = [int(scene.grid[0]), int(scene.grid[1])]
        if scene.points is not None and len(scene.points):
            write_ply_points(tmp / "sparse_pc.ply", scene.points)
            doc["ply_file_path"] = "sparse_pc.ply"
        doc["frames"] = frames
        with open(tmp / "transforms.json", "w", encoding="utf-8") as f:
            json.dump(doc, f, indent=2)
            f.write("\n")

        if out.exists():
            trash = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
            os.replace(out, trash / "old")
            os.replace(tmp, out)
            shutil.rmtree(trash, ignore_errors=True)
        else:
            os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
