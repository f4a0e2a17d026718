"""Photograph masks (nerfstudio's ``mask_path``; docs/explanation/renderer.md, "Photograph masks"): a
passer-by in one source photograph, masked out or not.

Two synthetic layouts: the 3×3 grid (a light field: its depth estimate is the light-field
method) and the hand-held layout of 7 views (multi-view stereo). One source's photograph
gets a saturated red block over a quarter of it (the intruder); the middle view is held out
and rendered by ULR and the default from the others, with the scene's exact depth and with
depth estimated from the sources, in four cases: the clean photographs; the clean
photographs with the mask (the cost of a view fewer under the block); the intruder, masked;
the intruder, unmasked. PSNR dB over the pixels both methods reconstruct (2-px border).

    python benchmarks/quality/masks.py [--size 192x144]
"""

from __future__ import annotations

import argparse

import numpy as np

LAYOUTS = {"grid": (9, "view_004", "view_003"), "handheld": (7, "view_003", "view_002")}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="192x144")
    args = ap.parse_args(argv)
    from vibr.eval.protocol import Setting, evaluate
    from vibr.synthetic import make_scene

    w, h = (int(x) for x in args.size.split("x"))
    block = np.zeros((h, w), bool)
    block[h // 7:(h * 5) // 7, w // 5:(w * 3) // 5] = True
    settings = [Setting("ulr"), Setting("gradient")]
    print(f"# synthetic scenes of {w}x{h}: the middle view from the others, one source with a red block "
          f"over {100 * block.mean():.0f} % of it; PSNR dB (pixels both methods reconstruct, 2-px border)\n")
    print("| layout (target; the intruder's view) | the intruder's photograph | depth | ULR | default |")
    print("|---|---|---|---|---|")
    for layout, (n, target, intruded) in LAYOUTS.items():
        scene = make_scene(layout, n_views=n, width=w, height=h)

        def case(paint, mask, keep_depth):
            views = []
            for v in scene.views:
                if v.name == intruded:
                    img = v.image.copy()
                    if paint:
                        img[block] = [1.0, 0.0, 0.0]
                    v = v.replace(image=img, mask=~block if mask else None)
                views.append(v if keep_depth else v.replace(depth=None))
            return scene.replace(views=views)

        for depth in ("gt", "estimated"):
            for label, paint, mask in (("clean", False, False), ("clean, masked", False, True),
                                       ("intruder, masked", True, True), ("intruder, not masked", True, False)):
                r = evaluate(case(paint, mask, depth == "gt"), target, settings, depth=depth, use_lpips=False)
                ps = [x["psnr"] for x in r["results"]]
                print(f"| {layout} ({target}; {intruded}) | {label} | {depth} | {ps[0]:.2f} | {ps[1]:.2f} |",
                      flush=True)


if __name__ == "__main__":
    main()
