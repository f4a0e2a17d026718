"""Depth-estimation benchmark: HCI cotton metrics and Strecha fountain MVS.

Usage::

    python benchmarks/perf/bench_depth.py cotton      # BadPix(0.07), MSE×100 of the centre view
    python benchmarks/perf/bench_depth.py fountain    # 11 views at 768×512: kept, reprojection, time,
                                                 # and the PSNR of view 5 rendered from the others
    python benchmarks/perf/bench_depth.py synthetic   # exact-depth scenes: % within 1 % relative error
    python benchmarks/perf/bench_depth.py temple      # 16-view ring: kept, reprojection, time (no GT)
    python benchmarks/perf/bench_depth.py             # all three

Prints tables. Timings are single runs on a shared machine (noisy); repeat with --repeat N to
get medians. Data: $VIBR_DATA or ../shared/data.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import centre_disparity_model, data_dir, hci_metrics, seen_count, surface_textured, textured  # noqa: E402


def bench_cotton(args) -> None:
    from vibr.io import load_scene, read_pfm
    from vibr.stereo.lightfield import lightfield_depth

    root = data_dir() / "hci2016_cotton"
    scene = load_scene(root)
    gt = np.asarray(read_pfm(root / "gt_disp_lowres.pfm"), np.float64)
    ref = scene.index("input_Cam040")
    pos = {scene.index(k): v for k, v in scene.meta["grid_pos"].items()}
    r0, c0 = pos[ref]
    block = [ref] + [i for i, (r, c) in pos.items() if max(abs(r - r0), abs(c - c0)) == 1]
    full = list(range(len(scene)))
    cams = [v.camera for v in scene.views]

    def img(i):
        return scene.views[i].image

    _bench_cotton_block(scene, gt, ref, block, args)
    if args.block_only:
        return
    rows = []
    for label, inputs in (("3x3 block (8 nb)", block), ("9x9 grid (80 nb)", full)):
        for refine in args.refine.split(","):
            times = []
            for _ in range(args.repeat):
                t = time.perf_counter()
                z, s, st, d = lightfield_depth(scene, ref, cams, img, inputs, refine=refine,
                                               pm_iter=args.refine_iter,
                                               median_radius=args.median_radius,
                                               return_disparity=True)
                times.append(time.perf_counter() - t)
            bp, mse = hci_metrics(d, gt, 15)
            bp0, mse0 = hci_metrics(d, gt, 0)
            rows.append((label, refine, bp, mse, bp0, mse0, statistics.median(times),
                         st.get("n_views", "-"), st.get("n_planes", "-")))
    print("\nhci2016_cotton, centre view input_Cam040 vs gt_disp_lowres.pfm (512x512)")
    print(f"{'inputs':<18} {'refine':<9} {'BadPix0.07 %':>12} {'MSE*100':>8} {'BadPix(all) %':>13} "
          f"{'MSE*100(all)':>12} {'time s':>7} {'sweep views':>11} {'planes':>6}")
    for r in rows:
        print(f"{r[0]:<18} {r[1]:<9} {r[2]:>12.2f} {r[3]:>8.3f} {r[4]:>13.2f} {r[5]:>12.3f} "
              f"{r[6]:>7.1f} {str(r[7]):>11} {str(r[8]):>6}")
    print("(first two metric columns: 15 px border excluded, as the benchmark; 'all': every pixel)")


def _bench_cotton_block(scene, gt, ref, block, args) -> None:
    """The 3×3-block estimate with estimate_depth's defaults: the 8 neighbours of the centre
    from each other (the centre held out, as in the structured protocol of
    benchmarks/quality/paper_tables.py), timed; and the centre view from its 8 neighbours, with its
    BadPix(0.07) / MSE×100 (15-px border excluded)."""
    from vibr.stereo import estimate_depth

    sub = scene.subset([scene.views[i].name for i in block])
    centre = scene.views[ref].name
    nbs = [scene.views[i].name for i in block if i != ref]
    t8, t1 = [], []
    for _ in range(args.repeat):
        t = time.perf_counter()
        estimate_depth(sub, views=nbs, exclude=[centre])
        t8.append(time.perf_counter() - t)
        t = time.perf_counter()
        est = estimate_depth(sub, views=[centre])
        t1.append(time.perf_counter() - t)
    z = est[centre].depth
    a, b = centre_disparity_model(sub, centre)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = -(a + b / z.astype(np.float64))
    bp, mse = hci_metrics(d, gt, 15)
    print(f"\nhci2016_cotton 3x3 block, estimate_depth defaults (load average {os.getloadavg()[0]:.1f}):")
    print(f"  8 views (each from the other 7, centre held out): {statistics.median(t8):.1f} s "
          f"(median of {len(t8)}: {', '.join(f'{x:.1f}' for x in sorted(t8))})")
    print(f"  centre view from its 8 neighbours: {statistics.median(t1):.1f} s; "
          f"BadPix(0.07) {bp:.2f} %, MSE*100 {mse:.3f} (15 px border excluded)")


def bench_fountain(args) -> None:
    from vibr.io import load_scene
    from vibr.stereo import estimate_depth

    root = data_dir() / "strecha_fountain-P11"
    t = time.perf_counter()
    scene = load_scene(root, scale=args.fountain_scale)
    t_load = time.perf_counter() - t
    h, w = scene[0].shape
    times = []
    for _ in range(args.repeat):
        t = time.perf_counter()
        est = estimate_depth(scene, method="mvs", n_neighbours=args.neighbours,
                             step_px=args.step_px, max_planes=args.max_planes,
                             refine_iter=args.refine_iter,
                             median_radius=args.median_radius, sweep_scale=args.sweep_scale,
                             coarse_iter=args.coarse_iter, fill_segments=args.fill_segments)
        times.append(time.perf_counter() - t)
    info = est.meta["depth_estimation"]["views"]
    print(f"\nstrecha_fountain-P11, all 11 views at {w}x{h} (load {t_load:.1f} s, not counted); "
          f"{args.neighbours} neighbours, step {args.step_px} px, <= {args.max_planes} planes; "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"{'view':<6} {'range (near..far)':>18} {'planes':>6} {'confident %':>11} {'kept %':>7} "
          f"{'filled %':>8} {'reproj px':>9} {'time s':>7}")
    for name, st in info.items():
        dr = st["depth_range"]
        print(f"{name:<6} {dr[0]:>8.2f}..{dr[1]:<8.2f} {st['n_planes']:>6} {100 * st['confident']:>11.1f} "
              f"{100 * st['kept']:>7.1f} {100 * st.get('filled', 0.0):>8.1f} "
              f"{st.get('reproj_px', float('nan')):>9.3f} {st['time_s']:>7.1f}")
    kept = np.mean([st["kept"] for st in info.values()])
    filled = np.mean([st.get("filled", 0.0) for st in info.values()])
    rep = np.nanmedian([st.get("reproj_px", np.nan) for st in info.values()])
    print(f"total depth time {statistics.median(times):.1f} s (median of {len(times)}: "
          f"{', '.join(f'{x:.1f}' for x in sorted(times))}), "
          f"mean kept {100 * kept:.1f} % (after the consistency check"
          + (f"; then filled from segment planes {100 * filled:.1f} %" if args.fill_segments else "")
          + f"), median of per-view mean reprojection error {rep:.3f} px")
    zs = np.concatenate([v.depth[np.isfinite(v.depth)] for v in est.views])
    print(f"estimated depth percentiles 1/50/99: {np.percentile(zs, [1, 50, 99]).round(2).tolist()}")
    if args.no_render:
        return
    try:
        from vibr.metrics import psnr
        from vibr.render import render
    except ImportError as exc:  # pragma: no cover
        print(f"render not available: {exc}")
        return
    tgt = scene.index("0005")
    t = time.perf_counter()
    held = estimate_depth(scene, views=[i for i in range(len(scene)) if i != tgt], exclude=[tgt],
                          method="mvs", n_neighbours=args.neighbours, step_px=args.step_px,
                          max_planes=args.max_planes, refine_iter=args.refine_iter,
                          median_radius=args.median_radius, sweep_scale=args.sweep_scale,
                          coarse_iter=args.coarse_iter, fill_segments=args.fill_segments)
    t_held = time.perf_counter() - t
    sources, target = held.split(tgt)
    for method in args.methods.split(","):
        t = time.perf_counter()
        res = render(sources, target, method=method)
        t_r = time.perf_counter() - t
        p_all = psnr(res.image, target.image)
        cov = getattr(res, "coverage", None)
        p_cov = psnr(res.image, target.image, mask=cov) if cov is not None else float("nan")
        print(f"view 5 from the other 10 ({w}x{h}, depth without view 5: {t_held:.1f} s): "
              f"{method:<8} PSNR {p_all:.2f} dB (covered pixels {p_cov:.2f} dB), render {t_r:.1f} s; "
              f"paper (Nieto et al. 2016, fountain, gradient method): 26.36 dB")


def bench_temple(args) -> None:
    """Middlebury templeSparseRing (16 views, 640x480, a wide-baseline ring; no public
    ground truth): kept fraction after the consistency check, reprojection error, time."""
    from vibr.io import load_scene
    from vibr.stereo import estimate_depth

    scene = load_scene(data_dir() / "middlebury_templeSparseRing")
    h, w = scene[0].shape
    t = time.perf_counter()
    est = estimate_depth(scene, method="mvs", n_neighbours=args.neighbours, step_px=args.step_px,
                         max_planes=args.max_planes, refine_iter=args.refine_iter,
                         median_radius=args.median_radius, sweep_scale=args.sweep_scale,
                         coarse_iter=args.coarse_iter, fill_segments=args.fill_segments)
    t = time.perf_counter() - t
    info = est.meta["depth_estimation"]["views"]
    kept = np.mean([st["kept"] for st in info.values()])
    rep = np.nanmedian([st.get("reproj_px", np.nan) for st in info.values()])
    planes = [st["n_planes"] for st in info.values()]
    print(f"\nmiddlebury_templeSparseRing, {len(info)} views at {w}x{h}; step {args.step_px} px, "
          f"<= {args.max_planes} planes, refine {args.refine_iter}: planes {min(planes)}..{max(planes)}, "
          f"mean kept {100 * kept:.1f} %, median reprojection error {rep:.3f} px, total {t:.1f} s "
          f"(load average {os.getloadavg()[0]:.1f})")


def _seen_elsewhere(scene, ref: int, tol: float = 0.02) -> np.ndarray:
    """Pixels of view ``ref`` whose exact 3D point is visible in at least one other view
    (:func:`_common.seen_count`). A pixel seen by no other view cannot be triangulated."""
    return seen_count(scene, ref, [j for j in range(len(scene)) if j != ref], tol) > 0


def bench_synthetic(args) -> None:
    """Exact-depth synthetic scenes: fraction of textured pixels within 1 % relative error."""
    for size in args.synthetic_size:
        _bench_synthetic_at(args, int(size))


def _bench_synthetic_at(args, W: int) -> None:
    from vibr.scene import Scene, View
    from vibr.stereo import estimate_depth
    from vibr.synthetic import default_world, free_cameras, make_scene, render_view

    H = W * 4 // 5
    world = default_world(0)
    cams = free_cameras(5, 0, width=W, height=H, pos_jitter=0.6)
    views = []
    for i, c in enumerate(cams):
        im, d = render_view(world, c)
        views.append(View(f"view_{i:03d}", im, c, depth=d))
    # (name, scene, world seed, reference, method, views to estimate)
    cases = [("free, 5 views, jitter 0.6", Scene(views), 0, 0, "mvs", [0])]
    for seed in range(7):
        cases.append((f"handheld, 7 views, seed {seed}",
                      make_scene("handheld", width=W, height=H, seed=seed), seed, 0, "mvs", None))
    for seed, bl in ((0, 0.3), (1, 0.3), (0, 0.2), (0, 0.1)):
        cases.append((f"grid 3x3, baseline {bl}, seed {seed}",
                      make_scene("grid", n_views=9, width=W, height=H, seed=seed, baseline=bl),
                      seed, 4, "lightfield", [4]))
    print(f"\nsynthetic scenes ({W}x{H}), reference view vs exact depth")
    print(f"{'':<32} {'':<10} {'share of textured %':>26} {'':>7} "
          f"{'within 1 % of exact depth, % of':>47}")
    print(f"{'scene':<32} {'method':<10} {'textured %':>10} {'seen':>7} {'surface':>7} {'kept %':>7} "
          f"{'textured':>9} {'tex+seen':>9} {'surface':>9} {'surf+seen':>9} {'kept':>7} {'time s':>7}")
    for name, scene, seed, ref, method, which in cases:
        t = time.perf_counter()
        est = estimate_depth(scene, views=which, method=method, step_px=args.step_px,
                             max_planes=args.max_planes, refine_iter=args.refine_iter,
                             median_radius=args.median_radius, sweep_scale=args.sweep_scale,
                             coarse_iter=args.coarse_iter, fill_segments=args.fill_segments)
        t = time.perf_counter() - t
        gt, d = scene[ref].depth, est[ref].depth
        tex = textured(scene[ref].image) & np.isfinite(gt)
        seen = tex & _seen_elsewhere(scene, ref)
        surf = tex & surface_textured(scene[ref].image, gt)
        kept = np.isfinite(d) & np.isfinite(gt)
        with np.errstate(invalid="ignore"):
            ok = np.abs(d - gt) / gt < 0.01
        n = tex.sum()
        print(f"{name:<32} {method:<10} {100 * tex.mean():>10.1f} {100 * seen.sum() / n:>7.1f} "
              f"{100 * surf.sum() / n:>7.1f} {100 * kept[tex].mean():>7.1f} "
              f"{100 * ok[tex].mean():>9.1f} {100 * ok[seen].mean():>9.1f} {100 * ok[surf].mean():>9.1f} "
              f"{100 * ok[surf & seen].mean():>9.1f} {100 * ok[kept].mean():>7.1f} {t:>7.1f}")
    print("(textured: 7x7 grey std > 0.02 and finite exact depth; seen: textured pixels whose point is "
          "visible in another view, exact geometry; surface: textured pixels whose own surface is "
          "textured, i.e. the std over the window pixels at the centre's exact depth (within 2 %) is "
          "> 0.02, which leaves out flat surfaces next to a textured one; kept %: of textured; unknown "
          "pixels count as misses; 'handheld' estimates all 7 views, so the consistency check has "
          "every partner)")


def _defaults() -> dict:
    """estimate_depth's own defaults (the benchmark measures them unless told otherwise)."""
    from vibr.stereo import DepthOptions

    opt = DepthOptions()
    keys = ("step_px", "max_planes", "refine_iter", "median_radius", "sweep_scale", "coarse_iter")
    return {k: getattr(opt, k) for k in keys}


def main(argv=None) -> None:
    global DEFAULTS
    DEFAULTS = _defaults()
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("what", nargs="*", default=["synthetic", "cotton", "fountain"],
                   choices=["cotton", "fountain", "synthetic", "temple"])
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--refine", default="st,sweep,sweep+tv")
    p.add_argument("--fountain-scale", type=float, default=0.25)
    p.add_argument("--neighbours", type=int, default=4)
    p.add_argument("--methods", default="gradient,ulr")
    p.add_argument("--step-px", type=float, default=DEFAULTS["step_px"], help="parallax step between planes")
    p.add_argument("--max-planes", type=int, default=DEFAULTS["max_planes"])
    p.add_argument("--refine-iter", type=int, default=DEFAULTS["refine_iter"],
                   help="slanted-plane refinement iterations (0: sweep only)")
    p.add_argument("--median-radius", type=int, default=DEFAULTS["median_radius"],
                   help="weighted median of the planes, window half-size (0: none; default "
                   "estimate_depth's: 9 for MVS, none for light fields)")
    p.add_argument("--synthetic-size", type=int, nargs="+", default=[256, 512],
                   help="synthetic image widths (height 4/5 of it); one table each")
    p.add_argument("--sweep-scale", type=float, default=DEFAULTS["sweep_scale"],
                   help="image scale of the coarse level (sweep and --coarse-iter iterations); 1: none")
    p.add_argument("--coarse-iter", type=int, default=DEFAULTS["coarse_iter"],
                   help="refinement iterations at the coarse level")
    p.add_argument("--fill-segments", action="store_true",
                   help="dense output: segment-plane completion after the consistency check "
                   "(estimate_depth(fill_segments=True))")
    p.add_argument("--no-render", action="store_true")
    p.add_argument("--block-only", action="store_true",
                   help="cotton: only the 3x3-block estimate (time and BadPix/MSE), not the table")
    args = p.parse_args(argv)
    if "synthetic" in args.what:
        bench_synthetic(args)
    if "cotton" in args.what:
        bench_cotton(args)
    if "fountain" in args.what:
        bench_fountain(args)
    if "temple" in args.what:
        bench_temple(args)


if __name__ == "__main__":
    main()
