"""COLMAP sparse models (read through ``pycolmap.Reconstruction``).

Layouts recognised (``root`` is what the user passes, or the model folder itself)::

    root/sparse/0/{cameras,images,points3D}.{bin,txt}   root/images/   (mapper output)
    root/sparse/{cameras,images,points3D}.{bin,txt}     root/images/   (image_undistorter output)
    root/stereo/depth_maps/NAME.geometric.bin           dense depth, used when present

Cameras: PINHOLE and SIMPLE_PINHOLE as they are; the distorted models (the mapper's
SIMPLE_RADIAL, OPENCV, the fisheyes, ...) are undistorted at load onto COLMAP's own pinhole
for them (:mod:`vibr.io.undistort`, as ``colmap image_undistorter`` would). COLMAP puts the
centre of the top-left pixel at (0.5, 0.5), so vibr's principal point is ``(cx − 0.5,
cy − 0.5)``. Poses are COLMAP's ``cam_from_world`` (world → camera, OpenCV axes, vibr's own
convention). Only registered images are loaded, listed by name (COLMAP's image ids follow
the order of registration). Points3D go to ``scene.points``.
"""

from __future__ import annotations

import logging
import struct
from pathlib import Path

import numpy as np

from .._runtime.pycolmap import import_pycolmap
from ..camera import Camera
from ..errors import VibrInputError
from ..scene import Scene
from .camera_json import as_rotation
from .colmap_check import check_colmap_model
from .depthfiles import fit_depth, read_depth
from .entries import select_entries
from .formats import Format, register_format
from .images import build_views
from .undistort import Distortion, check_lens, pinhole
from .undistort import summary as undistort_summary

logger = logging.getLogger(__name__)

_MODEL_FILES = ("cameras", "images")
_ZERO_DIST_OK = ("SIMPLE_RADIAL", "RADIAL", "OPENCV", "FULL_OPENCV")


def _is_model_dir(p: Path) -> bool:
    return p.is_dir() and all((p / f"{n}.bin").is_file() or (p / f"{n}.txt").is_file() for n in _MODEL_FILES)


def find_colmap_model(path) -> tuple[Path, Path] | None:
    """(model folder, scene root) for a COLMAP layout at ``path``, or None."""
    p = Path(path)
    if _is_model_dir(p):
        if p.parent.name == "sparse":
            return p, p.parent.parent
        if p.name == "sparse":
            return p, p.parent
        return p, p
    for cand in (p / "sparse" / "0", p / "sparse", p / "dense" / "sparse", p / "dense" / "0" / "sparse"):
        if _is_model_dir(cand):
            return cand, cand.parent.parent if cand.name == "0" else cand.parent
    return None


def _image_count(model: Path) -> int | None:
    """Images in a model folder, from images.bin's header or images.txt's two lines per
    image; None when unreadable (the model's own check names the problem if it is loaded)."""
    try:
        if (model / "images.bin").is_file():
            with open(model / "images.bin", "rb") as fh:
                return struct.unpack("<Q", fh.read(8))[0]
        lines = (model / "images.txt").read_text(encoding="utf-8", errors="replace").splitlines()
        return len([ln for ln in lines if not ln.strip().startswith("#")]) // 2
    except (OSError, struct.error):
        return None


def _note_other_models(model: Path) -> None:
    """COLMAP's mapper writes one numbered folder per disconnected reconstruction; vibr loads
    ``sparse/0``, the convention (nerfstudio's too), and says what else is there."""
    others = sorted((d for d in model.parent.iterdir() if d.name.isdigit() and d != model and _is_model_dir(d)),
                    key=lambda d: int(d.name))
    if not others:
        return
    n0 = _image_count(model)
    listed = ", ".join(f"{d.name} ({_image_count(d)} images)" for d in others)
    larger = [d for d in others if (_image_count(d) or 0) > (n0 or 0)]
    hint = f"; the largest is {max(larger, key=lambda d: _image_count(d) or 0)}" if larger else ""
    logger.warning(f"{model.parent}: COLMAP made {len(others) + 1} reconstructions; loading {model.name} "
                   f"({n0} images), not {listed}{hint}: pass a model folder to load another")


def colmap_camera(cam, source):
    """vibr's K (top-left pixel centre at (0, 0)), width and height of a pycolmap camera,
    and its :class:`~vibr.io.undistort.Distortion` (None for a pinhole): a distorted camera
    is given as the pinhole its image is undistorted onto at load."""
    model = cam.model.name
    params = np.asarray(cam.params, dtype=np.float64)
    extra = [int(i) for i in cam.extra_params_idxs()]
    if model not in ("PINHOLE", "SIMPLE_PINHOLE") and (model not in _ZERO_DIST_OK or np.any(params[extra] != 0)):
        dist = Distortion(model, tuple(params.tolist()), int(cam.width), int(cam.height))
        try:
            K, w, h = pinhole(dist)
        except Exception as exc:  # noqa: BLE001 - COLMAP's words for a model it cannot undistort
            raise VibrInputError(f"camera {cam.camera_id} ({model}) cannot be undistorted: {exc}", source) from None
        return K, w, h, check_lens(dist, f"{source} (camera {cam.camera_id})")
    fx, fy = float(cam.focal_length_x), float(cam.focal_length_y)
    cx, cy = float(cam.principal_point_x) - 0.5, float(cam.principal_point_y) - 0.5
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]), int(cam.width), int(cam.height), None


def load_colmap(path, *, scale: float = 1.0, views=None) -> Scene:
    """Load a COLMAP sparse model (+ images, + dense geometric depth maps when present)."""

    rec, model, root = _read_reconstruction(path)
    img_dirs = [d for d in (root / "images", model / "images", model.parent / "images") if d.is_dir()]
    if not img_dirs:
        raise VibrInputError("no images folder found beside the COLMAP model (expected root/images)", root)
    entries = _image_entries(rec, model, img_dirs[0], root / "stereo" / "depth_maps")
    entries = select_entries(entries, views, root)
    n_depth = _attach_depth(entries)
    undistorted = undistort_summary(entries)
    vs = build_views(entries, scale, desc="reading images")
    pts = np.array([p.xyz for p in rec.points3D.values()], dtype=np.float64).reshape(-1, 3)
    return Scene(vs, name=root.name, root=root, points=pts if len(pts) else None,
                 meta={"format": "COLMAP", "scale": scale, "model": str(model),
                       "depth_source": "stereo/depth_maps/*.geometric.bin" if n_depth else None,
                       **({"undistorted": undistorted} if undistorted else {})})


def _read_reconstruction(path):
    """``(reconstruction, model folder, scene root)``: the model found under ``path``,
    checked before pycolmap reads it."""
    pycolmap = import_pycolmap()
    found = find_colmap_model(path)
    if found is None:
        raise VibrInputError("no COLMAP model (cameras + images .bin/.txt) found", path)
    model, root = found
    if model.parent.name == "sparse" and model.name.isdigit() and Path(path) != model:
        _note_other_models(model)
    check_colmap_model(model)  # bounds, counts and references: pycolmap trusts the files
    try:
        rec = pycolmap.Reconstruction(str(model))
    except Exception:  # what the check above does not cover; pycolmap's words are C++ internals
        raise VibrInputError("inconsistent COLMAP model: pycolmap cannot read it (records that "
                             "contradict each other)", model) from None
    return rec, model, root


def _image_entries(rec, model: Path, img_dir: Path, depth_dir: Path) -> list:
    """One loader entry per registered image, by name (as a folder lists them)."""
    entries = []
    for iid in sorted(rec.images, key=lambda i: (rec.images[i].name, i)):
        im = rec.images[iid]
        if not im.has_pose:
            continue
        src = f"{model} image {im.name}"
        K, w, h, dist = colmap_camera(rec.cameras[im.camera_id], src)
        T = im.cam_from_world() if callable(im.cam_from_world) else im.cam_from_world
        R = as_rotation(T.rotation.matrix(), src)
        t = np.asarray(T.translation, dtype=np.float64)
        e = {"name": Path(im.name).with_suffix("").as_posix(), "path": img_dir / im.name,
             "camera": Camera(K, R, t, w, h, source=src), "depth_path": depth_dir / f"{im.name}.geometric.bin"}
        if dist is not None:
            e["distortion"] = dist
        entries.append(e)
    if not entries:
        raise VibrInputError("the COLMAP model has no registered images", model)
    return entries


def _attach_depth(entries: list) -> int:
    """Read each entry's dense depth map where COLMAP wrote one; the number read."""
    n_depth = 0
    for e in entries:
        dp = e.pop("depth_path")
        if dp.is_file():
            # COLMAP's dense maps are at its max_image_size (often smaller than the images)
            d = e.get("distortion")
            shape = e["camera"].shape if d is None else (d.height, d.width)
            e["depth"] = fit_depth(read_depth(dp), shape, dp, f"image {e['name']}")
            n_depth += 1
    return n_depth


def is_colmap(path: Path) -> bool:
    """A COLMAP sparse model: a folder holding one (``sparse/0``, ``sparse``, ...) or the model
    folder itself (never a file)."""
    return not path.is_file() and find_colmap_model(path) is not None


register_format(Format("colmap", "COLMAP sparse model", is_colmap, load_colmap, looks_for="a COLMAP sparse model",
                       priority=30))
