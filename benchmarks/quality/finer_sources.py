"""Sources finer than the target: the target's own grid against the supersampled grid
(docs/explanation/renderer.md, "Sources finer than the target").

A held-out view is rendered at ``1/f`` of its sources' resolution (its camera scaled by
:meth:`vibr.Camera.scaled`) and compared with the photograph averaged over ``f × f`` blocks
(``skimage.transform.downscale_local_mean``: a pixel-integrating sensor). Per method (ULR,
BVS, the default ``gradient``), three ways:

* *target grid*: the sources as they are, on the target's grid, bilinear PSF (vibr before
  supersampling: ``compute_samples`` + ``render_samples``);
* *footprint*: the same with ``psf="footprint"`` (the paper's model of a source pixel's
  footprint, §4.1);
* *auto*: :func:`vibr.render.render` with its default ``supersample="auto"`` (a grid ``k``
  times finer, ``k × k`` blocks averaged; ``k = round(1 / pixel size)``, at most 4).

Cases, fixed before any number was seen: *choose* (where the rule was looked at first):
cotton (HCI 2016, centre from its 8 neighbours at stride 2, ground-truth depth) and the
synthetic 3×3 grid at 256² (exact depth); *held out*: Middlebury templeSR0004 from its 6
best views and Strecha fountain 0005 from its 10 others at image scale 0.5, both with depth
estimated from the sources (cached on disk: a second run is rendering only).

PSNR dB over the pixels every render of the row covers, 2-px border; seconds: geometry and
render of that column (numba warm).

``--coarser``: the opposite, sources ``f`` times coarser than the target (a camera closer to
the scene than the photographs, a video larger than them): the sources resized by ``1/f``
(``vibr.geometry.resample.scaled_scene``; temple and fountain loaded at ``1/f`` of the target's scale
and their depth estimated there), the target at its own size against its own photograph,
PSNR over all pixels (on the target's own grid most pixels receive no sample when ``f = 4``:
its coverage is no common ground). Per method: *own grid* (``compute_samples`` +
``render_samples``: the gradient term with gamma as it is); for the default also
``render(..., supersample=1)`` (the target's grid, the gradient term weighed by ``1 / s²``,
``s`` the sources' pixel size on the grid); *auto*: ``render()`` (a grid ``g`` times coarser,
enlarged, :func:`vibr.geometry.resolution.coarsen_factor`).

    python benchmarks/quality/finer_sources.py [--cases cotton,synthetic,temple,fountain] [--factors 2,4]
    python benchmarks/quality/finer_sources.py --coarser [--factors 2,4]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import cotton_gt_case, data_dir, synthetic_grid_case  # noqa: E402

METHODS = ("ulr", "bvs", "gradient")
WAYS = ("target grid", "footprint", "auto")


def cotton():

    name, src, tgt = cotton_gt_case()
    return "cotton, stride 2, GT depth", src, tgt


def synthetic():

    name, src, tgt = synthetic_grid_case()
    return "synthetic grid 256², exact depth", src, tgt


def temple():
    from vibr.io import load_scene
    from vibr.pipeline import prepare

    sc = load_scene(data_dir(None) / "middlebury_templeSparseRing")
    src, tgt = prepare(sc, "templeSR0004", depth="estimated", n_views=6)
    return "temple 0004, 6 best views, estimated depth", src, tgt


def fountain():
    from vibr.io import load_scene
    from vibr.pipeline import prepare

    sc = load_scene(data_dir(None) / "strecha_fountain-P11", scale=0.5)
    src, tgt = prepare(sc, "0005", depth="estimated")
    return "fountain 0005 at ×0.5, 10 views, estimated depth", src, tgt


def coarser_case(key, f):
    """``(name, sources, target)``: the sources ``f`` times coarser than the target."""
    from vibr.geometry.resample import scaled_scene
    from vibr.io import load_scene
    from vibr.pipeline import prepare

    if key in ("cotton", "synthetic"):
        name, src, tgt = CASES[key]()
        return name, scaled_scene(src, 1.0 / f), tgt
    folder, target, scale, kw = {"temple": ("middlebury_templeSparseRing", "templeSR0004", 1.0, {"n_views": 6}),
                                 "fountain": ("strecha_fountain-P11", "0005", 0.25, {})}[key]
    lo = load_scene(data_dir(None) / folder, scale=scale / f)
    src, _ = prepare(lo, target, depth="estimated", **kw)
    name = {"temple": "temple 0004, 6 best views, estimated depth",
            "fountain": "fountain 0005 at ×0.25, 10 views, estimated depth"}[key]
    return name, src, load_scene(data_dir(None) / folder, scale=scale)[target]


def run_coarser(key, factors):
    from vibr.metrics import psnr
    from vibr.render import render

    rows = []
    for f in factors:
        name, src, tgt = coarser_case(key, f)
        cam = tgt.camera
        render_way(src, cam, "ulr", "target grid")  # numba warm
        res = {}
        for m in METHODS:
            res[m, "own"] = render_way(src, cam, m, "target grid")
            if m == "gradient":
                t0 = time.perf_counter()
                res[m, "own s2"] = render(src, cam, m, supersample=1), None
                res[m, "own s2"] = res[m, "own s2"][0], time.perf_counter() - t0
            res[m, "auto"] = render_way(src, cam, m, "auto")
        auto = res["gradient", "auto"][0]
        s = res["gradient", "own s2"][0].params.get("grid_source_size", 1.0)
        cells = [f"{psnr(r.image, tgt.image, border=2):.2f}" for r, _ in res.values()]
        cover = f"{100 * res['gradient', 'own'][0].coverage.mean():.0f} / {100 * auto.coverage.mean():.0f}"
        secs = f"{res['gradient', 'own s2'][1]:.2f} / {res['gradient', 'auto'][1]:.2f}"
        W, H = src.views[0].camera.width, src.views[0].camera.height
        line = (f"| {name} ({SPLIT[key]}) | {W}×{H} → {cam.width}×{cam.height} | {s:.2f} | "
                f"{auto.params.get('coarsen', 1.0):.2f} | " + " | ".join(cells) + f" | {cover} | {secs} |")
        print(line, flush=True)
        rows.append(line)
    return rows


CASES = {"cotton": cotton, "synthetic": synthetic, "temple": temple, "fountain": fountain}
SPLIT = {"cotton": "choose", "synthetic": "choose", "temple": "held out", "fountain": "held out"}


def render_way(src, cam, method, way):
    """``(result, seconds)`` of one render of ``cam`` the given way."""
    from vibr.geometry import compute_samples
    from vibr.render import render, render_samples

    t0 = time.perf_counter()
    if way == "auto":
        res = render(src, cam, method)
    else:
        psf = "footprint" if way == "footprint" else "bilinear"
        S = compute_samples(src, cam, keep=("jac",) if psf == "footprint" else ())
        res = render_samples(S, method, psf=psf)
    return res, time.perf_counter() - t0


def run_case(key, factors):
    from skimage.transform import downscale_local_mean

    from vibr.metrics import psnr

    name, src, tgt = CASES[key]()
    rows = []
    for f in factors:
        H, W = tgt.image.shape[:2]
        Hc, Wc = (H // f) * f, (W // f) * f
        ref = downscale_local_mean(tgt.image[:Hc, :Wc].astype(np.float64), (f, f, 1)).astype(np.float32)
        cam = tgt.camera.scaled(1.0 / f).with_size(Wc // f, Hc // f)
        render_way(src, cam, "ulr", "target grid")  # numba warm for the timings
        res = {(m, w): render_way(src, cam, m, w) for m in METHODS for w in WAYS}
        cover = np.logical_and.reduce([r.coverage for r, _ in res.values()])
        k = res["gradient", "auto"][0].params["supersample"]
        cells = []
        for m in METHODS:
            cells += [f"{psnr(res[m, w][0].image, ref, mask=cover, border=2):.2f}" for w in WAYS]
        secs = " / ".join(f"{res['gradient', w][1]:.2f}" for w in WAYS)
        line = (f"| {name} ({SPLIT[key]}) | {W}×{H} → {cam.width}×{cam.height} | {k} | " + " | ".join(cells)
                + f" | {secs} |")
        print(line, flush=True)
        rows.append(line)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", default="cotton,synthetic,temple,fountain")
    ap.add_argument("--factors", default="2,4", help="target = sources / factor (integers)")
    ap.add_argument("--coarser", action="store_true", help="sources f times coarser than the target instead")
    a = ap.parse_args(argv)
    factors = [int(x) for x in a.factors.split(",")]
    if a.coarser:
        print("# sources coarser than the target; PSNR dB against the target's photograph, all pixels, border 2; "
              "s: the sources' median pixel size on the target; g: the coarser grid of auto")
        print(
            "| case | sources → target | s | g | ulr own grid | ulr auto | bvs own grid | bvs auto | "
            "gradient own grid, "
            "gamma as is | gradient own grid, gamma / s² | gradient auto | covered % own / auto | gradient s, "
            "own grid / auto |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for c in a.cases.split(","):
            run_coarser(c, factors)
        return
    head = " | ".join(f"{m} {w}" for m in METHODS for w in WAYS)
    print("# PSNR dB against the photograph averaged over f×f blocks, pixels every render covers, border 2")
    print(f"| case | sources → target | k (auto) | {head} | gradient s: " + " / ".join(WAYS) + " |")
    print("|---|---|---|" + "---|" * (len(METHODS) * len(WAYS)) + "---|")
    for c in a.cases.split(","):
        run_case(c, factors)


if __name__ == "__main__":
    main()
