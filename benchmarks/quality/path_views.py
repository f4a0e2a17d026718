"""A fly-through of a scene without depth estimates depth only for the views its frames may
use (``vibr.paths.flythrough.views_for_path``; docs/explanation/flythrough.md, "Depth for the views the path
uses"): time and quality against estimating every view.

The synthetic hand-held layout with ``--views`` views (no depth maps), a path interpolated
through three neighbouring views; rendered twice by ``render_path`` with ``n_views`` 4 (no
cache): with every view's depth estimated (``PATH_MARGIN`` set beyond the scene) and with
the path's views only (the default). PSNR of each frame against the ray-cast truth at the
frame's camera (2-px border), and the depth time.

    python benchmarks/quality/path_views.py [--views 24] [--size 256x192] [--frames 8]
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", type=int, default=24)
    ap.add_argument("--size", default="256x192")
    ap.add_argument("--frames", type=int, default=8)
    args = ap.parse_args(argv)
    import vibr.paths.flythrough as fl
    from vibr.io import read_image
    from vibr.metrics import psnr
    from vibr.paths.camera_path import interpolate
    from vibr.synthetic import default_world, make_scene, render_view

    w, h = (int(x) for x in args.size.split("x"))
    scene = make_scene("handheld", n_views=args.views, width=w, height=h, seed=2)
    scene = scene.replace(views=[v.replace(depth=None, sigma_z=None) for v in scene.views])
    path = interpolate(scene, views=["view_003", "view_004", "view_005"], n_frames=args.frames)
    truth = [render_view(default_world(2), c)[0] for c in path.cameras]
    need = fl.views_for_path(scene, path.cameras, 4)
    print(f"# hand-held layout, {args.views} views of {w}x{h} without depth; {args.frames} frames through "
          f"view_003..005, 4 sources a frame; the path may use {len(need or scene)} views\n")
    print("| depth estimated for | views | depth s | frames s | mean PSNR dB | min | max |")
    print("|---|---|---|---|---|---|---|")
    margin = fl.PATH_MARGIN
    for label, m in (("every view", 10**6), ("the path's views (default)", margin)):
        fl.PATH_MARGIN = m
        with tempfile.TemporaryDirectory() as d:
            r = fl.render_path(scene, path, d + "/f", n_views=4, cache_dir=False, executor=None, progress=False)
            frames = [read_image(f"{d}/f/{fl.frame_name(i)}") for i in range(len(path.cameras))]
        p = [psnr(a, t, border=2) for a, t in zip(frames, truth)]
        n = args.views if m > margin else len(need or scene)
        print(f"| {label} | {n} | {r.times['depth']:.1f} | {r.times['frames']:.1f} | {np.mean(p):.2f} | "
              f"{min(p):.2f} | {max(p):.2f} |", flush=True)
    fl.PATH_MARGIN = margin


if __name__ == "__main__":
    main()
