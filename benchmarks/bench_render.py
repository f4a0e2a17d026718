"""Rendering speed: a 768×768 view from 8 sources of a synthetic scene (issue 7).

Prints, as medians over ``--repeat`` runs (after one warm-up run that loads the compiled
kernels):

* the time of each stage: depth preparation, z-buffer splatting (warps of every source
  pixel's quad), visibility, sample fields (warps, Jacobians, colours, gradients of the
  visible samples), weights, initial blend (+ push–pull), operator assembly, solve, total;
* the iteration counts (FISTA iterations and power iterations for the step size);
* the peak resident memory of the process;
* the memory bandwidth of the machine, measured in the same run (STREAM triad
  ``a = b + s·c`` on 3 × 128 MiB float32 arrays, compiled, all threads) just before each
  run, and the *floor*: the time the solve's minimal memory traffic would take at that
  bandwidth; the ratio solve / floor is taken per run and its median reported, so that it
  holds on a noisy machine.

Minimal traffic of the solve, in image planes of H·W float32 (what any implementation of
the same iterations must read or write once): one application of the normal operator
``H = alpha·A + gamma·DᵀA_gD`` reads the two 9-point stencils and the 3-channel input and
writes the 3-channel output (24 planes); a FISTA iteration is one such application plus
one dual step of the TV prox (reads the image and the 6-plane dual, writes both: 18) and
the momentum extrapolation (reads two iterates, writes one: 9), 51 planes. The power
iterations that set the step size are counted as operator applications.

Then a scaling table (``--scaling``): target sizes 256², 512², 768², 1536² from 8 sources,
and 2, 4, 8, 16 source views (the k nearest of a 5×5 grid, chosen by
:func:`vibr.selection.select_views`) at 512²; and a 100-view scene (10×10 grid) rendered
from its k = 8 best views for the centre target against an 8-view scene (3×3 grid).

    python benchmarks/bench_render.py [--size 768] [--repeat 5] [--scaling] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import sys
import time

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True)
def _triad(a, b, c, s):
    for i in prange(a.shape[0]):
        a[i] = b[i] + s * c[i]


def bandwidth(n_bytes: int = 128 * 2 ** 20, repeat: int = 7) -> float:
    """STREAM triad bandwidth in bytes/s (counts 2 reads + 1 write per element)."""
    n = n_bytes // 4
    a = np.zeros(n, np.float32)
    b = np.ones(n, np.float32)
    c = np.ones(n, np.float32)
    _triad(a, b, c, np.float32(0.5))
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        _triad(a, b, c, np.float32(0.5))
        ts.append(time.perf_counter() - t0)
    return 3 * n * 4 / float(np.median(ts))


def peak_rss_mb() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r / 1024 if sys.platform != "darwin" else r / 2 ** 20


def grid_scene(rows: int, cols: int, size: int, seed: int = 0):
    from vibr.synthetic import make_scene

    return make_scene("grid", width=size, height=size, seed=seed, grid=(rows, cols))


def centre_index(scene) -> int:
    r, c = scene.grid
    return (r // 2) * c + c // 2


def run_once(sources, target, measure_bw=False, **params):
    """One geometry + render pass; returns a dict of stage times and counts (and, with
    ``measure_bw``, the bandwidth measured just before and the solve / floor ratio)."""
    from vibr.geometry import compute_samples
    from vibr.render import render_samples

    bw = bandwidth(repeat=3) if measure_bw else None
    t0 = time.perf_counter()
    S = compute_samples(sources, target.camera)
    t_geo = time.perf_counter() - t0
    r = render_samples(S, "gradient", **params)
    total = time.perf_counter() - t0
    g = S.meta["times"]
    n_iter = len(r.energy) - len(r.outer)
    out = {
        "depth preparation": g["depth"], "z-buffer (quad warps)": g["zbuffer"],
        "visibility": g["visibility"], "sample fields (warps, Jacobians)": g["assembly"],
        "geometry": t_geo, "weights": r.times["weights"], "initial blend": r.times["init"],
        "operator assembly": r.times["assembly"], "solve": r.times["solve"], "total": total,
        "iterations": r.iterations, "power iterations": r.power_iterations,
        "samples": len(S), "image": r.image, "coverage": r.coverage,
    }
    if bw is not None:
        floor, _ = floor_seconds(out, target.shape, bw)
        out["bandwidth"] = bw
        out["solve / floor"] = out["solve"] / floor
    return out


def median_runs(sources, target, repeat, measure_bw=False, **params):
    run_once(sources, target, **params)  # warm-up: loads the compiled kernels
    runs = [run_once(sources, target, measure_bw, **params) for _ in range(repeat)]
    keys = [k for k in runs[0] if k not in ("image", "coverage")]
    med = {k: float(np.median([r[k] for r in runs])) for k in keys}
    return med, runs[-1]


def floor_seconds(med, shape, bw):
    H, W = shape
    plane = H * W * 4
    traffic = (51 * med["iterations"] + 24 * med["power iterations"]) * plane
    return traffic / bw, traffic


def many_views(repeat):
    """A 100-view scene (10×10 grid) rendered from its k = 8 best views for a central
    target, against the 9-view scene made of that target and its 8 grid neighbours (the
    same cameras and images), 512², selection included in the time."""
    from vibr.pipeline import prepare

    big = grid_scene(10, 10, 512)
    tname = big.views[centre_index(big)].name
    r, c = big.meta["grid_pos"][tname]
    inv = {rc: n for n, rc in big.meta["grid_pos"].items()}
    small = big.subset([inv[(r + dr, c + dc)] for dr in (-1, 0, 1) for dc in (-1, 0, 1)])
    cases = (("8-view scene (the target's 3×3 block)", small), ("100-view scene, k=8", big))
    ts = {name: [] for name, _ in cases}
    for rep in range(max(2, repeat // 2) + 1):
        for name, sc in cases:  # interleaved, so that drifts of a shared machine hit both
            t0 = time.perf_counter()
            src, tg = prepare(sc, tname, n_views=8)
            run_once(src, tg)
            if rep:
                ts[name].append(time.perf_counter() - t0)
    res = {name: float(np.median(t)) for name, t in ts.items()}
    print("\n| scene (512², centre target) | views used | render s (selection + geometry + solve) |")
    print("|---|---|---|")
    for name, t in res.items():
        print(f"| {name} | 8 | {t:.3f} |")
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=768)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--scaling", action="store_true", help="also run the scaling tables")
    ap.add_argument("--many-views-only", action="store_true",
                    help="only the 100-view (k = 8) against 8-view comparison")
    ap.add_argument("--json", help="write all results here")
    a = ap.parse_args(argv)
    import numba

    from vibr.metrics import dssim, psnr

    report = {"machine": {"cpu": platform.processor() or platform.machine(), "python": platform.python_version(),
                          "numba_threads": numba.get_num_threads()}}
    bw = bandwidth()
    report["bandwidth_GBps"] = bw / 1e9
    print(f"# vibr render benchmark: numba threads {numba.get_num_threads()}, "
          f"memory bandwidth (STREAM triad, this run) {bw / 1e9:.1f} GB/s")

    if a.many_views_only:
        report["many_views"] = many_views(a.repeat)
        return
    t0 = time.perf_counter()
    scene = grid_scene(3, 3, a.size)
    ti = centre_index(scene)
    sources, target = scene.split(ti)
    print(f"# synthetic 3x3 grid, {a.size}x{a.size}, target {target.name} from {len(sources)} sources "
          f"(made in {time.perf_counter() - t0:.1f} s); medians of {a.repeat} runs")
    med, last = median_runs(sources, target, a.repeat, measure_bw=True)
    floor, traffic = floor_seconds(med, target.shape, med["bandwidth"])
    q = {"psnr": psnr(last["image"], target.image, mask=last["coverage"], border=2),
         "dssim": dssim(last["image"], target.image, mask=last["coverage"], border=2)}
    print("\n| stage | median s |\n|---|---|")
    for k in ("depth preparation", "z-buffer (quad warps)", "visibility", "sample fields (warps, Jacobians)",
              "weights", "initial blend", "operator assembly", "solve", "total"):
        print(f"| {k} | {med[k]:.3f} |")
    print(f"\niterations: {med['iterations']:.0f} FISTA + {med['power iterations']:.0f} power; "
          f"{med['samples']:.0f} samples; PSNR {q['psnr']:.2f} dB, DSSIM {q['dssim']:.1f} (covered pixels)")
    # a power iteration is one operator application, 24 of a FISTA iteration's 51 planes
    eq_iters = med["iterations"] + 24 / 51 * med["power iterations"]
    print(f"solve per FISTA iteration (power iterations counted as 24/51 of one, by traffic): "
          f"{1e3 * med['solve'] / max(1.0, eq_iters):.1f} ms")
    print(f"solve traffic floor: {traffic / 1e6:.0f} MB per solve; bandwidth measured before each run "
          f"(median {med['bandwidth'] / 1e9:.1f} GB/s) -> floor {floor:.3f} s; "
          f"solve / floor, median of the per-run ratios: {med['solve / floor']:.1f}x")
    print(f"peak resident memory: {peak_rss_mb():.0f} MB")
    report["main"] = {"size": a.size, "n_sources": len(sources), **med, **q, "floor_s": floor,
                      "traffic_bytes": traffic, "solve_over_floor": med["solve / floor"],
                      "peak_rss_MB": peak_rss_mb()}
    del scene, sources, target, last

    if a.scaling:
        rows = []
        print("\n| target | sources | samples | geometry s | solve s | total s | total / (px·views) vs 512², 8 views |")
        print("|---|---|---|---|---|---|---|")
        ref = None
        for size in (256, 512, 768, 1536):
            sc = grid_scene(3, 3, size)
            src, tg = sc.split(centre_index(sc))
            m, _ = median_runs(src, tg, max(1, a.repeat // 2))
            rows.append({"size": size, "views": 8, **m})
            del sc, src, tg
        sc = grid_scene(5, 5, 512)
        from vibr.selection import select_views

        src_all, tg = sc.split(centre_index(sc))
        for k in (2, 4, 8, 16):
            src = src_all.subset(select_views(src_all, tg.camera, k))
            m, _ = median_runs(src, tg, max(1, a.repeat // 2))
            rows.append({"size": 512, "views": k, **m})
        del sc, src_all, src, tg
        ref = next(r for r in rows if r["size"] == 512 and r["views"] == 8)
        for r in rows:
            unit = r["total"] / (r["size"] ** 2 * r["views"])
            unit0 = ref["total"] / (512 ** 2 * 8)
            print(f"| {r['size']}² | {r['views']} | {r['samples']:.0f} | {r['geometry']:.3f} | {r['solve']:.3f} | "
                  f"{r['total']:.3f} | {unit / unit0:.2f} |")
        report["scaling"] = rows

        report["many_views"] = many_views(a.repeat)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(report, f, indent=2, default=float)
        print(f"wrote {a.json}")


if __name__ == "__main__":
    main()
