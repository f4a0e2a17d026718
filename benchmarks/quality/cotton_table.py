"""Cotton (HCI 2016): centre view input_Cam040 from its 8 neighbours at strides 1, 2, 4.

Prints, per stride and geometry (ground-truth depth / planar proxy), PSNR (dB) and DSSIM
(1e4·(1−SSIM)) of ulr, savsr, bvs and gradient at gamma 0, 1, 2, 3, over the covered pixels
with a 2-pixel border excluded, plus the reference baseline: the plain average of the 8
neighbours sampled (bilinear) through the centre's own ground-truth disparity.

    python benchmarks/quality/cotton_table.py [--strides 1,2,4] [--depth gt,planar] [-- extra k=v]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data" / "hci2016_cotton"


def neighbours(scene, s):
    inv = {rc: n for n, rc in scene.meta["grid_pos"].items()}
    return [inv[(4 + dr * s, 4 + dc * s)] for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)]


def baseline(scene, s):
    """Plain average of the 8 neighbours warped by the centre's GT disparity."""
    from scipy.ndimage import map_coordinates

    from vibr.io import read_pfm
    from vibr.metrics import dssim, psnr

    d = read_pfm(DATA / "gt_disp_lowres.pfm").astype(np.float64)  # top row first
    if d.ndim == 3:
        d = d[..., 0]
    H, W = d.shape
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    acc = np.zeros((H, W, 3))
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if (dr, dc) == (0, 0):
                continue
            img = scene.views[scene.index(f"input_Cam{9 * (4 + dr * s) + 4 + dc * s:03d}")].image
            xs, ys = xx - dc * s * d, yy - dr * s * d
            for c in range(3):
                acc[..., c] += map_coordinates(img[..., c].astype(np.float64), [ys, xs], order=1, mode="nearest")
    avg = (acc / 8).astype(np.float32)
    ref = scene["input_Cam040"].image
    return psnr(avg, ref, border=2), dssim(avg, ref, border=2), psnr(avg, ref)


SETTINGS = [("ulr", {}), ("savsr", {}), ("bvs", {})] + [("gradient", {"gamma": float(g)}) for g in (0, 1, 2, 3)]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--strides", default="1,2,4")
    ap.add_argument("--depth", default="gt,planar")
    ap.add_argument("extra", nargs="*", help="render parameters k=v (e.g. lam=0.3 precond=True)")
    a = ap.parse_args(argv)
    extra = {k: eval(v) for k, v in (e.split("=", 1) for e in a.extra)}  # noqa: S307 - a benchmark
    from vibr.geometry import compute_samples
    from vibr.io import load_scene
    from vibr.metrics import dssim, psnr
    from vibr.pipeline import prepare
    from vibr.render.api import render_samples

    scene = load_scene(DATA)
    tgt = scene["input_Cam040"]
    print(f"# cotton, centre from 8 neighbours; extra params {extra}; PSNR dB / DSSIM over covered px, border 2")
    print("| stride | geometry | " + " | ".join(m if not kw else f"{m} γ={kw['gamma']:g}" for m, kw in SETTINGS) + " |")
    print("|---|---|" + "---|" * len(SETTINGS))
    for s in [int(x) for x in a.strides.split(",")]:
        bp, bd, bp0 = baseline(scene, s)
        print(
            f"| {s} | baseline (plain avg through centre GT disparity) | {bp:.2f} / {bd:.0f} (no border: {bp0:.2f}) |",
            flush=True,
        )
        for depth in a.depth.split(","):
            src, _ = prepare(scene.subset(neighbours(scene, s) + ["input_Cam040"]), tgt.name, depth=depth)
            S = compute_samples(src, tgt.camera)
            Cs = np.array([v.camera.centre for v in src.views])
            cells = []
            for m, kw in SETTINGS:
                t0 = time.perf_counter()
                r = render_samples(S, m, source_centres=Cs, target_centre=tgt.camera.centre, **{**kw, **extra})
                dt = time.perf_counter() - t0
                p = psnr(r.image, tgt.image, mask=r.coverage, border=2)
                d = dssim(r.image, tgt.image, mask=r.coverage, border=2)
                cells.append(f"{p:.2f} / {d:.0f}")
                print(
                    f"#   stride {s} {depth} {m} {kw}: {p:.3f} dB, DSSIM {d:.1f}, {dt:.1f} s, "
                    f"{len(r.energy)} iterations",
                    file=sys.stderr,
                    flush=True,
                )
            print(f"| {s} | {'GT' if depth == 'gt' else 'planar'} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
