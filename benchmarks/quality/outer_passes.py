"""The outer re-weighting passes (``n_outer``) on the cases of the defaults' sweep
(docs/explanation/renderer.md, "Known gaps"): ULR and the default ``gradient`` with 1, 2 (the default)
and 3 passes, each rendered through :func:`vibr.render.shared_geometry` (the grid ``vibr
render`` uses); all-pixel PSNR dB, 2-px border; the FISTA iterations of each pass of the
default. Estimated depth comes from the depth cache (``benchmarks/quality/sweep_defaults.py``).

    python benchmarks/quality/outer_passes.py [--workers 2] [--only temple,fountain]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import SWEEP_BORDER, SceneCache, data_dir, sparse_cases, sweep_cases, sweep_sources  # noqa: E402

PASSES = (1, 2, 3)


def run_case(cache, case) -> dict:
    from vibr.metrics import psnr
    from vibr.render import shared_geometry

    src, tv = sweep_sources(cache, case)
    geo = shared_geometry(src, tv)
    res = {"ULR": float(psnr(geo.render("ulr").image, tv.image, border=SWEEP_BORDER))}
    iters = []
    for n in PASSES:
        r = geo.render("gradient", n_outer=n)
        res[f"n_outer {n}"] = float(psnr(r.image, tv.image, border=SWEEP_BORDER))
        if n == 2:
            starts = [int(x) for x in r.outer] + [len(r.energy)]
            iters = [b - a for a, b in zip(starts, starts[1:])]
    return {"name": case["name"], "split": case["split"], "psnr": res, "iters": iters}


def main(argv=None):
    from vibr.executor import run_tasks

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    ap.add_argument("--workers", type=int, default=2, metavar="N")
    ap.add_argument("--only", default="", help="comma list of case-name prefixes")
    a = ap.parse_args(argv)
    cases = sweep_cases() + sparse_cases()
    if a.only:
        cases = [c for c in cases if c["name"].startswith(tuple(a.only.split(",")))]
    t0 = time.perf_counter()
    reps = run_tasks(run_case, cases, setup=SceneCache, setup_args=(str(data_dir(a.data)),),
                     executor=a.workers, desc="cases")
    labs = list(reps[0]["psnr"])
    print("| case | split | " + " | ".join(labs) + " | FISTA iterations per pass (n_outer 2) |")
    print("|---|---|" + "---|" * (len(labs) + 1))
    for r in reps:
        print(f"| {r['name']} | {r['split']} | " + " | ".join(f"{r['psnr'][k]:.2f}" for k in labs)
              + f" | {' + '.join(map(str, r['iters']))} |")
    print("\n| mean | cases | " + " | ".join(labs) + " |\n|---|---|" + "---|" * len(labs))
    for sp in ("choose", "report"):
        sel = [r for r in reps if r["split"] == sp]
        if sel:
            print(
                f"| {sp} | {len(sel)} | "
                + " | ".join(f"{np.mean([r['psnr'][k] for r in sel]):.3f}" for k in labs)
                + " |"
            )
    print(f"\n{len(reps)} cases in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
