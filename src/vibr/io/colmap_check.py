"""Validation of COLMAP sparse models before pycolmap reads them.

pycolmap's readers trust the files: a cut ``images.bin`` or ``frames.bin`` makes them read
garbage counts and loop for minutes, a cut ``points3D.bin`` allocates without bound, a cut
``cameras.bin`` can load with garbage parameters, and references to missing records end in
C++ messages (``unordered_map::at``). :func:`check_colmap_model` walks every file of the
model (binary or text; ``cameras``, ``images``, ``points3D`` and, when present, ``rigs`` and
``frames``) with bounds checks, and raises :class:`~vibr.errors.VibrInputError` naming the
file, the byte offset (binary) or line (text) and the problem:

* every record count is checked against the bytes left in the file before it is used;
* image names end with a NUL inside the file;
* camera model ids are known and each camera has its model's number of parameters, a
  size of 1 to 10⁶ pixels per side and finite parameters; poses are finite;
* nothing follows the last record; ids are unique; every reference (image → camera,
  image → frame, frame → rig, track → image and 2-D point) names an existing record.

The binary layout is COLMAP's (``src/colmap/scene/reconstruction_io_binary.cc``, little
endian). Binary files are read into memory once; the walk costs one Python step per record
(about a second per million 3-D points).
"""

from __future__ import annotations

import struct
from functools import lru_cache
from pathlib import Path

import numpy as np

from .._runtime.pycolmap import import_pycolmap
from ..errors import VibrInputError

_MAX_SIDE = 1_000_000
_SENSOR_CAMERA = 0
_SENSOR_TYPES = (-1, 0, 1)

# COLMAP camera models: id -> (name, number of parameters); pycolmap's own table when it has
# one (newer models), this one otherwise.
_MODELS_FALLBACK = {0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4),
                    3: ("RADIAL", 5), 4: ("OPENCV", 8), 5: ("OPENCV_FISHEYE", 8),
                    6: ("FULL_OPENCV", 12), 7: ("FOV", 5), 8: ("SIMPLE_RADIAL_FISHEYE", 4),
                    9: ("RADIAL_FISHEYE", 5), 10: ("THIN_PRISM_FISHEYE", 12),
                    11: ("RAD_TAN_THIN_PRISM_FISHEYE", 16)}


@lru_cache(maxsize=1)
def camera_models() -> dict[int, tuple[str, int]]:
    """COLMAP camera model id -> (name, number of parameters)."""
    try:
        pycolmap = import_pycolmap()

        out = {}
        for name, mid in pycolmap.CameraModelId.__members__.items():
            if int(mid) < 0:
                continue
            cam = pycolmap.Camera.create_from_model_id(1, mid, 1.0, 1, 1)
            out[int(mid)] = (name, len(cam.params))
        return out or dict(_MODELS_FALLBACK)
    except Exception:  # an older pycolmap: the classic models
        return dict(_MODELS_FALLBACK)


class _Model:
    """What the walk found: the records and their references."""

    def __init__(self):
        self.cameras: set[int] = set()
        self.rigs: set[int] = set()
        self.frames: set[int] = set()
        self.frame_images: dict[int, str] = {}  # image id -> where (for messages)
        self.frame_refs: list[tuple[int, str]] = []  # (rig id, where)
        self.images: dict[int, int] = {}  # image id -> number of 2-D points
        self.image_refs: list[tuple[int, int, str]] = []  # (image id, camera id, where)
        self.track_img: list[np.ndarray] = []
        self.track_idx: list[np.ndarray] = []
        self.track_where: str = ""
        self.has_frames = False


# ----------------------------------------------------------------------------- binary
class _Reader:
    def __init__(self, path: Path):
        self.path = path
        with open(path, "rb") as f:
            self.data = f.read()
        self.pos = 0

    def fail(self, problem: str, at: int | None = None):
        raise VibrInputError(f"{problem} (byte {self.pos if at is None else at})", self.path)

    def left(self) -> int:
        return len(self.data) - self.pos

    def take(self, fmt: str, what: str):
        n = struct.calcsize(fmt)
        if self.left() < n:
            self.fail(f"file cut short: {what} needs {n} bytes, {self.left()} left")
        out = struct.unpack_from(fmt, self.data, self.pos)
        self.pos += n
        return out

    def count(self, what: str, min_size: int, fmt: str = "<Q") -> int:
        at = self.pos
        (n,) = self.take(fmt, f"the number of {what}")
        if n * min_size > self.left():
            self.fail(f"{n} {what} need at least {n * min_size} bytes, {self.left()} left "
                      "(file cut short or not a COLMAP model)", at)
        return n

    def name(self, what: str) -> str:
        end = self.data.find(b"\0", self.pos)
        if end < 0:
            self.fail(f"{what}: name not terminated (no NUL byte before the end of the file)")
        raw = self.data[self.pos:end]
        if not raw:
            self.fail(f"{what}: empty name")
        self.pos = end + 1
        return raw.decode("utf-8", "replace")

    def finite(self, values, what: str, at: int):
        if not all(np.isfinite(values)):
            self.fail(f"{what}: non-finite value", at)

    def end(self):
        if self.left():
            self.fail(f"{self.left()} bytes after the last record (not a COLMAP model, or a wrong count)")


def _unique(ids: set, i: int, what: str, r):
    if i in ids:
        r.fail(f"{what} {i} is defined twice")
    ids.add(i)


def _bin_cameras(path: Path, m: _Model):
    r, models = _Reader(path), camera_models()
    for _ in range(r.count("cameras", 24 + 8)):
        at = r.pos
        cid, mid, w, h = r.take("<IiQQ", "a camera record")
        if mid not in models:
            r.fail(f"camera {cid}: unknown camera model id {mid}", at + 4)
        if not (1 <= w <= _MAX_SIDE and 1 <= h <= _MAX_SIDE):
            r.fail(f"camera {cid}: image size {w}x{h} is out of range", at + 8)
        n = models[mid][1]
        params = r.take(f"<{n}d", f"camera {cid}'s {n} parameters ({models[mid][0]})")
        r.finite(params, f"camera {cid} parameters", at + 24)
        _unique(m.cameras, cid, "camera", r)
    r.end()


def _bin_rigs(path: Path, m: _Model):
    r = _Reader(path)
    for _ in range(r.count("rigs", 8)):
        (rid,) = r.take("<I", "a rig id")
        ns = r.count(f"sensors of rig {rid}", 8, "<I")
        if ns:
            r.take("<iI", "the reference sensor")
        for _ in range(max(0, ns - 1)):
            at = r.pos
            st, _sid, has = r.take("<iIB", "a sensor")
            if st not in _SENSOR_TYPES or has not in (0, 1):
                r.fail(f"rig {rid}: bad sensor record", at)
            if has:
                r.finite(r.take("<7d", "a sensor pose"), f"rig {rid} sensor pose", at + 9)
        _unique(m.rigs, rid, "rig", r)
    r.end()


def _bin_frames(path: Path, m: _Model):
    r = _Reader(path)
    m.has_frames = True
    for _ in range(r.count("frames", 4 + 4 + 56 + 4)):
        at = r.pos
        fid, rid = r.take("<II", "a frame record")
        r.finite(r.take("<7d", f"frame {fid}'s pose"), f"frame {fid} pose", at + 8)
        nd = r.count(f"data ids of frame {fid}", 16, "<I")
        for _ in range(nd):
            st, _sid, did = r.take("<iIQ", "a data id")
            if st not in _SENSOR_TYPES:
                r.fail(f"frame {fid}: unknown sensor type {st}", r.pos - 16)
            if st == _SENSOR_CAMERA:
                m.frame_images[did] = f"{path} (frame {fid})"
        m.frame_refs.append((rid, f"{path}: frame {fid} (byte {at})"))
        _unique(m.frames, fid, "frame", r)
    r.end()


def _bin_images(path: Path, m: _Model):
    r = _Reader(path)
    for _ in range(r.count("images", 4 + 56 + 4 + 2 + 8)):
        at = r.pos
        (iid,) = r.take("<I", "an image id")
        pose = r.take("<7d", f"image {iid}'s pose")
        r.finite(pose, f"image {iid} pose", at + 4)
        (cid,) = r.take("<I", f"image {iid}'s camera id")
        name = r.name(f"image {iid}")
        npts = r.count(f"2-D points of image {iid} ({name})", 24)
        r.pos += 24 * npts
        if iid in m.images:
            r.fail(f"image {iid} is defined twice", at)
        m.images[iid] = npts
        m.image_refs.append((iid, cid, f"{path}: image {iid} {name} (byte {at})"))
    r.end()


def _bin_points(path: Path, m: _Model):
    r = _Reader(path)
    ids, spans = [], []
    for _ in range(r.count("3-D points", 8 + 24 + 3 + 8 + 8)):
        at = r.pos
        pid, x, y, z, _r, _g, _b, _err, n = r.take("<Q3d3BdQ", "a 3-D point")
        if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(z)):
            r.fail(f"3-D point {pid}: non-finite position", at + 8)
        if 8 * n > r.left():
            r.fail(f"3-D point {pid}: a track of {n} elements needs {8 * n} bytes, {r.left()} left", at + 43)
        spans.append((r.pos, n))
        r.pos += 8 * n
        ids.append(pid)
    r.end()
    _check_unique_points(np.array(ids, dtype=np.uint64), path)
    if spans:
        dt = np.dtype([("img", "<u4"), ("idx", "<u4")])
        tr = np.frombuffer(b"".join(r.data[p:p + 8 * n] for p, n in spans), dtype=dt)
        m.track_img.append(tr["img"].astype(np.int64))
        m.track_idx.append(tr["idx"].astype(np.int64))
    m.track_where = str(path)


def _check_unique_points(ids: np.ndarray, path):
    if len(ids) and len(np.unique(ids)) != len(ids):
        raise VibrInputError("a 3-D point id is defined twice", path)


# ----------------------------------------------------------------------------- text
def _lines(path: Path):
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise VibrInputError(f"cannot read ({exc.strerror})", path) from None
    for k, ln in enumerate(text.splitlines(), 1):
        s = ln.strip()
        if s and not s.startswith("#"):
            yield k, s.split()


def _num(tok: str, kind, path, k: int, what: str):
    try:
        v = kind(tok)
    except ValueError:
        raise VibrInputError(f"line {k}: {what} is not a{'n integer' if kind is int else ' number'}: {tok!r}",
                             path) from None
    if kind is float and not np.isfinite(v):
        raise VibrInputError(f"line {k}: {what} is not finite", path)
    if kind is int and not 0 <= v < 2**32:
        raise VibrInputError(f"line {k}: {what} {v} is out of range", path)
    return v


def _txt_cameras(path: Path, m: _Model):
    names = {name: n for name, n in camera_models().values()}
    for k, t in _lines(path):
        if len(t) < 4:
            raise VibrInputError(f"line {k}: a camera needs CAMERA_ID MODEL WIDTH HEIGHT PARAMS", path)
        cid = _num(t[0], int, path, k, "camera id")
        if t[1] not in names:
            raise VibrInputError(f"line {k}: unknown camera model {t[1]!r}", path)
        w, h = (_num(v, int, path, k, "image size") for v in t[2:4])
        if not (1 <= w <= _MAX_SIDE and 1 <= h <= _MAX_SIDE):
            raise VibrInputError(f"line {k}: image size {w}x{h} is out of range", path)
        if len(t) - 4 != names[t[1]]:
            raise VibrInputError(f"line {k}: {t[1]} has {names[t[1]]} parameters, got {len(t) - 4}", path)
        for v in t[4:]:
            _num(v, float, path, k, "a camera parameter")
        if cid in m.cameras:
            raise VibrInputError(f"line {k}: camera {cid} is defined twice", path)
        m.cameras.add(cid)


def _pose(t, path, k, what):
    for v in t:
        _num(v, float, path, k, what)


def _txt_rigs(path: Path, m: _Model):
    for k, t in _lines(path):
        if len(t) < 2:
            raise VibrInputError(f"line {k}: a rig needs RIG_ID NUM_SENSORS ...", path)
        rid, ns = _num(t[0], int, path, k, "rig id"), _num(t[1], int, path, k, "sensor count")
        pos = 2
        if ns:
            if len(t) < 4 or t[2] not in ("CAMERA", "IMU"):
                raise VibrInputError(f"line {k}: rig {rid} has no valid reference sensor", path)
            _num(t[3], int, path, k, "sensor id")
            pos = 4
        for _ in range(max(0, ns - 1)):
            if len(t) < pos + 3 or t[pos] not in ("CAMERA", "IMU") or t[pos + 2] not in ("0", "1"):
                raise VibrInputError(f"line {k}: rig {rid}: bad sensor record", path)
            _num(t[pos + 1], int, path, k, "sensor id")
            has = t[pos + 2] == "1"
            pos += 3
            if has:
                if len(t) < pos + 7:
                    raise VibrInputError(f"line {k}: rig {rid}: sensor pose cut short", path)
                _pose(t[pos:pos + 7], path, k, "a sensor pose value")
                pos += 7
        if pos != len(t):
            raise VibrInputError(f"line {k}: rig {rid}: {len(t) - pos} unexpected values", path)
        if rid in m.rigs:
            raise VibrInputError(f"line {k}: rig {rid} is defined twice", path)
        m.rigs.add(rid)


def _txt_frames(path: Path, m: _Model):
    m.has_frames = True
    for k, t in _lines(path):
        if len(t) < 10:
            raise VibrInputError(f"line {k}: a frame needs FRAME_ID RIG_ID QW QX QY QZ TX TY TZ NUM_DATA_IDS", path)
        fid, rid = _num(t[0], int, path, k, "frame id"), _num(t[1], int, path, k, "rig id")
        _pose(t[2:9], path, k, "a pose value")
        nd = _num(t[9], int, path, k, "data id count")
        if len(t) != 10 + 3 * nd:
            raise VibrInputError(f"line {k}: frame {fid} lists {nd} data ids but has {len(t) - 10} values "
                                 f"(expected {3 * nd})", path)
        for j in range(nd):
            st, sid, did = t[10 + 3 * j:13 + 3 * j]
            if st not in ("CAMERA", "IMU"):
                raise VibrInputError(f"line {k}: frame {fid}: unknown sensor type {st!r}", path)
            _num(sid, int, path, k, "sensor id")
            did = _num(did, int, path, k, "data id")
            if st == "CAMERA":
                m.frame_images[did] = f"{path} (frame {fid})"
        m.frame_refs.append((rid, f"{path}: line {k}: frame {fid}"))
        if fid in m.frames:
            raise VibrInputError(f"line {k}: frame {fid} is defined twice", path)
        m.frames.add(fid)


def _txt_images(path: Path, m: _Model):
    rows = list(_lines_keep_empty(path))
    i = 0
    while i < len(rows):
        k, t = rows[i]
        if not t:
            i += 1
            continue
        if len(t) < 10:
            raise VibrInputError(f"line {k}: an image needs IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME", path)
        iid = _num(t[0], int, path, k, "image id")
        _pose(t[1:8], path, k, "a pose value")
        cid = _num(t[8], int, path, k, "camera id")
        pts = rows[i + 1][1] if i + 1 < len(rows) else []
        if len(pts) % 3:
            raise VibrInputError(f"line {k + 1}: 2-D points come in triples X Y POINT3D_ID, got {len(pts)} values",
                                 path)
        for v in pts[0::3] + pts[1::3]:
            _num(v, float, path, k + 1, "a 2-D point coordinate")
        for v in pts[2::3]:
            if v != "-1":
                _num(v, int, path, k + 1, "a 3-D point id")
        if iid in m.images:
            raise VibrInputError(f"line {k}: image {iid} is defined twice", path)
        m.images[iid] = len(pts) // 3
        m.image_refs.append((iid, cid, f"{path}: line {k}: image {iid}"))
        i += 2


def _lines_keep_empty(path: Path):
    """(line number, tokens) of images.txt with empty 2-D point lines kept (comments dropped)."""
    text = Path(path).read_text(encoding="utf-8", errors="replace")
    for k, ln in enumerate(text.splitlines(), 1):
        if not ln.strip().startswith("#"):
            yield k, ln.split()


def _txt_points(path: Path, m: _Model):
    ids, img, idx = [], [], []
    for k, t in _lines(path):
        if len(t) < 8 or (len(t) - 8) % 2:
            raise VibrInputError(f"line {k}: a 3-D point needs POINT3D_ID X Y Z R G B ERROR and pairs "
                                 "IMAGE_ID POINT2D_IDX", path)
        ids.append(_num(t[0], int, path, k, "3-D point id"))
        _pose(t[1:4], path, k, "a coordinate")
        for v in t[4:7]:
            if not 0 <= _num(v, int, path, k, "a colour") <= 255:
                raise VibrInputError(f"line {k}: colour out of 0..255", path)
        _num(t[7], float, path, k, "the error") if t[7] != "-1" else None
        tr = [_num(v, int, path, k, "a track entry") for v in t[8:]]
        img += tr[0::2]
        idx += tr[1::2]
    _check_unique_points(np.array(ids, dtype=np.uint64), path)
    m.track_img.append(np.array(img, dtype=np.int64))
    m.track_idx.append(np.array(idx, dtype=np.int64))
    m.track_where = str(path)


# ----------------------------------------------------------------------------- references
def _check_refs(m: _Model, model_dir: Path):
    for rid, where in m.frame_refs:
        if m.rigs and rid not in m.rigs:
            raise VibrInputError(f"{where} names rig {rid}, which the model does not define", model_dir)
    for iid, cid, where in m.image_refs:
        if cid not in m.cameras:
            raise VibrInputError(f"{where} names camera {cid}, which the model does not define", model_dir)
        if m.has_frames and iid not in m.frame_images:
            raise VibrInputError(f"{where} belongs to no frame of frames.bin/.txt", model_dir)
    if m.track_img:
        img, idx = np.concatenate(m.track_img), np.concatenate(m.track_idx)
        if len(img):
            known = np.array(sorted(m.images), dtype=np.int64)
            npts = np.array([m.images[i] for i in sorted(m.images)], dtype=np.int64)
            pos = np.searchsorted(known, img)
            ok = (pos < len(known)) & (known[np.minimum(pos, len(known) - 1)] == img) if len(known) else \
                np.zeros(len(img), bool)
            if not ok.all():
                bad = int(img[~ok][0])
                raise VibrInputError(f"a track names image {bad}, which the model does not define",
                                     m.track_where)
            if np.any(idx >= npts[pos]):
                j = int(np.argmax(idx >= npts[pos]))
                raise VibrInputError(f"a track names 2-D point {int(idx[j])} of image {int(img[j])}, "
                                     f"which has {int(npts[pos][j])}", m.track_where)


def check_colmap_model(model_dir) -> str:
    """Validate the COLMAP model in ``model_dir``; returns ``"bin"`` or ``"txt"`` (the files
    pycolmap will read: binary when ``cameras.bin`` exists, as pycolmap does).

    Raises :class:`VibrInputError` naming the file and the problem (see the module
    docstring).
    """
    d = Path(model_dir)
    ext = "bin" if (d / "cameras.bin").is_file() else "txt"
    m = _Model()
    readers = ({"rigs": _bin_rigs, "cameras": _bin_cameras, "frames": _bin_frames, "images": _bin_images,
                "points3D": _bin_points} if ext == "bin" else
               {"rigs": _txt_rigs, "cameras": _txt_cameras, "frames": _txt_frames, "images": _txt_images,
                "points3D": _txt_points})
    for name, fn in readers.items():
        p = d / f"{name}.{ext}"
        if p.is_file():
            fn(p, m)
        elif name in ("cameras", "images"):
            raise VibrInputError(f"the COLMAP model has no {name}.{ext}", d)
    if (d / f"frames.{ext}").is_file() != (d / f"rigs.{ext}").is_file():
        raise VibrInputError(f"the COLMAP model has only one of rigs.{ext} and frames.{ext}", d)
    _check_refs(m, d)
    return ext
