"""Solver settings on real data: outer re-weighting passes and inner TV iterations.

Cotton (HCI 2016), centre view input_Cam040 from its 8 neighbours at strides 1, 2, 4, with
ground-truth and planar geometry: PSNR (dB, covered pixels, 2-pixel border), DSSIM, FISTA +
power iterations and solve time for ``n_outer`` 2 vs 3 and ``tv_iter`` 1, 2, 5 (bvs and
gradient gamma = 1), and at a 20× larger lambda (2.0) where the TV prox matters more.
With ``--tol-outer``: the stopping tolerance of the outer passes before the last,
``tol_outer`` 1e-4 (every pass at ``tol``, the default), 3e-4 and 1e-3, with each method's
defaults; the FISTA iterations are given per pass.

    python benchmarks/quality/solver_settings.py
    python benchmarks/quality/solver_settings.py --tol-outer
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import centre_index, cotton_neighbours, data_dir, grid_scene  # noqa: E402


def main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tol-outer", action="store_true",
                    help="the table of tol_outer (1e-4, 3e-4, 1e-3) instead of n_outer / tv_iter")
    if ap.parse_args(argv).tol_outer:
        return tol_outer_table()
    from vibr.geometry import compute_samples
    from vibr.io import load_scene
    from vibr.metrics import dssim, psnr
    from vibr.pipeline import prepare
    from vibr.render.api import render_samples

    scene = load_scene(data_dir() / "hci2016_cotton")
    tgt = scene["input_Cam040"]
    variants = [dict(n_outer=2, tv_iter=2), dict(n_outer=3, tv_iter=2), dict(n_outer=2, tv_iter=1),
                dict(n_outer=2, tv_iter=5)]
    print(
        "| stride | geometry | method | "
        + " | ".join(f"n_outer={v['n_outer']}, tv_iter={v['tv_iter']}" for v in variants)
        + " |"
    )
    print("|---|---|---|" + "---|" * len(variants))
    for s in (1, 2, 4):
        for depth in ("gt", "planar"):
            src, _ = prepare(scene.subset(cotton_neighbours(scene, s) + ["input_Cam040"]), tgt.name, depth=depth)
            S = compute_samples(src, tgt.camera)
            for m, kw in [("bvs", {}), ("gradient", {"gamma": 1.0}), ("gradient", {"gamma": 1.0, "lam": 2.0})]:
                cells = []
                for v in variants:
                    r = render_samples(S, m, **{**kw, **v})
                    cells.append(
                        f"{psnr(r.image, tgt.image, mask=r.coverage, border=2):.3f} / "
                        f"{dssim(r.image, tgt.image, mask=r.coverage, border=2):.1f} "
                        f"({r.iterations}+{r.power_iterations} it, {r.times['solve']:.2f} s)"
                    )
                label = m + "".join(f" {k}={x:g}" for k, x in kw.items())
                print(
                    f"| {s} | {'GT' if depth == 'gt' else 'planar'} | {label} | " + " | ".join(cells) + " |", flush=True
                )


def tol_outer_table():
    """PSNR (dB, covered pixels, 2-pixel border) and FISTA iterations per pass for
    ``tol_outer`` 1e-4, 3e-4, 1e-3: cotton (strides 1, 2, 4, GT and planar geometry) and the
    synthetic 768² grid of ``bench_render.py``, with each method's defaults."""
    from vibr.geometry import compute_samples
    from vibr.io import load_scene
    from vibr.metrics import psnr
    from vibr.pipeline import prepare
    from vibr.render.api import render_samples

    tols = (1e-4, 3e-4, 1e-3)
    print("| scene | geometry | method | " + " | ".join(f"tol_outer={t:g}" for t in tols) + " |")
    print("|---|---|---|" + "---|" * len(tols))

    def row(scene_label, geometry, S, tgt):
        for m in ("gradient", "bvs"):
            cells = []
            for t in tols:
                r = render_samples(S, m, tol_outer=t)
                its = [b - a - 1 for a, b in zip(r.outer, r.outer[1:] + [len(r.energy)])]
                cells.append(
                    f"{psnr(r.image, tgt.image, mask=r.coverage, border=2):.3f} ({' + '.join(map(str, its))} it)"
                )
            print(f"| {scene_label} | {geometry} | {m} | " + " | ".join(cells) + " |", flush=True)

    scene = load_scene(data_dir() / "hci2016_cotton")
    tgt = scene["input_Cam040"]
    for s in (1, 2, 4):
        for depth in ("gt", "planar"):
            src, _ = prepare(scene.subset(cotton_neighbours(scene, s) + ["input_Cam040"]), tgt.name, depth=depth)
            row(f"cotton stride {s}", "GT" if depth == "gt" else "planar", compute_samples(src, tgt.camera), tgt)
    grid = grid_scene(3, 3, 768)
    src, tgt = grid.split(centre_index(grid))
    row("synthetic 768² grid", "exact", compute_samples(src, tgt.camera), tgt)


if __name__ == "__main__":
    main()
