"""Photos taken walking towards the scene (docs/explanation/depth.md, step 2 "Depth range"): 7 synthetic
160×120 views, each 0.25 units ahead of the one before; view f3 held out and rendered from
the others with depth estimated from them, and with the exact depth. Prints each view's
depth range and kept fraction and the PSNR of ULR and the default.

    python benchmarks/quality/walking_forward.py
"""

from __future__ import annotations

import argparse

import numpy as np


def main(argv=None):
    argparse.ArgumentParser(description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args(argv)
    from vibr.camera import Camera
    from vibr.pipeline import prepare
    from vibr.render import render
    from vibr.scene import Scene, View
    from vibr.synthetic import SCENE_CENTRE, _focal, _look_at, default_world, render_view

    world = default_world(0)
    W, H = 160, 120
    K = Camera.intrinsics(_focal(W, 55.0), W, H)
    start = np.array([0.0, -0.3, -0.6])
    views = []
    for i in range(7):
        eye = start + [0.02 * i, 0.0, 0.25 * i]
        cam = _look_at(eye, eye + (np.array(SCENE_CENTRE) - start), K, W, H)
        img, depth = render_view(world, cam)
        views.append(View(f"f{i}", img, cam, depth=depth, sigma_z=0.005))
    exact = Scene(views, "walking-forward")
    bare = exact.replace(views=[v.replace(depth=None, sigma_z=None) for v in views])
    src, target = prepare(bare, "f3", cache_dir=False, fallback="never")
    for name, st in src.meta["depth_estimation"]["views"].items():
        print(
            f"{name}: depth range {st['depth_range'][0]:.2f}..{st['depth_range'][1]:.2f}, kept {100 * st['kept']:.1f} %"
        )
    for label, scene in (("estimated depth", bare), ("exact depth", exact)):
        s, t = prepare(scene, "f3", cache_dir=False)
        print(f"{label}: " + ", ".join(f"{m} {render(s, t, m).metrics['psnr']:.2f} dB" for m in ("ulr", "gradient")))


if __name__ == "__main__":
    main()
