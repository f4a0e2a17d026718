"""Rotation-only captures (docs/explanation/renderer.md, "Rotation-only captures"): the synthetic ``pan``
layout (cameras at one centre turned about the vertical), each inner view held out and
rendered from the others by ULR, BVS and the default, with the scene's exact depth and
without depth (the sphere vibr puts around the shared centre). PSNR / DSSIM over the pixels
every method reconstructs (the paper's mask, `vibr eval`'s default).

    python benchmarks/quality/rotation_only.py [--views 5] [--size 160x120] [--pan-deg 24]
"""

from __future__ import annotations

import argparse

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", type=int, default=5)
    ap.add_argument("--size", default="160x120")
    ap.add_argument("--pan-deg", type=float, default=24.0)
    args = ap.parse_args(argv)
    from vibr.eval.protocol import Setting, evaluate
    from vibr.scene import Scene, View
    from vibr.synthetic import DEFAULT_SIGMA_Z, default_world, pan_cameras, render_view

    w, h = (int(x) for x in args.size.split("x"))
    world = default_world(0)
    cams = pan_cameras(args.views, pan_deg=args.pan_deg, width=w, height=h)
    views = []
    for i, c in enumerate(cams):
        img, d = render_view(world, c, 2)
        views.append(View(f"view_{i:03d}", img, c, depth=d, sigma_z=DEFAULT_SIGMA_Z))
    exact = Scene(views, "synthetic-pan")
    bare = exact.replace(views=[v.replace(depth=None, sigma_z=None) for v in views])
    settings = [Setting("ulr"), Setting("bvs"), Setting("gradient")]
    print(f"# pan: {args.views} views of {w}x{h} at one centre, {args.pan_deg:g} degrees in all; "
          f"PSNR dB / DSSIM (reconstructed pixels, 2-px border)\n")
    print("| target | depth | " + " | ".join(s.label for s in settings) + " |")
    print("|---|---|" + "---|" * len(settings))
    rows = {}
    for t in range(1, args.views - 1):
        for label, sc in (("exact", exact), ("none (sphere)", bare)):
            rep = evaluate(sc, t, settings)
            res = {r["label"]: r for r in rep["results"]}
            rows.setdefault(label, []).append([res[s.label]["psnr"] for s in settings])
            cells = " | ".join(f"{res[s.label]['psnr']:.2f} / {res[s.label]['dssim']:.0f}" for s in settings)
            print(f"| view_{t:03d} | {label} | {cells} |", flush=True)
    for label, r in rows.items():
        m = np.mean(r, axis=0)
        print(f"| mean | {label} | " + " | ".join(f"{x:.2f}" for x in m) + " |")


if __name__ == "__main__":
    main()
