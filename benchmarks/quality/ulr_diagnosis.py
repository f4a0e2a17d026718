"""Why ULR beats the variational methods on fountain: PSNR per pixel group, by the
number of source views that land on a pixel and by the angle of the best view (between the
target's and the source's rays to the sample's point), for ULR and `gradient` with and
without the view prior (`view_k`, docs/explanation/renderer.md "What ULR knows").

    python benchmarks/quality/ulr_diagnosis.py [--target 0005] [--scale 0.25] [--data DIR]

Fountain-P11 at ``--scale``, the target from the 10 other views, depth estimated from those
(as benchmarks/quality/paper_tables.py); PSNR dB, 2-px border for "all".
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SETTINGS = [("ulr", {}), ("gradient", {}), ("gradient", {"view_k": 4, "grad_weighting": "W"})]


def view_maps(smp, Cs, Cu):
    """(number of views landing with splat weight > 0.5, best view's angle in degrees) per pixel."""
    from vibr.render.operators import Splat
    from vibr.render.ulr import ulr_penalty

    H, W = smp.target_shape
    pen = ulr_penalty(smp, Cs, Cu, 0.0)  # angle only
    cnt, best = np.zeros((H, W)), np.full((H, W), np.inf)
    for v in range(len(Cs)):
        sel = smp.view == v
        if not sel.any():
            continue
        s = Splat(smp.xy[sel], (H, W)).adjoint(np.stack([pen[sel], np.ones(int(sel.sum()))], 1))
        ok = s[..., 1] > 0.5
        cnt += ok
        best = np.where(ok, np.minimum(best, s[..., 0] / np.maximum(s[..., 1], 1e-9)), best)
    return cnt, np.degrees(best)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--target", default="0005")
    ap.add_argument("--scale", type=float, default=0.25)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    args = ap.parse_args(argv)
    from vibr.geometry import compute_samples
    from vibr.io import load_scene
    from vibr.metrics import psnr
    from vibr.pipeline import prepare
    from vibr.render import render

    data = Path(args.data or os.environ.get("VIBR_DATA") or ROOT.parent / "shared" / "data")
    src, tv = prepare(load_scene(data / "strecha_fountain-P11", scale=args.scale), args.target,
                      depth="estimated")
    smp = compute_samples(src, tv.camera)
    cnt, deg = view_maps(smp, np.array([v.camera.centre for v in src.views]), tv.camera.centre)
    imgs = [render(src, tv.camera, method=m, samples=smp, **p).image for m, p in SETTINGS]
    H, W = tv.shape
    inner = np.zeros((H, W), bool)
    inner[2:-2, 2:-2] = True
    print("| pixels | share | " + " | ".join(f"{m} {json.dumps(p)}" for m, p in SETTINGS) + " |")
    print("|---" * (len(SETTINGS) + 2) + "|")
    print("| all | 100 % | " + " | ".join(f"{psnr(i, tv.image, border=2):.2f}" for i in imgs) + " |")
    groups = [(f"{a}–{c} views", (cnt >= a) & (cnt <= c)) for a, c in ((0, 0), (1, 1), (2, 3), (4, 6), (7, 10))]
    groups += [
        (f"best angle {a}–{c}°", (deg >= a) & (deg < c)) for a, c in ((0, 3), (3, 6), (6, 10), (10, 20), (20, 90))
    ]
    for lab, mk in groups:
        mk = mk & inner
        if mk.sum() >= 100:
            print(
                f"| {lab} | {mk.mean():.1%} | " + " | ".join(f"{psnr(i, tv.image, mask=mk):.2f}" for i in imgs) + " |"
            )


if __name__ == "__main__":
    main()
