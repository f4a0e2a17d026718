"""Fly-throughs: render every camera of a path, write the frames, encode a video.

:func:`render_path` loads nothing itself: it takes a loaded scene and a
:class:`vibr.paths.camera_path.CameraPath`, gets the sources' depth once
(:func:`vibr.stereo.cache.scene_with_depth`, cached on disk), then renders frame by frame.

Per frame (:func:`render_frame`, a top-level function of ``(context, frame index)`` so that
:func:`vibr.executor.run_tasks` can run frames on processes or Dask):

1. **Sources with soft weights** (:func:`view_weights`): views are ranked for the frame's
   camera as :func:`vibr.geometry.selection.rank_views` does (penalty ``p_k``); with ``n_views = K``
   the threshold is the midpoint ``m`` of the K-th and (K+1)-th smallest penalties and a
   view's blend weight is ``s_k = smoothstep(½ + (m − p_k) / (blend · m))``. Far from a
   change of the selected set the K best have weight 1 and the others 0 (the frame is what
   ``vibr render --views K`` gives); when two views swap ranks both are in the set with
   weights crossing smoothly through ½, so a view leaves the set with weight 0 and the
   image does not jump ("popping"). The weight multiplies every sample of the view in
   both data terms (``samples.meta["sample_weight"]``, read by
   :func:`vibr.render.render_samples`).
2. geometry (:func:`vibr.geometry.compute_samples`) and render
   (:func:`vibr.render.render_samples`) with the method's parameters;
3. the frame is written atomically as ``frame_NNNNN.png`` (8-bit) in the frames folder,
   with a key (:func:`frame_key`: the camera, the sources, the method and its parameters,
   vibr's code) in a text chunk. A frame already there with the same key is skipped unless
   ``overwrite``; one rendered for another path or other settings is rendered again.
4. with ``depth_dir``, the frame's depth (:func:`vibr.geometry.target_depth`, the
   geometry stage's z-buffer brought to the frame's pixels as :attr:`vibr.render.RenderResult.depth`)
   as ``depth_NNNNN.npy`` (float32, scene units, 0 where no surface: what
   :func:`vibr.io.depthfiles.read_depth` reads), written before the frame;
5. with ``uncertainty``, the frame's σ map (:mod:`vibr.render.uncertainty`, grey levels)
   as ``sigma_NNNNN.npz`` beside it (float16, with the frame's key); the σ video is drawn
   once every frame is there, on one colour scale for the whole path
   (:func:`write_sigma_video`), so that its colours mean the same in every frame.

Work that does not depend on the frame is done once (:func:`prepare_sources`): the scene,
the sources' depth, the world points of every source used to rank views (a strided
subsample of each depth map, backprojected) and each source's depth slopes
(:func:`vibr.geometry.prepare_depth`, passed to :func:`compute_samples` as ``prepared``);
measured in docs/explanation/flythrough.md.

A path can be split over independent processes (a job array): with ``shard=(I, N)`` a
process renders only the frames ``f`` with ``f % N == I - 1`` (:func:`vibr.executor.shard_of`)
and writes no video; :func:`assemble_path` then encodes the video from the complete frames
folder. The frames do not depend on the shard: each is a function of the path, the sources
and the settings only, so the assembled video is the one a single process makes.
"""

from __future__ import annotations

import fnmatch
import logging
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .._runtime.atomic import atomic_path
from .._runtime.checkpoint import code_fingerprint, digest
from ..camera import Camera
from ..errors import VibrInputError
from ..eval.sigma_figures import sigma_figure, sigma_scale
from ..executor import auto_workers, parse_executor, parse_shard, run_tasks, shard_of
from ..geometry import compute_samples, prepare_depth, target_depth
from ..geometry.depth import DEFAULT_EDGE_REL
from ..geometry.resolution import SUPERSAMPLE_MAX, check_supersample
from ..geometry.selection import depth_points, rank_views, select_views
from ..io import read_image, write_image
from ..io.depthfiles import write_depth
from ..io.images import read_png_text
from ..io.outputs import check_frames_folder, check_not_input, read_marker, write_marker
from ..io.video import VIDEO_FORMATS, check_video_options, is_video, write_video
from ..progress import progress as bar
from ..render import fine_grid, grid_params, render_samples
from ..render.checks import check_render_memory, render_memory
from ..render.methods import METHODS, as_params, with_sample_fields
from ..render.params import RenderParams
from ..scene import Scene
from ..stereo.cache import scene_with_depth
from .camera_path import scene_centre, scene_points

logger = logging.getLogger(__name__)

__all__ = ["FrameContext", "FlyOptions", "FlyResult", "render_path", "render_frame", "view_weights", "auto_executor",
           "frame_name", "sigma_name", "depth_name", "check_path_sees_scene", "write_sigma_video", "assemble_path"]

FRAME_PATTERN = "frame_{:05d}.png"
SIGMA_PATTERN = "sigma_{:05d}.npz"
DEPTH_PATTERN = "depth_{:05d}.npy"


def depth_name(i: int) -> str:
    return DEPTH_PATTERN.format(i)


def sigma_name(i: int) -> str:
    return SIGMA_PATTERN.format(i)


def frame_name(i: int) -> str:
    return FRAME_PATTERN.format(i)


#: What a frame that sees nothing of the scene stops on, said with its error.
_SEES_NOTHING = "; the path goes where no photograph looked (inside or behind the object?)"

#: The PNG text chunk of a frame that holds its :func:`frame_key`.
FRAME_KEY = "vibr-frame"


@dataclass
class FrameContext:
    """Everything a frame task needs (picklable: sent once per worker)."""

    sources: Scene
    cameras: list
    frames_dir: str
    method: str = "gradient"
    params: RenderParams | dict = field(default_factory=dict)  # a dict: keyword arguments, made a RenderParams
    n_views: int | None = 8
    blend: float = 0.25
    overwrite: bool = False
    geometry_kw: dict = field(default_factory=dict)
    view_points: list = field(default_factory=list)  # per source: (N_k, 3) world points
    prepared: dict = field(default_factory=dict)  # per source: prepare_depth's (z, z_x, z_y)
    job_key: str = ""  # what every frame depends on besides its camera (:func:`job_key`)
    uncertainty: bool = False  # also each frame's σ map (sigma_NNNNN.npz)
    supersample: object = "auto"  # sources finer than a frame (vibr.render.fine_grid)
    depth_dir: str = ""  # also each frame's depth (depth_NNNNN.npy) in this folder

    def __post_init__(self):
        self.params = as_params(self.method, self.params)
        # the optional sample fields the method reads (the footprint PSF's Jacobians), once
        # for every frame
        self.geometry_kw = with_sample_fields(self.geometry_kw, (self.method, self.params))


def _source_points(sources: Scene, max_points: int = 1024) -> list:
    """Per source, the strided subsample of its depth map backprojected to the world
    (exactly :func:`vibr.geometry.selection.target_points`' sampling, done once per source)."""

    per_view = max(64, max_points // max(1, len(sources)))
    return [depth_points(v, per_view) for v in sources.views]


def _points_in_target(view_points, target: Camera, max_points: int = 1024):
    """The sources' points the target sees: the same filtering and random subsample (seed
    0) as :func:`vibr.geometry.selection.target_points`, so the ranking is the same."""
    pts = [p for p in view_points if len(p)]
    if not pts:
        return None
    P = np.concatenate(pts)
    P = P[target.sees(P)[2]]
    if not len(P):
        return None
    if len(P) > max_points:
        P = P[np.random.default_rng(0).choice(len(P), max_points, replace=False)]
    return P


def prepare_sources(ctx: FrameContext, cache_depth: bool = True) -> None:
    """The per-source work that does not depend on the frame, done once: the points used to
    rank views and (``cache_depth``) the depth and its slopes (:func:`prepare_depth`)."""

    ctx.view_points = _source_points(ctx.sources)
    ctx.job_key = job_key(ctx)
    ctx.prepared = {}
    if cache_depth:
        fill = bool(ctx.geometry_kw.get("fill_holes", False))
        edge = ctx.geometry_kw.get("edge_rel", DEFAULT_EDGE_REL)
        ctx.prepared = {v.name: prepare_depth(v, fill_holes=fill, edge_rel=edge) for v in ctx.sources.views}


def job_key(ctx: FrameContext) -> str:
    """SHA-1 of what every frame depends on besides its camera: vibr's code, the method and
    its parameters, the source selection and the sources (names, cameras, images, depth,
    sigma_z, fallback masks, photograph masks)."""

    parts = [code_fingerprint(), ctx.method, ctx.params.as_dict(), ctx.n_views, ctx.blend, ctx.geometry_kw,
             str(ctx.supersample)]
    for v in ctx.sources.views:
        c = v.camera
        parts += [v.name, c.K, c.R, c.t, list(c.shape), v.image, v.depth,
                  v.sigma_z if isinstance(v.sigma_z, np.ndarray) else [v.sigma_z],
                  v.fallback if v.fallback is not None else [],
                  v.mask if v.mask is not None else []]
    return digest(*parts)


def frame_key(ctx: FrameContext, i: int) -> str:
    """The key written into frame ``i``'s PNG (text chunk ``vibr-frame``): a frame on disk is
    reused only when its key is this one (:func:`render_frame`)."""

    c = ctx.cameras[i]
    return digest(ctx.job_key, c.K, c.R, c.t, list(c.shape))


def frame_done(ctx: FrameContext, i: int, key: str | None = None) -> bool:
    """Whether frame ``i`` is on disk with its :func:`frame_key` (``key`` when given)."""

    key = frame_key(ctx, i) if key is None else key
    if read_png_text(os.path.join(ctx.frames_dir, frame_name(i))).get(FRAME_KEY) != key:
        return False
    if ctx.depth_dir and not os.path.isfile(os.path.join(ctx.depth_dir, depth_name(i))):
        return False
    return not ctx.uncertainty or _sigma_key(os.path.join(ctx.frames_dir, sigma_name(i))) == key


def _sigma_key(path) -> str | None:
    """The frame key stored with a σ map, None when there is none (or no readable file)."""
    import zipfile

    try:
        with np.load(path) as z:
            return str(z["key"])
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None


def _write_sigma_frame(path, sigma, key: str) -> None:
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, sigma=np.asarray(sigma, np.float16), key=np.array(key))


def write_sigma_video(paths, out, *, fps: float, crf: int = 18) -> tuple[int, int, int, float]:
    """The σ maps of a path's frames (``sigma_NNNNN.npz``) as a video, each frame colour-mapped
    with a scale bar (:func:`vibr.eval.sigma_figures.sigma_figure`) on one scale for all:
    :func:`vibr.eval.sigma_figures.sigma_scale` of every frame's σ (0 to their 99th
    percentile below σ_hole, rounded up). Returns ``(n_frames, width, height, vmax)``."""

    def load(p):
        with np.load(p) as z:
            return z["sigma"].astype(np.float32)

    # the scale from every frame (a strided sample of each: the maps are not all held at once)
    vmax = sigma_scale(np.concatenate([load(p)[::4, ::4].ravel() for p in paths]) if paths else [])
    n, w, h = write_video(out, (sigma_figure(load(p), vmax) for p in paths), fps=fps, crf=crf)
    return n, w, h, vmax


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def view_weights(sources: Scene, camera: Camera, n_views: int | None, *, blend: float = 0.25,
                 view_points=None, min_overlap: float = 0.05) -> np.ndarray:
    """Blend weight in [0, 1] of every source for ``camera`` (module docstring, step 1).

    ``p_k`` is :func:`vibr.geometry.selection.rank_views`' penalty (``inf`` below ``min_overlap``);
    ``m = (p_(K) + p_(K+1)) / 2``; ``s_k = smoothstep(½ + (m − p_k) / (blend · m))``.
    ``blend = 0`` is the hard selection of :func:`vibr.geometry.selection.select_views`.
    """

    n = len(sources)
    if n_views is None or n_views >= n:
        return np.ones(n)
    pts = None
    if view_points is not None:
        pts = _points_in_target(view_points, camera)
    order, penalty, overlap = rank_views(sources, camera, points=pts, min_overlap=min_overlap)
    w = np.zeros(n)
    key = np.where(overlap >= min_overlap, penalty, np.inf)
    ks = np.sort(key)
    a, b = ks[n_views - 1], ks[n_views]
    if blend <= 0 or not np.isfinite(a) or not np.isfinite(b):
        w[order[:n_views]] = 1.0
        return w
    m = 0.5 * (a + b)
    width = blend * max(m, 1e-12)
    w = _smoothstep(0.5 + (m - key) / width)
    w[~np.isfinite(key)] = 0.0
    return w


def render_frame(ctx: FrameContext, i: int) -> dict:
    """Render frame ``i`` of the path and write it (the per-frame task, see the module
    docstring). Returns a small dict: index, skipped, seconds, views and weights, and the
    seconds of each stage (``times``); for a frame that sees nothing, ``failed`` (why) and no
    file (:func:`render_path` then names every such frame in one error)."""

    out = os.path.join(ctx.frames_dir, frame_name(i))
    key = frame_key(ctx, i)
    if not ctx.overwrite and frame_done(ctx, i, key):
        return {"index": i, "skipped": True, "seconds": 0.0}
    t0 = time.perf_counter()
    if ctx.depth_dir:  # a frame on disk says its depth is its own: the stale frame goes first
        _remove_stale_frame(out)
    cam = ctx.cameras[i]
    tm = {}
    w = view_weights(ctx.sources, cam, ctx.n_views, blend=ctx.blend,
                     view_points=ctx.view_points or None)
    idx = np.flatnonzero(w > 0)
    if not len(idx):  # reported with the other such frames once every frame is done
        return {"index": i, "skipped": False, "seconds": 0.0, "failed": f"no source view sees it (camera {cam})"}
    views = [ctx.sources.views[k] for k in idx]
    sub = Scene(views, ctx.sources.name, ctx.sources.root, None, ctx.sources.points, {})
    tm["view weights"] = -t0 + (t := time.perf_counter())
    try:
        sub, fine, prepared, plan = fine_grid(sub, cam, ctx.supersample, ctx.prepared or None,
                                              [(ctx.method, ctx.params)])
        samples = compute_samples(sub, fine, prepared=prepared, return_zbuffer=bool(ctx.depth_dir),
                                  **ctx.geometry_kw)
    except VibrInputError as exc:
        return {"index": i, "skipped": False, "seconds": 0.0, "failed": f"{exc.problem} (camera {cam})"}
    tm["geometry"] = -t + (t := time.perf_counter())
    ws = w[idx]
    if np.any(ws < 1.0):
        samples.meta["sample_weight"] = ws[samples.view].astype(np.float32)
    res = render_samples(samples, ctx.method, params=grid_params(ctx.method, ctx.params, plan),
                         source_centres=np.array([v.camera.centre for v in views]), target_centre=cam.centre,
                         uncertainty=ctx.uncertainty)
    res.depth = target_depth(samples)
    res = res.on_target(plan, cam.shape)
    tm["render"] = -t + (t := time.perf_counter())
    if ctx.depth_dir:
        write_depth(os.path.join(ctx.depth_dir, depth_name(i)), res.depth)
    if ctx.uncertainty:  # first: a colour frame on disk with its key says the frame is done
        _write_sigma_frame(os.path.join(ctx.frames_dir, sigma_name(i)), res.uncertainty, key)
    write_image(out, res.image, bits=8, text={FRAME_KEY: key})
    tm["write"] = time.perf_counter() - t
    tm.update({f"geometry: {k}": v for k, v in samples.meta.get("times", {}).items()})
    tm.update({f"render: {k}": v for k, v in res.times.items() if k != "total"})
    return {"index": i, "skipped": False, "seconds": time.perf_counter() - t0, "supersample": plan.supersample,
            "coarsen": plan.coarsen,
            "views": [v.name for v in views], "weights": ws.tolist(), "times": tm, "samples": len(samples),
            "coverage": float(res.coverage.mean()), "iterations": res.iterations}


def _remove_stale_frame(path) -> None:
    """Remove a frame vibr wrote (it carries a frame key) before it is rendered again."""
    if os.path.isfile(path) and FRAME_KEY in read_png_text(path):
        os.remove(path)


def _same(x):
    return x


@dataclass
class FlyResult:
    """What :func:`render_path` did."""

    n_frames: int
    rendered: int
    skipped: int
    frames_dir: str
    video: str | None
    video_frames: int | None = None
    video_size: tuple | None = None
    sigma_video: str | None = None  # the σ video (uncertainty) and the top of its colour scale
    sigma_vmax: float | None = None
    depth_source: str = ""
    times: dict = field(default_factory=dict)
    frames: list = field(default_factory=list)
    engine: str = "in this process"  # where the frames ran: "on N processes", "on Dask (ADDRESS)", ...
    shard: tuple | None = None  # (I, N): this process rendered shard I of N, no video
    depth_dir: str | None = None  # where each frame's depth went (depth_NNNNN.npy)

    @property
    def seconds_per_frame(self) -> float:
        return self.times.get("frames", 0.0) / max(1, self.rendered)


#: A fly-through whose scene has no depth estimates it only for the views its frames may use
#: when the scene has more than this many times ``n_views`` views: the union over the frames of
#: their PATH_MARGIN · n_views best views, ranked before any depth is known.
PATH_MARGIN = 2


def views_for_path(scene: Scene, cameras, n_views: int | None, exclude=()) -> list[str] | None:
    """Names of the views a path's frames may take as sources, or None for all of them.

    Each frame's ``PATH_MARGIN · n_views`` best views by :func:`vibr.geometry.selection.rank_views`
    on the geometry known before depth (the scene's sparse points, else a plane where the
    cameras' axes meet), united over the frames. None when ``n_views`` is None or the scene
    has at most ``PATH_MARGIN · n_views`` views (every view may serve)."""

    if n_views is None:
        return None
    ex = {scene.views[scene.index(e)].name for e in exclude}
    kept = [v.replace(depth=None, sigma_z=None) for v in scene.views if v.name not in ex]
    k = PATH_MARGIN * int(n_views)
    if len(kept) <= k:
        return None
    bare = scene.replace(views=kept)
    chosen = set()
    for cam in cameras:
        chosen.update(select_views(bare, cam, k))
    return None if len(chosen) == len(kept) else [kept[i].name for i in sorted(chosen)]


def check_path_sees_scene(scene: Scene, cameras, source=None) -> None:
    """Raise :class:`VibrInputError` when most of the path's cameras see nothing of the
    scene: the centre of the scene (:func:`vibr.paths.camera_path.scene_centre`) lies behind or outside
    the frame (with a one-frame margin) for more than half of them — typically a path
    exported by nerfstudio's viewer, which lives in nerfstudio's normalised frame."""


    X = scene_centre([v.camera for v in scene.views], scene_points(scene))
    seen = 0
    for c in cameras:
        xy, z = c.project(X)
        if z > 0 and -c.width <= xy[0] <= 2 * c.width and -c.height <= xy[1] <= 2 * c.height:
            seen += 1
    if seen <= len(cameras) / 2:
        C = np.array([v.camera.centre for v in scene.views])
        P = np.array([c.centre for c in cameras])
        raise VibrInputError(
            f"the path's cameras are nowhere near the scene's: the scene's centre is in view in "
            f"{seen} of {len(cameras)} frames (path centred at {np.round(P.mean(0), 3).tolist()}, "
            f"scene cameras at {np.round(C.mean(0), 3).tolist()}); a path exported by nerfstudio "
            f"lives in its normalised frame: give --dataparser-transforms dataparser_transforms.json",
            source)


def _frames_dir_for(out: Path, frames_dir) -> tuple[Path, Path | None]:
    if is_video(out):
        return (Path(frames_dir) if frames_dir else out.with_name(out.stem + "_frames")), out
    if out.suffix:
        raise VibrInputError(f"output must be a video ({', '.join(VIDEO_FORMATS)}) or a folder for the frames", out)
    if frames_dir and Path(frames_dir) != out:
        raise VibrInputError("--frames-dir is for a video output; the frames go to OUT", out)
    return out, None


def _check_frame_memory(scene: Scene, cams, n_views, source, supersample="auto") -> None:
    """Refuse, before the depth work, a path whose largest frame could not be rendered in
    the memory available (:func:`vibr.render.checks.check_render_memory`; the largest sources, the
    frame on the grid it is rendered on: with "auto", as fine as the largest source's pixels
    allow, at most ``SUPERSAMPLE_MAX`` times)."""

    if not cams:
        return
    big = max(cams, key=lambda c: c.width * c.height)
    shapes = sorted((v.camera.shape for v in scene.views), key=lambda s: s[0] * s[1], reverse=True)
    k = supersample
    if k == "auto":
        k = int(min(SUPERSAMPLE_MAX, max(1, round(max(shapes[0]) / max(big.shape)))))
    check_render_memory(shapes[:n_views] if n_views else shapes, big.scaled(k).shape if k > 1 else big.shape, source,
                        way_out="make the path with smaller frames (vibr path --size WxH)")


@dataclass(frozen=True)
class FlyOptions:
    """How :func:`render_path` renders a camera path (every field has a default).

    Attributes
    ----------
    method, params : str, RenderParams or dict
        The render method and its parameters (a :class:`vibr.render.params.RenderParams`, or
        keyword arguments of :meth:`~vibr.render.params.RenderParams.from_kwargs`, ``preset``
        included); "auto" weights are refused (each frame would need its own tuning).
    n_views : int or None
        K best sources per frame (soft weights, module docstring); None: all.
    blend : float
        Width of the weight transition (relative to the penalty threshold).
    geometry_kw : dict
        Arguments of :func:`vibr.geometry.compute_samples`.
    supersample : "auto" or int
        Frames coarser than the photographs are rendered on a finer grid and averaged back
        (:func:`vibr.render.render`'s ``supersample``; the factor is in each frame's record).
    depth, estimate_kw, cache_dir, exclude
        The sources' depth: see :func:`vibr.stereo.cache.scene_with_depth`.
    frames_dir : path, optional
        Where the frames go with a video output (default ``OUT_frames/`` beside it).
    crf, fps : int, float
        Video quality and frame rate (default the path's).
    overwrite : bool
        Render frames already written again (default: skip them: resumable).
    uncertainty : path, optional
        A video (same formats as ``out``) of each frame's σ map (:mod:`vibr.render.uncertainty`,
        grey levels of 255, colour-mapped on one scale for the whole path with its scale
        bar: :func:`write_sigma_video`); the maps stay in the frames folder as
        ``sigma_NNNNN.npz``.
    executor : "auto", None, "processes:N", int or a Dask address
        Passed to :func:`vibr.executor.run_tasks`; None: serial, here. "auto" (default):
        frames on :func:`vibr.executor.auto_workers` local processes (serial for a short
        path or small frames, :func:`auto_executor`). A depth estimate runs there too when
        the engine is named (not on "auto").
    progress : bool
        A bar per frame (on a terminal, :func:`vibr.progress.progress`).
    shard : (I, N) or "I/N", optional
        Render only shard ``I`` of ``N`` (frames ``f % N == I - 1``, module docstring) and
        write no video: :func:`assemble_path` encodes it once every shard is done.
    depth_out : path, optional
        A folder for each frame's depth, ``depth_NNNNN.npy`` (module docstring, step 4).
    check_scene : bool
        Refuse a path whose cameras see none of the scene (:func:`check_path_sees_scene`).
    """

    method: str = "gradient"
    params: RenderParams | dict | None = None
    n_views: int | None = 8
    blend: float = 0.25
    geometry_kw: dict | None = None
    supersample: object = "auto"
    depth: str = "auto"
    estimate_kw: dict | None = None
    cache_dir: object = None
    exclude: tuple = ()
    frames_dir: object = None
    crf: int = 18
    fps: float | None = None
    overwrite: bool = False
    uncertainty: object = None
    executor: object = "auto"
    progress: bool = True
    check_scene: bool = True
    shard: object = None
    depth_out: object = None


def render_path(scene: Scene, camera_path, out, *, options: FlyOptions | None = None, **kw) -> FlyResult:
    """Render every camera of ``camera_path`` from ``scene`` to numbered PNGs and a video.

    Parameters
    ----------
    scene : Scene
    camera_path : vibr.paths.camera_path.CameraPath
    out : path
        a video (``*.mp4``, or another of :data:`vibr.io.video.VIDEO_FORMATS`; frames in
        ``frames_dir``, default ``OUT_frames/`` beside it) or a folder
        (the frames only).
    options : FlyOptions, optional
        How to render; ``kw`` (its fields, e.g. ``n_views=4``) applies over it. Any other
        keyword raises ``TypeError``.
    """

    t_start = time.perf_counter()
    o = replace(options or FlyOptions(), **kw)
    o = replace(o, supersample=check_supersample(o.supersample),
                shard=None if o.shard is None else parse_shard(o.shard))
    fdir, video, fps = _checked_outputs(scene, camera_path, out, o)
    cams = list(camera_path.cameras)
    if o.check_scene:
        check_path_sees_scene(scene, cams, camera_path.meta.get("file"))
    _check_frame_memory(scene, cams, o.n_views, camera_path.meta.get("file"), o.supersample)
    t0 = time.perf_counter()
    # depth, when estimated, for the views the frames may use, on the engine the caller
    # named (on "auto" here: on one machine the sweeps' kernels already use every core)
    sources = scene_with_depth(scene, depth=o.depth, estimate_kw=o.estimate_kw, cache_dir=o.cache_dir,
                               exclude=o.exclude, executor=None if o.executor == "auto" else o.executor,
                               views=views_for_path(scene, cams, o.n_views, o.exclude))
    t_depth = time.perf_counter() - t0
    fdir.mkdir(parents=True, exist_ok=True)
    _mark_frames(fdir, len(cams), o.uncertainty is not None)
    if o.depth_out is not None:
        Path(o.depth_out).mkdir(parents=True, exist_ok=True)
    ctx = FrameContext(sources, cams, str(fdir), o.method, as_params(o.method, o.params), o.n_views, o.blend,
                       o.overwrite, dict(o.geometry_kw or {}), uncertainty=o.uncertainty is not None,
                       supersample=o.supersample, depth_dir="" if o.depth_out is None else os.fspath(o.depth_out))
    prepare_sources(ctx)
    t_first = time.perf_counter() - t_start
    t0 = time.perf_counter()
    mine = shard_of(len(cams), o.shard)
    frames, engine = _run_frames(ctx, mine, o.executor, o.progress)
    t_frames = time.perf_counter() - t0
    _check_frames_rendered(frames, fdir, camera_path.meta.get("file"))
    rendered = sum(not f["skipped"] for f in frames)
    res = FlyResult(len(cams), rendered, len(mine) - rendered, str(fdir), None,
                    depth_source=sources.meta.get("depth_source", ""), frames=frames, engine=engine,
                    shard=o.shard, depth_dir=None if o.depth_out is None else os.fspath(o.depth_out))
    t0 = time.perf_counter()
    if o.shard is None:  # a shard's frames are encoded by assemble_path
        _write_videos(res, fdir, len(cams), video, o.uncertainty, fps, o.crf)
    t_video = time.perf_counter() - t0
    res.times = {"depth": t_depth, "to_first_frame": t_first, "frames": t_frames, "video": t_video,
                 "total": time.perf_counter() - t_start,
                 "depth_source_time": sources.meta.get("depth_time_s", t_depth)}
    return res


def _owned_frame_file(path: Path) -> bool | None:
    """Whether ``path``, named as a frame or a σ map, is one a fly-through wrote: a frame
    with its key chunk (:data:`FRAME_KEY`), a σ map with its key; None for another name
    (:func:`vibr.io.outputs.check_frames_folder`)."""
    if fnmatch.fnmatch(path.name, "frame_[0-9][0-9][0-9][0-9][0-9].png"):
        return FRAME_KEY in read_png_text(path)
    if fnmatch.fnmatch(path.name, "sigma_[0-9][0-9][0-9][0-9][0-9].npz"):
        return _sigma_key(path) is not None
    return None


def _mark_frames(fdir: Path, n: int, uncertainty: bool) -> None:
    """The frames folder's marker (:data:`vibr.io.outputs.MARKER`), listing every frame (and
    σ map) of the path, written before the first frame: the folder is then vibr's."""
    names = [frame_name(i) for i in range(n)] + ([sigma_name(i) for i in range(n)] if uncertainty else [])
    try:
        write_marker(fdir, sorted(set(names) | (read_marker(fdir) or set())))
    except OSError as exc:
        raise VibrInputError(f"cannot write in the frames folder ({exc.strerror or exc})", fdir) from None


def assemble_path(camera_path, out, *, frames_dir=None, fps: float | None = None, crf: int = 18,
                  uncertainty=None, depth_out=None) -> FlyResult:
    """The video of a path whose frames were rendered by shards (:class:`FlyOptions`'s
    ``shard``): every frame of ``camera_path`` read from the frames folder and encoded.

    Parameters
    ----------
    camera_path : vibr.paths.camera_path.CameraPath
        The path the shards rendered (its number of frames and frame rate).
    out : path
        The video (:data:`vibr.io.video.VIDEO_FORMATS`).
    frames_dir, fps, crf, uncertainty
        As :class:`FlyOptions` (the frames folder defaults to ``OUT_frames/``).
    depth_out : path, optional
        The folder of the frames' depth: checked complete too.

    Raises
    ------
    VibrInputError
        One line naming every frame (σ map, depth map) not in the folder, or a frame there
        that vibr did not render (no frame key); nothing is written then.
    """

    t0 = time.perf_counter()
    out = Path(out)
    if not is_video(out):
        raise VibrInputError(f"the assembled output is a video ({', '.join(VIDEO_FORMATS)})", out)
    fdir, video = _frames_dir_for(out, frames_dir)
    n = len(camera_path.cameras)
    fps = camera_path.fps if fps is None else fps
    for v in (video, uncertainty):
        if v is not None:
            check_video_options(v, fps=fps, crf=crf)
    wanted = [(fdir / frame_name(i), i) for i in range(n)]
    if uncertainty is not None:
        wanted += [(fdir / sigma_name(i), i) for i in range(n)]
    if depth_out is not None:
        wanted += [(Path(depth_out) / depth_name(i), i) for i in range(n)]
    missing = sorted({i for p, i in wanted if not p.is_file()
                      or (p.suffix == ".png" and FRAME_KEY not in read_png_text(p))})
    if missing:
        raise VibrInputError(f"{len(missing)} of {n} frames are missing in {fdir}: {_index_runs(missing)}; "
                             "render them (their shards again, or the whole path) before assembling",
                             camera_path.meta.get("file"))
    res = FlyResult(n, 0, n, str(fdir), None, frames=[], engine="assembled from the frames folder",
                    depth_dir=None if depth_out is None else os.fspath(depth_out))
    _write_videos(res, fdir, n, video, uncertainty, fps, crf)
    res.times = {"depth": 0.0, "frames": 0.0, "video": time.perf_counter() - t0, "total": time.perf_counter() - t0}
    return res


def _index_runs(idx) -> str:
    """Sorted indices as runs: ``0, 3-5, 9``."""
    runs, start = [], idx[0]
    for a, b in zip(idx, list(idx[1:]) + [None]):
        if b != a + 1:
            runs.append(str(a) if a == start else f"{start}-{a}")
            start = b
    return ", ".join(runs)


def _checked_outputs(scene: Scene, camera_path, out, o: FlyOptions):
    """The frames folder, the video (None: frames only) and the frame rate of a path's
    outputs, every option checked before any frame is rendered."""

    if o.method not in METHODS:
        raise VibrInputError(f"unknown method {o.method!r} (choose from {', '.join(METHODS)})")
    if as_params(o.method, o.params).auto:  # every parameter checked before the work
        raise VibrInputError("gamma/lam 'auto' does not apply to a camera path: give numbers")
    if o.n_views is not None and o.n_views < 1:
        raise VibrInputError(f"n_views must be at least 1, got {o.n_views}")
    fdir, video = _frames_dir_for(Path(out), o.frames_dir)
    # frames among the photographs would become views of an image-folder scene (Strecha)
    check_not_input(fdir, [v.path for v in scene.views if v.path] + ([scene.root] if scene.root else []))
    # a folder holding files vibr did not write (a user's own frame_00002.png) is not written over
    check_frames_folder(fdir, _owned_frame_file, overwrite=o.overwrite)
    fps = camera_path.fps if o.fps is None else o.fps
    sigma = o.uncertainty
    if sigma is not None and not is_video(sigma):
        raise VibrInputError(f"the σ output of a path is a video ({', '.join(VIDEO_FORMATS)})", os.fspath(sigma))
    for v in (video, sigma):
        if v is not None:
            check_video_options(v, fps=fps, crf=o.crf)  # before any frame is rendered
    if sigma is not None and video is not None and Path(sigma).resolve() == video.resolve():
        raise VibrInputError("the σ video must not be the frames' video", sigma)
    return fdir, video, fps


def _write_videos(res: FlyResult, fdir: Path, n: int, video, uncertainty, fps: float, crf: int) -> None:
    """The frames' video and the σ video, when asked, into ``res``."""

    if video is not None:
        paths = [fdir / frame_name(i) for i in range(n)]
        k, w, h = write_video(video, (read_image(p) for p in paths), fps=fps, crf=crf)
        res.video, res.video_frames, res.video_size = str(video), k, (w, h)
    if uncertainty is not None:
        *_, vmax = write_sigma_video([fdir / sigma_name(i) for i in range(n)], uncertainty, fps=fps, crf=crf)
        res.sigma_video, res.sigma_vmax = str(uncertainty), vmax


def _check_frames_rendered(frames: list, fdir, source) -> None:
    """One error naming every frame that saw nothing (render_frame's ``failed``), raised once
    the other frames are on disk, before the video: a rerun of the mended path renders only
    what is missing."""
    bad = [f for f in frames if f.get("failed")]
    if not bad:
        return
    idx = [f["index"] for f in bad]
    raise VibrInputError(f"{len(bad)} of {len(frames)} frames saw nothing: frame{'s' if len(bad) > 1 else ''} "
                         f"{_index_runs(idx)} (frame {idx[0]}: {bad[0]['failed']}){_SEES_NOTHING}; the other "
                         f"frames are in {fdir}", source)


def _context_bytes(ctx: FrameContext) -> int:
    """Bytes of the arrays a worker holds for the whole path (the sources and their slopes)."""
    n = 0
    for v in ctx.sources.views:
        n += sum(a.nbytes for a in (v.image, v.depth) if isinstance(a, np.ndarray))
    for arrs in ctx.prepared.values():
        n += sum(a.nbytes for a in arrs if isinstance(a, np.ndarray))
    return n


def auto_executor(ctx: FrameContext, n_todo: int):
    """``executor="auto"``: the number of processes :func:`vibr.executor.auto_workers` gives
    for ``n_todo`` frames of the path's size, each worker holding the context and one
    render from ``n_views`` + 2 sources (the soft selection's extra views); None for 1."""

    cam = ctx.cameras[0]
    k = len(ctx.sources) if ctx.n_views is None else min(len(ctx.sources), ctx.n_views + 2)
    shapes = sorted((v.camera.shape for v in ctx.sources.views), key=lambda s: -s[0] * s[1])[:k]
    need = _context_bytes(ctx) + render_memory(shapes, cam.shape)
    n = auto_workers(n_todo, cam.width * cam.height, need)
    return n if n > 1 else None


def _run_frames(ctx: FrameContext, indices: list, executor, progress: bool) -> tuple[list, str]:
    """The frames' summaries in frame order, and where they ran (:attr:`FlyResult.engine`).
    Frames already on disk with their key are skipped here, before any task is made: the
    progress line and its time left then count only the frames still to render."""
    done = [] if ctx.overwrite else [i for i in indices if frame_done(ctx, i)]
    todo = sorted(set(indices) - set(done))
    skipped = [{"index": i, "skipped": True, "seconds": 0.0} for i in done]
    if executor == "auto":
        executor = auto_executor(ctx, len(todo))
    if executor is not None:
        kind, arg = parse_executor(executor)
        n_proc = min(arg, max(len(todo), 1)) if kind == "processes" else arg
        engine = {"serial": "in this process", "processes": f"on {n_proc} processes",
                  "dask-local": f"on a local Dask cluster of {arg} workers"}.get(kind, f"on Dask ({arg})")
        out = run_tasks(render_frame, todo, setup=_same, setup_args=(ctx,), executor=executor,
                        desc="frames") if todo else []
    else:
        engine = "in this process"
        out = [render_frame(ctx, i) for i in (bar(todo, desc="frames") if progress else todo)]
    return sorted(out + skipped, key=lambda f: f["index"]), engine
