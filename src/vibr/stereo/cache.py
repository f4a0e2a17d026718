"""Depth for every source view, estimated once per scene and kept on disk.

A fly-through renders many frames from the same sources: their depth must be obtained
once, not per frame and not per run. :func:`scene_with_depth` gives every view a depth map:

* the scene's own depth (a dataset's ground truth, ``vibr depth`` output loaded from its
  transforms.json folder, depth files recorded in a transforms.json): views that lack it get
  it by transfer (:func:`vibr.geometry.ensure_source_depth`);
* otherwise depth estimated by :func:`vibr.stereo.estimate_depth`, **cached on disk**: one
  ``depth-KEY.npz`` file per (scene, views, depth parameters), ``KEY`` a SHA-256 of the
  scene's root folder, the view names, image sizes, image files (size and modification
  time, or the pixels for scenes made in memory), camera matrices, the excluded views, the
  estimation parameters and vibr's code. A second run, or a second path on the same scene,
  loads it (tens of milliseconds) instead of estimating again (a minute on fountain at
  768×512, six at 3072×2048). :func:`estimated_depth` is that step alone: ``vibr render``
  and ``vibr eval`` (:func:`vibr.pipeline.prepare`) estimate their sources' depth through it.

The cache folder is ``cache_dir``, else ``$VIBR_CACHE_DIR``, else ``$XDG_CACHE_HOME/vibr``
(``~/.cache/vibr``): never the dataset's folder, which is often shared or read-only. It is
kept under :data:`CACHE_MAX_BYTES` (``$VIBR_CACHE_MAX_GB``): after each write the least
recently used entries are removed (:func:`prune_cache`).
Files are written atomically (temporary name, then rename), so an interrupted run leaves
no partial cache entry.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import shutil
import time
from pathlib import Path

import numpy as np

from .._runtime.atomic import atomic_path
from .._runtime.checkpoint import code_fingerprint, resume_folder
from ..camera import shared_centre
from ..errors import VibrInputError
from ..geometry import apply_fallback, ensure_source_depth, sphere_proxy
from ..scene import Scene
from .api import ESTIMATOR_VERSION, estimate_depth

logger = logging.getLogger(__name__)

__all__ = ["scene_with_depth", "estimated_depth", "default_cache_dir", "depth_cache_key",
           "prune_cache", "CACHE_MAX_BYTES"]

CACHE_VERSION = 2  # 2: the estimator's statistics; vibr's code in the key

#: The cache folder's entries are kept under this many bytes (``$VIBR_CACHE_MAX_GB``
#: overrides it, in GB): after each write the least recently used entries go. One entry of
#: cotton's 80 views at 512² is 170 MB, fountain's 10 views at 3072×2048 about 500 MB.
CACHE_MAX_BYTES = 8 * 10**9


def default_cache_dir() -> Path:
    """``$VIBR_CACHE_DIR``, else ``$XDG_CACHE_HOME/vibr``, else ``~/.cache/vibr``."""
    env = os.environ.get("VIBR_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "vibr"


def _view_fingerprint(v, h) -> None:
    """Feed what identifies a view's image and camera into hash ``h``."""
    h.update(v.name.encode())
    h.update(np.asarray(v.camera.shape, np.int64).tobytes())
    for m in (v.camera.K, v.camera.R, v.camera.t):
        h.update(np.round(np.asarray(m, np.float64), 12).tobytes())
    st = None
    if v.path and os.path.isfile(v.path):
        st = os.stat(v.path)
    if st is not None:
        h.update(f"{os.path.abspath(v.path)}|{st.st_size}|{st.st_mtime_ns}".encode())
    elif v.image is not None:
        h.update(np.ascontiguousarray(v.image).tobytes())
    if v.mask is not None:  # the estimate leaves masked pixels out of its matching
        h.update(b"mask" + np.packbits(v.mask).tobytes())


def depth_cache_key(scene: Scene, estimate_kw: dict | None = None, exclude=()) -> str:
    """SHA-256 (hex) of the scene root, views (names, sizes, images, cameras), the
    excluded views, the estimation parameters, the estimator's version
    (:data:`vibr.stereo.api.ESTIMATOR_VERSION`) and vibr's code
    (:func:`vibr._runtime.checkpoint.code_fingerprint`): other code estimates again rather than
    take maps it might not make."""

    h = hashlib.sha256()
    h.update(f"vibr-depth-cache v{CACHE_VERSION} estimator {ESTIMATOR_VERSION} code {code_fingerprint()}|".encode())
    h.update(str(os.path.abspath(scene.root)).encode() if scene.root else b"<memory>")
    for v in scene.views:
        _view_fingerprint(v, h)
    h.update(json.dumps(sorted(str(e) for e in exclude)).encode())
    h.update(json.dumps(estimate_kw or {}, sort_keys=True, default=repr).encode())
    return h.hexdigest()[:32]


def _cache_max_bytes() -> int:
    env = os.environ.get("VIBR_CACHE_MAX_GB")
    try:
        return int(float(env) * 10**9) if env else CACHE_MAX_BYTES
    except ValueError:
        logger.warning("ignoring VIBR_CACHE_MAX_GB=%r (not a number)", env)
        return CACHE_MAX_BYTES


def mark_used(path: Path) -> None:
    """Mark a cache entry as just used (its modification time orders the pruning)."""
    with contextlib.suppress(OSError):
        os.utime(path)


def prune_cache(folder, keep=(), max_bytes: int | None = None) -> int:
    """Remove the least recently used entries (``depth-*.npz``, ``scene-*.pkl``) of the cache
    ``folder`` until the rest fit in ``max_bytes`` (default :data:`CACHE_MAX_BYTES` or
    ``$VIBR_CACHE_MAX_GB``); ``keep`` are never removed. Returns the bytes freed."""
    max_bytes = _cache_max_bytes() if max_bytes is None else int(max_bytes)
    keep = {Path(k).resolve() for k in keep}
    entries = []
    for p in list(Path(folder).glob("depth-*.npz")) + list(Path(folder).glob("scene-*.pkl")):
        with contextlib.suppress(OSError):
            st = p.stat()
            entries.append((st.st_mtime, st.st_size, p))
    total = sum(e[1] for e in entries)
    freed = 0
    for _, size, p in sorted(entries, key=lambda e: e[0]):
        if total - freed <= max_bytes:
            break
        if p.resolve() in keep:
            continue
        with contextlib.suppress(OSError):
            p.unlink()
            freed += size
            logger.info("cache: removed %s, the least recently used entry (%.0f MB)", p.name, size / 1e6)
    return freed


def _load(path: Path, scene: Scene) -> Scene | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            names = [str(s) for s in z["names"]]
            if names != scene.names:
                return None
            views = []
            for i, v in enumerate(scene.views):
                d = z[f"depth_{i}"]
                s = z[f"sigma_{i}"]
                views.append(v.replace(depth=d, sigma_z=s if s.ndim == 2 else (None if np.isnan(s) else float(s))))
            stats = json.loads(str(z["estimation"]))
    except (OSError, KeyError, ValueError) as exc:
        logger.warning("ignoring unreadable depth cache %s (%s)", path, exc)
        return None
    return Scene(views, scene.name, scene.root, scene.grid, scene.points, dict(scene.meta, depth_estimation=stats))


def _plain(x):
    """JSON for the estimator's numpy numbers and arrays."""
    return x.tolist() if hasattr(x, "tolist") else str(x)


def _save(path: Path, scene: Scene) -> None:
    arrays = {"names": np.array(scene.names),
              "estimation": np.array(json.dumps(scene.meta.get("depth_estimation", {}), default=_plain))}
    for i, v in enumerate(scene.views):
        arrays[f"depth_{i}"] = np.asarray(v.depth, np.float32)
        s = v.sigma_z
        arrays[f"sigma_{i}"] = np.asarray(np.nan if s is None else s, np.float32)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez(f, **arrays)
    except OSError as exc:  # a cache that cannot be written only costs time next run
        logger.warning("could not write the depth cache %s (%s)", path, getattr(exc, "problem", exc))


def scene_with_depth(scene: Scene, *, depth: str = "auto", estimate_kw: dict | None = None,
                     cache_dir=None, exclude=(), fallback="auto", executor=None, views=None) -> Scene:
    """The scene (minus ``exclude``) with a depth map on every view.

    Parameters
    ----------
    scene : Scene
    depth : {"auto", "gt", "estimated"}
        ``gt``: the scene's depth (views without it get it by transfer); ``estimated``:
        :func:`vibr.stereo.estimate_depth` from the kept views only, cached; ``auto``:
        ``gt`` when any view has depth, else ``estimated``.
    estimate_kw : dict, optional
        Arguments of :func:`vibr.stereo.estimate_depth` (part of the cache key).
    cache_dir : path, optional
        Cache folder (default :func:`default_cache_dir`); ``False`` disables the cache.
    exclude : views (names or indices) left out entirely: never sources, never inputs of
        the depth estimation (a held-out view).
    fallback : {"auto", "always", "never"}
        The fallback proxy for pixels of unknown depth (:func:`vibr.geometry.apply_fallback`,
        as :func:`vibr.pipeline.prepare`); applied after the cache (not part of its key).
    executor : where the views' depth is estimated (:func:`vibr.stereo.estimate_depth`; not
        part of the key: the depths are the same).
    views : names, optional
        When depth is estimated: only these views get it, and only they are returned (all
        kept views still serve as stereo partners; part of the key). A fly-through passes
        the views its frames may use (:func:`vibr.paths.flythrough.views_for_path`).

    Returns
    -------
    Scene
        ``meta["depth_source"]`` is ``"scene"``, ``"cache"`` or ``"estimated"``;
        ``meta["depth_cache"]`` the cache file (when used), ``meta["depth_time_s"]`` the
        time spent obtaining depth.
    """

    out = _scene_with_depth(scene, depth, estimate_kw, cache_dir, exclude, executor, views)
    return apply_fallback(out, fallback)


def _scene_with_depth(scene: Scene, depth, estimate_kw, cache_dir, exclude, executor=None, views=None) -> Scene:
    t0 = time.perf_counter()
    if depth not in ("auto", "gt", "estimated"):
        raise VibrInputError(f"depth must be auto, gt or estimated for a camera path, got {depth!r}")
    ex = {scene.views[scene.index(e)].name for e in exclude}
    keep = [v.name for v in scene.views if v.name not in ex]
    if not keep:
        raise VibrInputError("no views left after the exclusions", scene.root)
    src = scene.subset(keep) if ex else scene
    if depth == "auto":
        depth = "gt" if any(v.depth is not None for v in src.views) else "estimated"
    if depth == "gt":
        if all(v.depth is None for v in src.views):
            raise VibrInputError("the scene has no depth maps: use depth='estimated'", scene.root)
        if not src.has_depth:
            src = ensure_source_depth(src)
        # a new meta: the caller's scene is not changed
        return src.replace(meta=dict(src.meta, depth_source="scene", depth_time_s=time.perf_counter() - t0))
    return estimated_depth(src, estimate_kw, cache_dir, executor, views)  # from the kept views only


def estimated_depth(scene: Scene, estimate_kw: dict | None = None, cache_dir=None, executor=None,
                    views=None) -> Scene:
    """Depth estimated for every view of ``scene`` (:func:`vibr.stereo.estimate_depth`; depth
    the views have is ignored), through the on-disk cache (module docstring).

    ``cache_dir``: the cache folder; None: :func:`default_cache_dir`; False: no cache (always
    estimated, nothing written). While estimating, each view's sweep is kept beside the cache
    file as it finishes, so that a run killed midway resumes. ``meta["depth_source"]`` is
    ``"cache"`` or ``"estimated"``, ``meta["depth_cache"]`` the cache file when used,
    ``meta["depth_time_s"]`` the time spent, ``meta["depth_estimation"]`` the estimator's
    statistics (kept from the run that filled the cache). ``executor``: where the views'
    sweeps run (:func:`vibr.stereo.estimate_depth`). ``views``: only these views get depth
    and are returned (the others still serve as stereo partners).
    """

    t0 = time.perf_counter()
    bare = Scene([v.replace(depth=None, sigma_z=None) for v in scene.views], scene.name, scene.root,
                 scene.grid, scene.points, dict(scene.meta))
    centre = shared_centre([v.camera for v in bare.views], bare.points)
    if centre is not None:  # no parallax to estimate depth from, and none needed
        out = sphere_proxy(bare, centre)
        logger.info("the %d views share one centre (rotation only): their images do not depend on depth, "
                    "a sphere of radius %.3g around it stands in for it", len(out), out.meta["proxy"]["radius"])
        out.meta.update(depth_source="shared centre", depth_time_s=time.perf_counter() - t0)
        return out
    kw = dict(estimate_kw or {})
    wanted = bare if views is None else bare.subset(list(views))
    cpath = None
    if cache_dir is not False:
        folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
        key_kw = kw if views is None else dict(kw, views=sorted(wanted.names))
        cpath = folder / f"depth-{depth_cache_key(bare, key_kw)}.npz"
        out = _load(cpath, wanted) if cpath.is_file() else None
        if out is not None:
            mark_used(cpath)
            logger.info("depth of %d views loaded from the cache %s", len(out), cpath)
            out.meta.update(depth_source="cache", depth_cache=str(cpath), depth_time_s=time.perf_counter() - t0)
            return out
    logger.info("estimating depth for %d%s views%s", len(wanted), "" if views is None else f" of {len(bare)}",
                "" if cpath is None else " (once; cached)")
    resume = None if cpath is None else resume_folder(cpath)
    out = estimate_depth(bare, views=None if views is None else wanted.names, checkpoint=resume,
                         executor=executor, **kw)
    if views is not None:
        out = out.subset(wanted.names)
    if cpath is not None:
        _save(cpath, out)
        shutil.rmtree(resume, ignore_errors=True)
        prune_cache(cpath.parent, keep=[cpath])
        out.meta["depth_cache"] = str(cpath)
    out.meta.update(depth_source="estimated", depth_time_s=time.perf_counter() - t0)
    return out


