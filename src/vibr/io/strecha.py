"""Strecha et al. (2008) multi-view folders (fountain-P11, Herz-Jesu, ...).

Each image ``NAME.ext`` has a camera file ``NAME.ext.camera`` (the original files are named
after the PNGs, so ``0005.png.camera`` is matched to ``0005.jpg`` too: matching is by the
image stem; ``0005.camera`` is also accepted). Camera files lie beside the images or in a
folder ``gt_dense_cameras/`` / ``cameras/`` beside them or beside the images folder.

File layout (9 lines of numbers)::

    K (3 lines)         intrinsics
    k1 k2 k3            radial distortion (must be 0: vibr handles pinholes only)
    R (3 lines)         camera-to-world rotation
    C                   camera centre (world)
    W H                 image size

Projection ``x̃ ~ K Rᵀ (X − C)``, so vibr's world-to-camera rotation is ``Rᵀ`` and
``t = −Rᵀ C``. Pixel convention assumed: ``K`` maps to coordinates with the **centre of the
top-left pixel at (0, 0)** (vibr's; the data give no way to tell, and the distinction is
0.5 px), so K is used unchanged.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..camera import Camera
from ..errors import VibrInputError
from ..scene import Scene
from .camera_json import as_rotation
from .entries import select_entries
from .formats import Format, register_format
from .images import build_views, is_image_file

_CAM_DIRS = ("gt_dense_cameras", "cameras", "gt_cameras")


def _image_dir(root: Path) -> Path:
    if (root / "images").is_dir():
        return root / "images"
    return root


def _camera_dirs(img_dir: Path) -> list[Path]:
    dirs = [img_dir]
    for base in (img_dir, img_dir.parent):
        dirs += [base / d for d in _CAM_DIRS if (base / d).is_dir()]
    return list(dict.fromkeys(dirs))


def is_strecha_folder(path) -> bool:
    p = Path(path)
    if not p.is_dir():
        return False
    return any(n.endswith(".camera") for d in _camera_dirs(_image_dir(p)) for n in os.listdir(d))


def read_strecha_camera(path) -> Camera:
    """Parse one ``.camera`` file into a vibr :class:`Camera` (see the module docstring)."""
    p = os.fspath(path)
    try:
        with open(p, encoding="ascii") as f:
            rows = [ln.split() for ln in f if ln.strip()]
        nums = [[float(x) for x in r] for r in rows]
    except (ValueError, UnicodeDecodeError):
        raise VibrInputError("malformed .camera file (non-numeric values)", p) from None
    except OSError as exc:
        raise VibrInputError(f"cannot read camera file ({exc.strerror})", p) from None
    lens = [len(r) for r in nums]
    if len(nums) < 9 or lens[:9] != [3, 3, 3, 3, 3, 3, 3, 3, 2]:
        raise VibrInputError(
            f"malformed .camera file: expected 9 lines (K 3x3, distortion 3, R 3x3, C 3, 'W H'), "
            f"got {len(nums)} lines of {lens[:9]} numbers", p)
    K = np.array(nums[0:3])
    dist = np.array(nums[3])
    R_c2w = np.array(nums[4:7])
    C = np.array(nums[7])
    w, h = nums[8]
    if np.any(dist != 0):
        raise VibrInputError(f"non-zero lens distortion {dist.tolist()}: undistort the images first "
                             "(vibr handles pinhole cameras only)", p)
    if not all(np.isfinite([w, h])) or w != int(w) or h != int(h) or not (1 <= w <= 1e6 and 1 <= h <= 1e6):
        raise VibrInputError(f"image size must be whole numbers of 1 to 10^6 pixels, got {w:g} {h:g}", p)
    R = as_rotation(R_c2w, p, "R (camera-to-world)").T
    return Camera.from_centre(K, R, C, int(w), int(h), source=p)


def load_strecha(path, *, scale: float = 1.0, views=None) -> Scene:
    """Load a Strecha folder (root with ``images/`` + ``gt_dense_cameras/``, or the images folder).

    Every image must have a camera file; a missing one raises :class:`VibrInputError` naming
    the image. No depth is loaded (the benchmark has none).
    """

    root = Path(path)
    img_dir = _image_dir(root)
    images = sorted(n for n in os.listdir(img_dir) if is_image_file(n) and (img_dir / n).is_file())
    if not images:
        raise VibrInputError("no images found in this Strecha folder", img_dir)
    cams = {}
    for d in _camera_dirs(img_dir):
        for n in sorted(os.listdir(d)):
            if n.endswith(".camera"):
                base = n[: -len(".camera")]
                stem = os.path.splitext(base)[0] if is_image_file(base) else base
                cams.setdefault(stem, d / n)
    entries = []
    for n in images:
        stem = os.path.splitext(n)[0]
        if stem not in cams:
            raise VibrInputError(
                f"no camera file for this image (looked for {stem}.*.camera in "
                f"{', '.join(str(d) for d in _camera_dirs(img_dir))})", img_dir / n)
        entries.append({"name": stem, "path": img_dir / n, "camera": cams[stem]})
    entries = select_entries(entries, views, root)
    for e in entries:
        e["camera"] = read_strecha_camera(e["camera"])
    vs = build_views(entries, scale, desc="reading images")
    name = root.name if root.name != "images" else root.parent.name
    return Scene(vs, name=name, root=root, meta={"format": "Strecha", "scale": scale,
                                                 "pixel_convention": "top-left pixel centre at (0,0)"})


register_format(Format("strecha", "Strecha", is_strecha_folder, load_strecha, looks_for="images with .camera files",
                       priority=50))
