"""Long fuzz profile of vibr's loaders: N hypothesis-drawn mutations per loader,
each run in a forked child under a time and memory budget (tests/_fuzz.py).

    python3 benchmarks/tools/fuzz_long.py                 # 1000 cases per loader
    python3 benchmarks/tools/fuzz_long.py --cases 200 --loaders colmap_bin,transforms

Prints one row per loader: cases, loaded (valid result), refused (VibrInputError),
unexpected (another exception, an invalid result or a crash), over the time budget, over the
memory budget, the slowest case and the largest memory growth; then the first failures in
full. Exit status 1 when any case failed the property.
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1] / "tests"))
sys.path.insert(0, str(HERE.parents[1] / "src"))

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import seed as hseed  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from _fuzz import SEEDS, add_camera_path_seed, build_seed, fresh_copy, mutate, run_case  # noqa: E402


def fuzz_loader(name: str, n: int, work: Path, time_budget: float, mem_budget: int, seed: int):
    s = SEEDS[name]
    seed_dir = build_seed(s, work / name / "seed")
    rows = []

    @settings(max_examples=n, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(st.data())
    def prop(data):
        folder = fresh_copy(seed_dir, work / name / "case")
        label = mutate(data, s, folder)
        rows.append((label, run_case(s.load, folder, time_budget=time_budget, mem_budget=mem_budget)))

    hseed(seed)(prop)()
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", type=int, default=1000, help="cases per loader (default 1000)")
    ap.add_argument("--loaders", default=None, help="comma-separated loaders (default: all)")
    ap.add_argument("--time-budget", type=float, default=10.0, help="seconds per case (default 10)")
    ap.add_argument("--mem-budget-gb", type=float, default=2.0, help="memory per case, GB (default 2)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    has_path = add_camera_path_seed()
    names = args.loaders.split(",") if args.loaders else sorted(SEEDS)
    mem_budget = int(args.mem_budget_gb * (1 << 30))
    print(f"fuzz_long: {args.cases} cases per loader, budget {args.time_budget:g} s and "
          f"{args.mem_budget_gb:g} GB per case; camera_path.json loader "
          f"{'included' if has_path else 'MISSING (vibr.paths.camera_path.read_camera_path not found)'}")
    header = (f"{'loader':<13} {'cases':>6} {'loaded':>7} {'refused':>8} {'unexpected':>10} "
              f"{'>time':>6} {'>mem':>5} {'slowest s':>10} {'max mem MB':>11} {'wall s':>7}")
    print(header)
    print("-" * len(header))
    failures, total_bad = [], 0
    with tempfile.TemporaryDirectory(prefix="vibr-fuzz-") as tmp:
        for name in names:
            t0 = time.perf_counter()
            rows = fuzz_loader(name, args.cases, Path(tmp), args.time_budget, mem_budget, args.seed)
            c = collections.Counter(o.status for _, o in rows)
            bad = [(lab, o) for lab, o in rows if not o.passed]
            over_t = sum(o.seconds > args.time_budget or o.status == "timeout" for _, o in rows)
            over_m = sum(o.mem_bytes > mem_budget for _, o in rows)
            total_bad += len(bad) + over_m
            failures += [(name, lab, o) for lab, o in bad[:3]]
            print(f"{name:<13} {len(rows):>6} {c['ok']:>7} {c['vibr_error']:>8} "
                  f"{len(bad) - c['timeout']:>10} {over_t:>6} {over_m:>5} "
                  f"{max(o.seconds for _, o in rows):>10.2f} {max(o.mem_bytes for _, o in rows) / 2**20:>11.1f} "
                  f"{time.perf_counter() - t0:>7.1f}", flush=True)
    for name, lab, o in failures:
        print(f"\n--- {name}: {lab}: {o.status} ({o.seconds:.2f} s)\n{o.message}")
    return 1 if total_bad else 0


if __name__ == "__main__":
    sys.exit(main())
