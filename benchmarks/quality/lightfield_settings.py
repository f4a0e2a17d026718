"""Light-field depth: plane step and refinement iterations against time and accuracy.

The light-field estimator (:func:`vibr.stereo.lightfield.lightfield_depth`) sweeps planes
``step`` px of disparity apart and refines the winners with ``pm_iter`` slanted-plane
iterations; the refinement is ~70 % of its time and the sweep ~27 % (docs/explanation/depth.md, "Where
the light-field time goes"). For each setting, on every light field we have:

* **cotton, 3×3 block** (``../shared/data/hci2016_cotton``, 512²): the 8 neighbours of the
  centre, each from the other 7 with the centre held out (``estimate_depth``'s timing case of
  bench_depth.py), wall time; the centre view from its 8 neighbours against
  ``gt_disp_lowres.pfm``: BadPix(0.07) % and MSE×100 (15-px border excluded); and the render
  that depth is for: the centre rendered from the 8 neighbours with their estimated depths
  (default method), PSNR against the centre photograph;
* **synthetic 3×3 grids** (exact depth, 512×409; baselines 0.3 (seeds 0 and 1), 0.2, 0.1):
  the centre view's share of textured pixels within 1 % of the exact depth (the measure of
  ``bench_depth.py synthetic``).

The settings run one after the other within each case (one run each: the times are indicative).

    python3 benchmarks/quality/lightfield_settings.py [--settings auto:2:1 auto:2 auto:3] [--size 512]
    python3 benchmarks/quality/lightfield_settings.py --strides   # cotton renders at strides 2, 4; 9×9 centre
    python3 benchmarks/quality/lightfield_settings.py --ab-block 2   # block timing, without the coarse level vs default
    python3 benchmarks/quality/lightfield_settings.py --synthetic-renders all --settings auto:2::2 auto:2
        # renders of the synthetic grids' centres from estimated depths, tuning and held-out grids
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import centre_disparity_model, data_dir, hci_metrics, textured  # noqa: E402


def _parse(s: str) -> tuple:
    """``STEP:ITER[:SCALE[:PM_RADIUS]]``; STEP ``auto`` is lightfield_depth's default (None:
    from the parallax); SCALE its ``pm_coarse_scale``, PM_RADIUS its ``pm_radius`` (empty or
    absent: lightfield_depth's default)."""
    parts = s.split(":") + ["", ""]
    step, it = parts[0], parts[1]
    scale = float(parts[2]) if parts[2] else None
    pm_radius = int(parts[3]) if parts[3] else None
    return (None if step == "auto" else float(step)), int(it), scale, pm_radius


def _kw(setting) -> dict:
    """estimate_depth's keywords for a setting (no SCALE, PM_RADIUS: lightfield_depth's
    defaults)."""
    step, it, scale, pm_radius = setting
    kw = dict(step=step, refine_iter=it)
    if scale is not None:
        kw["pm_coarse_scale"] = scale
    if pm_radius is not None:
        kw["pm_radius"] = pm_radius
    return kw


def _name(setting) -> str:
    step, it, scale, pm_radius = setting
    return (f"step {step} iter {it}" + (f" coarse {scale}" if scale is not None else "")
            + (f" pm_radius {pm_radius}" if pm_radius is not None else ""))


def _cotton():
    """Cotton (all 81 views), its centre-view disparity ground truth, the centre's index and
    every view's grid position."""
    from vibr.io import load_scene, read_pfm

    root = data_dir() / "hci2016_cotton"
    scene = load_scene(root)
    gt = np.asarray(read_pfm(root / "gt_disp_lowres.pfm"), np.float64)
    ref = scene.index("input_Cam040")
    pos = {scene.index(k): v for k, v in scene.meta["grid_pos"].items()}
    return scene, gt, ref, pos


def _block(scene, ref, pos, stride: int = 1):
    """The 3×3 block around the centre at grid ``stride`` (neighbours 4±s in row and column,
    as benchmarks/quality/paper_tables.py): the sub-scene, the centre's name and the 8 neighbours'."""
    r0, c0 = pos[ref]
    block = [ref] + [i for i, (r, c) in pos.items()
                     if (r - r0) in (-stride, 0, stride) and (c - c0) in (-stride, 0, stride) and (r, c) != (r0, c0)]
    sub = scene.subset([scene.views[i].name for i in block])
    return sub, scene.views[ref].name, [scene.views[i].name for i in block if i != ref]


def cotton_strides(settings, strides):
    """Render PSNR of the centre from its 8 neighbours at grid ``stride`` (neighbours 4±s in
    row and column, as benchmarks/quality/paper_tables.py), their depths estimated with each setting;
    and the centre of the 9×9 grid from its 80 neighbours (BadPix / MSE×100)."""
    from vibr.render import render
    from vibr.stereo import estimate_depth
    from vibr.stereo.lightfield import lightfield_depth

    scene, gt, ref, pos = _cotton()
    out = {}
    for st in strides:
        sub, centre, nbs = _block(scene, ref, pos, st)
        for se in settings:
            est8 = estimate_depth(sub, views=nbs, exclude=[centre], **_kw(se))
            res = render(est8.subset(nbs), sub[centre])
            out[(st,) + se] = res.metrics["psnr"]
            print(f"  cotton stride {st}, {_name(se)}: render PSNR {res.metrics['psnr']:.2f} dB", flush=True)
    cams = [v.camera for v in scene.views]
    for se in settings:
        kw = _kw(se)
        kw["pm_iter"] = kw.pop("refine_iter")  # lightfield_depth's name
        t = time.perf_counter()
        _, _, _, d = lightfield_depth(scene, ref, cams, lambda i: scene.views[i].image, list(range(len(scene))),
                                      return_disparity=True, **kw)
        t = time.perf_counter() - t
        bp, mse = hci_metrics(d, gt, 15)
        out[("9x9",) + se] = (bp, mse, t)
        print(f"  cotton 9x9 centre, {_name(se)}: BadPix {bp:.2f} MSE*100 {mse:.3f}, {t:.1f} s", flush=True)
    return out


def cotton_case(settings):
    from vibr.render import render
    from vibr.stereo import estimate_depth

    scene, gt, ref, pos = _cotton()
    sub, centre, nbs = _block(scene, ref, pos)
    rows = {}
    for se in settings:
        kw = _kw(se)
        t = time.perf_counter()
        est8 = estimate_depth(sub, views=nbs, exclude=[centre], **kw)
        t8 = time.perf_counter() - t
        est1 = estimate_depth(sub, views=[centre], **kw)
        a, b = centre_disparity_model(sub, centre)
        with np.errstate(divide="ignore", invalid="ignore"):
            d = -(a + b / est1[centre].depth.astype(np.float64))
        bp, mse = hci_metrics(d, gt, 15)
        res = render(est8.subset(nbs), sub[centre])
        rows[se] = dict(t8=t8, badpix=bp, mse=mse, psnr=res.metrics["psnr"])
        print(f"  cotton {_name(se)}: 8 views {t8:.1f} s, centre BadPix {bp:.2f} MSE*100 {mse:.3f}, "
              f"render PSNR {res.metrics['psnr']:.2f} dB", flush=True)
    return rows


#: The synthetic grids (seed, baseline) the defaults were chosen on, and held-out ones.
GRIDS = ((0, 0.3), (1, 0.3), (0, 0.2), (0, 0.1))
HELD_OUT_GRIDS = ((2, 0.25), (3, 0.15), (4, 0.3), (5, 0.1))


def synthetic_renders(settings, W: int, grids):
    """Per grid and setting: the centre view rendered (default method) from its 8
    neighbours with their depths estimated without it, PSNR against the exact image; and
    the centre's share of textured pixels within 1 % of the exact depth."""
    from vibr.render import render
    from vibr.stereo import estimate_depth
    from vibr.synthetic import make_scene

    H = W * 4 // 5
    out = {}
    for seed, bl in grids:
        scene = make_scene("grid", n_views=9, width=W, height=H, seed=seed, baseline=bl)
        names = [v.name for v in scene.views]
        centre, nbs = names[4], names[:4] + names[5:]
        gt = scene[4].depth
        tex = textured(scene[4].image) & np.isfinite(gt)
        for se in settings:
            kw = _kw(se)
            t = time.perf_counter()
            est8 = estimate_depth(scene, views=nbs, exclude=[centre], method="lightfield", **kw)
            t8 = time.perf_counter() - t
            est1 = estimate_depth(scene, views=[centre], method="lightfield", **kw)
            with np.errstate(invalid="ignore"):
                within = 100 * (np.abs(est1[4].depth - gt) / gt < 0.01)[tex].mean()
            psnr = render(est8.subset(nbs), scene[4]).metrics["psnr"]
            out[(seed, bl) + se] = (psnr, within, t8)
            print(f"  synthetic grid baseline {bl} seed {seed}, {_name(se)}: render PSNR {psnr:.2f} dB, "
                  f"centre {within:.2f} % within 1 %, 8 views {t8:.1f} s", flush=True)
    print("\n| grid (seed, baseline) | " + " | ".join(_name(se) for se in settings) + " |")
    print("|---|" + "---|" * len(settings))
    for seed, bl in grids:
        cells = [f"{out[(seed, bl) + se][0]:.2f} dB, {out[(seed, bl) + se][1]:.2f} %" for se in settings]
        print(f"| {seed}, {bl} | " + " | ".join(cells) + " |")
    return out


def synthetic_cases(settings, W: int):
    from vibr.stereo import estimate_depth
    from vibr.synthetic import make_scene

    H = W * 4 // 5
    out = {}
    for seed, bl in GRIDS:
        scene = make_scene("grid", n_views=9, width=W, height=H, seed=seed, baseline=bl)
        gt = scene[4].depth
        tex = textured(scene[4].image) & np.isfinite(gt)
        for se in settings:
            t = time.perf_counter()
            est = estimate_depth(scene, views=[4], method="lightfield", **_kw(se))
            t = time.perf_counter() - t
            with np.errstate(invalid="ignore"):
                ok = np.abs(est[4].depth - gt) / gt < 0.01
            out[(seed, bl) + se] = (100 * ok[tex].mean(), t)
            print(f"  synthetic grid baseline {bl} seed {seed}, {_name(se)}: "
                  f"{100 * ok[tex].mean():.1f} % within 1 %, {t:.1f} s", flush=True)
    return out


def ab_block(rounds: int) -> None:
    """The cotton block's 8-view estimate without the coarse level (``pm_coarse_scale=1``,
    the former default) and with the default, alternating (the order flips every round), in
    this process."""
    import statistics

    from vibr.stereo import estimate_depth

    scene, _, ref, pos = _cotton()
    sub, centre, nbs = _block(scene, ref, pos)
    T = {"no coarse level (former default)": [], "default (coarse level at 0.5)": []}
    for r in range(rounds):
        for k in (list(T) if r % 2 == 0 else list(T)[::-1]):
            kw = {"pm_coarse_scale": 1.0} if k.startswith("no coarse") else {}
            t = time.perf_counter()
            estimate_depth(sub, views=nbs, exclude=[centre], **kw)
            T[k].append(time.perf_counter() - t)
            print(f"{k}: {T[k][-1]:.1f} s (load {os.getloadavg()[0]:.1f})", flush=True)
    for k, v in T.items():
        print(f"{k}: median {statistics.median(v):.1f} s ({min(v):.1f}-{max(v):.1f}, n={len(v)})")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--settings", nargs="+", default=["auto:2:1", "auto:2"],
                    help="STEP:REFINE_ITER[:COARSE_SCALE[:PM_RADIUS]]; STEP 'auto': lightfield_depth's "
                         "default; COARSE_SCALE: its pm_coarse_scale (1: no coarse level), PM_RADIUS its "
                         "pm_radius (empty or absent: lightfield_depth's defaults)")
    ap.add_argument("--size", type=int, default=512, help="width of the synthetic grids")
    ap.add_argument("--strides", action="store_true",
                    help="only the cotton renders at strides 2 and 4 and the 9×9 grid's centre")
    ap.add_argument("--ab-block", type=int, metavar="ROUNDS",
                    help="only the block's 8-view estimate, without the coarse level against the default, alternating")
    ap.add_argument("--synthetic-renders", choices=("tuning", "held-out", "all"),
                    help="only the synthetic grids' centre renders from estimated depths (and depth "
                         "within 1 %%): the grids the defaults were chosen on, held-out grids, or both")
    a = ap.parse_args()
    settings = [_parse(s) for s in a.settings]
    if a.synthetic_renders:
        grids = {"tuning": GRIDS, "held-out": HELD_OUT_GRIDS, "all": GRIDS + HELD_OUT_GRIDS}[a.synthetic_renders]
        synthetic_renders(settings, a.size, grids)
        return
    if a.ab_block:
        ab_block(a.ab_block)
        return
    if a.strides:
        cotton_strides(settings, (2, 4))
        return
    print(f"load average {os.getloadavg()[0]:.2f}", flush=True)
    cot = cotton_case(settings)
    syn = synthetic_cases(settings, a.size)
    print("\n| setting (step px, refinement iterations) | cotton 3×3: 8 views s | centre BadPix / MSE×100 "
          "| render PSNR dB | synthetic 3×3, % within 1 %: bl 0.3 s0 / 0.3 s1 / 0.2 / 0.1 |")
    print("|---|---|---|---|---|")
    for se in settings:
        step, it, scale, pm_radius = se
        c = cot[se]
        s = " / ".join(f"{syn[(seed, bl) + se][0]:.1f}" for seed, bl in GRIDS)
        label = (
            f"{'auto' if step is None else f'{step} px'}, {it}"
            + (f", coarse {scale}" if scale is not None else "")
            + (f", pm_radius {pm_radius}" if pm_radius is not None else "")
        )
        print(f"| {label} | {c['t8']:.1f} | {c['badpix']:.2f} / {c['mse']:.3f} | {c['psnr']:.2f} | {s} |")
    print(f"\nload average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
