"""Views and scenes.

A :class:`View` is one calibrated photograph: an H×W×3 float32 image in [0, 1], its
:class:`~vibr.camera.Camera`, and optionally an orthogonal depth map (H×W float32, scene
units, **NaN where depth is unknown**) and a depth uncertainty ``sigma_z`` (scalar or H×W,
scene units). A :class:`Scene` is an ordered list of views plus metadata (light-field
grid shape, sparse points, where it was loaded from).

A *target* is what to render: a held-out :class:`View` (its image is then the reference)
or a bare :class:`Camera` (intrinsics, pose and size).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable, Union

import numpy as np

from .camera import Camera, shared_centre
from .errors import VibrInputError


def check_depth(depth, shape, source=None, what="depth") -> np.ndarray:
    """Validate an orthogonal depth map as stored in memory.

    Returns an H×W float32 array. NaN marks unknown depth; ±inf, negative or zero values
    and a shape other than ``shape`` raise :class:`VibrInputError`.
    """
    d = np.asarray(depth)
    if d.ndim == 3 and d.shape[2] == 1:
        d = d[..., 0]
    if d.shape != tuple(shape):
        raise VibrInputError(f"{what} has shape {d.shape[:2]}, image has {tuple(shape)}", source)
    d = d.astype(np.float32, copy=False)
    finite = np.isfinite(d)
    if np.any(np.isinf(d)):
        raise VibrInputError(f"{what} has {int(np.isinf(d).sum())} infinite values", source)
    if np.any(d[finite] <= 0):
        raise VibrInputError(
            f"{what} has {int((d[finite] <= 0).sum())} zero or negative values "
            f"(min {float(d[finite].min()):.4g})",
            source,
        )
    return d


#: How far outside [0, 1] a float image may stray (resampling overshoot) before it is taken
#: for an image in other units (0..255) and refused.
IMAGE_RANGE_TOL = 1e-3


def check_image(img, source=None) -> np.ndarray:
    """An H×W×3 image as vibr holds it: contiguous float32 in [0, 1]. Unsigned integers are
    scaled by their type's range (uint8 / 255, uint16 / 65535), as scikit-image's
    ``img_as_float`` does; a float image outside [0, 1] (values in 0..255, NaN) or of another
    type is refused rather than rendered as nonsense."""
    a = np.asarray(img)
    if a.dtype.kind == "u":
        return np.ascontiguousarray(a, dtype=np.float32) / np.float32(np.iinfo(a.dtype).max)
    if a.dtype.kind != "f":
        raise VibrInputError(f"image must be float in [0, 1] or unsigned integers, got {a.dtype}", source)
    a = np.ascontiguousarray(a, dtype=np.float32)
    lo, hi = (float(a.min()), float(a.max())) if a.size else (0.0, 0.0)
    if not (lo >= -IMAGE_RANGE_TOL and hi <= 1.0 + IMAGE_RANGE_TOL):  # NaN and inf fail too
        hint = " (8-bit values as floats? divide by 255)" if hi > 2.0 else ""
        raise VibrInputError(f"float image values must lie in [0, 1], found {lo:.4g} .. {hi:.4g}{hint}", source)
    return a


def check_sigma_z(sigma_z, shape, source=None):
    """Depth uncertainty (scene units): a finite scalar >= 0, or an H×W map of values >= 0
    (NaN where unknown). Negative or infinite values are refused (the weights square them)."""
    if np.ndim(sigma_z) == 0:
        s = float(sigma_z)
        if not (math.isfinite(s) and s >= 0):
            raise VibrInputError(f"sigma_z must be finite and >= 0, got {s}", source)
        return s
    m = np.asarray(sigma_z, dtype=np.float32)
    if m.shape != tuple(shape):
        raise VibrInputError(f"sigma_z has shape {m.shape}, image has {tuple(shape)}", source)
    if np.any(np.isinf(m)) or np.any(m[np.isfinite(m)] < 0):
        raise VibrInputError("sigma_z map has negative or infinite values", source)
    return m


def depth_from_file_values(values, shape, source=None, what="depth") -> np.ndarray:
    """Convert depth as read from a file to vibr's in-memory form.

    In files, ``0`` marks unknown depth (the COLMAP / 16-bit PNG convention); NaN, inf
    and negative values are errors. Returns H×W float32 with NaN where unknown.
    """
    d = np.asarray(values, dtype=np.float64)
    if d.ndim == 3 and d.shape[2] == 1:
        d = d[..., 0]
    if np.any(np.isnan(d)):
        raise VibrInputError(f"{what} has {int(np.isnan(d).sum())} NaN values", source)
    if np.any(np.isinf(d)):
        raise VibrInputError(f"{what} has {int(np.isinf(d).sum())} infinite values", source)
    if np.any(d < 0):
        raise VibrInputError(
            f"{what} has {int((d < 0).sum())} negative values (min {d.min():.4g})", source
        )
    d = d.astype(np.float32)
    d[d == 0] = np.nan
    return check_depth(d, shape, source, what)


@dataclass(eq=False)
class View:
    """One calibrated image.

    Attributes
    ----------
    name : str
        Identifier, normally the image file's stem (``input_Cam040``, ``0005``).
    image : ndarray or None
        H×W×3 float32 in [0, 1]; None for a bare target camera.
    camera : Camera
    depth : ndarray or None
        H×W float32 orthogonal depth in scene units, NaN where unknown.
    sigma_z : float, ndarray or None
        Depth uncertainty (standard deviation, scene units), scalar or H×W.
    path : str or None
        The image file, for messages.
    fallback : ndarray or None
        H×W bool: the pixels whose depth is not a measurement but the fallback proxy
        (:func:`vibr.geometry.fallback_depth`); the geometry stage lets known depth hide
        them. Reset to None by :meth:`replace` when the depth changes without it.
    mask : ndarray or None
        H×W bool: the pixels of the photograph that show the scene (nerfstudio's
        ``mask_path``, 0 = ignore: a passer-by, the photographer's shadow, a fisheye's black
        surround). The others give the renderer no sample and hide nothing (their depth is
        unknown to the geometry stage, :func:`vibr.geometry.prepare_depth`), and a held-out
        view is measured on its mask only. None: the whole photograph.
    """

    name: str
    image: np.ndarray | None
    camera: Camera
    depth: np.ndarray | None = None
    sigma_z: float | np.ndarray | None = None
    path: str | None = None
    fallback: np.ndarray | None = None
    mask: np.ndarray | None = None

    def __post_init__(self):
        src = self.path or self.name
        if self.image is not None:
            img = np.asarray(self.image)
            if img.ndim == 2:
                img = np.repeat(img[..., None], 3, axis=2)
            if img.ndim != 3 or img.shape[2] != 3:
                raise VibrInputError(f"image must be H×W×3, got shape {img.shape}", src)
            if img.shape[:2] != self.camera.shape:
                raise VibrInputError(
                    f"image is {img.shape[1]}x{img.shape[0]} but its camera is "
                    f"{self.camera.width}x{self.camera.height}",
                    src,
                )
            self.image = check_image(img, src)
        if self.depth is not None:
            self.depth = check_depth(self.depth, self.camera.shape, src)
        if self.sigma_z is not None:
            self.sigma_z = check_sigma_z(self.sigma_z, self.camera.shape, src)
        if self.fallback is not None:
            m = np.asarray(self.fallback, dtype=bool)
            if m.shape != self.camera.shape:
                raise VibrInputError(f"fallback mask has shape {m.shape}, image has {self.camera.shape}", src)
            self.fallback = m if m.any() else None
        if self.mask is not None:
            m = np.asarray(self.mask)
            if m.shape != self.camera.shape:
                raise VibrInputError(f"mask is {m.shape[1::-1] if m.ndim >= 2 else m.shape} but the image is "
                                     f"{self.camera.width}x{self.camera.height}", src)
            m = m.astype(bool)
            if not m.any():
                raise VibrInputError("mask excludes every pixel of the photograph", src)
            self.mask = None if m.all() else m

    @property
    def shape(self) -> tuple[int, int]:
        return self.camera.shape

    @property
    def has_depth(self) -> bool:
        return self.depth is not None

    def depth_range(self) -> tuple[float, float] | None:
        if self.depth is None or not np.any(np.isfinite(self.depth)):
            return None
        return float(np.nanmin(self.depth)), float(np.nanmax(self.depth))

    def replace(self, **changes) -> "View":
        if "depth" in changes and "fallback" not in changes:
            changes["fallback"] = None  # a new depth map says nothing of the old one's proxy
        return replace(self, **changes)


Target = Union[View, Camera]


@dataclass(eq=False)
class Scene:
    """An ordered collection of views.

    Attributes
    ----------
    views : list of View
    name : str
    root : Path or None
        Folder the scene was loaded from.
    grid : (rows, cols) or None
        For light fields, the grid shape; view ``i`` is at row ``i // cols``, column
        ``i % cols``.
    points : (N, 3) ndarray or None
        Sparse world points (from SfM), used to bound depth ranges.
    meta : dict
        Anything else a loader knows (format, depth kind, baseline, ...).
    """

    views: list[View]
    name: str = "scene"
    root: Path | None = None
    grid: tuple[int, int] | None = None
    points: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        if len(self.views) == 0:
            raise VibrInputError("scene has no views", self.root)
        bad = next((v for v in self.views if not isinstance(v, View)), None)
        if bad is not None:
            raise VibrInputError(f"a scene holds View objects, got {type(bad).__name__}", self.root)
        names = [v.name for v in self.views]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise VibrInputError(f"duplicate view names: {sorted(dup)}", self.root)

    def __len__(self) -> int:
        return len(self.views)

    def replace(self, **fields) -> "Scene":
        """A copy with ``fields`` changed (:func:`dataclasses.replace`); ``meta`` is copied
        unless given, so that the copy's metadata can change without touching this one."""
        fields.setdefault("meta", dict(self.meta))
        return replace(self, **fields)

    def __iter__(self):
        return iter(self.views)

    @property
    def names(self) -> list[str]:
        return [v.name for v in self.views]

    def index(self, key: int | str) -> int:
        """Index of a view given by index, name (file stem) or numeric string."""
        if isinstance(key, (int, np.integer)):
            i = int(key)
            if not 0 <= i < len(self.views):  # -1 is an error, not the last view
                raise VibrInputError(f"no view {i}: the scene has {len(self.views)} views "
                                     f"(indices 0 to {len(self.views) - 1})", self.root)
            return i
        key = str(key)
        names = self.names
        if key in names:
            return names.index(key)
        stem = Path(key).stem
        if stem in names:
            return names.index(stem)
        if key.lstrip("-").isdigit():
            return self.index(int(key))
        if stem in (self.meta.get("missing_views") or {}):
            raise VibrInputError(f"{stem} is missing from this light field: there is no photograph of it "
                                 f"(vibr render --target {stem} renders it at its grid position)", self.root)
        raise VibrInputError(
            f"no view named {key!r} (views: {', '.join(names[:6])}{', ...' if len(names) > 6 else ''})",
            self.root,
        )

    def __getitem__(self, key: int | str) -> View:
        return self.views[self.index(key)]

    def subset(self, keys: Iterable[int | str]) -> "Scene":
        """A scene holding only the given views (in the given order)."""
        idx = [self.index(k) for k in keys]
        return replace(self, views=[self.views[i] for i in idx], meta=dict(self.meta, subset=idx))

    def split(self, target: int | str, sources: Iterable[int | str] | None = None) -> tuple["Scene", View]:
        """Hold out view ``target``: returns (sources scene, target view). The target is
        never among the sources."""
        ti = self.index(target)
        if sources is None:
            src = [i for i in range(len(self)) if i != ti]
        else:
            src = [self.index(s) for s in sources]
            if ti in src:
                raise VibrInputError(f"target view {self.views[ti].name} is also listed as a source", self.root)
        if not src:
            raise VibrInputError("no source views left after holding out the target", self.root)
        return self.subset(src), self.views[ti]

    @property
    def has_depth(self) -> bool:
        return all(v.depth is not None for v in self.views)

    def depth_range(self) -> tuple[float, float] | None:
        """(min, max) over known depths of all views, or from sparse points, or None."""
        ranges = [r for r in (v.depth_range() for v in self.views) if r is not None]
        if ranges:
            return min(r[0] for r in ranges), max(r[1] for r in ranges)
        if self.points is not None and len(self.points):
            zs = np.concatenate([v.camera.project(self.points)[1] for v in self.views])
            zs = zs[zs > 0]
            if zs.size:
                return float(np.percentile(zs, 1)), float(np.percentile(zs, 99))
        return None

    def summary(self) -> str:
        """A human-readable multi-line summary (what ``vibr info`` prints)."""
        lines = [f"scene    {self.name}" + (f"  ({self.root})" if self.root else "")]
        fmt = self.meta.get("format")
        if fmt:
            lines.append(f"format   {fmt}")
        sizes = sorted({(v.camera.width, v.camera.height) for v in self.views})
        lines.append(
            f"views    {len(self)}" + (f" in a {self.grid[0]}x{self.grid[1]} grid" if self.grid else "")
        )
        lines.append("size     " + ", ".join(f"{w}x{h}" for w, h in sizes))
        nd = sum(v.depth is not None for v in self.views)
        dr = self.depth_range()
        lines.append(
            f"depth    {nd}/{len(self)} views with depth"
            + (f", range {dr[0]:.4g} .. {dr[1]:.4g}" if dr else "")
        )
        if self.points is not None:
            lines.append(f"points   {len(self.points)} sparse points")
        C = np.array([v.camera.centre for v in self.views])
        span = np.linalg.norm(C.max(0) - C.min(0))
        one = shared_centre([v.camera for v in self.views], self.points) is not None
        lines.append("centres  one centre: a rotation-only capture (no parallax; renders need no depth)" if one
                     else f"centres  bounding-box diagonal {span:.4g} scene units")
        lines.append("")
        lines.append(f"{'#':>3}  {'name':<16} {'size':>10} {'fx':>9} {'fy':>9} {'cx':>8} {'cy':>8}  centre")
        for i, v in enumerate(self.views):
            K = v.camera.K
            c = v.camera.centre
            lines.append(
                f"{i:>3}  {v.name:<16} {v.camera.width:>4}x{v.camera.height:<5} {K[0,0]:>9.2f} {K[1,1]:>9.2f} "
                f"{K[0,2]:>8.2f} {K[1,2]:>8.2f}  ({c[0]:+.4g}, {c[1]:+.4g}, {c[2]:+.4g})"
            )
        return "\n".join(lines)
