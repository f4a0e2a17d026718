"""The planar proxy's depth uncertainty sigma_z, chosen across scenes with a held-out split.

Where a scene has no geometry, ``depth="planar"`` (``vibr.geometry.planar_proxy``) gives every
source a fronto-parallel plane of the target at depth D and one scalar ``sigma_z``. This
benchmark renders each case with the plane and several rules for ``sigma_z``:

* ``default``: the library's rule (``vibr.geometry.planar_proxy``: ``max(0.02 D, 0.1 (p95 − p5))``
  of the depth seen from the target, since 2026-11-28);
* ``× k``: k times it; ``× 5`` is the former rule ``max(0.1 D, ½ (p95 − p5))``;
* ``f D`` for a few fractions f of the plane's depth.

Cases (the sweep's, ``benchmarks/quality/sweep_defaults.py``, with the plane instead of depth):
cotton's centre from its 8 neighbours at strides 1, 2, 4 (the plane placed from the centre's
ground-truth depth, as ``prepare(..., depth="planar")`` does for a light field whose sources
have none); fountain 0002, 0005, 0008 from the 10 others at scale 0.25 and templeSR0004 from
its 4 best views (the plane placed from the sources' estimated depth: these scenes have no
depth maps and no sparse points); the synthetic grid, arc, free and handheld layouts at
128² (the plane from their exact depth). The split is the sweep's, fixed in advance: within
each family (cotton, fountain, temple + synthetic) the 1st, 3rd, … case is *choose*, the
2nd, 4th, … *report*. The rule with the best mean all-pixel PSNR (2-px border) on *choose*
is reported on *report*, beside ULR and BVS on the same plane.

    python benchmarks/quality/planar_sigma_z.py [--workers 2] [--only cotton,synthetic]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import SceneCache, data_dir, planar_cases, plane_sources  # noqa: E402

FRACTIONS = (0.005, 0.01, 0.02, 0.04, 0.08, 0.16)
FACTORS = (0.25, 0.5, 2.5, 5.0)  # of the default; 5: the former rule
BORDER = 2


def rules(D, default):
    """label → sigma_z."""
    out = {"default": default}
    out.update({f"× {k:g}" + (" (former)" if k == 5 else ""): k * default for k in FACTORS})
    out.update({f"{f:g} D": f * D for f in FRACTIONS})
    return out


def run_case(cache, case):
    from vibr.metrics import psnr
    from vibr.render import shared_geometry

    t0 = time.perf_counter()
    src, tv, D, default = plane_sources(cache, case)
    res = {}
    for lab, sz in rules(D, default).items():
        s = src.replace(views=[v.replace(sigma_z=sz) for v in src.views])
        geo = shared_geometry(s, tv)
        for m in ("gradient", "bvs"):
            r = geo.render(m)
            res[f"{m} {lab}"] = float(psnr(r.image, tv.image, border=BORDER))
        if lab == "default":  # ULR has no use for sigma_z
            r = geo.render("ulr")
            res["ulr"] = float(psnr(r.image, tv.image, border=BORDER))
    return {**case, "D": D, "sigma_z": default, "results": res, "seconds": round(time.perf_counter() - t0, 1)}


def table(reps):
    labs = [f"gradient {lab}" for lab in rules(1.0, 1.0)]
    ch = [r for r in reps if r["split"] == "choose"]
    rp = [r for r in reps if r["split"] == "report"]
    best = max(labs, key=lambda lab: np.mean([r["results"][lab] for r in ch])) if ch else labs[0]
    bvs = ["bvs × 5 (former)", "bvs default", "bvs " + best.split(" ", 1)[1]]
    cols = ["ulr"] + list(dict.fromkeys(bvs)) + labs
    L = ["PSNR dB, all pixels (2-px border); *gradient* the default method and settings, *bvs* BVS "
         "on the same plane; columns: the plane's sigma_z rule.", "",
         "| case | split | D | default σ_z | " + " | ".join(c.replace("gradient ", "") for c in cols) + " |",
         "|---|---|---|---|" + "---|" * len(cols)]
    for r in reps:
        L.append(f"| {r['name']} | {r['split']} | {r['D']:.3g} | {r['sigma_z']:.3g} | "
                 + " | ".join(f"{r['results'][c]:.2f}" for c in cols) + " |")
    for name, part in (("mean choose", ch), ("mean report", rp)):
        if part:
            L.append(
                f"| {name} | | | | "
                + " | ".join(f"{np.mean([r['results'][c] for r in part]):.2f}" for c in cols)
                + " |"
            )
    L.append("")
    L.append(f"chosen on *choose*: **{best}**")
    for r in reps:
        d = r["results"][best] - max(r["results"]["ulr"], r["results"]["bvs " + best.split(" ", 1)[1]])
        L.append(
            f"* {r['name']} ({r['split']}): {best} {r['results'][best]:.2f} dB, minus the better baseline {d:+.2f} dB"
        )
    return "\n".join(L)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    ap.add_argument("--workers", type=int, metavar="N", help="run the cases on N local processes")
    ap.add_argument("--only", default="", help="comma list of case-name prefixes")
    a = ap.parse_args(argv)
    from vibr.executor import run_tasks

    cases = [c for c in planar_cases() if not a.only or any(c["name"].startswith(p) for p in a.only.split(","))]
    t0 = time.perf_counter()
    reps = run_tasks(
        run_case,
        cases,
        setup=SceneCache,
        setup_args=(str(data_dir(a.data)),),
        executor=a.workers,
        desc="planar sigma_z",
    )
    print(f"# {len(reps)} cases in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    print(table(reps))


if __name__ == "__main__":
    main()
