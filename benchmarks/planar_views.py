"""The planar proxy with many source views: where ULR still leads (docs/RENDERER.md, "Known gaps").

Each case renders a held-out view through ``prepare(..., depth="planar")`` from its n best
views (``n_views``; ``all``: every other view, what ``vibr eval --depth planar`` does) with
ULR, BVS and ``gradient`` at the library's defaults, plus two diagnostics of ``gradient`` on
every view: gamma = 0 (no gradient term) and a probe that multiplies every sample of both
data terms by ULR's view prior (``samples.meta["sample_weight"]``; the colour term then
reads the prior twice): the gradient term otherwise reads every view that lands, however
far the plane misplaces it. PSNR dB, all pixels, 2-px border.

Cases: cotton (HCI 2016, 9×9) views input_Cam040 / 020 / 060 from the 80 others (the plane
from the scene's ground truth, as ``prepare`` places it); the synthetic grid (25 views, the
middle one from the 24 others) and arc, free, handheld (16 views, 128²; the plane from their
exact depth).

    python benchmarks/planar_views.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from paper_tables import SceneCache, data_dir  # noqa: E402

NS = (4, 8, 16, "all")


def cases():
    from vibr.synthetic import make_scene

    sc = SceneCache(data_dir(None)).get("hci2016_cotton", 1.0)
    for t in ("input_Cam040", "input_Cam020", "input_Cam060"):
        yield f"cotton {t}", sc, t
    for lo, n in (("grid", 25), ("arc", 16), ("free", 16), ("handheld", 16)):
        s = make_scene(lo, n_views=n, width=128, height=128)
        yield f"synthetic {lo} ({n} views)", s, s.views[len(s) // 2].name


def _psnr(src, tv, S, method, **kw):
    from vibr.metrics import psnr
    from vibr.render import render

    return psnr(render(src, tv.camera, method, samples=S, **kw).image, tv.image, border=2)


def main():
    from vibr.geometry import compute_samples
    from vibr.pipeline import prepare
    from vibr.render.operators import Splat
    from vibr.render.weights import view_prior

    head = " | ".join(f"n = {n}: ULR / BVS / gradient" for n in NS)
    print(f"| case | {head} | all: gradient γ 0 | all: prior on both terms (probe) |")
    print("|---|" + "---|" * (len(NS) + 2))
    for name, sc, t in cases():
        cells = []
        for n in NS:
            src, tv = prepare(sc, t, depth="planar", n_views=n)
            S = compute_samples(src, tv.camera)
            cells.append(" / ".join(f"{_psnr(src, tv, S, m):.2f}" for m in ("ulr", "bvs", "gradient")))
        # src, S: every view (the last n)
        g0 = _psnr(src, tv, S, "gradient", gamma=0.0)
        centres = np.array([v.camera.centre for v in src.views])
        S.meta["sample_weight"] = view_prior(S, centres, tv.camera.centre, 4, 0.1,
                                             splat=Splat(S.xy, S.target_shape)).astype(np.float32)
        probe = _psnr(src, tv, S, "gradient")
        print(f"| {name} ({len(src)} others) | " + " | ".join(cells) + f" | {g0:.2f} | {probe:.2f} |", flush=True)


if __name__ == "__main__":
    main()
