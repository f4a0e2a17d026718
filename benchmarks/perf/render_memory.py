"""Memory of a render against vibr.render.checks.render_memory's estimate (docs/reference/errors-and-limits.md), and
the time and memory of a 4K render.

    python3 benchmarks/perf/render_memory.py [SIZE]                 # synthetic grid, SIZE² from 8 views
    /usr/bin/time -v python3 benchmarks/perf/render_memory.py 3840 2160 --once [--json out.json]

``--json FILE`` writes the figures either way (benchmarks/perf/run_all.py reads them).

Default: renders once to warm up, then measures how far the peak resident memory of a
second render rises above the resident memory before it (Linux ru_maxrss), and prints the
estimate. ``--once`` (for large targets): the kernels are warmed up on a 128² scene, then
one render of the W × H target from the 8 sources of the 3 × 3 grid (each rendered at
W × H too), default method; prints its time (geometry + render), the peak resident memory
of the whole process (scene included) and the PSNR against the target's own render.
"""

from __future__ import annotations

import argparse
import gc
import json
import resource
import time

from vibr.render import render
from vibr.render.checks import render_memory
from vibr.synthetic import make_scene


def _rss() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize()


def _peak() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("width", nargs="?", type=int, default=512)
    ap.add_argument("height", nargs="?", type=int)
    ap.add_argument("--once", action="store_true", help="warm up on a small scene, render the big one once")
    ap.add_argument("--json", help="write the figures here")
    a = ap.parse_args()
    W, H = a.width, a.height or a.width
    if a.once:
        s = make_scene("grid", n_views=9, width=128, height=128, seed=1)
        src, tv = s.split(4)
        render(src, tv, "gradient")
        del s, src, tv
        gc.collect()
    t0 = time.perf_counter()
    s = make_scene("grid", n_views=9, width=W, height=H, seed=1)
    t_scene = time.perf_counter() - t0
    src, tv = s.split(4)
    del s
    est = render_memory([v.camera.shape for v in src.views], tv.camera.shape)
    if not a.once:
        render(src, tv, "gradient")  # compile and warm up: the peak below includes this run's
    gc.collect()
    rss0 = _rss()
    t0 = time.perf_counter()
    r = render(src, tv, "gradient")
    t_render = time.perf_counter() - t0
    peak = _peak()
    print(f"{W}x{H} from {len(src)} views: estimate {est / 2**20:.0f} MiB, resident before the render "
          f"{rss0 / 2**20:.0f} MiB, peak {peak / 2**20:.0f} MiB, growth {max(0, peak - rss0) / 2**20:.0f} MiB")
    if a.once:
        from vibr.metrics import psnr

        q = psnr(r.image, tv.image, mask=r.coverage, border=2)
        print(f"scene made in {t_scene:.1f} s; render (geometry + solve) {t_render:.1f} s; "
              f"{r.n_samples} samples; PSNR {q:.2f} dB (covered pixels); peak resident memory of the process "
              f"{peak / 2**30:.2f} GiB")
    if a.json:
        rep = {"width": W, "height": H, "once": a.once, "render_s": t_render, "scene_s": t_scene,
               "samples": r.n_samples, "peak_rss_mb": peak / 2**20, "estimate_mb": est / 2**20,
               "resident_before_mb": rss0 / 2**20, "growth_mb": max(0, peak - rss0) / 2**20, "times": r.times}
        if a.once:
            rep["psnr"] = q
        with open(a.json, "w") as f:
            json.dump(rep, f, indent=2)


if __name__ == "__main__":
    main()
