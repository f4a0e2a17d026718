"""From a loaded scene and a target to the sources the renderer needs.

This is the glue shared by ``vibr render``, ``vibr eval`` and the Python API: pick the
target (a held-out view or a bare camera), pick the source views (all others, a given list,
or the k best by :mod:`vibr.selection`), and give every source a depth map according to the
chosen geometry:

``gt``
    the depth loaded with the scene (a dataset's ground truth, or depth files recorded in a
    transforms.json). Views lacking depth get it transferred from the views that have it
    (:func:`vibr.geometry.ensure_source_depth`) — for a light field whose ground truth is the
    centre view's disparity and whose centre is the target, that is the target's own depth,
    which is the paper's "ground-truth geometry" protocol.
``estimated``
    estimated from the sources alone (:func:`vibr.stereo.estimate_depth`); the target never
    takes part.
``planar``
    a fronto-parallel plane in the target camera (:func:`vibr.geometry.planar_proxy`), the
    paper's coarsest proxy, with a large depth uncertainty. Its depth and uncertainty come
    from the sources' depth or sparse points; when the sources have neither (a light field
    whose only depth is the held-out centre's), from the scene's views that have depth —
    two scalars (median and spread of that depth seen from the target), as
    ``render(depth="planar")`` does; ``meta["proxy"]["from_views"]`` then names them.
``auto``
    ``gt`` when the scene carries depth (any view, or the held-out target of a light
    field), else ``estimated``: a scene with no geometry at all still renders.
``files``
    depth files in a folder, one per source view, named after the view (``NAME.npy``,
    ``NAME.pfm`` or ``NAME.png``; 0 = unknown).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

from .camera import Camera
from .errors import VibrInputError
from .scene import Scene, View

DEPTH_MODES = ("auto", "gt", "estimated", "planar", "files")


def _depth_file_for(folder: Path, name: str) -> Path:
    for ext in (".npy", ".pfm", ".png", ".bin"):
        p = folder / f"{name}{ext}"
        if p.is_file():
            return p
    raise VibrInputError(f"no depth file for view {name} (looked for {name}.npy/.pfm/.png/.bin)", folder)


def prepare(scene: Scene, target: int | str | Camera, *, sources: Sequence[int | str] | None = None,
            depth: str = "gt", depth_files: str | os.PathLike | None = None, n_views: int | None = None,
            estimate_kw: dict | None = None) -> tuple[Scene, View | Camera]:
    """Choose the target and the sources, and give every source a depth map.

    Parameters
    ----------
    scene : Scene
    target : int, str or Camera
        A view of the scene (index or name; it is held out of the sources and of depth
        estimation) or a bare camera.
    sources : sequence of int or str, optional
        Source views; default all views but the target (or the ``n_views`` best).
    depth : {"gt", "auto", "estimated", "planar", "files"}
        Where the sources' depth comes from (module docstring).
    depth_files : path, optional
        Folder of depth files, for ``depth="files"``.
    n_views : int, optional
        Keep only this many source views, the best for the target (:mod:`vibr.selection`).
    estimate_kw : dict, optional
        Extra arguments of :func:`vibr.stereo.estimate_depth`.

    Returns
    -------
    sources : Scene
        Every view has depth (NaN where unknown).
    target : View or Camera
    """
    from .geometry import ensure_source_depth, planar_proxy
    from .selection import select_views

    if depth not in DEPTH_MODES:
        raise VibrInputError(f"unknown depth mode {depth!r} (choose from {', '.join(DEPTH_MODES)})")
    if depth == "auto":
        depth = "gt" if any(v.depth is not None for v in scene.views) else "estimated"
        if depth == "estimated":
            from .progress import log

            log("the scene has no depth maps: estimating them from the source views (--depth estimated)")
    if isinstance(target, Camera):
        tview: View | Camera = target
        tcam = target
        src = scene if sources is None else scene.subset(sources)
        ti = None
    else:
        ti = scene.index(target)
        src, tview = scene.split(ti, sources)
        tcam = tview.camera
    if n_views is not None and sources is None and n_views < len(src):
        src = src.subset(select_views(src, tcam, n_views))

    if depth == "gt":
        if all(v.depth is None for v in src.views):
            if ti is not None and scene.views[ti].depth is not None:
                # Ground truth given for the target only (HCI centre disparity): transfer it.
                full = Scene(src.views + [scene.views[ti]], scene.name, scene.root, scene.grid,
                             scene.points, scene.meta)
                src = Scene(ensure_source_depth(full).views[:-1], scene.name, scene.root,
                            scene.grid, scene.points, dict(src.meta))
            else:
                raise VibrInputError("the scene has no depth maps: use --depth estimated or --depth planar",
                                     scene.root)
        elif not src.has_depth:
            src = ensure_source_depth(src)
    elif depth == "estimated":
        from .stereo import estimate_depth

        src = estimate_depth(src, **(estimate_kw or {}))
    elif depth == "planar":
        plane = {}
        if (all(v.depth is None for v in src.views)
                and (src.points is None or not len(src.points))):
            # Nothing among the sources to place the plane (a light field whose only depth is
            # the held-out centre's ground truth): take its depth and uncertainty — two
            # scalars, as render(depth="planar") does — from the scene's views with depth.
            known = [v for v in scene.views if v.depth is not None]
            if known:
                ref = planar_proxy(Scene(known, scene.name, scene.root, None, None, {}), tcam).meta["proxy"]
                plane = {"depth": ref["depth"], "sigma_z": ref["sigma_z"]}
        src = planar_proxy(src, tcam, **plane)
        if plane:
            src.meta["proxy"] = dict(src.meta["proxy"], from_views=[v.name for v in known])
    elif depth == "files":
        if depth_files is None:
            raise VibrInputError("--depth files needs --depth-files DIR")
        from .io import read_depth

        folder = Path(depth_files)
        if not folder.is_dir():
            raise VibrInputError("depth folder not found", folder)
        views = []
        for v in src.views:
            p = _depth_file_for(folder, v.name)
            d = read_depth(p)
            if d.shape != v.shape:
                raise VibrInputError(f"depth is {d.shape[1]}x{d.shape[0]}, view {v.name} is "
                                     f"{v.shape[1]}x{v.shape[0]}", p)
            views.append(v.replace(depth=d))
        src = Scene(views, src.name, src.root, src.grid, src.points, dict(src.meta))
    return src, tview
