"""The scale of the plane sweep's sigma_z (``vibr.stereo.api.MVS_SIGMA_SCALE``,
docs/explanation/depth.md, "sigma_z"): its error statistics and what it does to the renders.

The renderer reads a sample's sigma_z as the standard deviation of its depth error (the
colour weight ``1/(sigma_s² + sigma_z²(∂τ/∂z·∇u)²)``, docs/explanation/method.md §3); the plane
sweep's heuristic (cost curvature and the agreeing partners' spread) is multiplied by
``MVS_SIGMA_SCALE`` for that. Here the heuristic is recovered (the estimate divided by the
library's scale) and multiplied by each factor ``f`` of ``--factors``.

Protocol, fixed before any measurement: the factor is chosen on the procedural scenes only,
the sweep's no-geometry cases (``_common.nogeo_scene``: arc, free and hand-held
layouts, seeds 0 and 1, the middle of 7 views of 256×192 rendered from the 6 others with the
depth estimated from them, the fallback where it is unknown; the sources photographed as the
sweep's, ``_common.CAPTURE``): the best mean all-pixel PSNR of
the default ``gradient`` render. ``--real`` reports fountain-P11 views 0002, 0005, 0008 at
scale 0.25 (from the 10 others) and templeSR0004 (from its 4 best views), never used to
choose. ``--lightfield`` measures the light-field estimator's sigma_z the same way, apart (it
has no scale of its own): the centre of procedural 3×3 grids (seeds 0 to 3, 192², exact
depth) from its 8 neighbours with the depth estimated from them.

Columns: for each factor, the all-pixel PSNR and the PSNR over the pixels every factor's
render covers (dB, 2-px border). First, on the procedural scenes, the heuristic's error
statistics over the sources' known pixels against the exact depth: the 68th and 90th
percentiles of ``|z_est − z_true| / sigma`` (a calibrated Gaussian: 1 and 1.64).

    python3 benchmarks/quality/mvs_sigma.py [--factors 1,0.3,0.1,0.07,0.03,0.01] [--real]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import CAPTURE, NOGEO_LAYOUTS, NOGEO_SEEDS, data_dir, nogeo_scene  # noqa: E402

BORDER = 2


def procedural():
    """(name, sources with estimated depth and no fallback, target, exact depth of the sources)."""
    from vibr.stereo.cache import scene_with_depth

    for layout in NOGEO_LAYOUTS:
        for seed in NOGEO_SEEDS:
            src, tv, truth = nogeo_scene(layout, seed, CAPTURE)
            yield (f"no geometry {layout} seed {seed}", scene_with_depth(src, depth="estimated", fallback="never"),
                   tv, truth)


def lightfield():
    """The procedural 3×3 grids' centres from their 8 neighbours (light-field estimate)."""
    from vibr.stereo.cache import scene_with_depth
    from vibr.synthetic import make_scene

    for seed in range(4):
        src, tv = make_scene("grid", width=192, height=192, seed=seed, grid=(3, 3)).split(4)
        truth = {v.name: v.depth for v in src.views}
        src = src.replace(views=[v.replace(depth=None, sigma_z=None) for v in src.views])
        yield f"grid seed {seed}", scene_with_depth(src, depth="estimated", fallback="never"), tv, truth


def real():
    from vibr.geometry.selection import select_views
    from vibr.io import load_scene
    from vibr.stereo.cache import scene_with_depth

    fountain = load_scene(data_dir() / "strecha_fountain-P11", scale=0.25)
    for t in ("0002", "0005", "0008"):
        rest, tv = fountain.split(t)
        yield f"fountain {t}", scene_with_depth(rest, depth="estimated", fallback="never"), tv, None
    temple = load_scene(data_dir() / "middlebury_templeSparseRing")
    rest, tv = temple.split("templeSR0004")
    src = rest.subset([rest.views[i].name for i in select_views(rest, tv.camera, 4)])
    yield "templeSR0004", scene_with_depth(src, depth="estimated", fallback="never"), tv, None


def scaled(raw, f):
    """``raw`` with every view's sigma_z the estimator's heuristic times ``f`` (the MVS estimate
    divided by the library's scale first)."""
    from vibr.stereo.api import MVS_SIGMA_SCALE

    base = 1.0 if raw.meta.get("depth_estimation", {}).get("method") == "lightfield" else MVS_SIGMA_SCALE
    return raw.replace(views=[v.replace(sigma_z=None if v.sigma_z is None
                                        else np.asarray(v.sigma_z, np.float32) * np.float32(f / base))
                              for v in raw.views])


def error_quantiles(raw, truth):
    """68th and 90th percentiles of |error| / heuristic sigma over the known pixels."""
    r = []
    for v in scaled(raw, 1.0).views:
        z, t = v.depth, truth[v.name]
        s = np.broadcast_to(np.asarray(v.sigma_z, np.float64), z.shape)
        k = np.isfinite(z) & np.isfinite(t) & (s > 0)
        r.append(np.abs(z[k] - t[k]) / s[k])
    r = np.concatenate(r)
    return np.quantile(r, 0.68), np.quantile(r, 0.9)


def renders(raw, tv, factors):
    """factor → (all-pixel PSNR, PSNR over the pixels every factor covers)."""
    from vibr.geometry import apply_fallback
    from vibr.metrics import psnr
    from vibr.render import render

    out = [render(apply_fallback(scaled(raw, f), "auto"), tv.camera, "gradient") for f in factors]
    cover = np.logical_and.reduce([np.asarray(r.coverage, bool) for r in out])
    return {f: (psnr(np.clip(r.image, 0, 1), tv.image, border=BORDER),
                psnr(np.clip(r.image, 0, 1), tv.image, mask=cover, border=BORDER)) for f, r in zip(factors, out)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--factors", default="1,0.3,0.1,0.07,0.03,0.01", help="comma list of factors on the heuristic")
    ap.add_argument("--real", action="store_true", help="also fountain 0002/0005/0008 and templeSR0004 (report)")
    ap.add_argument("--lightfield", action="store_true", help="the light-field estimator on procedural grids instead")
    a = ap.parse_args(argv)
    factors = [float(x) for x in a.factors.split(",")]
    print("| case | split | |e|/σ q68 / q90 | " + " | ".join(f"f={f:g} all / covered" for f in factors) + " |")
    print("|---|---|---|" + "---|" * len(factors))
    mean = {f: [] for f in factors}
    sets = ([("choose", lightfield())] if a.lightfield else [("choose", procedural())]
            + ([("report", real())] if a.real else []))
    for split, cases in sets:
        for name, raw, tv, truth in cases:
            q = "%.3f / %.3f" % error_quantiles(raw, truth) if truth is not None else "—"
            res = renders(raw, tv, factors)
            if split == "choose":
                for f in factors:
                    mean[f].append(res[f][0])
            print(f"| {name} | {split} | {q} | " + " | ".join(f"{res[f][0]:.2f} / {res[f][1]:.2f}" for f in factors)
                  + " |", flush=True)
    best = max(factors, key=lambda f: np.mean(mean[f]))
    print("\nmean all-pixel PSNR over the choose cases: "
          + ", ".join(f"f={f:g} {np.mean(mean[f]):.3f}" for f in factors) + f"; best f={best:g}")


if __name__ == "__main__":
    main()
