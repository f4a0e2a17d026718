"""Fountain view 5 rendered from the other 10 with depth estimated with and without the
segment completion (``estimate_depth(fill_segments=True)``, docs/explanation/depth.md step 9): does
the dense depth help the render?

PSNR dB / DSSIM over the pixels both geometries' renders covered, 2-pixel border, as
``vibr eval --depth estimated`` measures (``vibr.eval.protocol.run_evaluation``).

    python benchmarks/quality/fill_segments_render.py [--scale 0.25] [--target 0005]
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
    ap.add_argument("--scale", type=float, default=0.25)
    ap.add_argument("--target", default="0005")
    ap.add_argument("--methods", default="gradient,ulr")
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    a = ap.parse_args(argv)
    from vibr.eval.protocol import Setting, run_evaluation
    from vibr.io import load_scene
    from vibr.metrics import dssim, psnr

    scene = load_scene(data_dir(a.data) / "strecha_fountain-P11", scale=a.scale)
    settings = [Setting(m) for m in a.methods.split(",")]
    runs = {}
    for fill in (False, True):
        t0 = time.perf_counter()
        runs[fill] = run_evaluation(scene, a.target, settings, depth="estimated",
                                    estimate_kw={"fill_segments": fill}, border=2, use_lpips=False)
        print(f"# fill_segments={fill}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    cover = runs[False].mask & runs[True].mask
    ref = runs[False].reference
    print(f"# fountain view {a.target} at scale {a.scale:g} from the other views, depth estimated; "
          f"PSNR dB / DSSIM on the {100 * cover.mean():.1f} % of pixels both covered, border 2")
    print("| method | without fill | with fill_segments |")
    print("|---|---|---|")
    for s in settings:
        cells = [f"{psnr(runs[f].images[s.label], ref, mask=cover, border=2):.2f} / "
                 f"{dssim(runs[f].images[s.label], ref, mask=cover, border=2):.0f}" for f in (False, True)]
        print(f"| {s.label} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
