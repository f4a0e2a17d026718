"""Rendering speed: a 768×768 view from 8 sources of a synthetic scene.

Prints, as medians over ``--repeat`` runs (after one warm-up run that loads the compiled
kernels):

* the time of each stage (:data:`STAGES`): depth preparation, z-buffer splatting (warps of
  every source pixel's quad), visibility, sample fields (warps, Jacobians, colours,
  gradients of the visible samples), the splat set-up with the coverage pass (the gradient
  term's unit-weight stencils and the initial blend's splat, one pass), the initial blend's
  push–pull, the weights with the colour stencils (one fused pass per outer pass), solve,
  total; each against its own floor, the time its minimal traffic (:func:`stage_traffic`)
  takes at the bandwidth measured in the same run;
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
:func:`vibr.geometry.selection.select_views`) at 512²; and a 100-view scene (10×10 grid) rendered
from its k = 8 best views for the centre target against an 8-view scene (3×3 grid).

    python benchmarks/perf/bench_render.py [--size 768] [--repeat 5] [--scaling] [--json out.json]
    python benchmarks/perf/bench_render.py --kernels [--repeat 5]   # the time of each compiled kernel
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit, prange

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import centre_index, grid_scene  # noqa: E402


@njit(parallel=True, cache=True)
def _triad(a, b, c, s):
    for i in prange(a.shape[0]):
        a[i] = b[i] + s * c[i]


def bandwidth(n_bytes: int = 128 * 2 ** 20, repeat: int = 7) -> float:
    """STREAM triad bandwidth in bytes/s (counts 2 reads + 1 write per element)."""
    n = n_bytes // 4
    # one block above glibc's mmap threshold (vibr._runtime.malloc): mapped and unmapped again, so
    # that the measurement leaves nothing in the heap the renders then use (peak memory)
    buf = np.ones(3 * n, np.float32)
    a, b, c = buf[:n], buf[n:2 * n], buf[2 * n:]
    a[:] = 0.0
    _triad(a, b, c, np.float32(0.5))
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        _triad(a, b, c, np.float32(0.5))
        ts.append(time.perf_counter() - t0)
    return 3 * n * 4 / float(np.median(ts))


def peak_rss_mb() -> float:
    """The process's peak resident memory (MB, 2^20 bytes) since the last
    :func:`reset_peak_rss` (Linux: VmHWM), else since it started (ru_maxrss)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r / 1024 if sys.platform != "darwin" else r / 2 ** 20


def reset_peak_rss() -> None:
    """Start :func:`peak_rss_mb` again from the present resident memory (Linux ≥ 4.0:
    ``/proc/self/clear_refs``), so that the benchmark's own bandwidth buffer, measured
    between runs, does not count as the render's."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def run_once(sources, target, measure_bw=False, **params):
    """One geometry + render pass; returns a dict of stage times and counts (and, with
    ``measure_bw``, the bandwidth measured just before and the solve / floor ratio)."""
    from vibr.geometry import compute_samples
    from vibr.render import render_samples

    bw = bandwidth(repeat=3) if measure_bw else None
    reset_peak_rss()
    t0 = time.perf_counter()
    S = compute_samples(sources, target.camera)
    t_geo = time.perf_counter() - t0
    r = render_samples(S, "gradient", **params)
    total = time.perf_counter() - t0
    g = S.meta["times"]
    out = {
        "depth preparation": g["depth"], "z-buffer (quad warps)": g["zbuffer"],
        "visibility": g["visibility"], "sample fields (warps, Jacobians)": g["assembly"],
        "geometry": t_geo, STAGES[4]: r.times["assembly"], STAGES[5]: r.times["init"],
        STAGES[6]: r.times["weights"], "solve": r.times["solve"], "total": total,
        "iterations": r.iterations, "power iterations": r.power_iterations,
        "samples": len(S), "image": r.image, "coverage": r.coverage, "peak_rss_mb": peak_rss_mb(),
    }
    traffic = stage_traffic(S, sources, target.shape, int(r.params["n_outer"]))
    if bw is not None:
        floor, tr = floor_seconds(out, target.shape, bw)
        traffic["solve"] = tr
        out["bandwidth"] = bw
        out["solve / floor"] = out["solve"] / floor
        for k, b in traffic.items():
            out[k + " / floor"] = out[k] / (b / bw)
    for k, b in traffic.items():
        out[k + " MB moved"] = b / 1e6
    del S
    return out


#: The stages of the table, in order (the render's fused passes named by what they compute).
STAGES = ("depth preparation", "z-buffer (quad warps)", "visibility", "sample fields (warps, Jacobians)",
          "splat set-up + coverage (fused with the blend's splat)", "initial blend (push-pull)",
          "weights + colour stencils (fused, all outer passes)", "solve")


def stage_traffic(S, sources, shape, n_outer):
    """Bytes each stage must read and write at least once (its floor's traffic).

    n_src source pixels, N samples, P target pixels, ``b(S)`` the bytes of one sample
    (the fields of :class:`vibr.geometry.Samples` computed):

    * depth preparation: read the depth, write z, z_x, z_y (float64): n_src (d + 24);
    * z-buffer: read z, z_x, z_y, write the target z-buffer (float64): 24 n_src + 8 P;
    * visibility: read z, z_x, z_y and the z-buffer, write the state (1 byte): 25 n_src + 8 P;
    * sample fields: read z, z_x, z_y, state, colour (12; its gradient is formed from it in
      cache), write the samples: n_src (24 + 1 + 12) + N b(S);
    * splat set-up + coverage: read xy, write the cell (x0, y0 int32, fx, fy float32; no
      row order: the samples come in block order), read it back with ∇v, colour, 1/|det|,
      write 19 planes: N (16 + 16 + 16 + 24 + 12 + 8) + 76 P;
    * initial blend: read the 4 blend planes and the coverage (float64), write 3 planes, the
      pyramid a third more: 4/3 · 40 P;
    * weights + colour stencils, per outer pass: read the cell (16), 1/|det|,
      sigma_z, ∂tau/∂z, colour, write 12 planes: N (16 + b(inv_det) + b(sigma_z) + b(dtau) + 12) + 48 P.
    """
    P = int(shape[0]) * int(shape[1])
    N = len(S)
    n_src = sum(v.depth.size for v in sources.views)
    d = sources.views[0].depth.itemsize
    bS = sum(getattr(S, f).nbytes for f in ("xy", "colour", "grad", "jac", "inv_det", "dtau_dz", "sigma_z",
                                             "view", "src_xy", "X") if getattr(S, f) is not None) / max(N, 1)
    per = lambda f: getattr(S, f).nbytes / max(N, 1)  # noqa: E731
    return {
        STAGES[0]: n_src * (d + 24), STAGES[1]: 24 * n_src + 8 * P, STAGES[2]: 25 * n_src + 8 * P,
        STAGES[3]: n_src * (24 + 1 + 12) + N * bS, STAGES[4]: N * (16 + 16 + 16 + 24 + 12 + 8) + 76 * P,
        STAGES[5]: 4 / 3 * 40 * P,
        STAGES[6]: n_outer * (N * (16 + per("inv_det") + per("sigma_z") + per("dtau_dz") + 12) + 48 * P),
    }


def median_runs(sources, target, repeat, measure_bw=False, all_runs=False, **params):
    run_once(sources, target, **params)  # warm-up: loads the compiled kernels
    runs = []
    for _ in range(repeat):
        if runs:  # only the last run's image is measured: the others' are not kept (peak memory)
            runs[-1] = {k: v for k, v in runs[-1].items() if k not in ("image", "coverage")}
        runs.append(run_once(sources, target, measure_bw, **params))
    keys = [k for k in runs[0] if k not in ("image", "coverage")]
    med = {k: float(np.median([r[k] for r in runs])) for k in keys}
    last = runs[-1]
    if all_runs:
        return med, last, [{k: r[k] for k in keys} for r in runs]
    return med, last


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


def kernel_profile(sources, target, repeat: int) -> list:
    """Where a render's time goes, kernel by kernel: every compiled kernel of vibr
    (numba dispatchers at module level) wrapped with a timer, ``repeat`` renders after a
    warm-up; rows (kernel, ms per render, calls per render), slowest first. Kernels called
    from other kernels count in their caller."""
    import collections
    import importlib
    import pkgutil

    from numba.core.registry import CPUDispatcher

    import vibr
    from vibr.render import render

    tot, calls = collections.Counter(), collections.Counter()
    patched = []

    def timed(f, key):
        def g(*a, **kw):
            t = time.perf_counter()
            try:
                return f(*a, **kw)
            finally:
                tot[key] += time.perf_counter() - t
                calls[key] += 1
        return g

    wrappers = {}
    for info in pkgutil.walk_packages(vibr.__path__, "vibr."):
        if info.name.endswith("__main__") or ".cli" in info.name or ".viewer" in info.name:
            continue
        mod = importlib.import_module(info.name)
        for name, obj in list(vars(mod).items()):
            if isinstance(obj, CPUDispatcher):
                key = f"{obj.py_func.__module__}.{obj.__name__}"
                wrappers.setdefault(id(obj), timed(obj, key))
                patched.append((mod, name, obj))
                setattr(mod, name, wrappers[id(obj)])
    try:
        render(sources, target)  # warm-up
        tot.clear()
        calls.clear()
        t0 = time.perf_counter()
        for _ in range(repeat):
            render(sources, target)
        wall = (time.perf_counter() - t0) / repeat
    finally:
        for mod, name, obj in patched:
            setattr(mod, name, obj)
    rows = [(k, 1e3 * v / repeat, calls[k] / repeat) for k, v in tot.most_common()]
    print(f"\n| kernel | ms per render | calls per render |  (medians not taken: means of {repeat} renders)")
    print("|---|---|---|")
    for k, ms, n in rows:
        if ms >= 1.0:
            print(f"| {k} | {ms:.1f} | {n:.0f} |")
    print(f"| all kernels | {sum(r[1] for r in rows):.1f} | |")
    print(f"| the renders' wall time | {1e3 * wall:.1f} | |")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=768)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--scaling", action="store_true", help="also run the scaling tables")
    ap.add_argument("--many-views-only", action="store_true",
                    help="only the 100-view (k = 8) against 8-view comparison")
    ap.add_argument("--json", help="write all results here")
    ap.add_argument("--kernels", action="store_true",
                    help="only the time of each compiled kernel in a render (--repeat renders)")
    a = ap.parse_args(argv)
    import numba

    from vibr._runtime.malloc import tune_malloc

    tune_malloc()  # as the vibr command does (VIBR_MALLOC=default: glibc's own settings)

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
    if a.kernels:
        scene = grid_scene(3, 3, a.size)
        sources, target = scene.split(centre_index(scene))
        kernel_profile(sources, target.camera, a.repeat)  # a camera: no image metrics
        return
    t0 = time.perf_counter()
    scene = grid_scene(3, 3, a.size)
    ti = centre_index(scene)
    sources, target = scene.split(ti)
    print(f"# synthetic 3x3 grid, {a.size}x{a.size}, target {target.name} from {len(sources)} sources "
          f"(made in {time.perf_counter() - t0:.1f} s); medians of {a.repeat} runs")
    med, last, runs = median_runs(sources, target, a.repeat, measure_bw=True, all_runs=True)
    floor, traffic = floor_seconds(med, target.shape, med["bandwidth"])
    q = {"psnr": psnr(last["image"], target.image, mask=last["coverage"], border=2),
         "dssim": dssim(last["image"], target.image, mask=last["coverage"], border=2)}
    print("\n| stage | median s | min–max s | MB moved (floor traffic) | floor s (this run's bandwidth) | s / floor |")
    print("|---|---|---|---|---|---|")
    for k in STAGES + ("total",):
        ts = [r[k] for r in runs]
        if k + " / floor" in med:
            fl = med[k + " MB moved"] * 1e6 / med["bandwidth"]
            extra = f"{med[k + ' MB moved']:.0f} | {fl:.4f} | {med[k + ' / floor']:.1f} |"
        else:
            extra = " | | |"
        print(f"| {k} | {med[k]:.3f} | {min(ts):.3f}–{max(ts):.3f} | {extra}")
    print(f"\niterations: {med['iterations']:.0f} FISTA + {med['power iterations']:.0f} power; "
          f"{med['samples']:.0f} samples; PSNR {q['psnr']:.2f} dB, DSSIM {q['dssim']:.1f} (covered pixels)")
    # a power iteration is one operator application, 24 of a FISTA iteration's 51 planes
    eq_iters = med["iterations"] + 24 / 51 * med["power iterations"]
    print(f"solve per FISTA iteration (power iterations counted as 24/51 of one, by traffic): "
          f"{1e3 * med['solve'] / max(1.0, eq_iters):.1f} ms")
    print(f"solve traffic floor: {traffic / 1e6:.0f} MB per solve; bandwidth measured before each run "
          f"(median {med['bandwidth'] / 1e9:.1f} GB/s) -> floor {floor:.3f} s; "
          f"solve / floor, median of the per-run ratios: {med['solve / floor']:.1f}x")
    peak = max(r["peak_rss_mb"] for r in runs)
    print(f"peak resident memory during a render (the process's, scene included; highest of the runs): "
          f"{peak:.0f} MB")
    report["main"] = {"size": a.size, "n_sources": len(sources), **med, **q, "floor_s": floor,
                      "traffic_bytes": traffic, "solve_over_floor": med["solve / floor"],
                      "peak_rss_mb": peak, "runs": runs,
                      "total_min": min(r["total"] for r in runs), "total_max": max(r["total"] for r in runs)}
    for k in ("solve", "total", "solve_over_floor", "peak_rss_mb"):
        report[k] = report["main"][k]
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
        from vibr.geometry.selection import select_views

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
