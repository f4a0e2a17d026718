"""How large a source pixel is in the target, and the grid to render on.

A source photographed at a finer resolution than the target (a 1080p video from 4K photos,
a thumbnail, a camera far from the scene) puts several samples in each target pixel. The
bilinear image-formation model (``psf="bilinear"``, paper §4.1) reads each of them as a point
sample of the target image, so the solution fits an aliased image. Rendering on a grid
``k`` times finer and averaging ``k × k`` blocks (a pixel-integrating sensor) avoids it
(docs/explanation/renderer.md, "Sources finer than the target"). :func:`source_pixel_size` measures
the ratio, :func:`resolution_plan` chooses ``k`` and the sources to reduce first (those
still much finer than the fine grid: the cost stays that of a render at the sources'
resolution), which :func:`vibr.render.render` applies.

The other way round (a camera closer to the scene than the photographs), a source pixel
covers ``s > 1`` target pixels and most target pixels receive no sample: the image between
them would be the TV prior's. The target is then rendered on a grid ``g ≈ s / √2`` times
coarser, where every pixel has samples, and enlarged (cubic spline) to its size
(docs/explanation/renderer.md, "Sources coarser than the target").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..camera import Camera
from ..errors import VibrInputError
from ..scene import View

__all__ = ["source_pixel_size", "reduction_scale", "coarsen_factor", "resolution_plan", "ResolutionPlan",
           "check_supersample", "REDUCTION_STEP",
           "SIZE_GRID", "SUPERSAMPLE_MAX", "REDUCE_BELOW", "MIN_REDUCED_SIDE"]

#: Reduction factors are powers of ``REDUCTION_STEP`` (1, 0.707, 0.5, 0.354, 0.25, ...): a
#: camera moving along a path reuses the same few resolutions, and a source is never reduced
#: below the target's resolution by more than this step's rounding.
REDUCTION_STEP = 1.0 / math.sqrt(2.0)

#: Source pixels measured per side (a regular grid over the view).
SIZE_GRID = 24

#: The largest supersampling factor ``k`` "auto" chooses (k² times the target's pixels).
SUPERSAMPLE_MAX = 4

#: A source whose pixels are smaller than this many pixels of the (supersampled) grid is
#: reduced first (:func:`reduction_scale`) ...
REDUCE_BELOW = 0.5
#: ... unless its shorter side would fall below this many pixels.
MIN_REDUCED_SIDE = 16

#: Sources coarser than the target: the grid is coarser by a power of √2 such that a source
#: pixel is about this many pixels of it (a little finer than the sources: the views' samples
#: fall at different sub-pixel places; chosen on the *choose* cases of
#: ``benchmarks/quality/finer_sources.py --coarser``, docs/explanation/renderer.md).
COARSE_GRID_SOURCE_SIZE = math.sqrt(2.0)


def _focal(cam: Camera) -> float:
    return math.sqrt(float(cam.K[0, 0]) * float(cam.K[1, 1]))


def source_pixel_size(view: View, camera: Camera, grid: int = SIZE_GRID) -> float:
    """The linear size, in pixels of ``camera``, of a pixel of ``view`` (median over the view).

    For a source pixel at orthogonal depth ``z_s`` that the target sees at depth ``z_t``:

    .. math:: s = \\frac{f_t / z_t}{f_s / z_s}, \\qquad f = \\sqrt{f_x f_y}

    (a fronto-parallel patch; the slant of the surface is ignored), the median over a
    ``grid × grid`` lattice of the view's pixels with a depth (or a fallback depth) that
    project in front of the target and inside its image. ``s < 1``: the source is finer
    than the target. NaN when fewer than 16 such pixels (nothing to measure).
    """
    z = view.depth if view.depth is not None else view.fallback
    if z is None:
        return math.nan
    cs = view.camera
    ys = np.linspace(0, cs.height - 1, min(grid, cs.height)).round().astype(np.intp)
    xs = np.linspace(0, cs.width - 1, min(grid, cs.width)).round().astype(np.intp)
    zs = np.asarray(z, np.float64)[np.ix_(ys, xs)]
    yy, xx = np.meshgrid(ys, xs, indexing="ij")
    ok = np.isfinite(zs) & (zs > 0)
    if view.mask is not None:
        ok &= np.asarray(view.mask, bool)[np.ix_(ys, xs)]
    pix = np.stack([xx[ok], yy[ok]], axis=-1).astype(np.float64)
    _, zt, inside = camera.sees(cs.backproject(pix, zs[ok]))
    if np.count_nonzero(inside) < 16:
        return math.nan
    size = (_focal(camera) / zt[inside]) * (zs[ok][inside] / _focal(cs))
    return float(np.median(size))


def reduction_scale(size: float) -> float:
    """The factor a source whose pixels are ``size`` target pixels wide is resized by: the
    smallest power of :data:`REDUCTION_STEP` that is at least ``size`` (so the reduced
    source is never coarser than the target), 1 for ``size ≥ REDUCTION_STEP`` or unknown.

    >>> reduction_scale(0.5), reduction_scale(0.6), reduction_scale(0.8)
    (0.5, 0.7071067811865476, 1.0)
    """
    if not math.isfinite(size) or size >= REDUCTION_STEP - 1e-12:
        return 1.0
    j = math.floor(math.log(size) / math.log(REDUCTION_STEP) + 1e-9)
    return 2.0 ** (-j / 2.0)


def coarsen_factor(size: float, shape) -> float:
    """How many times coarser than a target of ``shape = (h, w)`` to render it when its
    sources' pixels are ``size`` target pixels wide: the power of √2 nearest (in log) to
    ``size / COARSE_GRID_SOURCE_SIZE``, 1 when that nearest power is 1 (``size < 2^0.75 ≈
    1.68``) or the size is unknown, and never so coarse that the grid's shorter side falls below
    :data:`MIN_REDUCED_SIDE` pixels.

    >>> coarsen_factor(1.5, (480, 640)), coarsen_factor(2.0, (480, 640)), coarsen_factor(4.0, (480, 640))
    (1.0, 1.4142135623730951, 2.8284271247461903)
    """
    if not math.isfinite(size) or size <= 0:
        return 1.0
    j = math.floor(2.0 * math.log2(size / COARSE_GRID_SOURCE_SIZE) + 0.5)
    while j > 0 and min(shape) / 2.0 ** (j / 2.0) < MIN_REDUCED_SIDE:
        j -= 1
    return 2.0 ** (j / 2.0) if j > 0 else 1.0


@dataclass(frozen=True)
class ResolutionPlan:
    """How a target is rendered from its sources (:func:`resolution_plan`).

    ``supersample``: the target is rendered on a grid ``k`` times finer
    (:meth:`vibr.camera.Camera.scaled`) and ``k × k`` blocks are averaged; ``coarsen``: on a
    grid ``g`` times coarser, enlarged after (at most one of the two differs from 1);
    ``scales``: view name → factor that source is resized by first; ``sizes``: view name →
    :func:`source_pixel_size` (target pixels, NaN where unmeasured); ``grid_source_size``:
    their median on the grid rendered on."""

    supersample: int = 1
    scales: dict = field(default_factory=dict)
    sizes: dict = field(default_factory=dict)
    coarsen: float = 1.0
    #: the grid's resolution over the target's: ``k``, or about ``1 / g`` (the coarser grid's
    #: size is rounded: ``√(s_x s_y)`` of :meth:`vibr.camera.Camera.scaled`)
    grid_scale: float = 1.0

    def grid_camera(self, camera: Camera) -> Camera:
        """``camera`` on this plan's grid."""
        if self.supersample > 1:
            return camera.scaled(self.supersample)
        return camera.scaled(1.0 / self.coarsen) if self.coarsen > 1 else camera

    @property
    def grid_source_size(self) -> float:
        """The median size of a source pixel in pixels of the grid rendered on (after the
        reductions); 1 where none is measured. Above 1 the sources are coarser than it."""
        on_grid = [x * self.grid_scale / self.scales.get(n, 1.0) for n, x in self.sizes.items() if math.isfinite(x)]
        return float(np.median(on_grid)) if on_grid else 1.0


def resolution_plan(sources, camera: Camera, supersample="auto", max_factor: int = SUPERSAMPLE_MAX) -> ResolutionPlan:
    """The supersampling factor and the source reductions for rendering ``camera``.

    ``supersample="auto"``: ``k = round(1 / s̃)`` clipped to ``[1, max_factor]``, ``s̃`` the
    median :func:`source_pixel_size` of the sources (1 where none is measured); where the
    sources are coarser (``s̃`` above about 1.68), ``k = 1`` and the grid is
    ``g = coarsen_factor(s̃)`` times coarser. An integer fixes ``k`` (and ``g = 1``). A source
    with ``s · grid_scale < REDUCE_BELOW`` (still more than twice finer than the grid) is
    reduced by ``reduction_scale(s · grid_scale)`` (unless its shorter side would fall below
    :data:`MIN_REDUCED_SIDE` pixels).
    """
    supersample = check_supersample(supersample)
    sizes = {v.name: source_pixel_size(v, camera) for v in sources.views}
    finite = [x for x in sizes.values() if math.isfinite(x)]
    k, g = supersample, 1.0
    if k == "auto":
        median = float(np.median(finite)) if finite else 1.0
        k = int(min(max_factor, max(1, round(1.0 / median))))
        g = coarsen_factor(median, camera.shape) if k == 1 else 1.0
    plan = ResolutionPlan(k, {}, sizes, g, float(k))
    if g > 1:
        grid = plan.grid_camera(camera)
        plan = replace(plan, grid_scale=math.sqrt(grid.width / camera.width * grid.height / camera.height))
    scales = {}
    for v in sources.views:
        x = sizes[v.name] * plan.grid_scale
        r = reduction_scale(x) if math.isfinite(x) and x < REDUCE_BELOW else 1.0
        if r < 1.0 and min(v.camera.width, v.camera.height) * r >= MIN_REDUCED_SIDE:
            scales[v.name] = r
    return replace(plan, scales=scales)


def check_supersample(value):
    """``value`` as "auto" or an int ≥ 1 (an integral float or string accepted); else
    :class:`VibrInputError`."""
    if isinstance(value, str) and value.strip().lower() == "auto":
        return "auto"
    try:
        k = float(value)
    except (TypeError, ValueError):
        k = math.nan
    if not (math.isfinite(k) and k >= 1 and k == int(k)) or isinstance(value, bool):
        raise VibrInputError(f"supersample must be 'auto' or an integer >= 1, got {value!r}")
    return int(k)
