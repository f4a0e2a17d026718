"""Photograph masks (nerfstudio's ``mask_path``; docs/RENDERER.md, "Photograph masks"): a
passer-by in one source photograph, masked out or not.

The synthetic 3×3 grid; view_003's photograph gets a saturated red block over a quarter of
it (the intruder). The centre view is held out and rendered by ULR and the default from the
8 others, with the scene's exact depth and with depth estimated from the sources, in four
cases: the clean photographs; the clean photographs with view_003's mask (the cost of a view
fewer under the block); the intruder, masked; the intruder, unmasked. PSNR dB over the
pixels both methods reconstruct (2-px border).

    python benchmarks/masks.py [--size 192x144]
"""

from __future__ import annotations

import argparse

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="192x144")
    args = ap.parse_args(argv)
    from vibr.evaluate import Setting, evaluate
    from vibr.synthetic import make_scene

    w, h = (int(x) for x in args.size.split("x"))
    grid = make_scene("grid", n_views=9, width=w, height=h)
    block = np.zeros((h, w), bool)
    block[h // 7:(h * 5) // 7, w // 5:(w * 3) // 5] = True

    def case(paint, mask, keep_depth):
        views = []
        for v in grid.views:
            if v.name == "view_003":
                img = v.image.copy()
                if paint:
                    img[block] = [1.0, 0.0, 0.0]
                v = v.replace(image=img, mask=~block if mask else None)
            views.append(v if keep_depth else v.replace(depth=None))
        return grid.replace(views=views)

    settings = [Setting("ulr"), Setting("gradient")]
    print(f"# synthetic grid {w}x{h}, view_004 from the 8 others; view_003 with a red block over "
          f"{100 * block.mean():.0f} % of it; PSNR dB (pixels both methods reconstruct, 2-px border)\n")
    print("| view_003's photograph | depth | ULR | default |")
    print("|---|---|---|---|")
    for depth in ("gt", "estimated"):
        for label, paint, mask in (("clean", False, False), ("clean, masked", False, True),
                                   ("intruder, masked", True, True), ("intruder, not masked", True, False)):
            r = evaluate(case(paint, mask, depth == "gt"), "view_004", settings, depth=depth, use_lpips=False)
            ps = [x["psnr"] for x in r["results"]]
            print(f"| {label} | {depth} | {ps[0]:.2f} | {ps[1]:.2f} |", flush=True)


if __name__ == "__main__":
    main()
