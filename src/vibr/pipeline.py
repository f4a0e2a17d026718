"""From a loaded scene and a target to the sources the renderer needs.

This is the one preparation step shared by ``vibr render``, ``vibr eval`` and the Python API
(for convenience :func:`vibr.render.render` holds out the target and transfers depth itself,
as ``depth="gt"`` does, when given sources that are not ready): pick the
target (a held-out view or a bare camera), pick the source views (all others, a given list,
or the k best by :mod:`vibr.geometry.selection`), and give every source a depth map according to the
chosen geometry:

``gt``
    the depth loaded with the scene (a dataset's ground truth, or depth files recorded in a
    transforms.json). Views lacking depth get it transferred from the views that have it
    (:func:`vibr.geometry.ensure_source_depth`) — for a light field whose ground truth is the
    centre view's disparity and whose centre is the target, that is the target's own depth,
    which is the paper's "ground-truth geometry" protocol.
``estimated``
    estimated from the sources alone (:func:`vibr.stereo.estimate_depth`, through the depth
    cache when ``cache_dir`` allows it, as ``vibr render`` and ``vibr eval`` do); the target
    never takes part. Source pixels that stereo leaves unknown (a black backdrop, the sky) get
    the fallback proxy (:func:`vibr.geometry.fallback_depth`: a plane of their view just
    behind its farthest known depth, with a large sigma_z), so that they still take part
    where no known surface hides them: by default (``fallback="auto"``) in the views that
    are mostly unknown (a backdrop: it wins on the temple ring) and, in the others, where
    the photograph is flat (a plain wall or sky, which stereo cannot match); the textured
    patches of the object that stereo missed take a depth completed from their view's, with
    the view's own sigma_z there (:func:`vibr.geometry.proxy.complete_depth`);
    docs/explanation/renderer.md "Fallback proxy".
``planar``
    a fronto-parallel plane in the target camera (:func:`vibr.geometry.planar_proxy`), the
    paper's coarsest proxy, with one depth uncertainty for every view (``max(0.02 D,
    0.1 (p95 − p5))``, docs/explanation/renderer.md "The planar proxy's sigma_z"). Its depth and uncertainty come
    from the sources' depth or sparse points; when the sources have neither (a light field
    whose only depth is the held-out centre's), from the scene's views that have depth —
    two scalars (median and spread of that depth seen from the target), as
    ``meta["proxy"]["from_views"]`` then names them.
``auto`` (the default of the API, ``vibr render`` and ``vibr eval``)
    ``gt`` when the scene carries depth (any view, or the held-out target of a light
    field), else ``estimated``: a scene with no geometry at all still renders.
``files``
    depth files in a folder, one per source view, named after the view (``NAME.npy``,
    ``NAME.pfm`` or ``NAME.png``; 0 = unknown).
"""

from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path
from typing import Sequence

from ._runtime.atomic import atomic_path
from ._runtime.checkpoint import code_fingerprint
from .camera import Camera
from .errors import VibrInputError
from .geometry import apply_fallback, ensure_source_depth, planar_proxy
from .geometry.selection import select_views
from .io import load_scene, read_depth
from .io.depthfiles import fit_depth
from .scene import Scene, View
from .stereo.cache import CACHE_VERSION, default_cache_dir, estimated_depth, mark_used, prune_cache

__all__ = ["ALL_VIEWS", "DEPTH_MODES", "ESTIMATED_SOURCES", "PLANAR_SOURCES", "prepare"]

logger = logging.getLogger(__name__)

#: When depth is estimated and neither ``sources`` nor ``n_views`` is given, a target is
#: rendered from this many best views (:mod:`vibr.geometry.selection`): each source costs one depth
#: estimate, and a 9×9 light field's 80 cost ten minutes and gain nothing over the 16 best
#: (docs/explanation/performance.md, "Many views and estimated depth"). Known depth keeps every view.
ESTIMATED_SOURCES = 16
#: With the planar proxy and neither ``sources`` nor ``n_views`` given, a target is rendered
#: from this many best views: the plane misplaces a view in proportion to its baseline, and
#: the gradient term reads every view that lands (the colour term only the view prior's
#: few). Chosen across scenes with a held-out split (``benchmarks/quality/planar_views.py``,
#: docs/explanation/renderer.md "The planar proxy's sigma_z"): +1.4 and +1.3 dB over every view on its two halves.
PLANAR_SOURCES = 4
#: ``n_views`` that asks for every view as a source (CLI ``--views all``).
ALL_VIEWS = "all"

#: The one depth vocabulary (module docstring); "auto" is the default everywhere.
DEPTH_MODES = ("auto", "gt", "estimated", "planar", "files")


class DepthUnavailable(VibrInputError):
    """``depth="gt"`` asked of a scene that has no depth maps."""


def _depth_file_for(folder: Path, name: str) -> Path:
    for ext in (".npy", ".pfm", ".png", ".bin"):
        p = folder / f"{name}{ext}"
        if p.is_file():
            return p
    raise VibrInputError(f"no depth file for view {name} (looked for {name}.npy/.pfm/.png/.bin)", folder)


def prepare(scene: Scene, target: int | str | Camera, *, sources: Sequence[int | str] | None = None,
            depth: str = "auto", depth_files: str | os.PathLike | None = None, n_views: int | str | None = None,
            estimate_kw: dict | None = None, fallback: str | bool = "auto",
            cache_dir=False) -> tuple[Scene, View | Camera]:
    """Choose the target and the sources, and give every source a depth map.

    Parameters
    ----------
    scene : Scene
    target : int, str or Camera
        A view of the scene (index or name; it is held out of the sources and of depth
        estimation) or a bare camera.
    sources : sequence of int or str, optional
        Source views; default all views but the target (or the ``n_views`` best).
    depth : {"auto", "gt", "estimated", "planar", "files"}
        Where the sources' depth comes from (module docstring).
    depth_files : path, optional
        Folder of depth files, for ``depth="files"``.
    n_views : int or "all", optional
        Keep only this many source views, the best for the target (:mod:`vibr.geometry.selection`)
        among ``sources`` when given.
        Default: every view, but the :data:`ESTIMATED_SOURCES` best when the depth is
        estimated and the :data:`PLANAR_SOURCES` best with the planar proxy, when
        ``sources`` is not given; ``"all"``: every view in any case.
    estimate_kw : dict, optional
        Extra arguments of :func:`vibr.stereo.estimate_depth`.
    fallback : {"auto", "always", "never"} or bool
        Give source pixels of unknown depth the fallback proxy
        (:func:`vibr.geometry.apply_fallback`): "auto" (default) at each view's backdrop
        (:func:`vibr.geometry.proxy.backdrop_pixels`), its other unknown pixels completed
        (:func:`vibr.geometry.proxy.complete_depth`), the samples that land on another
        view's backdrop carved (:func:`vibr.geometry.proxy.carve_silhouettes`), "always"
        (True) the plane at every unknown pixel, "never" (False).
    cache_dir : path, None or False
        Estimated depth through the on-disk cache of :func:`vibr.stereo.cache.estimated_depth`
        (keyed by the sources, their images and cameras, ``estimate_kw`` and vibr's code):
        a folder, None for the default one, False (default) for none.

    Returns
    -------
    sources : Scene
        Every view has depth (NaN where unknown).
    target : View or Camera
    """
    auto = depth == "auto"
    depth = depth_mode(scene, depth)  # an unknown mode is refused here
    n_views, note = _source_count(scene, n_views, sources, depth)
    src, tview, ti = _hold_out(scene, target, sources, n_views)  # its errors first
    if auto and depth == "estimated":
        logger.info("the scene has no depth maps: the sources get depth estimated from them (or cached)")
    if note:
        logger.info(note)
    tcam = tview if isinstance(tview, Camera) else tview.camera
    if depth == "gt":
        src = _gt_depth(scene, src, ti)
    elif depth == "estimated":
        if len(src) < 2:  # the target takes no part in its sources' depth
            raise VibrInputError("depth is estimated from the sources alone and one source is too few: "
                                 "use two or more (--views K, --sources), or --depth planar / files", scene.root)
        src = estimated_depth(src, estimate_kw, cache_dir)
    elif depth == "planar":
        src = _planar_depth(scene, src, tcam)
    else:
        src = _files_depth(src, depth_files)

    return apply_fallback(src, fallback), tview


def _source_count(scene: Scene, n_views, sources, depth: str):
    """``(n_views, note)``: ``n_views`` as :func:`_hold_out` takes it (None: every view;
    :data:`ALL_VIEWS` is None; not given and no ``sources`` listed, :data:`ESTIMATED_SOURCES`
    when the depth is estimated, :data:`PLANAR_SOURCES` with the planar proxy) and the line
    that announces that default when the scene has more views (else "")."""
    if n_views == ALL_VIEWS:
        return None, ""
    if isinstance(n_views, (str, bool, float)) or (n_views is not None and n_views < 1):
        raise VibrInputError(f"n_views must be a positive integer or {ALL_VIEWS!r}, got {n_views!r}")
    default = {"estimated": (ESTIMATED_SOURCES, "depth is estimated for each source view"),
               "planar": (PLANAR_SOURCES, "the planar proxy misplaces the farther views")}.get(depth)
    if n_views is None and sources is None and default is not None:
        n, why = default
        note = (f"{why}: rendering from the {n} best of the scene's {len(scene)} views "
                f"(n_views='all', --views all: every view)")
        return n, note if len(scene) - 1 > n else ""
    return n_views, ""


def depth_mode(scene: Scene, depth: str = "auto") -> str:
    """The mode ``depth`` means for ``scene``: "auto" is "gt" when a view has depth, else
    "estimated"; the others are themselves."""
    if depth not in DEPTH_MODES:
        raise VibrInputError(f"unknown depth mode {depth!r} (choose from {', '.join(DEPTH_MODES)})")
    if depth == "auto":
        return "gt" if any(v.depth is not None for v in scene.views) else "estimated"
    return depth


def missing_view_camera(scene: Scene, name) -> Camera | None:
    """The camera of a light field's absent grid position named ``name``
    (``scene.meta["missing_views"]``, :func:`vibr.io.hci.load_hci`): a novel view, with no
    photograph to compare with. None for any other name."""
    missing = scene.meta.get("missing_views") or {}
    if not isinstance(name, str) or name in scene.names or Path(name).stem not in missing:
        return None
    stem = Path(name).stem
    return Camera.from_dict(missing[stem], source=f"{stem} (missing from the light field)")


def _hold_out(scene: Scene, target, sources, n_views):
    """(sources, target View or Camera, target index or None): the target held out, the
    sources listed or the ``n_views`` best (:func:`vibr.geometry.selection.select_views`)."""

    absent = missing_view_camera(scene, target)
    if absent is not None:
        logger.info(f"{absent.source}: rendered at its grid position, with no photograph to compare with")
        target = absent
    if isinstance(target, Camera):
        src = scene if sources is None else scene.subset(sources)
        tview, tcam, ti = target, target, None
    else:
        ti = scene.index(target)
        src, tview = scene.split(ti, sources)
        tcam = tview.camera
    if n_views is not None and n_views < len(src):  # the K best of the listed sources, or of all
        src = src.subset(select_views(src, tcam, n_views))
    return src, tview, ti


def _gt_depth(scene: Scene, src: Scene, ti) -> Scene:
    """The scene's depth; views without it get it by transfer (a light field whose ground
    truth is the held-out centre's: from the target, which is never rendered from)."""

    if all(v.depth is None for v in src.views):
        if ti is None or scene.views[ti].depth is None:
            raise DepthUnavailable("the scene has no depth maps (depth 'estimated' or 'planar' need none)",
                                   scene.root)
        full = scene.replace(views=src.views + [scene.views[ti]])
        return src.replace(views=ensure_source_depth(full).views[:-1])
    if not src.has_depth:
        return ensure_source_depth(src)
    return src


def _planar_depth(scene: Scene, src: Scene, tcam) -> Scene:
    """The fronto-parallel plane in the target camera (:func:`vibr.geometry.planar_proxy`)."""

    plane, known = {}, []
    if all(v.depth is None for v in src.views) and (src.points is None or not len(src.points)):
        # Nothing among the sources to place the plane (a light field whose only depth is
        # the held-out centre's ground truth): take its depth and uncertainty (two scalars)
        # from the scene's views with depth.
        known = [v for v in scene.views if v.depth is not None]
        if known:
            ref = planar_proxy(scene.replace(views=known, grid=None, points=None, meta={}), tcam)
            plane = {"depth": ref.meta["proxy"]["depth"], "sigma_z": ref.meta["proxy"]["sigma_z"]}
    src = planar_proxy(src, tcam, **plane)
    if plane:
        src.meta["proxy"] = dict(src.meta["proxy"], from_views=[v.name for v in known])
    return src


def _files_depth(src: Scene, depth_files) -> Scene:
    """Depth read from ``NAME.npy/.pfm/.png/.bin`` files in the folder ``depth_files``."""

    if depth_files is None:
        raise VibrInputError("depth 'files' needs a folder of depth files (depth_files)")
    folder = Path(depth_files)
    if not folder.is_dir():
        raise VibrInputError("depth folder not found", folder)
    views, resized = [], []
    for v in src.views:
        p = _depth_file_for(folder, v.name)
        d = read_depth(p)
        if d.shape != v.shape:
            d = fit_depth(d, v.shape, p, f"view {v.name}")
            resized.append(v.name)
        views.append(v.replace(depth=d))
    if resized:
        logger.info("depth files of another size than their views (--scale, or depth computed at another "
                    "resolution) resized to them, nearest neighbour: %s", ", ".join(resized))
    return src.replace(views=views)


# ------------------------------------------------------------------ the loaded-scene cache
def _folder_fingerprint(root: Path, h, max_files: int = 20000) -> None:
    """Feed the names, sizes and modification times of the files under ``root`` (hidden
    ones and the cache's own files skipped) into hash ``h``."""
    n = 0
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
        for f in sorted(filenames):
            if f.startswith("."):
                continue
            st = os.stat(os.path.join(dirpath, f))
            h.update(f"{os.path.relpath(os.path.join(dirpath, f), root)}|{st.st_size}|{st.st_mtime_ns}\n".encode())
            n += 1
            if n > max_files:
                raise OSError("too many files to fingerprint")


def load_scene_cached(path, *, scale: float = 1.0, cache_dir=None):
    """:func:`vibr.io.load_scene` through an on-disk cache of the loaded (resized) scene.

    Decoding and resizing full-size photographs (fountain: 11 JPEGs of 3072×2048) takes
    seconds; a second fly-through of the same scene at the same scale loads the resized
    views instead (``scene-KEY.pkl``, KEY a SHA-256 of the folder, the names, sizes and
    modification times of its files, the scale and vibr's code). The file is a pickle written by vibr
    in the user's own cache folder (:func:`default_cache_dir`); ``cache_dir=False``
    disables it.
    """
    import pickle

    root = Path(path)
    if cache_dir is False:
        return load_scene(path, scale=scale)
    h = hashlib.sha256()
    # vibr's code in the key: a loader that changed (undistortion, masks) loads afresh
    h.update(f"vibr-scene-cache v{CACHE_VERSION} code {code_fingerprint()}|{os.path.abspath(root)}|"
             f"{float(scale)!r}|".encode())
    try:
        _folder_fingerprint(root if root.is_dir() else root.parent, h)
    except OSError:
        return load_scene(path, scale=scale)
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    cpath = folder / f"scene-{h.hexdigest()[:32]}.pkl"
    if cpath.is_file():
        try:
            with open(cpath, "rb") as f:
                scene = pickle.load(f)
            if isinstance(scene, Scene):
                mark_used(cpath)
                logger.info("scene loaded from the cache %s", cpath)
                return scene
        except Exception as exc:  # noqa: BLE001 - a bad cache entry is only a slower load
            logger.warning("ignoring unreadable scene cache %s (%s)", cpath, exc)
    scene = load_scene(path, scale=scale)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with atomic_path(cpath) as tmp:
            with open(tmp, "wb") as f:
                pickle.dump(scene, f, protocol=pickle.HIGHEST_PROTOCOL)
        prune_cache(folder, keep=[cpath])
    except OSError as exc:
        logger.warning("could not write the scene cache %s (%s)", cpath, getattr(exc, "problem", exc))
    return scene

