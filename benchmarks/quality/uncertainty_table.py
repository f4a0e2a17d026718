"""Calibration of vibr's per-pixel uncertainty on held-out views, and the choice of its terms.

Split by scene, fixed here before any run (:func:`split`). *Choose*: the defaults' sweep's
procedural families (:data:`PROCEDURAL`: no geometry, far background, rings; 256×192, the
middle view from the 6 others or a ring view from its 4 best, depth estimated), sources
photographed as the sweep's (``_common.CAPTURE``) and, unlike the sweep's, the target too,
with its own seed: σ predicts the error against a photograph, which has an exposure and
noise of its own. The sum of terms with the lowest mean AUSE over them is the library's
(:data:`vibr.render.uncertainty.TERMS`) unless its paired gain over the library's is within its
standard error; a run whose choice differs from the library's exits 1 and says so.
*Report*: HCI 2016 *cotton* (512×512), centre view ``input_Cam040`` from the 8 neighbours of
its 3×3 block at strides 1, 2, 4, with ground-truth, estimated and planar-proxy geometry
(as benchmarks/quality/paper_tables.py); Strecha *fountain-P11* views 0002, 0005, 0008 at image
scale 0.25 from the 10 other views, depth estimated from those only; Middlebury *templeSR*
view 0004 from its 4 best views (an object on a black backdrop), depth estimated from them.

Per case the view is rendered with the ``gradient`` method at the library's defaults (what a
user gets; ``--paper-settings``: cotton alpha, gamma, lam = 1, 1, 0.1 and fountain the
paper's 0.1, 1, 0.002, in vibr's units, as before this release) with
``uncertainty=TERMS`` for each candidate combination of terms (:data:`VARIANTS`; ``model``: Jacobi
``1/diag(H)``; ``spread``: the W-weighted spread of the samples around u times
``1 + 1/n_eff``; ``views``: the spread taken with each source view's photometric offset
removed, plus the offsets' bias and variance; ``gain``: the same with each view's offset a
gain, proportional to the pixel's intensity; ``hole``: their sum times
``1 + 4 px / distance to a push–pull pixel``), and
ULR with its own σ. Scored against the per-pixel error (RMS over channels, grey levels):
AUSE (normalised sparsification curves, 50 fractions; lower is better) and Spearman's rho
between σ and the error, over every pixel of the image (2-pixel border excluded; pixels
filled by push–pull included: they get σ_hole). Baselines: the spread of the source samples
alone (``sample_spread_sigma``) and 1 / number of views seeing the pixel
(``view_count_sigma``), both scored against the same gradient render.

    python benchmarks/quality/uncertainty_table.py                       # all cases, print the table
    python benchmarks/quality/uncertainty_table.py --write-docs          # ... and write its section
                                                                         # of docs/results/paper-tables.md
    python benchmarks/quality/uncertainty_table.py --cases cotton_s2_gt,fountain_0005

JSON per case and the sparsification plots go to ``--out`` (default out/uncertainty, git-ignored).
A fountain case whose Spearman ρ falls below :data:`SPEARMAN_FLOOR` makes the run exit 1 with a
one-line reason. The time σ costs: ``benchmarks/perf/bench_uncertainty_overhead.py``.
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import (  # noqa: E402
    CAPTURE,
    NOGEO_LAYOUTS,
    NOGEO_SEEDS,
    RESULTS,
    ROOT,
    SceneCache,
    cotton_neighbours,
    data_dir,
    paired_gain,
    replace_block,
    replaces_default,
    sweep_sources,
)
from vibr.render.uncertainty import TERMS  # noqa: E402

#: the generated page whose uncertainty section this script writes (--write-docs)
PAGE = RESULTS / "paper-tables.md"
#: the lowest Spearman ρ between σ and the error on a fountain view
SPEARMAN_FLOOR = 0.4

VARIANTS = ("model", "spread", "model+spread", "model+spread+hole", "model+spread+views", "model+spread+gain+hole",
            "spread+views+hole", "model+spread+views+hole", "model+spread+gain+hole+fill")
CHOSEN = "+".join(TERMS)  # the library's sum, which the choose half keeps or replaces
#: the procedural families of the choose half (the defaults' sweep's, photographed with
#: _common.CAPTURE): no geometry, a far background stereo misses, an object on a backdrop
PROCEDURAL = ([f"proc_nogeo_{lo}_s{sd}" for lo in NOGEO_LAYOUTS for sd in NOGEO_SEEDS]
              + [f"proc_far_{lo}_s{sd}" for lo in ("free", "handheld") for sd in (0, 1)]
              + [f"proc_ring_{k}_{t}" for k in ("textureless", "textured") for t in (4, 11)])
COTTON_PARAMS = dict(alpha=1.0, gamma=1.0, lam=0.1)
FOUNTAIN_PARAMS = dict(alpha=0.1, gamma=1.0, lam=0.002)
PAPER_SETTINGS = [False]  # --paper-settings: the two dicts above instead of the defaults


def all_cases():
    out = [f"cotton_s{s}_{d}" for s in (1, 2, 4) for d in ("gt", "estimated", "planar")]
    return PROCEDURAL + out + [f"fountain_{v}" for v in ("0002", "0005", "0008")] + ["temple_0004"]


def split(case: str) -> str:
    """A case's half, by scene, fixed before the run: procedural *choose*, photographs *report*."""
    return "choose" if case.startswith("proc_") else "report"


def procedural(case: str):
    """(sources with estimated depth, target View) of a ``proc_*`` case: the sources as the
    defaults' sweep builds them (``_common.sweep_sources`` with ``CAPTURE``), and the target
    photographed too, with an exposure and noise of its own (the sweep keeps it ray-cast): σ
    predicts the error against a held-out photograph, as on the photographs of the report half."""
    from vibr.scene import Scene
    from vibr.synthetic import photograph

    kind, a, b = case.split("_")[1:]
    if kind == "ring":
        c = dict(kind="ring", ring=a, target=int(b))
    else:
        c = dict(kind=kind, layout=a, seed=int(b[1:]))
    src, tv = sweep_sources(None, c, CAPTURE)
    return src, photograph(Scene([tv]), seed=1000 + PROCEDURAL.index(case), **CAPTURE).views[0]


def prepared(case, data, scenes, cache=None):
    """``prepare`` of a case (sources with depth, held-out target view); with ``cache`` a
    pickle per case in that folder is reused (depth estimation is deterministic and most of
    a case's time)."""
    import pickle

    from vibr.io import load_scene
    from vibr.pipeline import prepare

    pk = Path(cache) / f"{case}.pkl" if cache else None
    if pk is not None and pk.exists():
        return pickle.loads(pk.read_bytes())
    m = re.fullmatch(r"cotton_s(\d)_(gt|estimated|planar)", case)
    if case.startswith("proc_"):
        out = procedural(case)
    elif case == "temple_0004":  # a black backdrop, from its 4 best views (the defaults' sweep's case)
        out = sweep_sources(SceneCache(data), dict(kind="temple"))
    elif m:
        if "cotton" not in scenes:
            scenes["cotton"] = load_scene(data / "hci2016_cotton")
        scene = scenes["cotton"]
        out = prepare(scene, "input_Cam040", sources=cotton_neighbours(scene, int(m.group(1))), depth=m.group(2))
    else:
        m = re.fullmatch(r"fountain_(\d{4})", case)
        if not m:
            raise SystemExit(f"unknown case {case}")
        if "fountain" not in scenes:
            scenes["fountain"] = load_scene(data / "strecha_fountain-P11", scale=0.25)
        out = prepare(scenes["fountain"], m.group(1), depth="estimated")
    if pk is not None:
        pk.parent.mkdir(parents=True, exist_ok=True)
        pk.write_bytes(pickle.dumps(out))
    return out


def run_case(case, data, scenes, log, cache=None):
    from vibr.geometry import compute_samples
    from vibr.metrics import ause, pixel_error, sparsification, spearman
    from vibr.render import render
    from vibr.render.uncertainty import sample_spread_sigma, view_count_sigma

    t0 = time.perf_counter()
    src, tv = prepared(case, data, scenes, cache)
    m = re.fullmatch(r"cotton_s\d_(\w+)", case)
    depth = m.group(1) if m else "estimated"
    paper = {"cotton": COTTON_PARAMS, "fountain": FOUNTAIN_PARAMS}.get(case.split("_")[0], {})
    params = paper if PAPER_SETTINGS[0] else {}
    t_depth = time.perf_counter() - t0
    S = compute_samples(src, tv.camera)
    ref = tv.image
    rows = {}

    def score(name, sig, img, seconds=None):
        err = pixel_error(img, ref)
        c = sparsification(sig, err, border=2)
        rows[name] = {"ause": ause(curves=c), "spearman": spearman(sig, err, border=2),
                      "curve": c["curve"], "oracle": c["oracle"], "fractions": c["fractions"],
                      "rmse": c["rmse"], "sigma_median": float(np.median(sig[np.isfinite(sig)]))}
        if seconds is not None:
            rows[name]["seconds"] = seconds

    base = None
    for v in VARIANTS:
        t = time.perf_counter()
        r = render(src, tv.camera, "gradient", samples=S, uncertainty=v, **params)
        score(f"vibr[{v}]", r.uncertainty, r.image, time.perf_counter() - t)
        rows[f"vibr[{v}]"]["uncertainty_seconds"] = r.times.get("uncertainty")
        base = r
    score("baseline: sample spread", sample_spread_sigma(S), base.image)
    score("baseline: 1/views", view_count_sigma(S), base.image)
    ru = render(src, tv.camera, "ulr", samples=S, uncertainty=True)
    score("ulr σ (ulr render)", ru.uncertainty, ru.image)
    score("ulr: 1/views", view_count_sigma(S), ru.image)
    from vibr.metrics import psnr

    out = {"case": case, "depth": depth, "params": params, "size": list(tv.shape),
           "coverage": float(base.coverage.mean()), "psnr_all": psnr(base.image, ref, border=2),
           "depth_seconds": round(t_depth, 1), "seconds": round(time.perf_counter() - t0, 1), "rows": rows}
    log(f"{case}: {out['seconds']:.0f} s (depth {t_depth:.0f} s), coverage {100 * out['coverage']:.1f} %, "
        + ", ".join(f"{k} AUSE {v['ause']:.3f} rho {v['spearman']:.2f}" for k, v in rows.items()))
    return out


def plot_curves(rep, path):
    """Sparsification plot (numpy-drawn PNG): vibr's curve, both baselines and the oracle."""
    from vibr.eval.sigma_figures import sparsification_plot

    rows = rep["rows"]
    curves = {"vibr σ": rows[f"vibr[{CHOSEN}]"]["curve"],
              "sample spread": rows["baseline: sample spread"]["curve"],
              "1/views": rows["baseline: 1/views"]["curve"],
              "oracle": rows[f"vibr[{CHOSEN}]"]["oracle"]}
    sparsification_plot(path, rows[f"vibr[{CHOSEN}]"]["fractions"], curves, title=rep["case"])


def table(reports):
    lines = ["| case | PSNR dB (all px) | vibr σ AUSE | ρ | sample spread AUSE | ρ | 1/views AUSE | ρ | "
             "vibr best? | ULR σ AUSE | ρ | ULR 1/views AUSE |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for rep in reports:
        r = rep["rows"]
        v, b1, b2 = r[f"vibr[{CHOSEN}]"], r["baseline: sample spread"], r["baseline: 1/views"]
        best = "yes" if v["ause"] < min(b1["ause"], b2["ause"]) else "**no**"
        lines.append(f"| {rep['case']} | {rep['psnr_all']:.2f} | {v['ause']:.3f} | {v['spearman']:.2f} | "
                     f"{b1['ause']:.3f} | {b1['spearman']:.2f} | {b2['ause']:.3f} | {b2['spearman']:.2f} | {best} | "
                     f"{r['ulr σ (ulr render)']['ause']:.3f} | {r['ulr σ (ulr render)']['spearman']:.2f} | "
                     f"{r['ulr: 1/views']['ause']:.3f} |")
    return "\n".join(lines)


def variant_table(reports):
    lines = ["| case | " + " | ".join(f"{v} AUSE / ρ" for v in VARIANTS) + " |",
             "|---|" + "---|" * len(VARIANTS)]
    for rep in reports:
        r = rep["rows"]
        lines.append(f"| {rep['case']} | " + " | ".join(
            f"{r[f'vibr[{v}]']['ause']:.3f} / {r[f'vibr[{v}]']['spearman']:.2f}" for v in VARIANTS) + " |")
    return "\n".join(lines)


def choose(reports):
    """(the σ sum the *choose* reports give the library, summary rows): the variant of the
    lowest mean AUSE replaces the library's :data:`CHOSEN` only when its paired AUSE gain over
    it exceeds the gain's standard error (``_common.replaces_default``)."""
    reps = [r for r in reports if split(r["case"]) == "choose"]
    if not reps:
        return CHOSEN, []
    a = {v: np.array([r["rows"][f"vibr[{v}]"]["ause"] for r in reps]) for v in VARIANTS}
    rho = {v: np.array([r["rows"][f"vibr[{v}]"]["spearman"] for r in reps]) for v in VARIANTS}
    rows = []
    for v in VARIANTS:
        gain, se = paired_gain(-a[v], -a[CHOSEN])  # an AUSE gain: lower is better
        d = a[CHOSEN] - a[v]
        rows.append(dict(variant=v, ause=float(a[v].mean()), spearman=float(np.nanmean(rho[v])), gain=gain,
                         se=se, better=int((d > 0).sum()), worse=int((d < 0).sum())))
    best = min(rows, key=lambda r: r["ause"])
    keep = best["variant"] == CHOSEN or not replaces_default(-a[best["variant"]], -a[CHOSEN])
    return (CHOSEN if keep else best["variant"]), rows


def choose_table(reports):
    choice, rows = choose(reports)
    n = sum(split(r["case"]) == "choose" for r in reports)
    lines = [f"| terms of σ² | mean AUSE | mean ρ | AUSE gain over the library's `{CHOSEN}` ± SE | better / worse |",
             "|---|---|---|---|---|"]
    for r in rows:
        name = f"**{r['variant']}**" if r["variant"] == choice else r["variant"]
        lines.append(f"| {name} | {r['ause']:.3f} | {r['spearman']:.2f} | {r['gain']:+.3f} ± {r['se']:.3f} | "
                     f"{r['better']} / {r['worse']} |")
    return f"Chosen on the {n} procedural cases ({', '.join(r['case'] for r in reports if split(r['case']) == 'choose')}):\n\n" + "\n".join(lines)


def targets(reports):
    """The two targets, checked on the reports given."""
    best, fountain = [], []
    for rep in [r for r in reports if split(r["case"]) == "report"]:
        r = rep["rows"]
        v = r[f"vibr[{CHOSEN}]"]
        best.append(v["ause"] < min(r["baseline: sample spread"]["ause"], r["baseline: 1/views"]["ause"]))
        if rep["case"].startswith("fountain"):
            fountain.append(f"{rep['case']} {v['spearman']:.2f} "
                            f"({'met' if v['spearman'] >= SPEARMAN_FLOOR else '**not met**'})")
    return (f"Targets: vibr's σ has the lowest AUSE on {sum(best)} of {len(best)} cases; Spearman ρ ≥ 0.4 on "
            f"fountain: {', '.join(fountain) or 'no fountain case run'}.")


SECTION = "## Uncertainty: calibration of the per-pixel σ"
BEGIN, END = "<!-- uncert:begin -->", "<!-- uncert:end -->"


def write_docs(reports, cmd, seconds):
    """Write the section between :data:`BEGIN` and :data:`END` of :data:`PAGE` (the rest of the
    page, paper_tables.py's, is kept)."""
    report = [r for r in reports if split(r["case"]) == "report"]
    body = (f"{SECTION}\n\nMade by `{cmd}` ({seconds / 60:.0f} min on a shared 2-core machine; "
            "method, metrics and baselines in the script's docstring and docs/explanation/renderer.md "
            "\"Uncertainty\"). "
            "AUSE: area between the normalised sparsification curve and the oracle's (50 fractions; lower is "
            "better); ρ: Spearman's rank correlation between σ and the per-pixel error; all pixels of the "
            "image with a 2-pixel border excluded (push–pull filled pixels included). vibr σ, sample spread and "
            "1/views are scored against the same `gradient` render ("
            + ("at the former explicit settings, "
               "`--paper-settings`" if PAPER_SETTINGS[0] else "at the library's defaults")
            + "); the ULR columns against a ULR render.\n\n"
            "The terms of σ² are chosen on procedural scenes and reported on the photographs, which take no "
            "part in the choice (the split by scene is fixed in the script: `split`). "
            f"{choose_table(reports)}\n\nReported on the photographs, the library's σ (`{CHOSEN}`):\n\n"
            f"{table(report)}\n\nEach sum of terms on the photographs, AUSE / ρ:\n\n"
            f"{variant_table(report)}\n\n{targets(reports)}\n")
    replace_block(PAGE, BEGIN, END, f"{BEGIN}\n{body}{END}", title="Reproducing the paper's tables")


def planar_figure(path, size=256):
    """docs figure: a synthetic 3×3 grid (exact depth), centre view rendered by ``gradient``
    from its 4 best neighbours (``prepare``'s default with the planar proxy) through the
    planar proxy; panels: reference, render, per-pixel
    error and σ (both in grey levels, the same colour scale)."""
    from PIL import Image, ImageDraw

    from vibr._runtime.atomic import atomic_path
    from vibr.eval.sigma_figures import _nice_ceiling, sigma_figure
    from vibr.metrics import pixel_error, uncertainty_metrics
    from vibr.pipeline import prepare
    from vibr.render import render
    from vibr.synthetic import make_scene

    src, tg = prepare(make_scene("grid", width=size, height=size, seed=0), 4, depth="planar")
    r = render(src, tg, "gradient", uncertainty=True)
    err = pixel_error(r.image, tg.image)
    m = uncertainty_metrics(r.uncertainty, r.image, tg.image, border=2)
    vmax = _nice_ceiling(float(np.percentile(np.r_[err.ravel(), r.uncertainty.ravel()], 99)))
    fe, fs = sigma_figure(err, vmax, "|error|, grey levels"), sigma_figure(r.uncertainty, vmax)
    pad = np.full((fe.shape[0] - size, size, 3), 255, np.uint8)
    to8 = lambda a: np.vstack([np.round(np.clip(a, 0, 1) * 255).astype(np.uint8), pad])  # noqa: E731
    panels = [to8(tg.image), to8(r.image), fe, fs]
    gap = np.full((fe.shape[0], 6, 3), 255, np.uint8)
    row = np.hstack([x for p in panels for x in (p, gap)][:-1])
    top = 16
    img = Image.new("RGB", (row.shape[1], row.shape[0] + top), (255, 255, 255))
    img.paste(Image.fromarray(row), (0, top))
    d = ImageDraw.Draw(img)
    for k, lab in enumerate(("reference (held out)", f"planar proxy render, {r.metrics['psnr']:.1f} dB",
                             "|error| (RMS over RGB)", f"predicted sigma (rho {m['spearman']:.2f})")):
        d.text((k * (size + 6) + 4, 2), lab, fill=(0, 0, 0))
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG")
    print(f"wrote {path}: PSNR {r.metrics['psnr']:.2f} dB, AUSE {m['ause']:.3f}, Spearman {m['spearman']:.2f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", default=",".join(all_cases()), help="comma-separated cases (default: all)")
    ap.add_argument("--data", help="data folder (default: ../shared/data or $VIBR_DATA)")
    ap.add_argument("--out", default=str(ROOT / "out" / "uncertainty"))
    ap.add_argument("--cache", metavar="DIR",
                    help="keep each case's prepared scene (sources with depth) as DIR/CASE.pkl and reuse it")
    ap.add_argument("--write-docs", action="store_true", help="write the table into docs/results/paper-tables.md")
    ap.add_argument("--from-json", metavar="DIR",
                    help="rebuild the tables (and with --write-docs the section) from the CASE.json reports "
                         "a previous run wrote to DIR, without rendering")
    ap.add_argument("--figure", metavar="PNG", help="only draw the synthetic planar-proxy figure (σ map) to PNG")
    ap.add_argument("--paper-settings", action="store_true",
                    help="render at the former explicit settings (cotton 1, 1, 0.1; fountain 0.1, 1, 0.002)")
    a = ap.parse_args(argv)
    PAPER_SETTINGS[0] = a.paper_settings
    if a.figure:
        planar_figure(a.figure)
        return
    data = data_dir(a.data)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    log = lambda msg: print(f"[{time.perf_counter() - t0:7.1f} s] {msg}", flush=True)  # noqa: E731
    reports, scenes = [], {}
    for case in [c.strip() for c in a.cases.split(",") if c.strip()]:
        if a.from_json:
            reports.append(json.loads((Path(a.from_json) / f"{case}.json").read_text()))
            continue
        rep = run_case(case, data, scenes, log, a.cache)
        (out / f"{case}.json").write_text(json.dumps(rep, indent=1))
        plot_curves(rep, out / f"{case}_sparsification.png")
        reports.append(rep)
    if a.from_json:
        t0 -= sum(r["seconds"] for r in reports)  # the run time of the renders it reports
    report = [r for r in reports if split(r["case"]) == "report"]
    print(choose_table(reports))
    print()
    print(table(report))
    print()
    print(variant_table(reports))
    print(targets(reports))
    choice = choose(reports)[0]
    if a.write_docs:
        cmd = "python benchmarks/quality/uncertainty_table.py --write-docs" + (
            "" if a.cases == ",".join(all_cases()) else f" --cases {shlex.quote(a.cases)}") + (
            " --cache CACHE" if a.cache and not a.from_json else "")
        if a.from_json:
            cmd = (f"python benchmarks/quality/uncertainty_table.py --cache CACHE --out {a.from_json} --cases …` "
                   "(processes in parallel, one per group of cases; CACHE keeps the prepared scenes), then `"
                   f"{cmd} --from-json {a.from_json}")
        write_docs(reports, cmd, time.perf_counter() - t0)
        print(f"wrote {PAGE.relative_to(ROOT)}")
    if choice != CHOSEN:
        sys.exit(f"uncertainty_table.py: the choose half prefers the terms {choice!r} to the library's {CHOSEN!r}: "
                 "set vibr.render.uncertainty.TERMS")
    low = [f"{r['case']} ρ {r['rows'][f'vibr[{CHOSEN}]']['spearman']:.2f}" for r in reports
           if r["case"].startswith("fountain") and r["rows"][f"vibr[{CHOSEN}]"]["spearman"] < SPEARMAN_FLOOR]
    if low:
        sys.exit(f"uncertainty_table.py: BELOW floor (Spearman ρ ≥ {SPEARMAN_FLOOR:g} on fountain): " + ", ".join(low))


if __name__ == "__main__":
    main()
