"""Render time with and without ``uncertainty=True`` (issue 28 target: ≤ 1.15×), on
benchmarks/perf/bench_render.py's scene (synthetic 3×3 grid, centre view from its 8 neighbours),
``gradient`` method, the same samples, the two alternated A/B/B/A in one process; prints the
medians, the per-pair ratio and the uncertainty step alone.

    python benchmarks/perf/bench_uncertainty_overhead.py                 # 768², 7 pairs
    python benchmarks/perf/bench_uncertainty_overhead.py --size 512 --repeat 3

The measurement itself is :func:`uncertainty_table.overhead` (one implementation).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=768, help="image side in pixels (default 768)")
    ap.add_argument("--repeat", type=int, default=7, help="alternating pairs after one warm-up pair (default 7)")
    a = ap.parse_args(argv)
    from uncertainty_table import overhead

    overhead(size=a.size, repeat=a.repeat)


if __name__ == "__main__":
    main()
