"""Fly-through benchmark: `vibr path interpolate` then `vibr render --path` on fountain.

    python3 benchmarks/perf/bench_path.py [--data ../shared/data] [--scale 0.25] [--frames 60]
                                     [--views 8] [--out /tmp/bench_path] [--hard] [--workers N]

Steps (the depth cache is a fresh folder under --out, so the first render estimates depth):
1. `vibr path interpolate SCENE -o path.json --frames N --scale S` (all 11 cameras);
2. run 1: `vibr render SCENE --path path.json -o run1.mp4 --scale S --views K` (no depth given:
   estimated once, cached): total time, depth time, seconds per frame after the depth;
3. the MP4 decoded back: frame count and size;
4. run 2: the same command on the first 3 frames of the path with --overwrite: time from the
   process start to the start of the frames (depth loaded from the cache);
5. popping: mean absolute change between consecutive frames (grey levels of 255) of run 1,
   max / median, and the change at the frames where the selected set changes;
6. with --hard, the same path rendered with hard view selection (blend 0), for comparison.

``--breakdown CACHE``: where a frame's time goes (``render_frame``'s stage times, medians
over every 6th frame of the path after one warm-up frame, in this process).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]

_DRIVER = r"""
import sys, time, json
t0 = time.perf_counter()
import vibr.paths.flythrough as F
first = []
_orig = F._run_frames  # wrapped, not render_frame: that one is pickled to worker processes
def _rf(*a, **k):
    first.append(time.perf_counter() - t0)
    return _orig(*a, **k)
F._run_frames = _rf
from vibr.cli import main
rc = main(sys.argv[1:])
print("BENCH " + json.dumps({"first_frame_s": first[0] if first else None, "rc": rc}), flush=True)
sys.exit(rc)
"""


def run(cmd, env):
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if p.returncode != 0:
        sys.exit(f"command failed ({p.returncode}): {' '.join(cmd)}\n{p.stderr[-2000:]}")
    return dt, p.stdout + p.stderr


def parse(out):
    info = {}
    m = re.search(r"depth: (\w+) \(([\d.]+) s\)", out)
    if m:
        info["depth_source"], info["depth_s"] = m.group(1), float(m.group(2))
    m = re.search(r"rendered (\d+) frames .* in ([\d.]+) s (.+?), ([\d.]+) s per frame; total ([\d.]+) s", out)
    if m:
        info.update(frames=int(m.group(1)), frames_s=float(m.group(2)), engine=m.group(3),
                    per_frame_s=float(m.group(4)), render_total_s=float(m.group(5)))
    m = re.search(r"video ([\d.]+) s\)", out)
    if m:
        info["video_s"] = float(m.group(1))
    m = re.search(r"BENCH (\{.*\})", out)
    if m:
        info.update(json.loads(m.group(1)))
    return info


def frame_changes(folder, n):
    from vibr.io import read_image

    prev, out = None, []
    for i in range(n):
        img = read_image(Path(folder) / f"frame_{i:05d}.png")
        if prev is not None:
            out.append(float(np.mean(np.abs(img - prev))) * 255.0)
        prev = img
    return np.array(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"))
    ap.add_argument("--scale", type=float, default=0.25)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--views", type=int, default=8)
    ap.add_argument("--out", default="/tmp/bench_path")
    ap.add_argument("--hard", action="store_true", help="also render with hard view selection (blend 0)")
    ap.add_argument("--workers", type=int, default=None,
                    help="passed to vibr render --path (default: none, i.e. its executor auto)")
    ap.add_argument("--ttff-only", metavar="CACHE",
                    help="only step 4, twice, with this cache folder (from an earlier run; the first "
                         "repetition fills the cache of resized views if it is empty)")
    ap.add_argument("--breakdown", metavar="CACHE",
                    help="only the per-frame stage times: frames of the path rendered in this process "
                         "with the depth from this cache folder (from an earlier run)")
    a = ap.parse_args()
    scene = str(Path(a.data) / "strecha_fountain-P11")
    if a.breakdown:
        breakdown(scene, a.breakdown, scale=a.scale, views=a.views, frames=a.frames)
        return
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    cache = out / f"cache-{os.getpid()}"
    env = dict(os.environ, PYTHONPATH=str(REPO / "src"))
    py = sys.executable
    rows = []
    if a.ttff_only:
        short = out / "path_3.json"
        for rep in (1, 2):
            dt2, o2 = run([py, "-c", _DRIVER, "render", scene, "--path", str(short), "-o",
                           str(out / "run2_frames"), "--overwrite", "--scale", str(a.scale), "--views",
                           str(a.views), "--cache-dir", a.ttff_only, "-q"], env)
            i2 = parse(o2)
            print(f"| run 2.{rep} (cached depth): process start to frames start | "
                  f"{i2.get('first_frame_s', float('nan')):.1f} s (depth: {i2.get('depth_source')}, "
                  f"{i2.get('depth_s', float('nan')):.2f} s; whole run {dt2:.1f} s) |")
        return

    path = out / "fountain_path.json"
    dt, _ = run([py, "-m", "vibr", "path", "interpolate", scene, "-o", str(path), "--frames", str(a.frames),
                 "--scale", str(a.scale)], env)
    rows.append(("vibr path interpolate (11 cameras, %d frames)" % a.frames, f"{dt:.1f} s"))

    common = ["--scale", str(a.scale), "--views", str(a.views), "--cache-dir", str(cache), "-q"]
    common += [] if a.workers is None else ["--workers", str(a.workers)]
    v1 = out / "run1.mp4"
    dt1, o1 = run([py, "-c", _DRIVER, "render", scene, "--path", str(path), "-o", str(v1),
                   "--frames-dir", str(out / "run1_frames"), "--overwrite"] + common, env)
    i1 = parse(o1)
    amort = (dt1 - i1.get("depth_s", 0.0)) / a.frames
    rows += [("run 1: vibr render --path, total (process)", f"{dt1:.1f} s"),
             ("run 1: one-off depth estimation", f"{i1.get('depth_s', float('nan')):.1f} s ({i1.get('depth_source')})"),
             ("run 1: frames only, per frame", f"{i1.get('per_frame_s', float('nan')):.2f} s ({i1.get('engine')})"),
             ("run 1: video encoding (PNGs read back, H.264)", f"{i1.get('video_s', float('nan')):.1f} s"),
             ("run 1: (total - depth) / frames, amortised", f"{amort:.2f} s"),
             ("run 1: process start to frames start", f"{i1.get('first_frame_s', float('nan')):.1f} s")]

    sys.path.insert(0, str(REPO / "src"))
    from vibr.io.video import read_video_info
    from vibr.paths.camera_path import read_camera_path, write_camera_path

    n, w, h, fps = read_video_info(v1)
    rows.append(("MP4 decoded back", f"{n} frames, {w}x{h}, {fps:g} fps"))

    short = out / "path_3.json"
    p = read_camera_path(path)
    write_camera_path(short, p.cameras[:3], fps=p.fps)
    dt2, o2 = run([py, "-c", _DRIVER, "render", scene, "--path", str(short), "-o", str(out / "run2_frames"),
                   "--overwrite"] + common, env)
    i2 = parse(o2)
    rows.append(("run 2 (cached depth): process start to frames start",
                 f"{i2.get('first_frame_s', float('nan')):.1f} s (depth: {i2.get('depth_source')}, "
                 f"{i2.get('depth_s', float('nan')):.2f} s)"))

    ch = frame_changes(out / "run1_frames", a.frames)
    med = float(np.median(ch))
    rows.append(("frame-to-frame mean |change| (0-255): median / max",
                 f"{med:.2f} / {ch.max():.2f} (max/median {ch.max() / med:.2f})"))

    # where the selected set changes (weights recomputed from the cached depth)
    from vibr.io import load_scene
    from vibr.paths.flythrough import _source_points, view_weights
    from vibr.stereo.cache import scene_with_depth

    sc = scene_with_depth(load_scene(scene, scale=a.scale), cache_dir=cache)
    pts = _source_points(sc)
    sets = []
    for cam in p.cameras:
        wts = view_weights(sc, cam, a.views, view_points=pts)
        sets.append(frozenset(np.flatnonzero(wts > 0)))
    at = [i for i in range(1, len(sets)) if sets[i] != sets[i - 1]]
    if at:
        at_ch = ch[np.array(at) - 1]
        rows.append(("change at the %d set changes: max (ratio to median)" % len(at),
                     f"{at_ch.max():.2f} ({at_ch.max() / med:.2f})"))
    if a.hard:
        from vibr.paths.flythrough import render_path

        t0 = time.perf_counter()
        render_path(sc, p, out / "hard_frames", n_views=a.views, blend=0.0, overwrite=True,
                    cache_dir=cache, progress=False)
        chh = frame_changes(out / "hard_frames", a.frames)
        medh = float(np.median(chh))
        rows.append(("hard selection (blend 0): median / max (max/median)",
                     f"{medh:.2f} / {chh.max():.2f} ({chh.max() / medh:.2f}), {time.perf_counter() - t0:.0f} s"))
        if at:
            rows.append(("hard selection: change at the set changes, max (ratio)",
                         f"{chh[np.array(at) - 1].max():.2f} ({chh[np.array(at) - 1].max() / medh:.2f})"))
    np.savetxt(out / "changes.txt", ch, fmt="%.4f")
    print(f"\nfountain-P11 at scale {a.scale} ({w}x{h}), {a.frames} frames, --views {a.views}, "
          f"{os.cpu_count()} cores, --workers {a.workers or 'auto'}, load average at the end "
          f"{os.getloadavg()[0]:.2f}\n")
    print("| measure | value |\n|---|---|")
    for k, v in rows:
        print(f"| {k} | {v} |")



def ab_prepared(scene_dir, cache, scale=0.25, views=8, n=6, frames=60):
    """Per-frame time with and without the per-source depth slopes prepared once
    (alternating frames A/B, medians): `python3 -c 'import bench_path as b; b.ab_prepared(...)'`."""
    import tempfile

    from vibr.io import load_scene
    from vibr.paths.camera_path import interpolate
    from vibr.paths.flythrough import FrameContext, prepare_sources, render_frame
    from vibr.stereo.cache import scene_with_depth

    sc = scene_with_depth(load_scene(scene_dir, scale=scale), cache_dir=cache)
    p = interpolate(sc, n_frames=frames)
    tmp = tempfile.mkdtemp()
    ctx = FrameContext(sc, p.cameras, tmp, n_views=views, overwrite=True)
    t_prep = time.perf_counter()
    prepare_sources(ctx, cache_depth=True)
    t_prep = time.perf_counter() - t_prep
    with_cache = dict(ctx.prepared)
    times = {"prepared once": [], "per frame": []}
    render_frame(ctx, 0)  # warm up
    for k in range(n):
        for mode in (("prepared once", "per frame") if k % 2 == 0 else ("per frame", "prepared once")):
            ctx.prepared = with_cache if mode == "prepared once" else {}
            i = 1 + (k * 7) % (frames - 1)
            times[mode].append(render_frame(ctx, i)["seconds"])
    print(f"preparing all {len(sc)} sources once: {t_prep:.3f} s")
    for mode, t in times.items():
        print(f"{mode}: median {np.median(t):.3f} s per frame (min {min(t):.3f}, max {max(t):.3f}, n={len(t)})")


def breakdown(scene_dir, cache, scale=0.25, views=8, frames=60, step=6):
    """Median stage times of :func:`vibr.paths.flythrough.render_frame` over frames 1, 1+step, ..."""
    import tempfile

    sys.path.insert(0, str(REPO / "src"))
    from vibr.paths.camera_path import interpolate
    from vibr.paths.flythrough import FrameContext, prepare_sources, render_frame
    from vibr.pipeline import load_scene_cached
    from vibr.stereo.cache import scene_with_depth

    t0 = time.perf_counter()
    sc = scene_with_depth(load_scene_cached(scene_dir, scale=scale, cache_dir=cache), cache_dir=cache)
    t_load = time.perf_counter() - t0
    p = interpolate(sc, n_frames=frames)
    ctx = FrameContext(sc, p.cameras, tempfile.mkdtemp(), n_views=views, overwrite=True)
    t0 = time.perf_counter()
    prepare_sources(ctx)
    t_prep = time.perf_counter() - t0
    t0 = time.perf_counter()
    render_frame(ctx, 0)
    t_first = time.perf_counter() - t0
    rs = [render_frame(ctx, i) for i in range(1, frames, step)]
    print(f"scene + depth from the caches {t_load:.2f} s, per-source preparation {t_prep:.2f} s, "
          f"first frame (kernels loaded) {t_first:.2f} s; {len(rs)} frames, load average "
          f"{os.getloadavg()[0]:.1f}\n")
    print("| stage | median s per frame | share |\n|---|---|---|")
    tot = float(np.median([r["seconds"] for r in rs]))
    for k in rs[0]["times"]:
        m = float(np.median([r["times"].get(k, 0.0) for r in rs]))
        print(f"| {k} | {m:.3f} | {100 * m / tot:.0f} % |")
    print(f"| **frame** | {tot:.3f} | |")
    print(f"\nsamples per frame: median {np.median([r['samples'] for r in rs]):.0f}; iterations: "
          f"{[r['iterations'] for r in rs]}; sources: {[len(r['views']) for r in rs]}")


if __name__ == "__main__":
    main()
