"""The correlation of the views' depth errors (``z_corr``), chosen across scenes with a
held-out split (docs/explanation/renderer.md, "Depth errors the views share").

Three sets of cases, each with its own split fixed in advance:

* ``sweep``: ``sweep_defaults.py``'s 19 cases (ground-truth, estimated and planar depth,
  fountain, temple, synthetic layouts) and templeSR0005 from its 15 others (not in either half);
* ``planar 4``: ``planar_views.py``'s 11 cases from their 4 best views on the plane, what
  ``vibr eval --depth planar`` renders by default (``PLANAR_SOURCES``);
* ``plane``: ``planar_sigma_z.py``'s cases but cotton's (the sweep has those): fountain,
  temple and the synthetic layouts from their sweep sources on the plane.

Each case renders ULR, BVS and ``gradient`` at the library's defaults with ``z_corr`` over
:data:`VALUES`, and with the default (``z_corr`` None: the geometry's); all-pixel PSNR dB,
2-px border. The cases fall in two groups by their depth: a *proxy* for every view (the
plane: the 4-view and plane sets and the sweep's cotton planar cases) and *per-view* depth
(the rest of the sweep). For the proxy group the value with the best mean over its *choose*
halves (of those within :data:`TIE` dB of the best, the smallest: the nearest the paper's
model) is ``vibr.geometry.proxy.PROXY_Z_CORR``; per-view depth keeps 0 (the paper's
independent errors) unless a value gains at least :data:`MIN_GAIN` dB on its *choose*
halves (the shared error costs a pass over the samples per outer pass). Both are reported
on the *report* halves.

    python3 benchmarks/quality/shared_depth_error.py [--workers 2]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import run_study, study_sources  # noqa: E402

VALUES = (0.0, 0.5, 0.7, 0.8, 0.9, 0.95)
MIN_GAIN = 0.05
TIE = 0.005


def run_case(cache, case) -> dict:
    from vibr.metrics import psnr
    from vibr.render import shared_geometry

    src, tv = study_sources(cache, case)
    geo = shared_geometry(src, tv)
    P = lambda m, **kw: float(psnr(geo.render(m, **kw).image, tv.image, border=2))  # noqa: E731
    res = {"ULR": P("ulr"), "BVS": P("bvs", lam=0.1) if case["set"] == "sweep" else P("bvs")}  # the sweep's BVS lam
    res.update({f"ρ {z:g}": P("gradient", z_corr=z) for z in VALUES})
    res["default"] = P("gradient")
    return {"name": case["name"], "split": case["split"], "set": case["set"], "psnr": res,
            "proxy": bool(geo.samples.meta.get("z_corr"))}


def _summary(reps, labs):
    from vibr.geometry.proxy import PROXY_Z_CORR

    mean = lambda sel, k: np.mean([r["psnr"][k] for r in sel])  # noqa: E731
    groups = {"proxy": lambda r: r["proxy"], "per-view": lambda r: not r["proxy"]}
    print("\n| mean | cases | " + " | ".join(labs) + " |\n|---|---|" + "---|" * len(labs))
    for sp in ("choose", "report"):
        for g, f in list(groups.items()) + [("all", lambda r: True)]:
            sel = [r for r in reps if r["split"] == sp and f(r)]
            print(f"| {sp}, {g} | {len(sel)} | " + " | ".join(f"{mean(sel, k):.3f}" for k in labs) + " |")
    grad = [k for k in labs if k.startswith("ρ")]
    for g, f in groups.items():
        ch = [r for r in reps if r["split"] == "choose" and f(r)]
        top = max(mean(ch, k) for k in grad)
        best = min((k for k in grad if mean(ch, k) >= top - TIE), key=lambda k: float(k.split()[1]))
        print(f"\n{g} depth: best on choose {best} ({mean(ch, best):.4f} dB; the highest {top:.4f}, "
              f"ρ 0 {mean(ch, 'ρ 0'):.4f})")
    ch = [r for r in reps if r["split"] == "choose" and not r["proxy"]]
    gain = max(mean(ch, k) for k in grad) - mean(ch, "ρ 0")
    print(f"per-view depth: the best value gains {gain:+.3f} dB on choose: "
          + ("a non-zero default" if gain >= MIN_GAIN else f"below {MIN_GAIN} dB, it keeps 0"))
    print(f"library: PROXY_Z_CORR = {PROXY_Z_CORR:g}; cases where the default trails ULR or BVS: "
          + (", ".join(f"{r['set']}: {r['name']}" for r in reps
                       if r["psnr"]["default"] < max(r["psnr"]["ULR"], r["psnr"]["BVS"])) or "none"))


def main(argv=None) -> None:
    run_study(run_case, _summary, __doc__, argv)


if __name__ == "__main__":
    main()
