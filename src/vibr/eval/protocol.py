"""The paper's evaluation protocol: hold a view out, render it, compare (paper §6).

:func:`evaluate` renders one target view of a scene with several methods and settings from
the same sources and geometry, and measures PSNR and DSSIM = 10⁴·(1 − SSIM) (Wang et al.
2004, Gaussian window σ = 1.5) against the held-out photograph. As in the paper, the metrics
are taken over the *reconstructed* pixels by default: the pixels that every compared method
covered (so that all rows of a table are measured on the same pixels); ``mask="all"`` uses the
whole image, holes filled by push–pull.
"""

from __future__ import annotations

import itertools
import json
import logging
import platform
import time
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from .._runtime.atomic import atomic_path
from ..errors import VibrInputError
from ..geometry.samples import view_counts
from ..metrics import METRIC_BORDER, METRICS, check_measurable, dssim, psnr, uncertainty_metrics, view_metrics
from ..pipeline import prepare
from ..progress import progress
from ..render import shared_geometry
from ..render.methods import DEFAULTS, METHODS, get_method
from ..render.params import AUTO, RenderParams
from ..scene import Scene

logger = logging.getLogger(__name__)


@dataclass
class Setting:
    """One row of a table: a method and the parameters given to :func:`vibr.render.render`."""

    method: str
    params: dict = field(default_factory=dict)

    @property
    def label(self) -> str:
        extra = ",".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in self.params.items())
        return self.method + (f"({extra})" if extra else "")


#: The gamma values of the paper's tables and vibr's default (one row each for the gradient
#: method): the default setting is always compared with the baselines.
GAMMAS = tuple(sorted({0.0, 1.0, 2.0, 3.0, float(DEFAULTS["gamma"])}))


def settings_grid(methods: Sequence[str] = METHODS, gammas: Sequence[float] = GAMMAS,
                  alphas: Sequence[float] | None = None, lams: Sequence[float] | None = None) -> list[Setting]:
    """Settings for each method: ``gradient`` once per gamma (``gamma`` is only its parameter),
    every variational method once per alpha and lambda given."""
    out = []
    for m in methods:
        spec = get_method(m)  # what the method uses decides which parameters vary
        gs = list(gammas) if spec.gradient else [None]
        al = [None] if (not spec.solve or not alphas) else list(alphas)
        lm = [None] if (not spec.solve or not lams) else list(lams)
        for g, a, l in itertools.product(gs, al, lm):
            p = {}
            if a is not None:
                p["alpha"] = float(a)
            if g is not None:
                p["gamma"] = g if g == AUTO else float(g)
            if l is not None:
                p["lam"] = l if l == AUTO else float(l)
            out.append(Setting(m, p))
    return out


@dataclass
class Evaluation:
    """What :func:`run_evaluation` measured: the JSON-serialisable ``report`` (see
    :func:`evaluate`), and for figures (:func:`vibr.eval.figures.write_evaluation_figures`) the
    held-out ``reference`` image, the rendered ``images`` by setting label, the evaluated
    pixels ``mask`` (H×W bool) and a default file-name ``prefix`` (``TARGET_DEPTH``)."""

    report: dict
    reference: np.ndarray
    images: dict
    mask: np.ndarray
    prefix: str


def evaluate(scene: Scene, target: int | str, settings: Sequence[Setting], **kw) -> dict:
    """Render the held-out ``target`` with each setting and measure it; returns the report
    of :func:`run_evaluation` (its keyword arguments)."""
    return run_evaluation(scene, target, settings, **kw).report


@dataclass(frozen=True)
class EvalOptions:
    """How :func:`run_evaluation` prepares, renders and measures a held-out view (every
    field has a default).

    Attributes
    ----------
    sources, depth, depth_files, n_views, estimate_kw, fallback, cache_dir
        The sources and their depth (:func:`vibr.pipeline.prepare`); ``cache_dir`` False
        (default): no cache of estimated depth.
    mask : {"reconstructed", "all"}
        Measure on the pixels every setting reconstructs (default) or on all of them (a
        view's own mask applies in both).
    border : int
        Pixels left out along the image's edges (:data:`vibr.metrics.METRIC_BORDER`).
    intensity_scale : float, optional
        The intensity scale the render parameters refer to (render's ``scale``; default the
        renderer's, 255). A setting's own ``scale`` parameter overrides it.
    render_kw : dict, optional
        Extra render parameters for every setting (a setting's params win).
    geometry_kw : dict, optional
        Arguments of :func:`vibr.geometry.compute_samples`.
    use_lpips : bool
        Also LPIPS, when the ``lpips`` package works here.
    view_split : int, optional
        Also measure each setting separately on the evaluated pixels seen by at most
        ``view_split`` source views and on those seen by more (:func:`view_counts`): entry
        ``regions`` = {"few": {...}, "many": {...}} with psnr, dssim and the pixel fraction.
    uncertainty : bool
        Render with ``uncertainty=True`` and add entry ``uncertainty`` = {ause, spearman,
        fractions, curve, oracle, rmse} (:func:`vibr.metrics.uncertainty_metrics`, the same
        pixels as the other metrics; plot: :func:`vibr.eval.sigma_figures.write_sparsification_figure`).
    supersample : "auto" or int
        The grid every setting renders on, as :func:`vibr.render.render` chooses it (a
        held-out view at its sources' resolution: the target's own).
    """

    sources: Sequence[int | str] | None = None
    depth: str = "auto"
    depth_files: object = None
    n_views: int | str | None = None
    estimate_kw: dict | None = None
    fallback: str | bool = "auto"
    cache_dir: object = False
    mask: str = "reconstructed"
    border: int = METRIC_BORDER
    intensity_scale: float | None = None
    render_kw: dict | None = None
    geometry_kw: dict | None = None
    use_lpips: bool = True
    view_split: int | None = None
    uncertainty: bool = False
    supersample: object = "auto"


def run_evaluation(scene: Scene, target: int | str, settings: Sequence[Setting], *,
                   options: EvalOptions | None = None, **kw) -> Evaluation:
    """Render the held-out ``target`` with each setting and measure it.

    The geometry is computed once: the sources get their depth (:func:`vibr.pipeline.prepare`;
    ``depth="estimated"`` estimates it here, from the sources only), then the warped samples
    are computed once, on the grid :func:`vibr.render.render` would choose
    (:func:`vibr.render.shared_geometry`), and every setting renders from them, as
    ``render()`` would render it. Per-setting ``seconds`` are therefore render times
    only; ``depth_seconds`` and ``samples_seconds`` are reported once. Nothing is written:
    figures are :func:`vibr.eval.figures.write_evaluation_figures`'s job.

    ``options`` (:class:`EvalOptions`) says how; ``kw`` (its fields, e.g. ``depth="gt"``)
    applies over it. Any other keyword raises ``TypeError``.

    Returns an :class:`Evaluation` whose ``report`` is JSON-serialisable: ``scene``,
    ``target``, ``sources``, ``scale`` (the image scale the scene was loaded at),
    ``intensity_scale``, ``size``, ``depth``, ``mask``, machine info, the geometry times,
    and ``results``: one entry per setting with ``method``, ``label``, ``params`` (every
    parameter the renderer used), ``depth``, ``psnr``, ``dssim``, ``ssim``, ``seconds``,
    ``coverage``, ``iterations`` (and ``lpips`` when the ``lpips`` package works here).
    """

    o = replace(options or EvalOptions(), **kw)
    settings, intensity_scale = _checked_settings(settings, o.mask, o.intensity_scale)
    check_measurable(scene.views[scene.index(target)].camera.shape, o.border, scene.root)
    t0 = time.perf_counter()
    src, tview = prepare(scene, target, sources=o.sources, depth=o.depth, depth_files=o.depth_files,
                         n_views=o.n_views, estimate_kw=o.estimate_kw, fallback=o.fallback, cache_dir=o.cache_dir)
    t_depth = time.perf_counter() - t0
    if tview.image is None:
        raise VibrInputError(f"target view {tview.name} has no image to compare with", scene.root)
    t0 = time.perf_counter()
    params = [setting_params(s, intensity_scale, o.render_kw) for s in settings]
    geo = shared_geometry(src, tview, [(p.method, p) for p in params], geometry_kw=o.geometry_kw,
                          supersample=o.supersample)
    src, samples = geo.sources, geo.samples
    t_samples = time.perf_counter() - t0
    logger.info(f"eval: {tview.name} from {len(src)} views, depth={o.depth} ({t_depth:.1f} s), "
                f"{len(samples)} samples ({t_samples:.1f} s)")
    rows = _render_settings(geo, tview, settings, params, o.depth, o.uncertainty)
    cover = np.ones(tview.shape, bool) if tview.mask is None else tview.mask.copy()
    if o.mask == "reconstructed":
        for _, res, _ in rows:
            cover &= np.asarray(res.coverage, bool)
    results = _measure_rows(rows, tview, cover, samples, intensity_scale, o)
    report = {
        "scene": scene.name,
        "scene_path": str(scene.root) if scene.root else None,
        "target": tview.name,
        "sources": [v.name for v in src.views],
        "scale": float(scene.meta.get("scale", 1.0)),
        "intensity_scale": intensity_scale,
        "size": [int(tview.shape[1]), int(tview.shape[0])],
        "depth": o.depth,
        "mask": o.mask,
        "border": o.border,
        "evaluated_fraction": float(cover.mean()),
        "n_samples": int(len(samples)),
        "depth_seconds": round(t_depth, 3),
        "samples_seconds": round(t_samples, 3),
        "geometry_seconds": round(t_depth + t_samples, 3),
        "machine": machine_info(),
        "results": results,
    }
    _add_context(report, src, o.depth, o.estimate_kw, o.view_split)
    return Evaluation(report=report, reference=tview.image,
                      images={s.label: res.image for s, res, _ in rows}, mask=cover,
                      prefix=f"{tview.name}_{o.depth}")


def _measure_rows(rows, tview, cover, samples, intensity_scale, o: EvalOptions) -> list[dict]:
    """One report entry per rendered setting: its metrics on the evaluated pixels
    (``cover``), with LPIPS, the uncertainty's and the per-region metrics when asked."""
    m = cover if o.mask == "reconstructed" or tview.mask is not None else None
    lp = _lpips_fn() if o.use_lpips else None
    counts = view_counts(samples) if o.view_split is not None else None
    results = []
    for s, res, dt in rows:
        entry = _measure(s, res, dt, tview.image, m, o.border, o.depth, intensity_scale)
        if lp is not None:
            entry["lpips"] = lp(res.image, tview.image)
        if o.uncertainty:
            entry["uncertainty"] = uncertainty_metrics(res.uncertainty, res.image, tview.image, mask=m,
                                                       border=o.border)
        if o.view_split is not None:
            entry["regions"] = _region_metrics(res.image, tview.image, cover, counts, o.view_split, o.border)
        results.append(entry)
    return results


def _checked_settings(settings, mask: str, intensity_scale):
    """The settings as a non-empty list and the intensity scale as a positive float
    (default the renderer's); a bad mask, no setting or a bad scale raise
    :class:`VibrInputError`."""
    if mask not in ("reconstructed", "all"):
        raise VibrInputError(f"mask must be 'reconstructed' or 'all', not {mask!r}")
    settings = list(settings)
    if not settings:
        raise VibrInputError("no setting to evaluate")
    if intensity_scale is None:
        intensity_scale = DEFAULTS["scale"]
    intensity_scale = float(intensity_scale)
    if not intensity_scale > 0:
        raise VibrInputError(f"the intensity scale must be > 0, got {intensity_scale}")
    return settings, intensity_scale


def setting_params(s: Setting, intensity_scale=None, render_kw: dict | None = None) -> RenderParams:
    """The :class:`~vibr.render.params.RenderParams` a setting renders with: ``render_kw``
    (keyword arguments of :meth:`RenderParams.from_kwargs`, ``preset`` included) for every
    setting, the setting's own params winning, on the intensity scale ``intensity_scale``
    unless they give ``scale``."""
    return RenderParams.from_kwargs(s.method, **{"scale": intensity_scale, **(render_kw or {}), **s.params})


def _render_settings(geo, tview, settings, params, depth, uncertainty=False):
    """Render the target once per setting (with its :func:`setting_params` ``params``) from the
    shared geometry ``geo`` (:func:`vibr.render.shared_geometry`): ``[(setting, result, seconds)]``."""
    rows = []
    for s, p in zip(progress(settings, desc=f"render {tview.name} ({depth})"), params):
        t = time.perf_counter()
        res = geo.render(p.method, params=p, uncertainty=uncertainty)
        rows.append((s, res, time.perf_counter() - t))
    return rows


def _measure(s: Setting, res, dt: float, ref, m, border: int, depth: str, intensity_scale: float) -> dict:
    """One result entry: the setting, the parameters the renderer used, PSNR / SSIM /
    DSSIM on the mask ``m`` (None: every pixel) inside ``border``, time and coverage."""
    used = {k: v for k, v in getattr(res, "params", {}).items()
            if isinstance(v, (int, float, str, bool)) or v is None}
    return {
        "method": s.method,
        "label": s.label,
        "params": {**used, **s.params},
        "intensity_scale": float(used.get("scale", intensity_scale)),
        "depth": depth,
        **{k: float(v) for k, v in view_metrics(res.image, ref, m, border).items()},
        "seconds": round(dt, 3),
        "coverage": float(np.asarray(res.coverage, bool).mean()),
        "iterations": len(getattr(res, "energy", []) or []),
        "energy": float(res.energy[-1]) if getattr(res, "energy", None) else None,
    }


def _region_metrics(img, ref, base, counts, view_split: int, border: int) -> dict:
    """PSNR, DSSIM and pixel fraction on the evaluated pixels seen by at most
    ``view_split`` source views ("few") and by more ("many")."""
    out = {}
    for name, sel in (("few", counts <= view_split), ("many", counts > view_split)):
        mm = base & sel
        inner = mm[border:mm.shape[0] - border, border:mm.shape[1] - border]
        if inner.any():
            out[name] = {"psnr": float(psnr(img, ref, mask=mm, border=border)),
                         "dssim": float(dssim(img, ref, mask=mm, border=border)),
                         "fraction": float(inner.mean())}
    return out


def _add_context(report: dict, src, depth: str, estimate_kw, view_split) -> None:
    """The report's optional entries: view split, planar proxy, depth-estimation options
    and statistics."""
    if view_split is not None:
        report["view_split"] = int(view_split)
    if depth == "planar" and "proxy" in src.meta:
        report["proxy"] = _jsonable(src.meta["proxy"])
    if estimate_kw:
        report["estimate_kw"] = _jsonable(estimate_kw)
    if depth == "estimated" and "depth_estimation" in src.meta:
        report["depth_estimation"] = _jsonable(_depth_summary(src.meta["depth_estimation"]))


def _depth_summary(meta: dict) -> dict:
    """The depth estimator's statistics, reduced to what a report needs: method, time, and
    per estimated view the kept fraction, planes, depth range and reprojection error."""
    keep = ("kept", "confident", "n_planes", "depth_range", "reproj_px", "time_s", "role")
    views = meta.get("views", {}) if isinstance(meta, dict) else {}
    out = {k: meta[k] for k in ("method", "scale", "excluded", "time_s") if k in meta}
    out["views"] = {name: {k: st[k] for k in keep if k in st} for name, st in views.items()
                    if isinstance(st, dict)}
    kept = [st["kept"] for st in out["views"].values() if "kept" in st and st.get("role", "target") == "target"]
    if kept:
        out["mean_kept"] = float(np.mean(kept))
    return out


def _jsonable(x):
    """Numbers, strings, lists and dicts only (numpy scalars and tuples converted)."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, (int, float, str, bool)) or x is None:
        return x
    return str(x)


def machine_info() -> dict:
    """Platform, CPU model, logical CPUs and numba threads of this machine."""
    import os

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    info = {"platform": platform.platform(), "processor": cpu, "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "numba_num_threads_env": os.environ.get("NUMBA_NUM_THREADS")}
    try:
        import numba

        info["numba_threads"] = int(numba.config.NUMBA_NUM_THREADS)
    except Exception:  # pragma: no cover
        pass
    return info


def _lpips_fn():
    """An LPIPS scorer when the optional ``lpips`` package works here, else None."""
    try:  # pragma: no cover - optional dependency, absent in CI
        import lpips
        import torch

        net = lpips.LPIPS(net="alex", verbose=False)

        def f(img, ref):
            to_t = lambda a: torch.from_numpy(np.ascontiguousarray(a.transpose(2, 0, 1)))[None] * 2 - 1  # noqa: E731
            with torch.no_grad():
                return float(net(to_t(img), to_t(ref)).item())

        return f
    except Exception:
        return None


def write_report(report: dict, path) -> None:
    """Write a report as JSON, atomically."""

    with atomic_path(path) as tmp:
        with open(tmp, "w") as fh:
            json.dump(report, fh, indent=2)
            fh.write("\n")


def format_table(report: dict) -> str:
    """A plain-text table of a report's results (what ``vibr eval`` prints): a column per
    registered metric with a heading (:data:`vibr.metrics.METRICS`: PSNR, DSSIM, then any a
    user registered); an LPIPS column appears when the report has LPIPS values."""
    has_lp = any("lpips" in r for r in report["results"])
    cols = [m for m in METRICS.values() if m.heading]
    lines = [f"{report['scene']} / {report['target']}  depth={report['depth']}  "
             f"{report['size'][0]}x{report['size'][1]} (image scale {report.get('scale', 1.0):g}, "
             f"intensity scale {report.get('intensity_scale', 255):g})  mask={report['mask']} "
             f"({100 * report['evaluated_fraction']:.1f}% of pixels), border {report.get('border', 0)}",
             f"{'setting':<40}" + "".join(f" {m.heading:>{m.width}}" for m in cols)
             + (f" {'LPIPS':>6}" if has_lp else "") + f" {'time s':>7}"]
    for r in report["results"]:
        lp = (f" {r['lpips']:>6.3f}" if "lpips" in r else f" {'':>6}") if has_lp else ""
        cells = "".join(f" {r[m.name]:>{m.width}{m.fmt}}" if m.name in r else f" {'':>{m.width}}" for m in cols)
        lines.append(f"{r['label']:<40}{cells}{lp} {r['seconds']:>7.2f}")
    lines.append(f"geometry: depth {report.get('depth_seconds', 0):.1f} s, samples "
                 f"{report.get('samples_seconds', 0):.1f} s (computed once for all settings)")
    return "\n".join(lines)
