"""Which source pixels of unknown depth get the fallback plane (docs/explanation/renderer.md, "Fallback proxy").

Stereo leaves a pixel without depth for two reasons: its window is flat (a plain wall, the
sky, a black backdrop: nothing to match), or matching failed on a textured surface (an
occlusion border, a reflection, the consistency check). The fallback proxy puts unknown
pixels on a plane behind the view's known depth. This script renders, with depth estimated
from the sources as ``vibr eval`` does for a scene without depth maps, under each rule:

* ``never``: unknown pixels left out (push–pull fills what no sample covers);
* ``views >= 50 %``: the plane in the views at least half unknown (a former rule);
* ``views >= 50 % + flat``: that, and in every other view the plane at the unknown pixels
  whose photograph is flat (:func:`vibr.geometry.proxy.flat_pixels`, ``FALLBACK_FLAT_STD``),
  the textured ones completed (the former ``"auto"``), and the same with the flat limit
  halved and doubled;
* ``auto (backdrop + carving)``: ``fallback="auto"``, the plane at each view's backdrop
  only, the samples that land on another view's backdrop carved
  (``benchmarks/quality/backdrop_carving.py``);
* ``auto + local background`` (measured, not the default): ``auto``, and each textured unknown
  pixel of those views takes the farthest depth of its view within ``BG_RADIUS`` px, the plane
  included (the background beside a silhouette, as depth-image-based rendering fills
  disocclusions; Fehn 2004), with the plane's relative sigma_z, as a fallback sample
  (:func:`local_background`);
* ``always``: the plane at every unknown pixel.

Cases: the middle of 7 synthetic views of 320×256 (arc, free, hand-held layouts, seeds 0–3)
from the 6 others; fountain-P11 at scale 0.25, views 0002 / 0005 / 0008 from the 10 others;
templeSR0004 from its 4 best views and from the 15 others. PSNR dB over all pixels, 2-px
border, of the default ``gradient`` and of ULR.

    python3 benchmarks/quality/fallback_rule.py [--size 320] [--seeds 4]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

_REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import data_dir  # noqa: E402

BG_RADIUS = 7


def local_background(src, radius: int = BG_RADIUS):
    """``fallback="auto"``, then each unknown pixel left takes the largest depth of its view
    within ``radius`` px (a (2r+1)² window, the border extended by its nearest pixels; the
    plane included), sigma_z ``FALLBACK_SIGMA_Z_REL`` times it, marked as fallback."""
    from scipy.ndimage import maximum_filter

    from vibr.geometry import apply_fallback
    from vibr.geometry.proxy import FALLBACK_SIGMA_Z_REL

    out = apply_fallback(src, "auto")
    views = []
    for v in out.views:
        z = np.asarray(v.depth, np.float32)
        far = maximum_filter(np.where(np.isfinite(z), z, -np.inf), size=2 * radius + 1, mode="nearest")
        bg = ~np.isfinite(z) & np.isfinite(far)
        if not bg.any():
            views.append(v)
            continue
        s = np.broadcast_to(np.asarray(v.sigma_z, np.float32), z.shape).copy()
        s[bg] = FALLBACK_SIGMA_Z_REL * far[bg]
        fb = bg if v.fallback is None else v.fallback | bg
        views.append(v.replace(depth=np.where(bg, far, z).astype(np.float32), sigma_z=s, fallback=fb))
    return out.replace(views=views)


def rules():
    """name → function(sources) → sources with the rule's fallback."""
    from vibr.geometry import apply_fallback
    from vibr.geometry.proxy import FALLBACK_FLAT_STD, fallback_depth

    def auto(flat_std):  # the former "auto": views at least half unknown, flat pixels of the others
        return lambda s: fallback_depth(s, min_fraction=0.5, flat_std=flat_std, complete=True)

    return {
        "never": lambda s: apply_fallback(s, "never"),
        "views >= 50 %": lambda s: fallback_depth(s, min_fraction=0.5),
        "views >= 50 % + flat": auto(FALLBACK_FLAT_STD),
        "auto (backdrop + carving)": lambda s: apply_fallback(s, "auto"),
        "auto + local background": local_background,
        "views >= 50 % + flat, flat limit / 2": auto(FALLBACK_FLAT_STD / 2),
        "views >= 50 % + flat, flat limit × 2": auto(FALLBACK_FLAT_STD * 2),
        "always": lambda s: apply_fallback(s, "always"),
    }


def cases(size: int, seeds: int):
    """(family, name, sources without the fallback, target view)."""

    from vibr.geometry.selection import select_views
    from vibr.io import load_scene
    from vibr.stereo.cache import scene_with_depth
    from vibr.synthetic import make_scene

    def est(src):
        return scene_with_depth(src, depth="estimated", fallback="never")

    for layout in ("arc", "free", "handheld"):
        for seed in range(seeds):
            sc = make_scene(layout, n_views=7, width=size, height=size * 4 // 5, seed=seed)
            src, tv = sc.split(3)
            yield "synthetic", f"{layout} seed {seed}", est(src.replace(
                views=[v.replace(depth=None, sigma_z=None) for v in src.views])), tv
    fo = load_scene(data_dir() / "strecha_fountain-P11", scale=0.25)
    for t in ("0002", "0005", "0008"):
        src, tv = fo.split(t)
        yield "fountain", f"fountain {t}", est(src), tv
    te = load_scene(data_dir() / "middlebury_templeSparseRing")
    rest, tv = te.split("templeSR0004")
    best = [rest.views[i].name for i in select_views(rest, tv.camera, 4)]
    yield "temple", "temple 0004 from its 4 best", est(rest.subset(best)), tv
    yield "temple", "temple 0004 from the 15 others", est(rest), tv


def main(argv=None) -> int:
    from vibr.metrics import psnr
    from vibr.render import render

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=320, help="synthetic image width (height 4/5 of it)")
    ap.add_argument("--seeds", type=int, default=4, help="synthetic worlds per layout")
    args = ap.parse_args(argv)
    R = rules()
    print("PSNR dB (all pixels, 2-px border), `gradient` / ULR; in brackets the share of source pixels "
          "given a fallback depth\n")
    print("| case | " + " | ".join(R) + " |")
    print("|---|" + "---|" * len(R))
    fam = {}
    for family, name, src, tv in cases(args.size, args.seeds):
        t, row = time.perf_counter(), {}
        for k, f in R.items():
            s = f(src)
            share = np.mean([0.0 if v.fallback is None else float(np.mean(v.fallback)) for v in s.views])
            row[k] = (*(psnr(render(s, tv, m).image, tv.image, border=2) for m in ("gradient", "ulr")), share)
        fam.setdefault(family, []).append(row)
        print(f"| {name} | " + " | ".join(f"{g:.2f} / {u:.2f} ({100 * sh:.0f} %)" for g, u, sh in row.values())
              + " |", flush=True)
        print(f"  ({time.perf_counter() - t:.0f} s)", file=sys.stderr)
    print()
    for family, rows in fam.items():
        print(f"* {family} ({len(rows)} cases), mean `gradient` / ULR: " + "; ".join(
            f"{k} {np.mean([r[k][0] for r in rows]):.2f} / {np.mean([r[k][1] for r in rows]):.2f}" for k in R))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
