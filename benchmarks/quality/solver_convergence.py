"""Plain against preconditioned FISTA (``precond``), each stopped by the default rule and run
to convergence (tol 1e-7, 600 iterations a pass), on cases of ``sweep_defaults.py``:
PSNR (all pixels, 2-px border), iterations per outer pass and the energy at the end of the
first pass (the same energy for every variant of a case: deformation-only weights).

    python3 benchmarks/quality/solver_convergence.py                       # fountain 0002, synthetic free, cotton gt s2
    python3 benchmarks/quality/solver_convergence.py --cases "fountain 0005,temple 0004" --view-k 4

Other parameters: the library's defaults, with ``view_k`` as given (default 0).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import SWEEP_BORDER, SceneCache, data_dir, sweep_cases, sweep_sources  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", default="fountain 0002,synthetic free,cotton gt s2", help="comma list of case names")
    ap.add_argument("--view-k", type=int, default=0, help="view prior (default 0: none)")
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    a = ap.parse_args(argv)

    from vibr.geometry import compute_samples
    from vibr.metrics import psnr
    from vibr.render import render

    names = [c.strip() for c in a.cases.split(",")]
    cases = [c for c in sweep_cases() if c["name"] in names]
    if len(cases) != len(names):
        sys.exit(f"unknown case among {names} (known: {', '.join(c['name'] for c in sweep_cases())})")
    cache = SceneCache(data_dir(a.data))
    variants = [("plain, default stop", dict(precond=False)), ("preconditioned, default stop", dict(precond=True)),
                ("plain, converged", dict(precond=False, max_iter=600, tol=1e-7)),
                ("preconditioned, converged", dict(precond=True, max_iter=600, tol=1e-7))]
    print("| case | solver | PSNR dB | iterations (per pass) | energy after pass 1 | s |\n|---|---|---|---|---|---|")
    for case in cases:
        src, tv = sweep_sources(cache, case)
        S = compute_samples(src, tv.camera)
        for label, kw in variants:
            t = time.perf_counter()
            r = render(src, tv.camera, "gradient", samples=S, view_k=a.view_k, **kw)
            dt = time.perf_counter() - t
            o = list(r.outer) + [len(r.energy)]
            per = [o[j + 1] - o[j] for j in range(len(o) - 1)]
            print(f"| {case['name']} | {label} | {psnr(r.image, tv.image, border=SWEEP_BORDER):.2f} | {r.iterations} "
                  f"({' + '.join(map(str, per))}) | {r.energy[o[1] - 1]:.6g} | {dt:.1f} |", flush=True)


if __name__ == "__main__":
    main()
