"""The render against the number of source views: cotton's centre view (input_Cam040) from
its n best views (vibr.geometry.selection's ranking), ground-truth depth, n = 8, 24, 48 and 80 (every
other view), each method at its defaults (docs/explanation/renderer.md, "Density with the view prior").

    python3 benchmarks/quality/many_views.py [--views 8,24,48,80] [--data DIR]

Prints one row per n: PSNR (dB, all pixels, 2-px border) of ULR, BVS and the default
``gradient``, and each render's time (s). Run it from a worktree of older code
(``PYTHONPATH=OLD/src``) to compare.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import data_dir  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", default="8,24,48,80", help="comma list of source counts")
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    a = ap.parse_args(argv)
    import vibr
    from vibr.geometry import compute_samples
    from vibr.io import load_scene
    from vibr.metrics import psnr
    from vibr.pipeline import prepare
    from vibr.render import render_samples

    sc = load_scene(data_dir(a.data) / "hci2016_cotton")
    print(f"# vibr {vibr.__file__}: cotton input_Cam040 from its n best views, GT depth; "
          "PSNR dB (all pixels, 2-px border) / render s")
    methods = ("ulr", "bvs", "gradient")
    print("| n | " + " | ".join(methods) + " |")
    print("|---|" + "---|" * len(methods))
    for n in (int(x) for x in a.views.split(",")):
        src, tv = prepare(sc, "input_Cam040", depth="gt", n_views=min(n, len(sc) - 1))
        S = compute_samples(src, tv.camera)
        cells = []
        for m in methods:
            t = time.perf_counter()
            r = render_samples(S, m)
            cells.append(f"{psnr(r.image, tv.image, border=2):.2f} / {time.perf_counter() - t:.2f}")
        print(f"| {len(src)} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
