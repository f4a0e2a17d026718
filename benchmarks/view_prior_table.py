"""The view prior (`view_k`, docs/explanation/renderer.md "What ULR knows") against ULR and today's
`gradient`, per case: PSNR dB over all pixels and over the pixels every setting covers
(2-px border).

    python benchmarks/view_prior_table.py [--cases fountain_0002,...] [--data DIR]

Cases: ``fountain_000N`` (scale 0.25, the 10 other views, estimated depth; ``_fallback``
appended: with the fallback proxy), ``temple`` and ``temple_fallback`` (templeSR0004 from its 4 best views, estimated depth, without / with the
fallback proxy), ``cotton_S_DEPTH`` (input_Cam040 from its 3×3 block at stride S; DEPTH gt,
estimated or planar).
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = [("ulr", {}), ("gradient", {}), ("gradient", {"view_k": 4, "grad_weighting": "W"})]
CASES = ("fountain_0002,fountain_0005,fountain_0008,temple,temple_fallback,cotton_1_gt,cotton_2_gt,"
         "cotton_4_gt,cotton_2_planar,cotton_2_estimated")


def prepared(data: Path, name: str):
    from vibr.io import load_scene
    from vibr.pipeline import prepare

    if name.startswith("temple"):
        return prepare(load_scene(data / "middlebury_templeSparseRing"), "templeSR0004", n_views=4,
                       depth="estimated", fallback=name.endswith("fallback"))
    if name.startswith("fountain"):
        return prepare(load_scene(data / "strecha_fountain-P11", scale=0.25), name.split("_")[1],
                       depth="estimated", fallback=name.endswith("fallback"))
    _, s, dep = name.split("_")
    s = int(s)
    nb = [f"input_Cam{(4 + dr * s) * 9 + 4 + dc * s:03d}" for dr in (-1, 0, 1) for dc in (-1, 0, 1)
          if (dr, dc) != (0, 0)]
    return prepare(load_scene(data / "hci2016_cotton"), "input_Cam040", sources=nb, depth=dep)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", default=CASES)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    args = ap.parse_args(argv)
    import numpy as np

    from vibr.metrics import psnr
    from vibr.render import shared_geometry

    data = Path(args.data or os.environ.get("VIBR_DATA") or ROOT.parent / "shared" / "data")
    print("| case | " + " | ".join(f"{m} {json.dumps(p)}" for m, p in SETTINGS) + " |")
    print("|---" * (len(SETTINGS) + 1) + "|")
    for name in args.cases.split(","):
        src, tv = prepared(data, name)
        geo = shared_geometry(src, tv, SETTINGS)
        res = [geo.render(m, **p) for m, p in SETTINGS]
        cov = np.logical_and.reduce([r.coverage for r in res])
        cells = [f"{psnr(r.image, tv.image, border=2):.2f} / {psnr(r.image, tv.image, mask=cov, border=2):.2f}"
                 for r in res]
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
