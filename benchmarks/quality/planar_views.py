"""The planar proxy with many source views: where ULR still leads (docs/explanation/renderer.md, "Known gaps").

Each case renders a held-out view through ``prepare(..., depth="planar")`` from its n best
views (``n_views``; ``all``: every other view, what ``vibr eval --depth planar`` does) with
ULR, BVS and ``gradient`` at the library's defaults, plus two diagnostics of ``gradient`` on
every view: gamma = 0 (no gradient term) and a probe that multiplies every sample of both
data terms by ULR's view prior (``samples.meta["sample_weight"]``; the colour term then
reads the prior twice): the gradient term otherwise reads every view that lands, however
far the plane misplaces it. PSNR dB, all pixels, 2-px border.

Cases: cotton (HCI 2016, 9×9) views input_Cam040 / 020 / 060 from the 80 others (the plane
from the scene's ground truth, as ``prepare`` places it); the synthetic grid (25 views, the
middle one from the 24 others) and arc, free, handheld (16 views), 128², worlds of seeds 0
and 1 (the plane from their exact depth). Split fixed in advance, as in
``benchmarks/quality/sweep_defaults.py``: within each family (cotton; synthetic, ordered layout by
layout, seed 0 then 1) the 1st, 3rd, … case is *choose*, the 2nd, 4th, … *report*. The
number of best views ``n`` with the best mean PSNR of ``gradient`` on *choose* is
``vibr.pipeline.PLANAR_SOURCES``, the planar proxy's default source count; it is reported
on *report* beside ULR and BVS from the same views and from every view.

    python benchmarks/quality/planar_views.py
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import planar_view_cases  # noqa: E402

NS = (4, 8, 16, "all")
SPLIT = ("choose", "report")


def _psnr(src, tv, S, method, **kw):
    from vibr.metrics import psnr
    from vibr.render import render

    return psnr(render(src, tv.camera, method, samples=S, **kw).image, tv.image, border=2)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    a = ap.parse_args(argv)
    from vibr.geometry import compute_samples
    from vibr.pipeline import prepare
    from vibr.render.operators import Splat
    from vibr.render.weights import view_prior

    head = " | ".join(f"n = {n}: ULR / BVS / gradient" for n in NS)
    print(f"| case | split | {head} | all: gradient γ 0 | all: prior on both terms (probe) |")
    print("|---|---|" + "---|" * (len(NS) + 2))
    rows = []
    for name, split, sc, t in planar_view_cases(a.data):
        res = {}
        for n in NS:
            src, tv = prepare(sc, t, depth="planar", n_views=n)
            S = compute_samples(src, tv.camera)
            res[n] = {m: _psnr(src, tv, S, m) for m in ("ulr", "bvs", "gradient")}
        # src, S: every view (the last n)
        g0 = _psnr(src, tv, S, "gradient", gamma=0.0)
        centres = np.array([v.camera.centre for v in src.views])
        S.meta["sample_weight"] = view_prior(S, centres, tv.camera.centre, 4, 0.1,
                                             splat=Splat(S.xy, S.target_shape)).astype(np.float32)
        probe = _psnr(src, tv, S, "gradient")
        rows.append((name, split, res))
        cells = [" / ".join(f"{res[n][m]:.2f}" for m in ("ulr", "bvs", "gradient")) for n in NS]
        print(f"| {name} ({len(src)} others) | {split} | " + " | ".join(cells) + f" | {g0:.2f} | {probe:.2f} |",
              flush=True)
    _summary(rows)


def _summary(rows):
    mean = lambda sel, n, m: np.mean([r[n][m] for _, sp, r in rows if sp == sel])  # noqa: E731
    print("\n| mean | " + " | ".join(f"n = {n}: ULR / BVS / gradient" for n in NS) + " |")
    print("|---|" + "---|" * len(NS))
    for sel in SPLIT:
        print(f"| {sel} | " + " | ".join(" / ".join(f"{mean(sel, n, m):.2f}" for m in ("ulr", "bvs", "gradient"))
                                       for n in NS) + " |")
    best = max(NS, key=lambda n: mean("choose", n, "gradient"))
    print(f"\nchosen on *choose*: n = {best}")
    for name, sp, r in rows:
        lead = r[best]["gradient"] - max(r[best]["ulr"], r[best]["bvs"], r["all"]["ulr"], r["all"]["bvs"])
        print(f"* {name} ({sp}): gradient from the {best} best {r[best]['gradient']:.2f} dB, from every view "
              f"{r['all']['gradient']:.2f}; minus the best baseline from those or every view {lead:+.2f} dB")


if __name__ == "__main__":
    main()
