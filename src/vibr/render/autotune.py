"""``gamma="auto"`` / ``lam="auto"``: the gradient-term and TV weights chosen per scene,
without the target's image (issue 23; measured in docs/RESULTS.md, the block of benchmarks/sweep_defaults.py).

Leave-one-source-out: the source view(s) nearest the target camera (by centre distance; the
target's image is never read, only its camera) are held out in turn and rendered from the
other sources at a reduced size; the weights whose renders best match the held-out
photographs (mean squared error over all their pixels, 2-pixel border excluded) are kept.
The search is a coordinate search: ``gamma`` over :data:`GAMMA_GRID` at the default ``lam``,
then ``lam`` over :data:`LAM_GRID` at the best ``gamma`` (a parameter that is not "auto"
stays fixed). The reduced size is chosen so that the probe renders together hold at most
``budget`` times the target's pixel count (``budget`` = 1: about the time of one render of
the target at full size, measured in docs/RESULTS.md).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from ..camera import Camera
from ..errors import VibrInputError
from ..geometry import compute_samples
from ..geometry.resample import scaled_scene
from ..metrics import mse
from ..scene import Scene
from .methods import get_method, render_samples, sample_fields
from .params import AUTO, DEFAULTS, RenderParams

logger = logging.getLogger("vibr.render.autotune")

__all__ = ["AUTO", "GAMMA_GRID", "LAM_GRID", "Tuned", "probe_views", "probe_scale", "tune",
           "resolve_auto"]

#: Candidate gradient-term weights (vibr's units, :mod:`vibr.render.methods`).
GAMMA_GRID = (0.0, 0.1, 0.2, 0.5, 1.0)
#: Candidate TV weights (grey levels of 255).
LAM_GRID = (0.2, 0.6, 1.0)
#: Metric border (pixels) of the probe renders, as the evaluation's.
BORDER = 2
#: Smallest probe size (pixels on the short side): below it the probe says little.
MIN_SIDE = 48


@dataclass
class Tuned:
    """The outcome of :func:`tune`: the chosen ``gamma`` and ``lam``, the probe views, the
    probe scale, ``scores`` {(gamma, lam): mean probe MSE} and the time spent (s)."""

    gamma: float
    lam: float
    probes: list
    scale: float
    scores: dict = field(default_factory=dict)
    seconds: float = 0.0


def probe_views(sources: Scene, target: Camera, n_probe: int = 1) -> list[int]:
    """Indices of the ``n_probe`` sources whose centres are nearest the target camera's."""
    c = np.asarray(target.centre, float)
    d = [float(np.linalg.norm(np.asarray(v.camera.centre, float) - c)) for v in sources.views]
    return [int(i) for i in np.argsort(d, kind="stable")[:n_probe]]


def probe_scale(sources: Scene, target: Camera, probes, n_renders: int, budget: float = 1.0) -> float:
    """The image scale s (≤ 1) at which ``n_renders`` renders of each probe view hold at most
    ``budget`` × the target's pixels (a render's cost grows with its pixels and samples,
    both ∝ s²); at least :data:`MIN_SIDE` pixels on the probe's short side."""
    tpx = float(target.width * target.height)
    ppx = sum(float(sources.views[i].camera.width * sources.views[i].camera.height) for i in probes)
    s = float(np.sqrt(budget * tpx / max(n_renders * ppx, 1.0)))
    short = min(min(sources.views[i].camera.shape) for i in probes)
    return float(min(1.0, max(s, MIN_SIDE / short)))


def _probe_cases(sources: Scene, probes, s: float, keep=()):
    """Per probe: (samples from the other sources, their centres, probe camera, probe image,
    the probe's mask or None: a masked pixel of its photograph is no error of a render)."""

    small = scaled_scene(sources, s)
    out = []
    for i in probes:
        pv = small.views[i]
        rest = small.replace(views=[v for j, v in enumerate(small.views) if j != i])
        samples = compute_samples(rest, pv.camera, keep=keep)
        if len(samples):
            out.append((samples, np.array([v.camera.centre for v in rest.views]), pv.camera, pv.image, pv.mask))
    return out


def _score(cases, params: RenderParams) -> float:
    """Mean over the probes of the MSE of their renders (all pixels of their masks, border
    excluded)."""

    errs = []
    for samples, centres, cam, img, mask in cases:
        r = render_samples(samples, params.method, params=params, source_centres=centres, target_centre=cam.centre)
        errs.append(mse(r.image, img, mask, BORDER))
    return float(np.mean(errs))


def tune(sources: Scene, target: Camera, method: str = "gradient", *, gamma=AUTO, lam=AUTO,
         gammas=GAMMA_GRID, lams=LAM_GRID, n_probe: int = 1, budget: float = 1.0,
         params: RenderParams | None = None, **kw) -> Tuned:
    """Choose ``gamma`` and/or ``lam`` (those given as ``"auto"``) for rendering ``target``
    (a :class:`~vibr.camera.Camera`: its image is never needed) from ``sources`` (views with
    depth), by leave-one-source-out on the sources (module docstring). ``params`` (a
    :class:`RenderParams` for ``method``) and/or the keyword arguments ``kw``: the other
    render parameters, used as given in every probe render."""
    if isinstance(target, Scene) or not isinstance(target, Camera):
        raise VibrInputError("tune: the target must be a Camera (its image is never used)")
    if len(sources) < 2:
        raise VibrInputError("gamma/lam 'auto' needs at least 2 source views (one is held out)")

    t0 = time.perf_counter()
    tune_g, tune_l = gamma == AUTO, lam == AUTO
    g0 = DEFAULTS["gamma"] if tune_g else float(gamma)
    l0 = DEFAULTS["lam"] if tune_l else float(lam)
    if g0 == AUTO:  # the default itself is "auto": start the lam search from the grid's middle
        g0 = float(gammas[len(gammas) // 2])
    if l0 == AUTO:
        l0 = float(lams[len(lams) // 2])
    n_renders = (len(gammas) if tune_g else 0) + (len(lams) - 1 if tune_l else 0)
    probes = probe_views(sources, target, n_probe)
    s = probe_scale(sources, target, probes, max(n_renders, 1), budget)

    rp = RenderParams.coerce(method, params, **kw).replace(gamma=g0, lam=l0)
    cases = _probe_cases(sources, probes, s, sample_fields(method, rp))
    scores: dict = {}

    def run(g, l):
        if (g, l) not in scores:
            scores[(g, l)] = _score(cases, rp.replace(gamma=g, lam=l))
        return scores[(g, l)]

    best_g, best_l = g0, l0
    if cases:
        if tune_g:
            best_g = min((float(g) for g in gammas), key=lambda g: run(g, l0))
        if tune_l:
            best_l = min((float(l) for l in lams), key=lambda l: run(best_g, l))
    else:
        logger.warning("auto weights: no probe view sees the other sources; keeping gamma %g, lam %g", g0, l0)
    out = Tuned(best_g, best_l, [sources.views[i].name for i in probes], s, scores, time.perf_counter() - t0)
    logger.info("auto weights: gamma %g, lam %g from %d probe render(s) of %s at scale %.2f (%.2f s)",
                out.gamma, out.lam, len(scores) * len(cases), ", ".join(out.probes), s, out.seconds)
    return out


def resolve_auto(sources: Scene, target: Camera, params: RenderParams) -> RenderParams:
    """``params`` with ``gamma`` / ``lam`` = :data:`AUTO` replaced by :func:`tune`'s choice;
    unchanged when neither is "auto" (for a method without the gradient term only an "auto"
    lam is tuned; a direct blend, ulr, has neither weight)."""

    m = get_method(params.method)
    g = params.gamma if m.gradient else 0.0
    if AUTO not in (g, params.lam):
        return params
    if not m.solve:
        return params.replace(gamma=0.0, lam=float(LAM_GRID[len(LAM_GRID) // 2]))
    t = tune(sources, target, m.name, gamma=g, lam=params.lam, params=params)
    return params.replace(gamma=t.gamma if m.gradient else params.gamma, lam=t.lam)
