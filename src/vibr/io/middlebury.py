"""Middlebury multi-view stereo ``*_par.txt`` files (Seitz et al. 2006).

Format: the number of images, then one line per image
``name k11 k12 k13 k21 k22 k23 k31 k32 k33 r11 r12 r13 r21 r22 r23 r31 r32 r33 t1 t2 t3``
with ``P = K [R | t]`` (world-to-camera, vibr's own convention). Images lie beside the file.
Pixel convention assumed: K maps to coordinates with the centre of the top-left pixel at
(0, 0) (used unchanged).
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
from .images import build_views, image_size


def find_par_file(path) -> Path | None:
    p = Path(path)
    if p.is_file() and p.name.endswith("_par.txt"):
        return p
    if p.is_dir():
        cands = sorted(p.glob("*_par.txt"))
        if cands:
            return cands[0]
    return None


def read_par(path) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """Parse a ``*_par.txt`` file → list of (image name, K, R, t)."""
    p = os.fspath(path)
    try:
        with open(p, encoding="utf-8") as f:
            lines = [ln.split() for ln in f if ln.strip()]
    except UnicodeDecodeError:
        raise VibrInputError("malformed _par.txt file (not text)", p) from None
    if not lines or len(lines[0]) != 1 or not lines[0][0].isdigit():
        raise VibrInputError("malformed _par.txt file: the first line must be the number of images", p)
    n = int(lines[0][0])
    if len(lines) - 1 != n:
        raise VibrInputError(f"malformed _par.txt file: says {n} images but has {len(lines) - 1} lines", p)
    out = []
    for i, ln in enumerate(lines[1:], start=2):
        if len(ln) != 22:
            raise VibrInputError(f"malformed _par.txt file: line {i} has {len(ln)} fields, expected 22 "
                                 "(name, K 9, R 9, t 3)", p)
        try:
            v = np.array([float(x) for x in ln[1:]])
        except ValueError:
            raise VibrInputError(f"malformed _par.txt file: non-numeric value on line {i}", p) from None
        out.append((ln[0], v[0:9].reshape(3, 3), v[9:18].reshape(3, 3), v[18:21]))
    return out


def load_middlebury(path, *, scale: float = 1.0, views=None) -> Scene:
    """Load a Middlebury scene from a ``*_par.txt`` file or a folder holding one."""

    par = find_par_file(path)
    if par is None:
        raise VibrInputError("no *_par.txt file found", path)
    root = par.parent
    entries = []
    for name, K, R, t in read_par(par):
        img = root / name
        if not img.is_file():
            raise VibrInputError(f"image listed in {par.name} not found", img)
        R = as_rotation(R, f"{par}: {name}")
        entries.append({"name": img.stem, "path": img, "camera": (K, R, t)})
    entries = select_entries(entries, views, root)
    for e in entries:
        K, R, t = e["camera"]
        w, h = image_size(e["path"])
        e["camera"] = Camera(K, R, t, w, h, source=f"{par}: {e['path'].name}")
    vs = build_views(entries, scale, desc="reading images")
    name = par.name[: -len("_par.txt")]
    return Scene(vs, name=name, root=root, meta={"format": "Middlebury", "scale": scale,
                                                 "par_file": str(par)})


def is_middlebury(path: Path) -> bool:
    """A Middlebury scene: a ``*_par.txt`` file, or a folder holding one."""
    return path.name.endswith("_par.txt") if path.is_file() else find_par_file(path) is not None


register_format(Format("middlebury", "Middlebury *_par.txt", is_middlebury, load_middlebury,
                       looks_for="a *_par.txt file", priority=40))
