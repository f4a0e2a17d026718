"""Solver speed: a W×W target from 8 sources of W×W (synthetic 3×3 grid, exact depth).

Plain vs diagonally preconditioned (variable-metric) FISTA on the same energy: per-stage
times (median of --repeat runs), iterations, final energy and PSNR, and the energy-vs-time
trace of the first outer pass.

    python benchmarks/bench_solver.py [--size 768] [--repeat 3] [--method gradient]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=768)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--method", default="gradient")
    ap.add_argument("--layout", default="grid")
    a = ap.parse_args(argv)
    import numba

    from vibr.geometry import compute_samples
    from vibr.metrics import psnr
    from vibr.render import render_samples
    from vibr.synthetic import make_scene

    t0 = time.perf_counter()
    sc = make_scene(a.layout, n_views=9, width=a.size, height=a.size, seed=0)
    ti = 4 if a.layout == "grid" else len(sc) // 2
    tgt = sc.views[ti]
    src = sc.subset([i for i in range(len(sc)) if i != ti])
    print(f"# {a.layout} scene {a.size}x{a.size}, {len(src)} sources, built in {time.perf_counter() - t0:.1f} s; "
          f"numba threads {numba.get_num_threads()}")
    geo = []
    for _ in range(a.repeat):
        t0 = time.perf_counter()
        S = compute_samples(src, tgt.camera)
        geo.append(time.perf_counter() - t0)
    print(f"geometry (compute_samples): median {np.median(geo):.3f} s over {a.repeat}; {len(S)} samples")
    for precond in (False, True):
        rows = []
        for rep in range(a.repeat + 1):  # the first run warms the JIT caches
            trace = []
            t_start = time.perf_counter()
            r = render_samples(S, a.method, precond=precond,
                               callback=lambda o, k, e, t: trace.append((o, k, time.perf_counter() - t_start, e)))
            if rep:
                rows.append(r)
        tt = {k: np.median([r.times[k] for r in rows]) for k in rows[0].times}
        r = rows[-1]
        p = psnr(r.image, tgt.image, mask=r.coverage, border=2)
        print(f"precond={precond}: solve {tt['solve']:.3f} s, total (no geometry) {tt['total']:.3f} s "
              f"[weights {tt['weights']:.3f}, init {tt['init']:.3f}, assembly {tt['assembly']:.3f}] (medians), "
              f"{len(r.energy)} energies, final E {r.energy[-1]:.6g}, PSNR {p:.2f} dB")
        first = [(k, t, e) for o, k, t, e in trace if o == 0]
        sel = first[:: max(1, len(first) // 8)] + first[-1:]
        print("   outer-1 trace (iter, s, E): " + ", ".join(f"({k}, {t:.2f}, {e:.6g})" for k, t, e in sel))


if __name__ == "__main__":
    main()
