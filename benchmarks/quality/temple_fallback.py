"""Middlebury temple ring, templeSR0004 from its 4 best views with estimated depth, without and
with the fallback proxy for source pixels of unknown depth (docs/explanation/renderer.md, "Fallback
proxy"). Prints PSNR (dB) over all pixels and over the pixels the render without fallback
covered (2-px border), and writes the figure reference | without | with.

    python benchmarks/quality/temple_fallback.py [--data DIR] [--figure docs/img/temple_fallback.png]
    python benchmarks/quality/temple_fallback.py --fountain     # also fountain 2/5/8 (scale 0.25, estimated)

Each table row gives the views' unknown-depth fractions (min–max over the sources); "with"
is the plane at every unknown pixel (``"always"``); ``benchmarks/quality/backdrop_carving.py``
measures ``fallback="auto"`` (each view's backdrop, silhouette carving) against the former rules.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
METHODS = ("ulr", "gradient")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    ap.add_argument("--figure", default=str(ROOT / "docs" / "img" / "temple_fallback.png"))
    ap.add_argument("--fountain", action="store_true", help="also fountain views 2, 5, 8 from the 10 others")
    args = ap.parse_args(argv)
    from vibr.geometry import fallback_depth
    from vibr.io import load_scene
    from vibr.metrics import psnr
    from vibr.pipeline import prepare
    from vibr.render import render, shared_geometry

    data = Path(args.data or os.environ.get("VIBR_DATA") or ROOT.parent / "shared" / "data")
    scene = load_scene(data / "middlebury_templeSparseRing")
    # prepare's own step, split in two: estimated depth, then (its default) the fallback
    raw, tv = prepare(scene, "templeSR0004", n_views=4, depth="estimated", fallback=False)
    images, cover = {}, None
    for fb, src in (("without", raw), ("with", fallback_depth(raw))):
        geo = shared_geometry(src, tv, [(m, {}) for m in METHODS])
        for m in METHODS:
            r = geo.render(m)
            images[(fb, m)] = r.image
            if fb == "without":
                cover = r.coverage if cover is None else cover & r.coverage
    print(f"templeSR0004 from {', '.join(v.name for v in raw.views)}; covered (without fallback): "
          f"{cover.mean():.1%} of the pixels; unknown depth per source view {_fractions(raw)}")
    print("| method | fallback | PSNR all pixels | PSNR covered |")
    print("|---|---|---|---|")
    for (fb, m), img in images.items():
        print(f"| {m} | {fb} | {psnr(img, tv.image, border=2):.2f} | {psnr(img, tv.image, mask=cover, border=2):.2f} |")
    _figure(args.figure, [tv.image, images[("without", "gradient")], images[("with", "gradient")]])
    if args.fountain:
        print("\n| fountain view (scale 0.25) | unknown depth per source view | gradient without | with (all pixels) |")
        print("|---|---|---|---|")
        fountain = load_scene(data / "strecha_fountain-P11", scale=0.25)
        for t in ("0002", "0005", "0008"):
            raw, tv = prepare(fountain, t, depth="estimated", fallback=False)
            p = [
                psnr(render(src, tv.camera, "gradient").image, tv.image, border=2) for src in (raw, fallback_depth(raw))
            ]
            print(f"| {t} | {_fractions(raw)} | {p[0]:.2f} | {p[1]:.2f} |")


def _fractions(scene):
    f = [float(np.mean(~np.isfinite(v.depth))) for v in scene.views]
    return f"{min(f):.0%}–{max(f):.0%}"


def _figure(path, panels):
    """Side-by-side strip (reference | gradient without fallback | with), half size."""
    from PIL import Image

    strip = np.concatenate([np.clip(p[::2, ::2], 0, 1) for p in panels], axis=1)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray((strip * 255 + 0.5).astype(np.uint8)).save(path)
    print(f"figure: {path}")


if __name__ == "__main__":
    main()
