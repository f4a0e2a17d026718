"""How many source views when depth is estimated (docs/explanation/performance.md, "Many views and
estimated depth"): the default's all-pixel PSNR, ULR's and BVS's, and the depth time, for a
target rendered from its K best views (``vibr eval --views K``), K against every view.

Estimated depth costs one estimate per source view, from the sources alone (the target never
takes part), so the number of sources sets the time of a render of a scene without depth.
Scenes: cotton's 9×9 light field without its ground truth and with 7 views missing (74 of 81
photographs, linked from the data folder); synthetic scenes of 24 views at 192² on an arc, a
hand-held sweep and free poses (exact depth saved, not used: ``--depth estimated``);
fountain at a quarter size (10 other views); the temple ring (15 other views). Three targets
per scene; within each scene the 1st and 3rd target are the *choose* half, the 2nd the
*report* half (fixed in advance).

    python benchmarks/perf/source_count.py --work DIR [--only cotton,synthetic] [--report-only]

Each case is one ``vibr -q eval SCENE --target T --views K --method ulr,bvs,gradient --gamma
0.2 --mask all --json DIR/json/CASE.json`` with ``VIBR_CACHE_DIR=DIR/cache`` (a second run
reads the depth from the cache, so its depth times are the cache's). About 40 minutes on two
cores from an empty cache.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import data_dir  # noqa: E402

#: cotton's views left out (a light field with missing views)
COTTON_MISSING = (3, 17, 22, 44, 58, 61, 79)
SYNTHETIC = ("arc", "handheld", "free")
#: scene → (targets, K values, extra vibr eval arguments)
CASES = {
    "cotton": (("input_Cam040", "input_Cam020", "input_Cam076"), ("8", "16", "24"), []),
    **{f"synthetic {lo}": (("view_006", "view_012", "view_018"), ("8", "16", "all"), ["--depth", "estimated"])
       for lo in SYNTHETIC},
    "fountain": (("0002", "0005", "0008"), ("8", "all"), ["--scale", "0.25"]),
    "temple": (("templeSR0004", "templeSR0010", "templeSR0014"), ("8", "12", "all"), []),
}


def make_scenes(data: Path, work: Path) -> dict:
    """Scene folders by case name: cotton's photographs linked without the missing views and
    without ground truth; the synthetic scenes saved; fountain and temple as they are."""
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    cotton = work / "cotton_missing"
    cotton.mkdir(parents=True, exist_ok=True)
    src = data / "hci2016_cotton"
    for i in range(81):
        link = cotton / f"input_Cam{i:03d}.png"
        if i not in COTTON_MISSING and not link.exists():
            link.symlink_to(src / link.name)
    if not (cotton / "parameters.cfg").exists():
        (cotton / "parameters.cfg").symlink_to(src / "parameters.cfg")
    out = {"cotton": cotton, "fountain": data / "strecha_fountain-P11",
           "temple": data / "middlebury_templeSparseRing"}
    for lo in SYNTHETIC:
        folder = work / f"{lo}24"
        if not (folder / "transforms.json").is_file():
            save_scene(make_scene(lo, n_views=24, width=192, height=192, seed=1), folder)
        out[f"synthetic {lo}"] = folder
    return out


def case_file(work: Path, name: str, target: str, k: str) -> Path:
    return work / "json" / f"{name.replace(' ', '_')}_{target}_k{k}.json"


def run_cases(scenes: dict, work: Path, names) -> None:
    env = {**os.environ, "VIBR_CACHE_DIR": str(work / "cache")}
    (work / "json").mkdir(parents=True, exist_ok=True)
    for name in names:
        targets, ks, extra = CASES[name]
        for t in targets:
            for k in ks:
                out = case_file(work, name, t, k)
                cmd = ["vibr", "-q", "eval", str(scenes[name]), "--target", t, "--views", k, "--method",
                       "ulr,bvs,gradient", "--gamma", "0.2", "--mask", "all", "--json", str(out), *extra]
                t0 = time.perf_counter()
                r = subprocess.run(cmd, env=env, capture_output=True, text=True)
                print(f"# {name} {t} K={k}: exit {r.returncode}, {time.perf_counter() - t0:.0f} s", file=sys.stderr)
                if r.returncode:
                    sys.exit(f"{' '.join(cmd)} failed: {r.stderr.strip()[-300:]}")


def load(path: Path):
    if not path.is_file():
        return None
    d = json.loads(path.read_text())
    r = {x["label"]: x["psnr"] for x in d["results"]}
    return {"n": len(d["sources"]), "depth": d.get("depth_seconds", 0.0), "ulr": r["ulr"], "bvs": r["bvs"],
            "default": r.get("gradient(gamma=0.2)", r.get("gradient"))}


def table(work: Path, names) -> str:
    ks = ("8", "12", "16", "24", "all")
    lines = ["| scene | target | split | " + " | ".join(f"K = {k}" for k in ks) + " |",
             "|---|---|---|" + "---|" * len(ks)]
    split = {"choose": {}, "report": {}}
    for name in names:
        for i, t in enumerate(CASES[name][0]):
            half = "choose" if i % 2 == 0 else "report"
            cells = []
            for k in ks:
                v = load(case_file(work, name, t, k))
                cells.append(
                    ""
                    if v is None
                    else f"{v['default']:.2f} / {v['ulr']:.2f} / {v['bvs']:.2f} ({v['n']} views, {v['depth']:.0f} s)"
                )
                if v is not None:
                    # K = 16 is every view of a scene with at most 16 others
                    for kk in {k} | ({"16"} if k == "all" and v["n"] <= 16 else set()):
                        split[half].setdefault(kk, {})[(name, t)] = v
            lines.append(f"| {name} | {t} | {half} | " + " | ".join(cells) + " |")
    lines.append("")
    for half, by_k in split.items():
        common = set.intersection(*[set(by_k.get(k, {})) for k in ("8", "16")]) if by_k else set()
        if not common:
            continue
        parts = [
            f"K = {k}: default {np.mean([by_k[k][c]['default'] for c in common]):.2f}, "
            f"ULR {np.mean([by_k[k][c]['ulr'] for c in common]):.2f}, "
            f"BVS {np.mean([by_k[k][c]['bvs'] for c in common]):.2f} dB"
            for k in ("8", "16")
        ]
        lines.append(f"* {half} half, mean of {len(common)} cases: " + "; ".join(parts))
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    ap.add_argument("--work", required=True, help="scenes, depth cache and JSON reports")
    ap.add_argument("--only", default="", help="comma list of scene-name prefixes (cotton, synthetic, ...)")
    ap.add_argument("--report-only", action="store_true", help="the table from the JSON reports in --work")
    a = ap.parse_args(argv)
    work = Path(a.work)
    names = [n for n in CASES if not a.only or any(n.startswith(p) for p in a.only.split(","))]
    if not a.report_only:
        run_cases(make_scenes(data_dir(a.data), work), work, names)
    print("# cell: all-pixel PSNR dB (2-px border) of the default / ULR / BVS (sources, depth seconds)\n")
    print(table(work, names))


if __name__ == "__main__":
    main()
