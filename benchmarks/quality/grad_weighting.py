"""The gradient term's weights under the default's solver and view prior, on
``sweep_defaults.py``'s 19 cases plus templeSR0005 from its 15 other views. Two studies:

* ``weighting`` (docs/explanation/renderer.md, "Known gaps"): ``grad_weighting`` "visibility" (the
  default) against "W" (the colour term's weights, the authors' ``gw_type 1``) at a few
  (gamma, lam);
* ``coverage`` (docs/explanation/renderer.md, "The gradient term where few samples land"): the
  consistency weight times ``min(1, coverage / grad_coverage)`` for a few ``grad_coverage``
  (0: no such factor), beside ULR and BVS; the value with the best mean on the sweep's
  *choose* half is the default.

Prints a table of all-pixel PSNR (dB, 2-px border) per case and setting, and the means over
the sweep's *choose* and *report* halves. Estimated depth goes through the depth cache.

    python3 benchmarks/quality/grad_weighting.py [--study weighting|coverage] [--workers 2]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import TEMPLE5, SceneCache, data_dir, sweep_cases, sweep_sources, temple5_sources  # noqa: E402

STUDIES = {
    "weighting": [("ULR", "ulr", {}), ("default", "gradient", {}), ("γ0", "gradient", {"gamma": 0.0}),
                  ("W γ0.2 λ0.6", "gradient", {"grad_weighting": "W"}),
                  ("W γ0.3 λ0.6", "gradient", {"grad_weighting": "W", "gamma": 0.3}),
                  ("W γ0.5 λ0.6", "gradient", {"grad_weighting": "W", "gamma": 0.5}),
                  ("W γ0.2 λ1", "gradient", {"grad_weighting": "W", "lam": 1.0}),
                  ("W γ0.3 λ1", "gradient", {"grad_weighting": "W", "gamma": 0.3, "lam": 1.0})],
    "coverage": [("ULR", "ulr", {}), ("BVS", "bvs", {"lam": 0.1})]  # BVS at the sweep's lam
    + [(f"cov {t:g}", "gradient", {"grad_coverage": t}) for t in (0.0, 1.0, 1.5, 2.0, 3.0)],
}
def run_case(cache, case) -> dict:
    from vibr.metrics import psnr
    from vibr.render import shared_geometry

    src, tv = temple5_sources(cache) if case["name"] == TEMPLE5 else sweep_sources(cache, case)
    geo = shared_geometry(src, tv, [(m, kw) for _, m, kw in STUDIES[case["study"]]])
    res = {lab: float(psnr(geo.render(m, **kw).image, tv.image, border=2))
           for lab, m, kw in STUDIES[case["study"]]}
    return {"name": case["name"], "split": case["split"], "psnr": res}


def main(argv=None) -> None:
    from vibr.executor import run_tasks

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    ap.add_argument("--workers", type=int, metavar="N", help="run the cases on N local processes")
    ap.add_argument("--study", choices=tuple(STUDIES), default="weighting", help="the settings compared")
    a = ap.parse_args(argv)
    cases = [{**c, "study": a.study} for c in sweep_cases() + [{"name": TEMPLE5, "split": "extra", "family": "extra"}]]
    t0 = time.perf_counter()
    reps = run_tasks(run_case, cases, setup=SceneCache, setup_args=(str(data_dir(a.data)),),
                     executor=a.workers, desc="cases")
    labs = [v[0] for v in STUDIES[a.study]]
    print("| case | split | " + " | ".join(labs) + " |\n|---|---|" + "---|" * len(labs))
    for r in reps:
        print(f"| {r['name']} | {r['split']} | " + " | ".join(f"{r['psnr'][k]:.2f}" for k in labs) + " |")
    for sp in ("choose", "report"):
        sel = [r for r in reps if r["split"] == sp]
        print(f"\nmean {sp} ({len(sel)} cases): "
              + ", ".join(f"{k} {np.mean([r['psnr'][k] for r in sel]):.3f}" for k in labs))
    grad = [lab for lab, m, _ in STUDIES[a.study] if m == "gradient"]
    best = max(grad, key=lambda k: np.mean([r["psnr"][k] for r in reps if r["split"] == "choose"]))
    print(
        f"\nbest on choose: {best}; cases where it trails ULR or BVS: "
        + (
            ", ".join(
                r["name"] for r in reps if r["psnr"][best] < max(r["psnr"].get("ULR", -1), r["psnr"].get("BVS", -1))
            )
            or "none"
        )
    )
    print(f"\n{len(reps)} cases in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
