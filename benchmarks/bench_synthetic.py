"""Benchmark of the synthetic renderer (vibr.synthetic.render_view).

Prints a table of render times of one view of ``default_world(0)`` (grid centre camera)
for several sizes and supersampling factors: median (and min / max) of ``--runs`` runs.
The first call of the process, which compiles the numba kernels (or loads them from the
on-disk cache), is timed separately and excluded from the medians.

    python3 benchmarks/bench_synthetic.py [--runs 5] [--sizes 128 256 512 768] [--ss 1 2 3] [--cold]

``--cold`` points numba at an empty cache folder so that the first call really compiles.
Times are wall-clock and process CPU time (all threads); on a shared machine the CPU
time is the steadier of the two.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--sizes", type=int, nargs="+", default=[128, 256, 512, 768])
    ap.add_argument("--ss", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--cold", action="store_true", help="compile with an empty numba cache")
    args = ap.parse_args()
    if args.cold:
        import tempfile

        os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="vibr-bench-numba-")

    import numba

    t0 = time.perf_counter()
    from vibr.synthetic import default_world, grid_cameras, make_scene, render_view

    t_import = time.perf_counter() - t0
    t0 = time.perf_counter()
    world = default_world(0)
    world._pack()
    t_world = time.perf_counter() - t0
    t0 = time.perf_counter()
    render_view(world, grid_cameras(1, 1, width=16, height=16)[0], supersample=2)
    t_first = time.perf_counter() - t0
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")

    print(f"vibr.synthetic benchmark: {os.cpu_count()} CPUs, numba {numba.__version__}, "
          f"{numba.get_num_threads()} threads, medians of {args.runs} runs, load average {load:.1f}")
    print(f"import {t_import:.3f} s; default_world (textures + pyramids) {t_world:.3f} s; first render "
          f"call ({'numba compile' if args.cold else 'numba compile or cache load'}, excluded below) "
          f"{t_first:.3f} s")
    print()
    print(f"{'size':>9} {'ss':>3} {'rays':>10} {'median s':>9} {'min s':>8} {'max s':>8} "
          f"{'CPU s':>8} {'Mrays/s':>8}")
    for size in args.sizes:
        cam = grid_cameras(1, 1, width=size, height=size)[0]
        for ss in args.ss:
            ts, cs = [], []
            for _ in range(args.runs):
                c0 = time.process_time()
                t0 = time.perf_counter()
                render_view(world, cam, supersample=ss)
                ts.append(time.perf_counter() - t0)
                cs.append(time.process_time() - c0)
            med = float(np.median(ts))
            rays = size * size * (ss * ss + (1 if ss > 1 else 0))  # + the depth (centre) ray
            print(f"{size:>4}x{size:<4} {ss:>3} {rays:>10d} {med:>9.4f} {min(ts):>8.4f} {max(ts):>8.4f} "
                  f"{np.median(cs):>8.4f} {rays / med / 1e6:>8.2f}")
    print()
    for size, n in ((128, 9), (768, 9)):
        ts = []
        for _ in range(max(1, args.runs if size <= 256 else 3)):
            t0 = time.perf_counter()
            make_scene(width=size, height=size)
            ts.append(time.perf_counter() - t0)
        print(f"make_scene() 3x3 grid {size}x{size}: median {np.median(ts):.3f} s over {len(ts)} runs")


if __name__ == "__main__":
    main()
