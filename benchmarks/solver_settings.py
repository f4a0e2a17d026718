"""Solver settings on real data: outer re-weighting passes and inner TV iterations.

Cotton (HCI 2016), centre view input_Cam040 from its 8 neighbours at strides 1, 2, 4, with
ground-truth and planar geometry: PSNR (dB, covered pixels, 2-pixel border), DSSIM, FISTA +
power iterations and solve time for ``n_outer`` 2 vs 3 and ``tv_iter`` 1, 2, 5 (bvs and
gradient gamma = 1), and at a 20× larger lambda (2.0) where the TV prox matters more.

    python benchmarks/solver_settings.py
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main():
    from cotton_table import DATA, neighbours
    from vibr.geometry import compute_samples
    from vibr.io import load_scene
    from vibr.metrics import dssim, psnr
    from vibr.pipeline import prepare
    from vibr.render.api import render_samples

    scene = load_scene(DATA)
    tgt = scene["input_Cam040"]
    variants = [dict(n_outer=2, tv_iter=2), dict(n_outer=3, tv_iter=2), dict(n_outer=2, tv_iter=1),
                dict(n_outer=2, tv_iter=5)]
    print("| stride | geometry | method | " + " | ".join(f"n_outer={v['n_outer']}, tv_iter={v['tv_iter']}" for v in variants) + " |")
    print("|---|---|---|" + "---|" * len(variants))
    for s in (1, 2, 4):
        for depth in ("gt", "planar"):
            src, _ = prepare(scene.subset(neighbours(scene, s) + ["input_Cam040"]), tgt.name, depth=depth)
            S = compute_samples(src, tgt.camera)
            for m, kw in [("bvs", {}), ("gradient", {"gamma": 1.0}), ("gradient", {"gamma": 1.0, "lam": 2.0})]:
                cells = []
                for v in variants:
                    r = render_samples(S, m, **{**kw, **v})
                    cells.append(f"{psnr(r.image, tgt.image, mask=r.coverage, border=2):.3f} / "
                                 f"{dssim(r.image, tgt.image, mask=r.coverage, border=2):.1f} "
                                 f"({r.iterations}+{r.power_iterations} it, {r.times['solve']:.2f} s)")
                label = m + "".join(f" {k}={x:g}" for k, x in kw.items())
                print(f"| {s} | {'GT' if depth == 'gt' else 'planar'} | {label} | " + " | ".join(cells) + " |",
                      flush=True)


if __name__ == "__main__":
    main()
