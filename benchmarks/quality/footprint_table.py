"""Bilinear vs footprint PSF (paper §4.1) where the footprint model matters: sources at a
higher resolution than the target.

The held-out view is rendered at ``1/f`` of the sources' resolution (its camera scaled by
:meth:`vibr.Camera.scaled`); the reference is the full-resolution held-out image reduced by
box averaging (``skimage.transform.downscale_local_mean``, factor f: a pixel-integrating
sensor). Cases:

* ``synthetic``: ``make_scene("grid", 256×256)`` (exact depth), view 4 from the 8 others;
* ``cotton``: HCI 2016 cotton, centre view input_Cam040 from its 8 neighbours at stride 2
  (views 4±2), sources at full resolution (512²), depth of the sources by transfer of the
  centre's ground truth (as ``benchmarks/quality/cotton_table.py``).
* ``coarse`` (the opposite case, a check of the shrink rule): the synthetic grid's 8
  sources at 128², target view 4 at 256² (the same world and poses, its own 256² image as
  the reference): every footprint is larger than a target pixel and is shrunk to 1 px, so
  the footprint PSF should give the bilinear result.

For each case and factor, bvs and gradient (γ = 1, the defaults otherwise) with
``psf="bilinear"`` and ``psf="footprint"``, and (f > 1) the bilinear render at the sources'
resolution box-averaged by f (the alternative to a footprint model: render fine, then
reduce; f² times the pixels); PSNR dB / DSSIM (1e4·(1−SSIM)) over the pixels covered in
*all* renders of the row (so every column is scored on the same pixels; a reduced render
covers a pixel when its f×f block is all covered), 2-pixel border excluded, and the fraction
of samples whose footprint had to be shrunk to 1 px.

    python benchmarks/quality/footprint_table.py [--cases synthetic,cotton,coarse] [--factors 1,2,4]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import cotton_gt_case, synthetic_grid_case  # noqa: E402

SETTINGS = [("bvs", "bilinear"), ("bvs", "footprint"), ("gradient", "bilinear"), ("gradient", "footprint")]


def run_case(name, src, tgt, factors, extra):
    from skimage.transform import downscale_local_mean

    from vibr.geometry import compute_samples
    from vibr.metrics import dssim, psnr
    from vibr.render import render_samples

    rows = []
    for f in factors:
        cam = tgt.camera.scaled(1.0 / f)
        H, W = tgt.image.shape[:2]
        assert H % f == 0 and W % f == 0, "the reference needs an integer box factor"
        ref = (downscale_local_mean(tgt.image.astype(np.float64), (f, f, 1)) if f > 1
               else tgt.image.astype(np.float64)).astype(np.float32)
        assert ref.shape[:2] == (cam.height, cam.width)
        S = compute_samples(src, cam, keep=("jac",))
        res = {}
        for m, psf in SETTINGS:
            t0 = time.perf_counter()
            r = render_samples(S, m, psf=psf, **extra)
            res[m, psf] = (r, time.perf_counter() - t0)
        fine = {}
        if f > 1:
            Sf = compute_samples(src, tgt.camera)
            for m in ("bvs", "gradient"):
                t0 = time.perf_counter()
                r = render_samples(Sf, m, psf="bilinear", **extra)
                img = downscale_local_mean(r.image.astype(np.float64), (f, f, 1)).astype(np.float32)
                cov = downscale_local_mean(r.coverage.astype(np.float64), (f, f)) > 1 - 1e-9
                fine[m] = (img, cov, time.perf_counter() - t0)
        cover = np.logical_and.reduce([r.coverage for r, _ in res.values()] + [c for _, c, _ in fine.values()])
        cells = []
        for key in SETTINGS + [(m, "fine") for m in fine]:
            if key[1] == "fine":
                img, _, dt = fine[key[0]]
                p = psnr(img, ref, mask=cover, border=2)
                d = dssim(img, ref, mask=cover, border=2)
                cells.append(f"{p:.2f} / {d:.0f}")
                print(f"#   {name} 1/{f} {key}: {p:.3f} dB, DSSIM {d:.1f}, {dt:.1f} s", file=sys.stderr, flush=True)
                continue
            r, dt = res[key]
            p = psnr(r.image, ref, mask=cover, border=2)
            d = dssim(r.image, ref, mask=cover, border=2)
            cells.append(f"{p:.2f} / {d:.0f}")
            print(f"#   {name} 1/{f} {key}: {p:.3f} dB, DSSIM {d:.1f}, {dt:.1f} s, "
                  f"{r.iterations} iterations, shrunk {r.params['psf_shrunk']:.3f}",
                  file=sys.stderr, flush=True)
        shr = res["bvs", "footprint"][0].params["psf_shrunk"]
        if not fine:
            cells += ["", ""]
        line = (f"| {name} | {W}² → {cam.width}×{cam.height} (1/{f}) | " + " | ".join(cells)
                + f" | {100 * shr:.1f} % |")
        print(line, flush=True)
        rows.append(line)
    return rows


def coarse_case(extra):
    """Sources at 128², target at 256² (footprints > 1 px: the shrink rule)."""
    from vibr.geometry import compute_samples
    from vibr.metrics import dssim, psnr
    from vibr.render import render_samples
    from vibr.synthetic import make_scene

    lo = make_scene("grid", width=128, height=128)
    hi = make_scene("grid", width=256, height=256)
    tgt = hi.views[4]
    src = lo.subset([v.name for v in lo.views if v.name != tgt.name])
    S = compute_samples(src, tgt.camera, keep=("jac",))
    res = {key: render_samples(S, key[0], psf=key[1], **extra) for key in SETTINGS}
    cover = np.logical_and.reduce([r.coverage for r in res.values()])
    cells = [f"{psnr(r.image, tgt.image, mask=cover, border=2):.2f} / "
             f"{dssim(r.image, tgt.image, mask=cover, border=2):.0f}" for r in res.values()]
    shr = res["bvs", "footprint"].params["psf_shrunk"]
    print("| synthetic grid, coarser sources | 128² → 256×256 (×2) | " + " | ".join(cells)
          + f" | | | {100 * shr:.1f} % |", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", default="synthetic,cotton,coarse")
    ap.add_argument("--factors", default="1,2,4", help="target = sources / factor (integers)")
    ap.add_argument("extra", nargs="*", help="render parameters k=v")
    a = ap.parse_args(argv)
    extra = {k: eval(v) for k, v in (e.split("=", 1) for e in a.extra)}  # noqa: S307 - a benchmark
    factors = [int(x) for x in a.factors.split(",")]
    print(f"# bilinear vs footprint PSF; extra params {extra}; PSNR dB / DSSIM over the pixels "
          "covered by all four renders, border 2; reference = held-out view box-averaged")
    print("| scene | sources → target | bvs bilinear | bvs footprint | gradient bilinear "
          "| gradient footprint | bvs bilinear fine, reduced | gradient bilinear fine, reduced "
          "| footprints shrunk |")
    print("|---|---|---|---|---|---|---|---|---|")
    for c in a.cases.split(","):
        if c == "coarse":
            coarse_case(extra)
            continue
        name, src, tgt = {"synthetic": synthetic_grid_case, "cotton": cotton_gt_case}[c]()
        run_case(name, src, tgt, factors, extra)


if __name__ == "__main__":
    main()
