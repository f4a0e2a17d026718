"""Cotton (HCI 2016), centre view from its 8 neighbours with ground-truth geometry: PSNR split
by region, near depth discontinuities and elsewhere (docs/explanation/renderer.md, "Why γ = 3 loses
with exact geometry").

"Near" is the dataset's ``mask_discontinuities_lowres.png`` dilated by 2 px; PSNR (dB) over
the pixels every render of the stride covered, 2-pixel border excluded.

    python benchmarks/quality/discontinuity_split.py [--strides 2,4]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import cotton_neighbours, data_dir  # noqa: E402

SETTINGS = [("bvs", {}), ("gradient γ=3", {"gamma": 3.0}),
            ("gradient γ=3, grad_weighting=W", {"gamma": 3.0, "grad_weighting": "W"}),
            ("gradient γ=1", {"gamma": 1.0})]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--strides", default="2,4")
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    a = ap.parse_args(argv)
    from scipy.ndimage import binary_dilation

    from vibr.geometry import compute_samples
    from vibr.io import load_scene, read_image
    from vibr.metrics import psnr
    from vibr.pipeline import prepare
    from vibr.render import render

    data = data_dir(a.data) / "hci2016_cotton"
    scene = load_scene(data)
    mask = read_image(data / "mask_discontinuities_lowres.png")
    near = binary_dilation(np.asarray(mask).reshape(mask.shape[0], mask.shape[1], -1).max(-1) > 0.5,
                           iterations=2)
    print(f"# near discontinuities: {100 * near.mean():.1f} % of the image")
    print("| stride, GT | all | near discontinuities | elsewhere |")
    print("|---|---|---|---|")
    for s in [int(x) for x in a.strides.split(",")]:
        src, tview = prepare(scene, "input_Cam040", sources=cotton_neighbours(scene, s), depth="gt")
        samples = compute_samples(src, tview.camera)
        res = {name: render(src, tview, method="bvs" if name == "bvs" else "gradient", samples=samples, **kw)
               for name, kw in SETTINGS}
        cover = np.logical_and.reduce([r.coverage for r in res.values()])
        print(f"| **stride {s}** | | | |")
        for name, r in res.items():
            cells = [psnr(r.image, tview.image, mask=cover & m, border=2) for m in (True, near, ~near)]
            print(f"| {name} | " + " | ".join(f"{c:.2f}" for c in cells) + " |", flush=True)


if __name__ == "__main__":
    main()
