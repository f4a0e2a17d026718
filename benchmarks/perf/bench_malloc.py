"""glibc's default allocator settings against vibr's (:mod:`vibr._runtime.malloc`), alternating.

Each round runs, in fresh processes and alternating the two settings (``VIBR_MALLOC=default``
for glibc's own):

* ``benchmarks/perf/bench_render.py --repeat R`` (768², 8 sources): its median total render time
  and its peak resident memory;
* a fly-through of ``--frames`` frames of the fountain (``vibr path interpolate`` then
  ``vibr render --path`` at scale 0.25, 8 views, the depth from a cache filled once before
  the rounds): wall time of the render process, its system (kernel) CPU time and its peak
  resident memory (``wait4``'s rusage of that child).

Prints a table of medians (min–max) over the rounds and checks that the frames of every
fly-through run are byte-identical (the allocator must not change a pixel).

    python benchmarks/perf/bench_malloc.py [--rounds 3] [--frames 24] [--repeat 5] [--out /tmp/bench_malloc]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SETTINGS = {"glibc default": "default", "vibr": ""}


def child(cmd, env):
    """(wall s, user s, sys s, peak RSS MB) of one child process."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = p.stdout.read()
    _, status, ru = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    dt = time.perf_counter() - t0
    if p.returncode != 0:
        sys.exit(f"failed ({p.returncode}): {' '.join(map(str, cmd))}\n{out[-2000:]}")
    return dt, ru.ru_utime, ru.ru_stime, ru.ru_maxrss / 1024.0


def frames_digest(folder: Path) -> str:
    h = hashlib.sha256()
    for f in sorted(folder.glob("*.png")):
        h.update(f.read_bytes())
    return h.hexdigest()


def spread(xs, fmt="{:.3f}"):
    return f"{fmt.format(statistics.median(xs))} ({fmt.format(min(xs))}–{fmt.format(max(xs))})"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--repeat", type=int, default=5, help="bench_render runs per process")
    ap.add_argument("--out", default="/tmp/bench_malloc")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    py = sys.executable
    base_env = dict(os.environ, PYTHONPATH=str(REPO / "src"), NUMBA_NUM_THREADS=str(os.cpu_count()))
    for v in ("VIBR_MALLOC", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES"):
        base_env.pop(v, None)
    envs = {k: dict(base_env, **({"VIBR_MALLOC": v} if v else {})) for k, v in SETTINGS.items()}

    scene = str(Path(a.data) / "strecha_fountain-P11")
    path, cache = out / "path.json", out / "cache"
    path.unlink(missing_ok=True)
    child([py, "-m", "vibr", "-q", "path", "interpolate", scene, "-o", str(path), "--frames", str(a.frames),
           "--scale", "0.25"], base_env)

    def flythrough(name, tag):
        frames = out / f"frames_{tag}"
        return child([py, "-m", "vibr", "-q", "render", scene, "--path", str(path), "-o", str(frames),
                      "--scale", "0.25", "--views", "8", "--cache-dir", str(cache), "--overwrite",
                      "--workers", "1"],  # one process: its peak memory and system time are the ones measured
                     envs[name]), frames

    flythrough("vibr", "warmup")  # fills the depth cache and the kernel cache
    res = {k: {"render_total": [], "render_peak": [], "path_wall": [], "path_sys": [], "path_peak": []}
           for k in SETTINGS}
    digests = set()
    for r in range(a.rounds):
        order = list(SETTINGS) if r % 2 == 0 else list(SETTINGS)[::-1]
        for name in order:
            js = out / f"render_{r}.json"
            child(
                [
                    py,
                    str(REPO / "benchmarks" / "perf" / "bench_render.py"),
                    "--repeat",
                    str(a.repeat),
                    "--json",
                    str(js),
                ],
                envs[name],
            )
            rep = json.loads(js.read_text())
            res[name]["render_total"].append(rep["total"])
            res[name]["render_peak"].append(rep["peak_rss_mb"])
            (wall, _, sys_s, peak), frames = flythrough(name, f"{r}_{SETTINGS[name] or 'vibr'}")
            res[name]["path_wall"].append(wall)
            res[name]["path_sys"].append(sys_s)
            res[name]["path_peak"].append(peak)
            digests.add(frames_digest(frames))
            print(
                f"round {r + 1} {name}: render total {rep['total']:.3f} s, fly-through {wall:.1f} s "
                f"(sys {sys_s:.1f} s, peak {peak:.0f} MB)",
                flush=True,
            )

    print(f"\n{a.rounds} rounds, alternating; medians (min–max)\n")
    print(
        f"| allocator | bench_render total s (768², median of {a.repeat}) | bench_render peak MB "
        f"| fly-through {a.frames} frames, wall s | its system CPU s | its peak MB |"
    )
    print("|---|---|---|---|---|---|")
    for name, r in res.items():
        print(
            f"| {name} | {spread(r['render_total'])} | {spread(r['render_peak'], '{:.0f}')} | "
            f"{spread(r['path_wall'], '{:.1f}')} | {spread(r['path_sys'], '{:.1f}')} | "
            f"{spread(r['path_peak'], '{:.0f}')} |"
        )
    print(f"\nframes byte-identical across all {2 * a.rounds} fly-through runs: {len(digests) == 1}")
    (out / "results.json").write_text(json.dumps(res, indent=1))
    return 0 if len(digests) == 1 else 1


if __name__ == "__main__":
    sys.exit(main())
