"""Scale-out benchmark: the same job serially, with --workers N and with --dask local;
wall times, and whether the engines give the same output (docs/explanation/scale-out.md).

Fly-through (default): the fountain path of docs/explanation/flythrough.md (`vibr path interpolate`
through the 11 cameras, 60 frames, 768x512 at --scale 0.25), rendered by
`vibr render SCENE --path path.json -o DIR --views 8` with each engine, each run a fresh
process (scene load, numba's cached kernels, worker start-up all counted). The sources'
depth is estimated once, before the timed runs, into a depth cache that every run reads
(`--cache-dir`): each run loads it in the driver, prepares the sources once and sends them
once to each worker (docs/explanation/scale-out.md). The PNG frames of every run must be byte-identical
to the first serial run's (exit status 1 otherwise).

    python3 benchmarks/perf/bench_scaleout.py                      # 60 frames, 3 engines, 2 rounds
    python3 benchmarks/perf/bench_scaleout.py --frames 4 --scale 0.125 --rounds 1   # a quick check

Leave-one-out (--loo): `vibr.eval.leave_one_out.evaluate_all` over --targets with each engine,
in this process; per-view reports must agree bit for bit.

    python3 benchmarks/perf/bench_scaleout.py --loo                # synthetic 9-view grid
    python3 benchmarks/perf/bench_scaleout.py --loo --scene ../shared/data/strecha_fountain-P11 \\
        --scale 0.25 --views 6 --depth estimated --targets 0004,0005 --rounds 1

The engines alternate within each round, and each round starts with a different engine
(the machine may be shared: compare within a run); the table gives median and range.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def _engines(workers: int) -> dict:
    # serial is --workers 1: without a flag `vibr render --path` picks its engine itself (auto)
    return {"serial": ["--workers", "1"], f"--workers {workers}": ["--workers", str(workers)],
            "--dask local": ["--dask", "local"]}


def _rotated(names: list, r: int) -> list:
    k = r % len(names)
    return names[k:] + names[:k]


def _run(cmd, env) -> tuple[float, str]:
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if p.returncode != 0:
        sys.exit(f"command failed ({p.returncode}): {' '.join(cmd)}\n{p.stderr[-3000:]}")
    return dt, p.stdout + p.stderr


def _frame_hashes(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.glob("frame_*.png"))}


def _table(times: dict, same: dict, unit: str) -> list[str]:
    med0 = statistics.median(times["serial"])
    lines = [f"{'engine':<14} {'median s':>9} {'min s':>8} {'max s':>8} {'vs serial':>10}  {unit}"]
    for name, ts in times.items():
        m = statistics.median(ts)
        lines.append(f"{name:<14} {m:>9.1f} {min(ts):>8.1f} {max(ts):>8.1f} {m / med0:>9.3f}x  {same[name]}")
    return lines


def bench_path(a) -> int:
    """The fly-through comparison (module docstring); returns the exit status."""
    out = Path(a.out or tempfile.mkdtemp(prefix="bench_scaleout_"))
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(REPO / "src"))
    env.pop("NUMBA_NUM_THREADS", None)  # serial: numba's default (all cores); workers: set by vibr
    py = sys.executable
    scene = a.scene or str(REPO.parent / "shared" / "data" / "strecha_fountain-P11")
    cache = out / "cache"
    path = out / "path.json"
    _run([py, "-m", "vibr", "path", "interpolate", scene, "-o", str(path), "--frames", str(a.frames),
          "--scale", str(a.scale)], env)
    common = ["--scale", str(a.scale), "--views", str(a.views), "--cache-dir", str(cache), "-q", "--overwrite"]
    # depth once, before the timed runs (a one-frame path: the estimation is the same)
    one = out / "path_1.json"
    pj = json.loads(path.read_text())
    pj["camera_path"] = pj["camera_path"][:1]
    one.write_text(json.dumps(pj))
    dt, log = _run([py, "-m", "vibr", "render", scene, "--path", str(one), "-o", str(out / "warm")] + common, env)
    m = re.search(r"depth: (\w+) \(([\d.]+) s\)", log)
    print(f"depth cache filled in {dt:.1f} s ({m.group(1) + ', ' + m.group(2) + ' s' if m else 'see log'})",
          file=sys.stderr, flush=True)
    engines = _engines(a.workers)
    times: dict = {k: [] for k in engines}
    ref, same = None, {k: "identical" for k in engines}
    for r in range(a.rounds):
        for name in _rotated(list(engines), r):
            frames = out / f"frames_{r}_{name.strip('-').split()[0]}"
            dt, _ = _run([py, "-m", "vibr", "render", scene, "--path", str(path), "-o", str(frames)]
                         + common + engines[name], env)
            times[name].append(dt)
            h = _frame_hashes(frames)
            if len(h) != a.frames:
                same[name] = f"{len(h)} of {a.frames} frames"
            elif ref is None:
                ref = h
            elif h != ref:
                same[name] = f"DIFFERENT ({sum(h[k] != ref.get(k) for k in h)} frames)"
            if not a.keep:
                shutil.rmtree(frames)
            print(f"round {r + 1} {name}: {dt:.1f} s", file=sys.stderr, flush=True)
    print(f"fly-through: {a.frames} frames, scale {a.scale:g}, --views {a.views}, {a.rounds} round(s), "
          f"engines alternating, each run a fresh process (depth from the cache)")
    print("\n".join(_table(times, same, "PNG frames vs the first serial run")))
    if not a.keep and a.out is None:
        shutil.rmtree(out, ignore_errors=True)
    return 0 if all(v == "identical" for v in same.values()) else 1


def bench_loo(a) -> int:
    """The leave-one-out comparison, in this process; returns the exit status."""
    sys.path.insert(0, str(REPO / "src"))
    from vibr.eval.leave_one_out import evaluate_all, resolve_targets, results_only
    from vibr.eval.protocol import settings_grid
    from vibr.io import load_scene, save_scene

    tmp = Path(tempfile.mkdtemp(prefix="bench_scaleout_"))
    try:
        scene_path = a.scene
        if scene_path is None:
            from vibr.synthetic import make_scene

            scene_path = tmp / "grid"
            save_scene(make_scene("grid", n_views=9, width=96, height=80, seed=3), scene_path)
        targets = resolve_targets(load_scene(scene_path, scale=a.scale), a.targets)
        settings = settings_grid([m for m in a.method.split(",") if m], gammas=(1.0,))
        engines = {"serial": None, f"--workers {a.workers}": a.workers, "--dask local": "local"}
        times: dict = {k: [] for k in engines}
        reports: dict = {}
        for r in range(a.rounds):
            for name in _rotated(list(engines), r):
                views = tmp / f"views_{r}_{name.strip('-').split()[0]}"
                t0 = time.perf_counter()
                rep = evaluate_all(scene_path, targets, settings, views_dir=views, scale=a.scale,
                                   executor=engines[name], depth=a.depth, n_views=a.views)
                times[name].append(time.perf_counter() - t0)
                reports.setdefault(name, []).append(results_only(rep["per_view"]))
                shutil.rmtree(views)
                print(f"round {r + 1} {name}: {times[name][-1]:.1f} s", file=sys.stderr, flush=True)
        ref = reports["serial"][0]
        same = {k: ("identical" if all(x == ref for x in v) else "DIFFERENT") for k, v in reports.items()}
        print(f"leave-one-out: {len(targets)} targets, {len(settings)} settings, {a.rounds} round(s), "
              f"engines alternating")
        print("\n".join(_table(times, same, "per-view results vs serial")))
        return 0 if all(v == "identical" for v in same.values()) else 1
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--loo", action="store_true", help="leave-one-out evaluations instead of a fly-through")
    ap.add_argument("--scene", help="scene folder (default: fountain-P11; --loo: a synthetic 9-view grid)")
    ap.add_argument("--scale", type=float, default=None, help="image scale (default 0.25; --loo: 1)")
    ap.add_argument("--frames", type=int, default=60, help="fly-through frames (default 60)")
    ap.add_argument("--views", type=int, default=None, help="K best sources (default 8; --loo: all)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", help="fly-through: work folder (default: a temporary one, removed)")
    ap.add_argument("--keep", action="store_true", help="fly-through: keep the frames")
    ap.add_argument("--targets", default="all", help="--loo: target views")
    ap.add_argument("--depth", default="auto", help="--loo: depth source")
    ap.add_argument("--method", default="ulr,gradient", help="--loo: methods")
    a = ap.parse_args(argv)
    if a.loo:
        a.scale = 1.0 if a.scale is None else a.scale
        return bench_loo(a)
    a.scale = 0.25 if a.scale is None else a.scale
    a.views = 8 if a.views is None else a.views
    return bench_path(a)


if __name__ == "__main__":
    sys.exit(main())
