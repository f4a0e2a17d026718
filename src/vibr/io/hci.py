"""HCI 4D light-field folders (Honauer et al. 2016 benchmark layout).

A folder holds ``input_CamNNN.png`` (view index ``NNN = cols·r + c``, row r top→bottom,
column c left→right), optionally ``parameters.cfg``, ``gt_disp_lowres.pfm`` (centre-view
disparity, pixels per view step) and ``gt_depth_lowres.pfm``.

Camera model
------------
The views are parallel shift-lens pinholes. With the world frame = the centre camera's frame
(R = I for every view), focal ``f`` (px), baseline ``b`` (scene units per view step) and
focus distance ``Z0`` (the plane with zero disparity), view (r, c) of a grid with centre
(rc, cc) has

* centre ``C = ((c − cc)·b, (r − rc)·b, 0)`` (camera x right, y down),
* ``K = [[f, 0, cx + (c − cc)·f·b/Z0], [0, f, cy + (r − rc)·f·b/Z0], [0, 0, 1]]`` with
  ``(cx, cy) = ((W − 1)/2, (H − 1)/2)``.

A centre-view point at pixel x with depth Z then appears in view (r, c) at
``x − (c − cc)·d`` with ``d = f·b·(1/Z − 1/Z0)``: the benchmark's grid relation
``I_cc(x, y) = I_rc(x − (c − cc)d, y − (r − rc)d)``. Depth is computed from the ground-truth
*disparity* as ``Z = 1 / (d/(f·b) + 1/Z0)`` so that the loaded cameras reproduce it exactly.

With ``parameters.cfg``: ``f = focal_length_mm · max(res) / sensor_size_mm``,
``b = baseline_mm / 1000`` (metres), ``Z0 = focus_distance_m``; grid from num_cams_x/y.

**Without** ``parameters.cfg`` (rule, documented here once): the grid is square,
``n = ceil(sqrt(max index + 1))`` per side unless ``grid`` is given; ``f = W`` (image width,
px), ``b = 1`` scene unit, and ``1/Z0 = (max|d| + 1)/(f·b)`` so every depth is positive
(``1/Z ≥ 1/(f·b)``); with only a depth file, that depth is used as is and ``Z0`` = its median.

Depth goes on the centre view only (the view the disparity belongs to). Missing views in the
grid are allowed (a light field with holes). ``scene.grid = (rows, cols)`` and
``scene.meta["grid_pos"] = {name: (row, col)}``.
"""

from __future__ import annotations

import configparser
import math
import os
import re
from pathlib import Path

import numpy as np

from ..camera import Camera
from ..errors import VibrInputError
from ..scene import Scene, depth_from_file_values
from .depthfiles import read_pfm
from .entries import select_entries
from .formats import Format, register_format
from .images import build_views, image_size

_CAM_RE = re.compile(r"^input_Cam(\d+)\.(png|jpg|jpeg|tif|tiff)$", re.IGNORECASE)


def is_hci_folder(path) -> bool:
    p = Path(path)
    if not p.is_dir():
        return False
    return (p / "parameters.cfg").is_file() or any(_CAM_RE.match(n) for n in os.listdir(p))


def _read_cfg(path: Path) -> dict:
    cp = configparser.ConfigParser(interpolation=None)
    try:
        cp.read(path, encoding="utf-8")
    except configparser.Error as exc:
        msg = str(exc).splitlines()[0] if str(exc) else "syntax error"
        raise VibrInputError(f"malformed parameters.cfg: {msg[:120]}", path) from None
    except UnicodeDecodeError:
        raise VibrInputError("malformed parameters.cfg: not UTF-8 text", path) from None
    keys = {"focal_mm": ("intrinsics", "focal_length_mm", float),
            "res_x": ("intrinsics", "image_resolution_x_px", int),
            "res_y": ("intrinsics", "image_resolution_y_px", int),
            "sensor_mm": ("intrinsics", "sensor_size_mm", float),
            "cols": ("extrinsics", "num_cams_x", int), "rows": ("extrinsics", "num_cams_y", int),
            "baseline_mm": ("extrinsics", "baseline_mm", float),
            "focus_m": ("extrinsics", "focus_distance_m", float)}
    out = {}
    for k, (sec, key, kind) in keys.items():
        if not cp.has_section(sec):
            raise VibrInputError(f"parameters.cfg has no [{sec}] section", path)
        if not cp.has_option(sec, key):
            raise VibrInputError(f"parameters.cfg: [{sec}] has no {key}", path)
        raw = cp.get(sec, key)
        try:
            v = kind(raw)
        except ValueError:
            raise VibrInputError(f"parameters.cfg: {key} = {raw[:40]!r} is not "
                                 f"{'an integer' if kind is int else 'a number'}", path) from None
        if not (math.isfinite(v) and v > 0) or (kind is int and v > 100000):
            raise VibrInputError(f"parameters.cfg: {key} must be positive and finite, got {raw[:40]}", path)
        out[k] = v
    pose = {}
    for k in cp.options("extrinsics"):
        if k.startswith("center_cam_"):
            try:
                pose[k] = float(cp.get("extrinsics", k))
            except ValueError:
                pose[k] = None  # informative only (meta), not used by the cameras
    out["pose"] = pose
    return out


def _read_ground_truth(disp_path: Path, depth_path: Path, H: int, W: int):
    """The centre view's ground truth: (disparity, depth), disparity preferred (it defines
    the grid relation); None where absent."""
    disp = depth_gt = None
    if disp_path.is_file():
        disp = read_pfm(disp_path).astype(np.float64)
        if disp.ndim != 2 or disp.shape != (H, W):
            raise VibrInputError(f"disparity has shape {disp.shape}, views are {H}x{W}", disp_path)
        if not np.all(np.isfinite(disp)):
            raise VibrInputError(f"disparity has {int((~np.isfinite(disp)).sum())} NaN or infinite values", disp_path)
    elif depth_path.is_file():
        depth_gt = depth_from_file_values(read_pfm(depth_path), (H, W), depth_path)
    return disp, depth_gt


def _grid_model(cfg, W: int, H: int, disp, depth_gt):
    """Focal length (px), baseline and focus distance of the grid: parameters.cfg's, or the
    equivalent pinhole model when there is none (module docstring)."""
    if cfg is not None:
        f = cfg["focal_mm"] * max(W, H) / cfg["sensor_mm"]
        return f, cfg["baseline_mm"] / 1000.0, cfg["focus_m"], "parameters.cfg"
    f, b = float(W), 1.0
    if disp is not None:
        Z0 = f * b / (np.abs(disp).max() + 1.0)
    elif depth_gt is not None and np.any(np.isfinite(depth_gt)):
        Z0 = float(np.nanmedian(depth_gt))
    else:
        Z0 = f * b
    return f, b, Z0, "no parameters.cfg: f = width, b = 1, 1/Z0 = (max|d| + 1)/(f b)"


def _centre_depth(disp, depth_gt, f, b, Z0, disp_path):
    """Orthogonal depth of the centre view from its disparity: 1/Z = d/(f b) + 1/Z0."""
    if disp is None:
        return depth_gt
    inv = disp / (f * b) + 1.0 / Z0
    if np.any(inv <= 0):
        raise VibrInputError(
            f"disparity down to {disp.min():.4g} px lies beyond infinity for f·b = {f * b:.5g}, "
            f"Z0 = {Z0:.5g}", disp_path)
    return (1.0 / inv).astype(np.float32)


def load_hci(path, *, scale: float = 1.0, views=None, grid: tuple[int, int] | None = None) -> Scene:
    """Load an HCI light-field folder (see the module docstring for the camera model).

    Parameters
    ----------
    path : folder
    scale : float
        Resize factor for images, cameras and depth.
    views : list of int or str, optional
        Subset (positions in the index-sorted view list, or names such as ``input_Cam040``).
    grid : (rows, cols), optional
        Grid shape when there is no parameters.cfg.
    """

    root = Path(path)
    files = {}
    for n in sorted(os.listdir(root)):
        m = _CAM_RE.match(n)
        if m:
            files[int(m.group(1))] = root / n
    if not files:
        raise VibrInputError("no input_CamNNN.png views in this HCI light-field folder", root)

    cfg_path = root / "parameters.cfg"
    cfg = _read_cfg(cfg_path) if cfg_path.is_file() else None
    rows, cols = _grid_shape(root, files, cfg, cfg_path, grid)
    rc, cc = rows // 2, cols // 2
    centre_idx = rc * cols + cc
    W, H = _common_size(files, centre_idx, cfg, cfg_path)

    disp_path, depth_path = root / "gt_disp_lowres.pfm", root / "gt_depth_lowres.pfm"
    disp, depth_gt = _read_ground_truth(disp_path, depth_path, H, W)
    f, b, Z0, rule = _grid_model(cfg, W, H, disp, depth_gt)
    depth_c = _centre_depth(disp, depth_gt, f, b, Z0, disp_path)

    def grid_camera(i, source):
        r, c = divmod(i, cols)
        K = np.array([[f, 0.0, cx0 + (c - cc) * f * b / Z0],
                      [0.0, f, cy0 + (r - rc) * f * b / Z0],
                      [0.0, 0.0, 1.0]])
        C = np.array([(c - cc) * b, (r - rc) * b, 0.0])
        return Camera.from_centre(K, np.eye(3), C, W, H, source=source)

    cx0, cy0 = (W - 1) / 2.0, (H - 1) / 2.0
    entries, grid_pos = [], {}
    for i, p in sorted(files.items()):
        r, c = divmod(i, cols)
        cam = grid_camera(i, str(p))
        name = p.stem
        grid_pos[name] = (r, c)
        entries.append({"name": name, "path": p, "camera": cam,
                        "depth": depth_c if i == centre_idx else None})
    entries = select_entries(entries, views, root)
    vs = build_views(entries, scale, desc="reading light field")
    names = {v.name for v in vs}
    meta = {
        "format": "HCI 4D light field",
        "grid_pos": {n: rcpos for n, rcpos in grid_pos.items() if n in names},
        "centre_view": files[centre_idx].stem if centre_idx in files else None,
        "focal_px": f, "baseline": b, "focus_distance": Z0, "camera_rule": rule,
        "depth_source": disp_path.name if disp is not None else (depth_path.name if depth_gt is not None else None),
        "scale": scale,
    }
    if cfg is not None and cfg["pose"]:
        meta["centre_pose_cfg"] = cfg["pose"]
    # the grid positions without a photograph: their cameras are known, so they can be rendered
    # (``vibr render LF --target input_Cam040``; Camera.to_dict: the meta stays JSON)
    meta["missing_views"] = {f"input_Cam{i:03d}": grid_camera(i, None).scaled(scale).to_dict()
                             for i in range(rows * cols) if i not in files}
    return Scene(vs, name=root.name, root=root, grid=(rows, cols), meta=meta)


def _grid_shape(root: Path, files: dict, cfg, cfg_path: Path, grid) -> tuple[int, int]:
    """(rows, cols) of the light field: parameters.cfg's, else ``grid``, else the smallest
    square holding the largest view index (refused where that leaves the ground truth's
    centre view ambiguous)."""
    if cfg is not None:
        rows, cols = cfg["rows"], cfg["cols"]
        if grid is not None and tuple(grid) != (rows, cols):
            raise VibrInputError(f"grid {tuple(grid)} contradicts num_cams_y/x = {(rows, cols)}", cfg_path)
    elif grid is not None:
        rows, cols = (int(g) for g in grid)
    else:
        rows = cols = math.isqrt(max(files) + 1 - 1) + 1  # ceil(sqrt(max index + 1))
    if max(files) >= rows * cols:
        bad = files[max(files)]
        raise VibrInputError(f"view index {max(files)} is outside the {rows}x{cols} grid", bad)
    centre_idx = (rows // 2) * cols + cols // 2
    has_gt = (root / "gt_disp_lowres.pfm").is_file() or (root / "gt_depth_lowres.pfm").is_file()
    if cfg is None and grid is None and has_gt and centre_idx not in files:
        raise VibrInputError(
            f"the ground truth belongs to the centre view, but input_Cam{centre_idx:03d} (centre of the "
            f"{rows}x{cols} grid inferred from the largest view index) is missing: give the grid shape "
            "(load_scene(..., grid=(rows, cols))) or add parameters.cfg", root)
    return rows, cols


def _common_size(files: dict, centre_idx: int, cfg, cfg_path: Path) -> tuple[int, int]:
    """(W, H) of every view: a grid's views must share one size (the model is one sensor
    shifted), and parameters.cfg's when it gives one."""
    sizes = {i: image_size(p) for i, p in files.items()}
    ref_i = centre_idx if centre_idx in sizes else min(sizes)
    W, H = sizes[ref_i]
    for i, s in sizes.items():
        if s != (W, H):
            raise VibrInputError(
                f"light-field views must all have the same size: this one is {s[0]}x{s[1]}, "
                f"{files[ref_i].name} is {W}x{H}", files[i])
    if cfg is not None and (cfg["res_x"], cfg["res_y"]) != (W, H):
        raise VibrInputError(
            f"parameters.cfg says {cfg['res_x']}x{cfg['res_y']} but the views are {W}x{H}", cfg_path)
    return W, H


def is_hci(path: Path) -> bool:
    """An HCI light field: a folder of ``input_CamNNN.png`` views or with ``parameters.cfg``,
    or that ``parameters.cfg`` file."""
    return path.name == "parameters.cfg" if path.is_file() else is_hci_folder(path)


def _load(path, *, scale: float = 1.0, views=None, **options) -> Scene:
    p = Path(path)
    return load_hci(p.parent if p.is_file() else p, scale=scale, views=views, **options)


register_format(Format("hci", "HCI light field", is_hci, _load, looks_for="input_CamNNN.png light-field views",
                       options=("grid",), priority=20))
