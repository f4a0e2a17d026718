"""Calibration benchmark on Strecha fountain-P11.

1. ``vibr.calib.colmap.calibrate`` on the scene's ``images/`` only (11 photos, 3072×2048),
   resized by ``--scale`` (default 0.5 → 1536×1024): registration count, per-stage times,
   and per-view rotation / centre errors after a similarity alignment to the ground-truth
   cameras (``gt_dense_cameras``, loaded by ``vibr.io.load_scene``), for both alignments
   of :func:`vibr.calib.colmap.pose_errors` (fitted to the poses, and to the centres only).
2. ``--e2e``: the end-to-end path calibrate → ``vibr.stereo.estimate_depth`` →
   ``vibr.render.render`` of view ``--target`` (default 0005) from the others, next to the
   same with the ground-truth cameras; both at ``--e2e-scale`` of the 1536×1024 scenes.
   PSNR is against each path's own held-out photo (the calibrated one is undistorted and
   cropped by COLMAP), over the rendered pixels covered by the sources.

SfM is run once (not a median: it takes ~1 min on 2 shared cores); times are wall-clock on
a shared machine and noisy.

    python benchmarks/perf/bench_calibrate.py [--data ../shared/data] [--scale 0.5] [--e2e]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"))
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--out", default="/tmp/vibr_bench_calibrate")
    ap.add_argument("--reuse", action="store_true", help="reuse OUT/scene from an earlier run")
    ap.add_argument("--e2e", action="store_true", help="also calibrate → depth → render vs ground truth")
    ap.add_argument("--target", default="0005")
    ap.add_argument("--e2e-scale", type=float, default=0.5)
    ap.add_argument("--method", default="gradient")
    ap.add_argument("--camera-model", default="SIMPLE_RADIAL")
    ap.add_argument("--e2e-only-calibrated", action="store_true", help="skip the ground-truth e2e path")
    args = ap.parse_args(argv)

    from vibr.calib.colmap import calibrate, pose_errors
    from vibr.io import load_scene

    fountain = Path(args.data) / "strecha_fountain-P11"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene_dir = out / "scene"
    if not (args.reuse and scene_dir.exists()):
        t0 = time.perf_counter()
        calibrate(fountain / "images", scene_dir, overwrite=True, scale=args.scale, work_dir=out / "work",
                  camera_model=args.camera_model)
        total = time.perf_counter() - t0
        info = json.loads((scene_dir / "calibration.json").read_text())
        info["total_s"] = total
        (out / "timing.json").write_text(json.dumps(info, indent=2))
    info = json.loads((out / "timing.json").read_text())
    est = load_scene(scene_dir)
    gt = load_scene(fountain, scale=args.scale)
    ref = {v.name: v.camera for v in gt.views}
    names = [n for n in est.names if n in ref]
    print(f"fountain-P11 images at scale {args.scale}: {gt.views[0].camera.width}x{gt.views[0].camera.height}")
    print(f"registered {len(info['registered'])}/{len(info['registered']) + len(info['unregistered'])}"
          f" (not registered: {info['unregistered'] or 'none'}), {info['num_points']} sparse points,"
          f" mean reprojection error {info['mean_reprojection_error_px']:.3f} px, principal point "
          f"{info.get('principal_point', '?')}")
    print("time (s, one run): " + ", ".join(f"{k} {v:.1f}" for k, v in info["times_s"].items())
          + f", total incl. writing {info['total_s']:.1f}")
    errs = {a: pose_errors([est[n].camera for n in names], [ref[n] for n in names], align=a)
            for a in ("poses", "centres")}
    print(f"baseline span (GT) {errs['poses']['span']:.3f} m")
    print(
        f"{'view':>6} {'rot° (pose-fit)':>16} {'centre % (pose-fit)':>20} {'rot° (centre-fit)':>18} "
        f"{'centre % (centre-fit)':>22}"
    )
    for i, n in enumerate(names):
        print(
            f"{n:>6} {errs['poses']['rot_deg'][i]:>16.4f} {100 * errs['poses']['centre_rel'][i]:>20.4f}"
            f" {errs['centres']['rot_deg'][i]:>18.4f} {100 * errs['centres']['centre_rel'][i]:>22.4f}"
        )
    for a, e in errs.items():
        print(f"max ({a}-fit): rotation {e['rot_deg'].max():.4f}°, centre {100 * e['centre_rel'].max():.4f} % of span")
    f_est = est.views[0].camera.K
    f_ref = ref[names[0]].K
    print(
        f"K calibrated (undistorted {est.views[0].camera.width}x{est.views[0].camera.height}): "
        f"f {f_est[0, 0]:.2f}, c ({f_est[0, 2]:.2f}, {f_est[1, 2]:.2f}); GT: f ({f_ref[0, 0]:.2f}, {f_ref[1, 1]:.2f}),"
        f" c ({f_ref[0, 2]:.2f}, {f_ref[1, 2]:.2f})"
    )
    sys.stdout.flush()

    if args.e2e:
        from vibr.metrics import psnr
        from vibr.render import render
        from vibr.stereo import estimate_depth

        paths = [("calibrated", scene_dir, args.e2e_scale), ("ground truth", fountain, args.scale * args.e2e_scale)]
        for label, path, scale in paths[: 1 if args.e2e_only_calibrated else 2]:
            sc = load_scene(path, scale=scale)
            t0 = time.perf_counter()
            ti = sc.index(args.target)
            sc = estimate_depth(sc, views=[i for i in range(len(sc)) if i != ti], exclude=[ti])
            t_depth = time.perf_counter() - t0
            sources, target = sc.split(ti)
            t0 = time.perf_counter()
            res = render(sources, target, method=args.method)
            t_render = time.perf_counter() - t0
            cov = res.coverage
            p_cov = psnr(res.image, target.image, mask=cov, border=2)
            p_all = psnr(res.image, target.image, border=2)
            print(
                f"e2e {label:>12}: {target.camera.width}x{target.camera.height}, view {target.name} from "
                f"{len(sources)}; PSNR {p_cov:.2f} dB on covered pixels ({100 * cov.mean():.1f} %), "
                f"{p_all:.2f} dB on all; depth {t_depth:.0f} s, render {t_render:.0f} s"
            )
            sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
