"""How well the estimated depth's sigma_z predicts its error, where the true depth is known.

The renderer reads ``sigma_z`` as the standard deviation of a source pixel's depth error
(docs/explanation/method.md §3: ``W = 1/(sigma_s² + sigma_z²(∂τ/∂z·∇u)²)``); the estimators give a
heuristic scale (docs/explanation/depth.md, step 8: the sweep cost's curvature and the agreeing partners'
spread). This script compares the two on every scene of ``../shared/data`` with true depth
and on synthetic scenes (exact depth), without rendering anything:

* **light field** (:func:`vibr.stereo.lightfield.lightfield_depth`, ``estimate_depth``'s
  default for grids): cotton's centre view from its 8 neighbours at strides 1, 2 and 4
  (against ``gt_disp_lowres.pfm``), and the synthetic 3×3 grids of ``bench_depth.py
  synthetic``;
* **MVS** (plane sweep): the synthetic hand-held layouts (7 views, every view estimated so
  that the consistency check has its partners; the reference view scored) and the free
  layout.

For each case, over the textured pixels (a 7×7 window's grey-level std above 0.02, as
``bench_depth.py``: where the photographs determine the depth; on a flat wall any depth
gives the same colours, and the estimators' gross errors there cost a render nothing) with
both depths known (a ``--border``-px frame left out), the normalised error ``r = (z_est − z_true) / sigma_z`` and:

* ``k = median(|r|) / 0.6745``: the factor by which sigma_z would have to be multiplied for
  the median error to be a Gaussian's (1 when calibrated; robust to gross errors, which a
  Gaussian model cannot describe anyway);
* ``k_rms = √mean(r²)``: the same for the mean squared error, which is what the weights'
  variance model needs (gross errors included), and ``k_rms99`` with ``|r|`` clipped at its
  99th percentile (the 1 % worst pixels' weight is near 0 either way);
* the share of gross errors, ``|e| / z`` > 5 %;
* the share of pixels within 1 and 2 sigma_z (68.3 % and 95.4 % for a calibrated Gaussian);
* Spearman's ρ between sigma_z and |z_est − z_true| (does a larger sigma_z mark a larger
  error);
* the median relative error ``|e| / z`` and relative sigma ``sigma_z / z``.

    python3 benchmarks/quality/sigma_z_calibration.py [--size 320] [--seeds 4]
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np

_REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import centre_disparity_model, cotton_neighbours, data_dir, textured  # noqa: E402

GAUSS_MAD = 0.6745  # median |x| of a standard normal
GROSS = 0.05  # a relative depth error beyond which a pixel counts as a gross error


def calibration(z_est, sigma, z_true, mask=None, border: int = 15) -> dict:
    """The statistics of the docstring over the pixels of ``mask`` (all: None) where both
    depths are finite."""
    from scipy.stats import spearmanr

    sl = (slice(border, -border), slice(border, -border)) if border else (slice(None),) * 2
    z, s, t = (np.asarray(a, np.float64)[sl] for a in (z_est, sigma, z_true))
    ok = np.isfinite(z) & np.isfinite(t) & np.isfinite(s) & (s > 0) & (t > 0)
    if mask is not None:
        ok &= np.asarray(mask, bool)[sl]
    e = z[ok] - t[ok]
    r = np.abs(e) / s[ok]
    return {"n": int(ok.sum()), "k": float(np.median(r) / GAUSS_MAD), "k_rms": float(np.sqrt(np.mean(r ** 2))),
            "k_rms99": float(np.sqrt(np.mean(np.minimum(r, np.quantile(r, 0.99)) ** 2))),
            "gross": float(np.mean(np.abs(e) / t[ok] > GROSS)), "in1": float(np.mean(r < 1)),
            "in2": float(np.mean(r < 2)), "rho": float(spearmanr(s[ok], np.abs(e)).statistic),
            "rel_err": float(np.median(np.abs(e) / t[ok])), "rel_sigma": float(np.median(s[ok] / t[ok]))}


def cotton_cases(strides):
    """(name, estimator, estimated view, true depth) of cotton's centre from its 8 neighbours at each stride."""

    from vibr.io import load_scene, read_pfm
    from vibr.stereo import estimate_depth

    root = data_dir() / "hci2016_cotton"
    scene = load_scene(root)
    gt = np.asarray(read_pfm(root / "gt_disp_lowres.pfm"), np.float64)
    centre = "input_Cam040"
    for s in strides:
        sub = scene.subset([centre, *cotton_neighbours(scene, s)])
        est = estimate_depth(sub, views=[centre])
        a, b = centre_disparity_model(sub, centre)
        with np.errstate(divide="ignore", invalid="ignore"):
            z_true = b / (-gt - a)  # d = −(a + b/z)
        yield f"cotton centre, stride {s}", "light field", est[centre], z_true


def synthetic_cases(size: int, seeds: int):
    """(name, estimator, estimated view, true depth) of the synthetic layouts (exact depth)."""
    from vibr.stereo import estimate_depth
    from vibr.synthetic import make_scene

    W, H = size, size * 4 // 5
    for seed in range(seeds):
        for bl in (0.1, 0.3):
            sc = make_scene("grid", n_views=9, width=W, height=H, seed=seed, baseline=bl)
            est = estimate_depth(sc, views=[4], method="lightfield")
            yield f"grid 3x3, baseline {bl}, seed {seed}", "light field", est[4], sc[4].depth
    for seed in range(seeds):
        sc = make_scene("handheld", width=W, height=H, seed=seed)
        est = estimate_depth(sc, method="mvs")
        yield f"handheld, 7 views, seed {seed}", "MVS", est[0], sc[0].depth
        sc = make_scene("free", width=W, height=H, seed=seed)
        est = estimate_depth(sc, method="mvs")
        yield f"free, 5 views, seed {seed}", "MVS", est[0], sc[0].depth


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=320, help="synthetic image width (height 4/5 of it)")
    ap.add_argument("--seeds", type=int, default=4, help="synthetic worlds per layout")
    ap.add_argument("--border", type=int, default=15, help="pixels left out at the image border")
    args = ap.parse_args(argv)
    print(
        "| case | estimator | textured pixels | k = median(|e|/σ)/0.6745 | k_rms | k_rms99 | gross % (all pixels) | "
        "within 1σ % | "
        "within 2σ % | Spearman ρ(σ, |e|) | median |e|/z | median σ/z | s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")

    ks = {}
    t = time.perf_counter()
    for name, method, v, zt in itertools.chain(cotton_cases((1, 2, 4)), synthetic_cases(args.size, args.seeds)):
        c = calibration(v.depth, v.sigma_z, zt, textured(v.image), args.border)
        gross_all = calibration(v.depth, v.sigma_z, zt, None, args.border)["gross"]
        ks.setdefault(method, []).append((c["k"], c["k_rms"], c["k_rms99"]))
        print(
            f"| {name} | {method} | {c['n']} | {c['k']:.2f} | {c['k_rms']:.2f} | {c['k_rms99']:.2f} | "
            f"{100 * c['gross']:.2f} ({100 * gross_all:.2f}) | {100 * c['in1']:.1f} | {100 * c['in2']:.1f} | "
            f"{c['rho']:.2f} | {c['rel_err']:.4f} | {c['rel_sigma']:.4f} | {time.perf_counter() - t:.0f} |",
            flush=True,
        )
        t = time.perf_counter()
    print()
    for m, v in ks.items():
        v = np.array(v)
        print(
            f"* {m}, {len(v)} cases: "
            + ", ".join(
                f"{lab} median {np.median(v[:, j]):.2f} (min {v[:, j].min():.2f}, max {v[:, j].max():.2f})"
                for j, lab in enumerate(("k", "k_rms", "k_rms99"))
            )
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
