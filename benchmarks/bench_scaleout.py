"""Wall time of a leave-one-out evaluation, serial vs --workers N vs --dask local, and whether
the engines agree (every metric of every view; ULR to the last bit, the variational methods
to 1e-6 dB, docs/SCALE.md).

    python benchmarks/bench_scaleout.py                      # synthetic 9-view grid, 3 rounds
    python benchmarks/bench_scaleout.py --scene ../shared/data/strecha_fountain-P11 \\
        --scale 0.25 --views 6 --depth estimated --targets 0004,0005,0006,0007 --rounds 1

The engines alternate within each round (the machine is shared: compare within a run);
the table gives the median and range of the wall times. Per-view reports go to a
temporary folder and are removed (a rerun must recompute, not skip).
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path


def main(argv=None):
    from vibr.evaluate import settings_grid
    from vibr.evaluate_all import evaluate_all, resolve_targets
    from vibr.io import load_scene, save_scene

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", help="scene folder (default: a synthetic 9-view grid, 96x80)")
    ap.add_argument("--targets", default="all")
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--views", type=int, default=None)
    ap.add_argument("--depth", default="auto")
    ap.add_argument("--method", default="ulr,gradient")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)

    tmp = Path(tempfile.mkdtemp(prefix="bench_scaleout_"))
    try:
        scene_path = args.scene
        if scene_path is None:
            from vibr.synthetic import make_scene

            scene_path = tmp / "grid"
            save_scene(make_scene("grid", n_views=9, width=96, height=80, seed=3), scene_path)
        scene = load_scene(scene_path, scale=args.scale)
        targets = resolve_targets(scene, args.targets)
        settings = settings_grid([m for m in args.method.split(",") if m], gammas=(1.0,))
        engines = {"serial": None, f"--workers {args.workers}": args.workers, "--dask local": "local"}
        times = {k: [] for k in engines}
        reports = {}
        for r in range(args.rounds):
            for name, ex in engines.items():
                out = tmp / f"views_{r}_{len(times[name])}_{name.replace(' ', '').replace('-', '')}"
                t0 = time.perf_counter()
                reports[name] = evaluate_all(scene_path, targets, settings, views_dir=out, scale=args.scale,
                                             executor=ex, depth=args.depth, n_views=args.views)
                times[name].append(time.perf_counter() - t0)
                shutil.rmtree(out)
                print(f"round {r + 1} {name}: {times[name][-1]:.1f} s", file=sys.stderr, flush=True)
        ref = reports["serial"]
        print(f"{len(targets)} targets, {len(settings)} settings, {args.rounds} round(s), engines alternating")
        print(f"{'engine':<14} {'median s':>9} {'min s':>7} {'max s':>7} {'vs serial':>9}  max |dPSNR| dB")
        med0 = statistics.median(times["serial"])
        for name in engines:
            d = max(abs(x["psnr"] - y["psnr"]) for t in targets
                    for x, y in zip(reports[name]["per_view"][t]["results"], ref["per_view"][t]["results"]))
            m = statistics.median(times[name])
            print(f"{name:<14} {m:>9.1f} {min(times[name]):>7.1f} {max(times[name]):>7.1f} "
                  f"{m / med0:>8.2f}x  {d:.2e}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
