"""Warm start of a fly-through frame from the previous frame warped to its camera: does it help?

    python3 benchmarks/bench_warm_start.py [--size 192] [--frames 16] [--views 8]

Synthetic arc scene (exact depth; the true image of any camera is ray-cast, so every frame
has a ground truth), a path interpolated through its cameras. Each frame is rendered cold
(the renderer's own initial image) and warm (the previous warm frame forward-warped with
its z-buffer, the renderer's initial image where nothing lands), alternating which goes
first. Prints medians of time, FISTA iterations and PSNR against the ray-cast truth.
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from vibr.flythrough import FrameContext, prepare_sources, render_frame
from vibr.io import read_image
from vibr.metrics import psnr
from vibr.path import interpolate
from vibr.synthetic import default_world, make_scene, render_view


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=192)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--views", type=int, default=8)
    a = ap.parse_args()
    scene = make_scene("arc", n_views=9, width=a.size, height=a.size, seed=0)
    world = default_world(0)
    path = interpolate(scene, n_frames=a.frames)
    ctx = {}
    for mode in ("cold", "warm"):
        c = FrameContext(scene, path.cameras, tempfile.mkdtemp(prefix=f"warm-{mode}-"), n_views=a.views,
                         overwrite=True, warm_start=mode == "warm")
        prepare_sources(c)
        ctx[mode] = c
    render_frame(ctx["cold"], 0)  # compile / warm caches
    rows = {m: {"t": [], "it": [], "psnr": []} for m in ctx}
    for i in range(a.frames):
        truth = render_view(world, path.cameras[i])[0]
        for mode in (("cold", "warm") if i % 2 == 0 else ("warm", "cold")):
            r = render_frame(ctx[mode], i)
            img = read_image(f"{ctx[mode].frames_dir}/frame_{i:05d}.png")
            rows[mode]["t"].append(r["seconds"])
            rows[mode]["it"].append(r["iterations"])
            rows[mode]["psnr"].append(psnr(img, truth, border=2))
    print(f"\nsynthetic arc, {a.size}x{a.size}, {a.frames} frames, --views {a.views} "
          f"(frame 0 of 'warm' starts cold; shared machine)\n")
    print("| start | median s/frame (min-max) | median FISTA iterations | median PSNR dB (min-max) |")
    print("|---|---|---|---|")
    for m, r in rows.items():
        t, it, p = (np.array(r[k][1:]) for k in ("t", "it", "psnr"))
        print(f"| {m} | {np.median(t):.3f} ({t.min():.3f}-{t.max():.3f}) | {np.median(it):.0f} | "
              f"{np.median(p):.2f} ({p.min():.2f}-{p.max():.2f}) |")


if __name__ == "__main__":
    main()
