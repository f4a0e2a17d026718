"""What numba compiles on a clean machine, and how long it takes: the test suite (or any pytest
selection) run with an empty kernel cache, each kernel's compilation timed.

A fresh clone (CI, a user's first ``vibr demo``) compiles every kernel it calls; a kernel
called with another dtype, layout or read-only flag than before compiles again. The script
runs pytest in a subprocess with ``NUMBA_CACHE_DIR`` set to an empty folder and a plugin that
listens to numba's compile events, then prints, per kernel, the seconds of its outermost
compilations (a callee compiled inside its caller counts in the caller) and how many there
were, with the total and the suite's wall time.

    PYTHONPATH=$PWD/src python3 benchmarks/perf/compile_times.py [--top 25] [-- PYTEST ARGS]

The default pytest arguments are ``-q -p no:cacheprovider`` (the whole suite: about as long
as CI's run). ``tests/test_compile_once.py`` checks that a pipeline run compiles the heaviest
kernels once.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PLUGIN = '''
import collections, json, os, time
from numba.core import event

_t, _n, _stack = collections.defaultdict(float), collections.Counter(), []


class _Timer(event.Listener):
    def on_start(self, ev):
        _stack.append(time.perf_counter())

    def on_end(self, ev):
        t0 = _stack.pop()
        if not _stack:  # outermost only: a callee compiled inside its caller counts there
            f = getattr(ev.data.get("dispatcher"), "py_func", None)
            key = f"{f.__module__}.{f.__qualname__}" if f is not None else "?"
            _t[key] += time.perf_counter() - t0
            _n[key] += 1


def pytest_configure(config):
    event.register("numba:compile", _Timer())


def pytest_unconfigure(config):
    with open(os.environ["VIBR_COMPILE_TIMES"], "w") as fh:
        json.dump({k: [_t[k], _n[k]] for k in _t}, fh)
'''


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    pytest_args = ["-q", "-p", "no:cacheprovider"]
    if "--" in argv:
        i = argv.index("--")
        argv, pytest_args = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--top", type=int, default=25, help="kernels listed (default 25)")
    a = ap.parse_args(argv)
    root = Path(__file__).resolve().parents[2]
    with tempfile.TemporaryDirectory() as tmp:
        Path(tmp, "vibr_compile_times.py").write_text(PLUGIN)
        report = Path(tmp, "times.json")
        env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp, "cache")), VIBR_COMPILE_TIMES=str(report),
                   PYTHONPATH=os.pathsep.join([tmp, str(root / "src"), os.environ.get("PYTHONPATH", "")]))
        t0 = time.perf_counter()
        rc = subprocess.run([sys.executable, "-m", "pytest", "-p", "vibr_compile_times", *pytest_args],
                            cwd=root, env=env).returncode
        wall = time.perf_counter() - t0
        if not report.exists():
            print("pytest did not finish: no compile times", file=sys.stderr)
            return 1
        times = json.loads(report.read_text())
    rows = sorted(times.items(), key=lambda kv: -kv[1][0])
    total = sum(t for t, _ in times.values())
    print(f"\npytest {' '.join(pytest_args)}: exit {rc}, {wall:.0f} s wall; numba compiled {len(rows)} kernels "
          f"{sum(n for _, n in times.values())} times in {total:.0f} s")
    print("| kernel | seconds | compilations |\n|---|---|---|")
    for k, (t, n) in rows[:a.top]:
        print(f"| `{k}` | {t:.1f} | {n} |")
    return rc


if __name__ == "__main__":
    raise SystemExit(main())
