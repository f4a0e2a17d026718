"""The viewer's renders: a vibr camera and the GUI's settings in, an image out.

Rendering is :func:`vibr.render.render` itself, from the ``n_views`` best sources for the
camera (:func:`vibr.geometry.selection.select_views`, ranked on a fixed sample of the scene's points
so that ranking costs no depth-map pass per request); nothing here is viewer-specific maths.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..camera import Camera
from ..errors import VibrInputError, check_stop
from ..geometry import prepare_depth
from ..geometry.resample import scaled_scene as _scaled
from ..geometry.selection import select_views
from ..render import render
from ..render.methods import DEFAULTS, METHODS
from ..render.params import RenderParams
from ..scene import Scene
from ..stereo.cache import scene_with_depth as _with_depth
from .geometry import point_cloud, points_in_view

logger = logging.getLogger(__name__)

__all__ = ["ViewSettings", "ViewImage", "ViewRenderer", "scaled_scene", "scene_with_depth",
           "SHOW"]


#: Memory the per-source depth preparation kept for a session may take (bytes): three
#: float64 maps per view (fountain at scale 0.25, 11 views of 768×512: 104 MB).
PREPARED_BUDGET_BYTES = 1 << 30

#: Outer passes (weights re-estimated from u) of a preview, for the methods that make more:
#: a preview lasts until the camera has been still for a moment, and one pass is faster at
#: about the same PSNR (docs/explanation/viewer.md, "Previews in one outer pass"). The full view keeps
#: the method's passes: it is what ``vibr render`` gives for the camera.
PREVIEW_OUTER = 1


#: What the viewer shows of a render (:attr:`ViewSettings.show`).
SHOW = {"image": "the rendered view",
        "sigma": "where it can be trusted: each pixel's standard deviation, viridis from 0 (dark) up"}


@dataclass(frozen=True)
class ViewSettings:
    """What the GUI controls (paper names; see :mod:`vibr.render.methods`).

    method : one of :data:`vibr.render.methods.METHODS` (default "gradient")
    gamma : gradient-term weight (eq. energy_final), method "gradient" only (default
        :data:`vibr.render.methods.DEFAULTS`' gamma, as ``vibr render``: a path composed in
        the viewer renders to video with the same settings)
    lam : TV weight, for intensities on [0, 255] (default: DEFAULTS' lam)
    params : the other render parameters, keyword arguments of
        :meth:`vibr.render.params.RenderParams.from_kwargs` (``preset`` included: gamma and
        lam are then read in its units), applied to whichever method the GUI selects
    n_views : number of source views (the best for the camera)
    preview_long_side : long side of the preview image while the camera moves (px)
    full_long_side : long side of the image once the camera is still (px); None: the
        scene's largest image side (the viewer fills it in)
    show : one of :data:`SHOW` — the render, or where it can be trusted: its per-pixel σ
        (:mod:`vibr.render.uncertainty`) colour-mapped
    """

    method: str = "gradient"
    gamma: float = DEFAULTS["gamma"]
    lam: float = DEFAULTS["lam"]
    n_views: int = 8
    preview_long_side: int = 256
    full_long_side: int | None = None
    show: str = "image"
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.method not in METHODS:
            raise VibrInputError(f"unknown method {self.method!r} (choose from {', '.join(METHODS)})")
        if self.n_views < 1 or self.preview_long_side < 8 or (self.full_long_side is not None and self.full_long_side < 8):
            raise VibrInputError("n_views must be >= 1 and image sizes >= 8 px")
        if not (self.gamma >= 0 and self.lam >= 0):
            raise VibrInputError("gamma and lam must be >= 0")
        if self.show not in SHOW:
            raise VibrInputError(f"show must be one of {', '.join(SHOW)}, got {self.show!r}")
        if {"gamma", "lam"} & set(self.params):
            raise VibrInputError("ViewSettings: gamma and lam are fields of their own, not params")
        self.render_params()  # every parameter checked here, not at the first render

    def render_params(self) -> RenderParams:
        """The :class:`~vibr.render.params.RenderParams` of a render with these settings."""
        return RenderParams.from_kwargs(self.method, **self.params, gamma=self.gamma, lam=self.lam)

    def replace(self, **changes) -> "ViewSettings":
        return replace(self, **changes)


@dataclass
class ViewImage:
    """A render for the viewer: ``image`` H×W×3 float32 in [0, 1], the ``camera`` it is
    for, the ``sources`` (view names) it used, ``seconds`` spent, the renderer's stage
    ``times``, its solver ``iterations`` and, when shown, its σ map ``uncertainty``."""

    image: np.ndarray
    camera: Camera
    sources: list
    seconds: float
    times: dict = field(default_factory=dict)
    iterations: int = 0
    uncertainty: np.ndarray | None = None  # σ, grey levels (ViewSettings.show "sigma")


class ViewRenderer:
    """Render any camera of a scene whose views all have depth.

    Parameters
    ----------
    scene : Scene
        Every view with depth (:func:`scene_with_depth`).
    rank_points : (N, 3) array, optional
        World points used to rank the sources per camera; default a 4096-point sample of
        the depth maps.
    threads : int, optional
        numba threads per render; default all that numba started (in ``vibr view``, two per
        core: :mod:`vibr._runtime.threads`). The image does not depend on it.
    """

    def __init__(self, scene: Scene, rank_points: np.ndarray | None = None, threads: int | None = None):
        self.scene = scene
        self._long_side = max(max(v.shape) for v in scene.views)
        self._scaled: dict[float, Scene] = {1.0: scene}
        # per scene scale: view name -> prepare_depth's (z, z_x, z_y), computed once per
        # session instead of once per request, within a memory budget
        self._prepared: dict[float, dict[str, tuple]] = {}
        self._prepared_bytes = 0
        # one render at a time: numba's default (workqueue) threading layer must not be
        # entered from two threads at once, and renders are CPU-bound anyway
        self._lock = threading.Lock()
        if threads is not None and int(threads) < 1:
            raise VibrInputError(f"threads must be >= 1, got {threads}")
        self.threads = threads
        if rank_points is None:
            rank_points, _ = point_cloud(scene, 4096, seed=1)
        self.rank_points = np.asarray(rank_points, dtype=np.float64)

    def scene_for(self, camera: Camera) -> Scene:
        """The scene at the resolution of ``camera``: for an image much smaller than the
        views (a preview), views resized by ``s = long side of camera / of the views``
        (:func:`scaled_scene`, cached per ``s``): warping every full-resolution source pixel
        would cost as much as a full-size render."""
        s = max(camera.width, camera.height) / self._long_side
        if s > 0.75:
            return self.scene
        s = round(s, 3)
        if s not in self._scaled:
            self._scaled[s] = scaled_scene(self.scene, s)
        return self._scaled[s]

    def prepared_for(self, scene: Scene, idx) -> dict:
        """``view name → (z, z_x, z_y)`` (:func:`vibr.geometry.prepare_depth`, the geometry
        stage's defaults) of the views ``idx`` of ``scene`` (this renderer's scene or one of
        its :meth:`scene_for` scalings): target-independent, so kept for the session (up to
        :data:`PREPARED_BUDGET_BYTES`; views beyond it are prepared per request)."""

        key = float(scene.meta.get("viewer_scale", 1.0))
        cache = self._prepared.setdefault(key, {})
        for k in idx:
            v = scene.views[k]
            if v.name in cache:
                continue
            need = 3 * 8 * v.depth.size
            if self._prepared_bytes + need > PREPARED_BUDGET_BYTES:
                continue
            cache[v.name] = prepare_depth(v)
            self._prepared_bytes += need
        return cache

    def sources_for(self, camera: Camera, n_views: int) -> list[int]:
        """Indices of the ``n_views`` best views for ``camera``."""
        if n_views >= len(self.scene):
            return list(range(len(self.scene)))
        pts = points_in_view(self.rank_points, camera)
        return select_views(self.scene, camera, n_views, points=pts if len(pts) else None)

    def render(self, camera: Camera, settings: ViewSettings, should_stop=None, preview: bool = False) -> ViewImage:
        """Render ``camera`` with ``settings`` (its size is the camera's); a ``preview`` in at
        most :data:`PREVIEW_OUTER` outer passes.

        ``should_stop()``, when given, is polled between the render's stages and after every
        solver iteration (:func:`vibr.render.render`'s ``stop``); when it returns True the
        render is abandoned by raising :class:`vibr.render.RenderStopped` (a newer camera
        arrived: finishing would only delay its image)."""
        import numba

        with self._lock:
            before = numba.get_num_threads()  # per calling thread
            numba.set_num_threads(min(int(self.threads or numba.config.NUMBA_NUM_THREADS),
                                      numba.config.NUMBA_NUM_THREADS))
            try:
                return self._render(camera, settings, should_stop, preview)
            finally:
                numba.set_num_threads(before)

    def _render(self, camera: Camera, settings: ViewSettings, should_stop, preview: bool = False) -> ViewImage:
        t0 = time.perf_counter()
        check_stop(should_stop)
        idx = self.sources_for(camera, settings.n_views)
        scene = self.scene_for(camera)
        src = scene.subset(idx)
        prepared = self.prepared_for(scene, idx)
        params = settings.render_params()
        if preview and params.n_outer > PREVIEW_OUTER:
            params = params.replace(n_outer=PREVIEW_OUTER)
        res = render(src, camera, params=params, stop=should_stop, geometry_kw={"prepared": prepared},
                     uncertainty=settings.show == "sigma")
        dt = time.perf_counter() - t0
        return ViewImage(res.image, camera, [v.name for v in src.views], dt, dict(res.times), res.iterations,
                         res.uncertainty)


def scaled_scene(scene: Scene, s: float) -> Scene:
    """Every view resized by ``s`` as :func:`vibr.io.load_scene` does with ``scale``
    (:func:`vibr.geometry.resample.scaled_scene`), the factor kept in ``meta["viewer_scale"]``."""

    return _scaled(scene, s).replace(meta=dict(scene.meta, viewer_scale=s))


def scene_with_depth(scene: Scene, *, cache_dir=None) -> Scene:
    """``scene`` with depth on every view, as fly-throughs get it
    (:func:`vibr.stereo.cache.scene_with_depth`, depth "auto"): the scene's own, transferred
    to the views without it, or estimated once and kept in the on-disk cache; the fallback
    proxy as ``vibr render`` applies it."""

    return _with_depth(scene, depth="auto", cache_dir=cache_dir)
