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
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from .errors import VibrInputError
from .metrics import dssim, psnr, ssim
from .progress import log, progress
from .scene import Scene

METHODS = ("ulr", "savsr", "bvs", "gradient")


@dataclass
class Setting:
    """One row of a table: a method and the parameters given to :func:`vibr.render.render`."""

    method: str
    params: dict = field(default_factory=dict)

    @property
    def label(self) -> str:
        extra = ",".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in self.params.items())
        return self.method + (f"({extra})" if extra else "")


def settings_grid(methods: Sequence[str] = METHODS, gammas: Sequence[float] = (0, 1, 2, 3),
                  alphas: Sequence[float] | None = None, lams: Sequence[float] | None = None) -> list[Setting]:
    """Settings for each method: ``gradient`` once per gamma (``gamma`` is only its parameter),
    every variational method once per alpha and lambda given."""
    out = []
    for m in methods:
        if m not in METHODS:
            raise VibrInputError(f"unknown method {m!r} (choose from {', '.join(METHODS)})")
        gs = list(gammas) if m == "gradient" else [None]
        al = [None] if (m == "ulr" or not alphas) else list(alphas)
        lm = [None] if (m == "ulr" or not lams) else list(lams)
        for g, a, l in itertools.product(gs, al, lm):
            p = {}
            if a is not None:
                p["alpha"] = float(a)
            if g is not None:
                p["gamma"] = float(g)
            if l is not None:
                p["lam"] = float(l)
            out.append(Setting(m, p))
    return out


def evaluate(scene: Scene, target: int | str, settings: Sequence[Setting], *,
             sources: Sequence[int | str] | None = None, depth: str = "gt",
             depth_files=None, n_views: int | None = None, mask: str = "reconstructed",
             border: int = 0, figures: str | Path | None = None, estimate_kw: dict | None = None,
             render_kw: dict | None = None) -> dict:
    """Render the held-out ``target`` with each setting and measure it.

    Returns a JSON-serialisable report: ``scene``, ``target``, ``sources``, ``scale``,
    ``depth``, ``mask``, machine info, the geometry time, and ``results``: one entry per
    setting with ``method``, ``params``, ``depth``, ``psnr``, ``dssim``, ``ssim``,
    ``seconds``, ``coverage`` (and ``lpips`` when the ``lpips`` package works here).
    """
    from .pipeline import prepare
    from .render import render

    if mask not in ("reconstructed", "all"):
        raise VibrInputError(f"--mask must be 'reconstructed' or 'all', not {mask!r}")
    t0 = time.perf_counter()
    src, tview = prepare(scene, target, sources=sources, depth=depth, depth_files=depth_files,
                         n_views=n_views, estimate_kw=estimate_kw)
    t_geom = time.perf_counter() - t0
    if tview.image is None:
        raise VibrInputError(f"target view {tview.name} has no image to compare with", scene.root)
    log(f"eval: {tview.name} from {len(src)} views, depth={depth} ({t_geom:.1f} s)")

    images, rows = {}, []
    for s in progress(settings, desc=f"render {tview.name}"):
        t = time.perf_counter()
        res = render(src, tview.camera, method=s.method, **{**(render_kw or {}), **s.params})
        dt = time.perf_counter() - t
        images[s.label] = res
        rows.append((s, res, dt))

    cover = np.ones(tview.shape, bool)
    if mask == "reconstructed":
        for _, res, _ in rows:
            cover &= np.asarray(res.coverage, bool)
    ref = tview.image
    lp = _lpips_fn()
    results = []
    for s, res, dt in rows:
        m = cover if mask == "reconstructed" else None
        entry = {
            "method": s.method,
            "label": s.label,
            "params": {**s.params, **{k: v for k, v in getattr(res, "params", {}).items()
                                      if isinstance(v, (int, float, str, bool)) or v is None}},
            "depth": depth,
            "psnr": float(psnr(res.image, ref, mask=m, border=border)),
            "ssim": float(ssim(res.image, ref, mask=m, border=border)),
            "dssim": float(dssim(res.image, ref, mask=m, border=border)),
            "seconds": round(dt, 3),
            "coverage": float(np.asarray(res.coverage, bool).mean()),
        }
        if lp is not None:
            entry["lpips"] = lp(res.image, ref)
        results.append(entry)

    report = {
        "scene": scene.name,
        "scene_path": str(scene.root) if scene.root else None,
        "target": tview.name,
        "sources": [v.name for v in src.views],
        "scale": scene.meta.get("scale", 1.0),
        "size": [int(tview.shape[1]), int(tview.shape[0])],
        "depth": depth,
        "mask": mask,
        "border": border,
        "evaluated_fraction": float(cover.mean()) if mask == "reconstructed" else 1.0,
        "geometry_seconds": round(t_geom, 3),
        "machine": {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
                    "python": platform.python_version()},
        "results": results,
    }
    if figures:
        from .figures import write_figures

        report["figures"] = write_figures(figures, ref, {k: r.image for k, r in images.items()},
                                          cover, prefix=f"{tview.name}_{depth}")
    return report


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
    from .io.atomic import atomic_path

    with atomic_path(path) as tmp:
        with open(tmp, "w") as fh:
            json.dump(report, fh, indent=2)
            fh.write("\n")


def format_table(report: dict) -> str:
    """A plain-text table of a report's results (what ``vibr eval`` prints)."""
    lines = [f"{report['scene']} / {report['target']}  depth={report['depth']}  "
             f"{report['size'][0]}x{report['size'][1]}  mask={report['mask']} "
             f"({100 * report['evaluated_fraction']:.1f}% of pixels)",
             f"{'setting':<34} {'PSNR dB':>8} {'DSSIM':>7} {'time s':>7}"]
    for r in report["results"]:
        lines.append(f"{r['label']:<34} {r['psnr']:>8.2f} {r['dssim']:>7.1f} {r['seconds']:>7.2f}")
    return "\n".join(lines)
