"""Render time with and without ``uncertainty=True`` (the target: ≤ 1.15×), on
benchmarks/perf/bench_render.py's scene (synthetic 3×3 grid, centre view from its 8 neighbours),
``gradient`` method, the same samples, the two alternated A/B/B/A in one process; prints the
medians, the per-pair ratio and the uncertainty step alone.

    python benchmarks/perf/bench_uncertainty_overhead.py                 # 768², 7 pairs
    python benchmarks/perf/bench_uncertainty_overhead.py --size 512 --repeat 3
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import centre_index, grid_scene  # noqa: E402


def overhead(size=768, repeat=5):
    """Render time with and without ``uncertainty=True`` on bench_render.py's scene
    (synthetic 3×3 grid, centre target from 8 sources), alternating, same samples; medians
    and (min, max) over ``repeat`` pairs after one warm-up pair."""
    from vibr.geometry import compute_samples
    from vibr.render import render_samples

    scene = grid_scene(3, 3, size)
    sources, target = scene.split(centre_index(scene))
    t0 = time.perf_counter()
    S = compute_samples(sources, target.camera)
    t_geo = time.perf_counter() - t0
    ts = {False: [], True: []}
    t_unc = []
    for rep in range(repeat + 1):
        for flag in ((False, True) if rep % 2 == 0 else (True, False)):
            t = time.perf_counter()
            r = render_samples(S, "gradient", uncertainty=flag)
            dt = time.perf_counter() - t
            if rep:
                ts[flag].append(dt)
                if flag:
                    t_unc.append(r.times["uncertainty"])
    med = {k: float(np.median(v)) for k, v in ts.items()}
    ratios = [b / a for a, b in zip(ts[False], ts[True])]
    print(f"# uncertainty overhead: {size}x{size}, {len(sources)} sources, {len(S)} samples, geometry "
          f"{t_geo:.2f} s (once); {repeat} alternating pairs after a warm-up, shared machine")
    print("| | median s | min | max |\n|---|---|---|---|")
    for k, name in ((False, "render_samples, uncertainty=False"), (True, "render_samples, uncertainty=True")):
        print(f"| {name} | {med[k]:.3f} | {min(ts[k]):.3f} | {max(ts[k]):.3f} |")
    print(f"| the uncertainty step alone (times['uncertainty']) | {np.median(t_unc):.3f} | {min(t_unc):.3f} | "
          f"{max(t_unc):.3f} |")
    print(f"ratio with / without per pair: median {np.median(ratios):.3f} (min {min(ratios):.3f}, max "
          f"{max(ratios):.3f}); uncertainty step / render without: {np.median(t_unc) / med[False]:.3f}; "
          f"with geometry counted in the render time: {(med[True] + t_geo) / (med[False] + t_geo):.3f}")
    return {"with": ts[True], "without": ts[False], "step": t_unc, "geometry": t_geo}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=768, help="image side in pixels (default 768)")
    ap.add_argument("--repeat", type=int, default=7, help="alternating pairs after one warm-up pair (default 7)")
    a = ap.parse_args(argv)
    overhead(size=a.size, repeat=a.repeat)


if __name__ == "__main__":
    main()
