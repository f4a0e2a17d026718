"""Benchmark of the geometry stage: 8 source views → Samples for one target.

Prints a per-stage table (median of ``--runs`` runs, after one warm-up run that also
compiles/loads the numba kernels): depth preparation (slopes), z-buffer splatting,
visibility (warp + test), sample assembly (warp, Jacobians, weights, colours, gradients,
world points), total. Scene: the synthetic arc layout (``vibr.synthetic.make_scene``),
9 views, view 4 is the target. Not a test; never run by CI.

    python3 benchmarks/bench_geometry.py --size 768 --runs 7
"""

from __future__ import annotations

import argparse
import os
import time

import numba
import numpy as np

from vibr import synthetic
from vibr.geometry import compute_samples


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=768)
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--layout", default="arc", choices=["arc", "grid", "free"])
    args = ap.parse_args()

    t0 = time.perf_counter()
    scene = synthetic.make_scene(args.layout, n_views=9, width=args.size, height=args.size,
                                 supersample=1)
    t_scene = time.perf_counter() - t0
    sources, target = scene.split(4)
    t0 = time.perf_counter()
    compute_samples(sources, target.camera)  # warm-up (numba cache load / compile)
    t_warm = time.perf_counter() - t0

    load0 = os.getloadavg()[0]
    stages = ["depth", "zbuffer", "visibility", "assembly"]
    rec = {k: [] for k in stages + ["total", "cpu"]}
    rec_cpu = {k: [] for k in stages}
    n = 0
    for _ in range(args.runs):
        t0 = time.perf_counter()
        c0 = time.process_time()
        s = compute_samples(sources, target.camera)
        rec["total"].append(time.perf_counter() - t0)
        rec["cpu"].append(time.process_time() - c0)
        for k in stages:
            rec[k].append(s.meta["times"][k])
            rec_cpu[k].append(s.meta["cpu_times"][k])
        n = len(s)
        del s
    print(f"geometry stage: {len(sources)} sources {args.size}x{args.size} -> target "
          f"{target.camera.width}x{target.camera.height}, layout {args.layout}, {n} samples")
    print(f"numba threads {numba.get_num_threads()}, cpus {os.cpu_count()}, "
          f"scene render {t_scene:.1f} s, warm-up run {t_warm:.2f} s, {args.runs} timed runs")
    names = {"depth": "depth prep (slopes)", "zbuffer": "z-buffer splat",
             "visibility": "warp + visibility", "assembly": "sample assembly (Jacobians)",
             "total": "total (wall)", "cpu": "total CPU time (all threads)"}
    print(f"load average (1 min) before / after the runs: {load0:.2f} / {os.getloadavg()[0]:.2f}")
    print(f"{'stage':<30}{'median s':>10}{'min s':>10}{'max s':>10}{'median CPU s':>14}")
    for k in stages + ["total", "cpu"]:
        a = np.array(rec[k])
        c = f"{np.median(rec_cpu[k]):>14.3f}" if k in rec_cpu else ""
        print(f"{names[k]:<30}{np.median(a):>10.3f}{a.min():>10.3f}{a.max():>10.3f}{c}")


if __name__ == "__main__":
    main()
