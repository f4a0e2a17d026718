"""Views that tie in the view prior (``view_tie``), chosen across scenes with a held-out split
(docs/explanation/renderer.md, "Views that tie").

Buehler's weights give the ``k`` best views ``(1 − p/p_(k+1)) / p``; where fewer than k + 1
views land, ``p_(k+1)`` is the largest present penalty inflated by 1 %. Where the views nearly
tie (a grid's four neighbours of the target, all about one baseline away) that threshold lies
just above them all, and the last digits of their penalties decide which of them weighs
nothing: one of two opposite views is dropped and its partner's misregistration is no longer
cancelled. ``view_tie`` keeps the threshold at least ``view_tie`` times the pixel's best
penalty.

The cases and their splits are ``shared_depth_error.py``'s (the sweep's 19 cases and
templeSR0005 from its 15 others, in neither half; ``planar_views.py``'s 11 cases from their 4
best views on the plane; ``planar_sigma_z.py``'s fountain, temple and synthetic cases on the
plane). Each renders ULR, BVS and ``gradient`` at the library's defaults with ``view_tie``
over :data:`VALUES` and with the default; all-pixel PSNR dB, 2-px border. The prior reads
every geometry, so one value is chosen over all *choose* cases: the best mean, of those
within :data:`TIE` dB of it the smallest (the nearest Buehler's rule), reported on the
*report* halves.

    python3 benchmarks/quality/view_prior_tie.py [--workers 2] [--json FILE]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import STUDY_SETS, run_study, study_sources  # noqa: E402

VALUES = (0.0, 1.1, 1.25, 1.5, 2.0)
TIE = 0.005


def run_case(cache, case) -> dict:
    from vibr.metrics import psnr
    from vibr.render import shared_geometry

    src, tv = study_sources(cache, case)
    geo = shared_geometry(src, tv)
    P = lambda m, **kw: float(psnr(geo.render(m, **kw).image, tv.image, border=2))  # noqa: E731
    res = {"ULR": P("ulr"), "BVS": P("bvs", lam=0.1) if case["set"] == "sweep" else P("bvs")}  # the sweep's BVS lam
    res.update({f"tie {t:g}": P("gradient", view_tie=t) for t in VALUES})
    res["default"] = P("gradient")
    return {"name": case["name"], "split": case["split"], "set": case["set"], "psnr": res}


def _summary(reps, labs):
    from vibr.render.methods import DEFAULTS

    mean = lambda sel, k: float(np.mean([r["psnr"][k] for r in sel]))  # noqa: E731
    print("\n| mean | cases | " + " | ".join(labs) + " |\n|---|---|" + "---|" * len(labs))
    for sp in ("choose", "report"):
        for s in (*STUDY_SETS, "all"):
            sel = [r for r in reps if r["split"] == sp and s in ("all", r["set"])]
            print(f"| {sp}, {s} | {len(sel)} | " + " | ".join(f"{mean(sel, k):.3f}" for k in labs) + " |")
    ties = [k for k in labs if k.startswith("tie")]
    ch = [r for r in reps if r["split"] == "choose"]
    top = max(mean(ch, k) for k in ties)
    best = min((k for k in ties if mean(ch, k) >= top - TIE), key=lambda k: float(k.split()[1]))
    rep = [r for r in reps if r["split"] == "report"]
    print(f"\nbest on choose: {best} ({mean(ch, best):.4f} dB; the highest {top:.4f}, tie 0 {mean(ch, 'tie 0'):.4f}); "
          f"on report {mean(rep, best):.4f} against {mean(rep, 'tie 0'):.4f}")
    print(f"library: view_tie = {DEFAULTS['view_tie']:g}; cases where the default trails ULR or BVS: "
          + (", ".join(f"{r['set']}: {r['name']}" for r in reps
                       if r["psnr"]["default"] < max(r["psnr"]["ULR"], r["psnr"]["BVS"])) or "none"))


if __name__ == "__main__":
    run_study(run_case, _summary, __doc__)
