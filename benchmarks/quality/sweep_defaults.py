"""The defaults of ``gradient`` (gamma, lam, TV variant) chosen by a sweep across
every scene and setting at hand, with a held-out split; and ``gamma="auto"`` measured.

Cases (each one task of ``vibr.executor.run_tasks``, ``--workers N``):

* cotton (HCI 2016): centre view input_Cam040 from its 8 neighbours at strides 1, 2, 4 with
  ground-truth (gt), estimated and planar depth (9 cases);
* backgammon (HCI 2016): its centre from its 8 neighbours at strides 1 and 2, estimated depth;
* fountain-P11: views 0002, 0005, 0008 from the 10 others, estimated depth, image scale 0.25;
* temple (Middlebury templeSparseRing): templeSR0004 from its 4 best views, estimated depth;
* synthetic (``vibr.synthetic.make_scene``, exact depth, 128×128): the middle view of the
  grid, arc, free and handheld layouts from the others;
* every other view a source, as ``vibr eval`` renders by default: cotton's centre from its
  80 other views (ground-truth depth) and templeSR0004 from the 15 others (estimated depth,
  the fallback proxy where it is unknown);
* few views (``_common.sparse_cases``): the middle of 7 synthetic views of
  256×192 (grid, arc, free, handheld layouts with exact depth; a pan turned on the spot,
  without depth) from its 2 and its 4 best views, seeds 0 and 1;
* no geometry (:func:`nogeo_cases`): the middle of 7 synthetic views of
  256×192 (arc, free, hand-held layouts, seeds 0 and 1) from the 6 others, their depth
  estimated from them as ``vibr eval`` does for a scene without depth maps (the fallback
  proxy where it is unknown);
* far background (:func:`far_cases`): the same in the world with a far façade seen past the
  back wall's corner (``vibr.synthetic.default_world(far=30)``), which stereo mostly leaves
  without depth, as it does fountain's buildings (free and hand-held layouts, seeds 0 and 1);
* rings (:func:`ring_cases`): views 4 and 11 of ``vibr.synthetic.ring_scene`` (a textureless
  object on black, a textured one on grey, 160×120) from their 4 best views;
* own camera (:func:`own_camera_cases`): views 0 and 3 of 7 free-layout synthetic views
  (192×160, seeds 0 and 1, exact depth with a fifth unknown in blobs) rendered at their own
  cameras from all 7: a frame at a photograph gives that photograph back.

The procedural sources are photographed (``_common.CAPTURE``, :func:`vibr.synthetic.photograph`:
a blur of 0.5 px, an exposure gain within ±5 % per view, sensor noise of 2 grey levels, 8 bits),
as the photographs are: ray-cast images without blur, noise or exposure differences chose
settings that did not hold on the photographs. The target keeps its ray-cast image (what the
render should show; a noise or exposure of its own would only add to every method's error),
except at a source's own camera, where the render should give back the photograph.

Estimated depth is computed from the sources only (the target never takes part) and cached
on disk (``vibr.stereo.cache``, default ~/.cache/vibr): a second run is rendering only.

Settings per *choose* case: ULR, BVS and the library's family, ``gradient`` with the
preconditioned solver (``precond=True``), ULR's view prior (``view_k=4``), the gradient term's
consistency weights (``grad_consistency=24``, with the library's ``grad_coverage``), lam against
the data's sum (``lam_density=3``) and the holes filled by push-pull (``hole_fill="push-pull"``),
labelled "P V4 C D", at gamma × lam = {0.2, 0.3, 0.45, 0.6, 0.8} × {0.4, 0.6, 0.8, 1, 1.4, 2, 2.8}; and
``gamma="auto", lam="auto"`` (``vibr.render.autotune``: leave-one-source-out on the sources,
never the target image), whose tuning time is measured against the median full-size render
time of the target over the case's gradient settings (same process, same minutes: the
machine's load hits both alike).

``--all-settings`` adds the former families, whose questions docs/explanation/renderer.md
answers: TV "uniform" without the view prior over gamma × lam = {0, 0.1, 0.25, 0.5, 1} × {0.1,
0.3}; TV "samples" (spatially varying) at gamma ∈ {0.1, 0.25, 0.5}, lam 0.1 and at gamma 0.1,
lam 0.3; the view prior at lam 0.3: gamma 0.1 and 0.25, gamma 0.1 with ``grad_weighting="W"``,
gamma 0.1 with TV "samples"; the preconditioned solver at (gamma, lam) = (0, 0.3), (0.1, 0.1),
(0.1, 0.3), (0.25, 0.3) and with the view prior at gamma × lam = {0.1, 0.2, 0.3} × {0.3, 0.6,
1}, the same nine with the consistency weights and (0.2, 0.6) with the scales 12 and 48
(without C: ``grad_consistency=0``, which leaves ``grad_coverage`` no weight to scale; without
D: ``lam_density=0``, ``hole_fill="solve"``).

Each case renders every setting from one geometry stage, on the grid ``vibr render`` would
choose (:func:`vibr.render.shared_geometry`: a supersampled or coarser grid, gamma / s² for
coarser sources).

Metrics: PSNR over all pixels and over the covered pixels (those every setting of the case
reconstructed), 2-pixel border excluded, and on the covered pixels :func:`vibr.metrics.sharpness`
(the render's high-frequency energy over the photograph's), tabled for the report half. The held-out split is by scene and fixed before any
number is seen (``_common.scene_split``): every scene ``vibr.synthetic`` generates (the synthetic,
few-view, no-geometry, far-background, ring and own-camera families) is "choose", every photographed scene (cotton, backgammon,
fountain, temple) is "report". The choose cases render every setting; the default is the setting
with the best mean all-pixel PSNR over them, unless it leads the library's current default by no
more than the standard error of their difference, paired by case (then the default stays: the
settings near the optimum differ by far less than the cases do). Only then are the report cases
rendered, with the
chosen setting, ULR, BVS and the auto weights, so no photograph takes part in the choice.

    python benchmarks/quality/sweep_defaults.py --workers 2 --write-docs   # docs/results/defaults.md
    python benchmarks/quality/sweep_defaults.py --choose-only               # the choice alone, no docs
    python benchmarks/quality/sweep_defaults.py --report-only --write-docs  # the table from the JSON

Each case writes its JSON report to --out as it completes (with the commit it ran on). The run
exits 1 with a one-line reason when the chosen setting misses one of the targets (the floors
printed under "The targets"); ``--report-only`` checks them on the JSON of an earlier run.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import (  # noqa: E402  (the cases other studies share)
    CAPTURE,
    NOGEO_LAYOUTS,
    NOGEO_SEEDS,
    RESULTS,
    ROOT,
    SWEEP_BORDER,
    SceneCache,
    data_dir,
    git_commit,
    paired_gain,
    replace_block,
    replaces_default,
    scene_split,
    sparse_cases,
    sweep_cases,
    sweep_sources,
)

#: the generated page (--write-docs)
PAGE = RESULTS / "defaults.md"

GAMMAS = (0.0, 0.1, 0.25, 0.5, 1.0)
LAMS = (0.1, 0.3)
SAMPLES_GAMMAS = (0.1, 0.25, 0.5)
PV4_GAMMAS = (0.1, 0.2, 0.3)
PV4_LAMS = (0.3, 0.6, 1.0)
BEGIN, END = "<!-- q23b:begin -->", "<!-- q23b:end -->"
BORDER = SWEEP_BORDER


#: every gradient setting pins what the library's defaults may change
BASE = {"tv_weighting": "uniform", "view_k": 0, "precond": False, "grad_weighting": "visibility",
        "grad_consistency": 0.0, "lam_density": 0.0, "hole_fill": "solve"}
#: the settings labelled D: lam against the data's sum (``lam_density``, the reference density in
#: views) and the holes filled by push-pull of the solved image, over gamma × lam
LAM_DENSITY = 3.0
D_GAMMAS = (0.2, 0.3, 0.45, 0.6, 0.8)
D_LAMS = (0.4, 0.6, 0.8, 1.0, 1.4, 2.0, 2.8)
#: the gradient term's consistency scale of the settings labelled C (grey levels / px), and the
#: other scales tried at the former default's (gamma, lam)
CONSISTENCY = 24.0
CONSISTENCY_OTHERS = (12.0, 48.0)
#: the library's default before the last change of defaults: a report case renders it too, so
#: the page shows what the change did to the photographs (column "previous")
PREVIOUS = "γ0.3 λ0.8 P V4 C D"
#: the layouts of the far-background family (:func:`far_cases`)
FAR_LAYOUTS = ("free", "handheld")
#: the targets of the ring family (:func:`ring_cases`)
RING_TARGETS = (4, 11)


def settings():
    """(label, method, params) of every setting the sweep knows, in table order."""
    return [(lab, m, {**BASE, **kw} if m == "gradient" else kw) for lab, m, kw in _settings()]


def sweep_labels(all_settings=False):
    """The labels a *choose* case renders: ULR, BVS and the library's family (D) over
    :data:`D_GAMMAS` × :data:`D_LAMS`; ``all_settings`` adds the former families (no view prior,
    TVs, plain FISTA, no consistency weights), whose questions the explanation pages answer."""
    return [lab for lab, m, kw in settings()
            if all_settings or m != "gradient" or kw["lam_density"] == LAM_DENSITY]


def _settings():
    out = [("ULR", "ulr", {}), ("BVS", "bvs", {"lam": 0.1})]  # BVS at the paper's light-field lam
    out += [(f"γ{g:g} λ{l:g}", "gradient", {"gamma": g, "lam": l, "tv_weighting": "uniform"})
            for g in GAMMAS for l in LAMS]
    out += [(f"γ{g:g} λ0.1 TVs", "gradient", {"gamma": g, "lam": 0.1, "tv_weighting": "samples"})
            for g in SAMPLES_GAMMAS]
    # the spatially varying TV at the stronger lam, and ULR's view prior (view_k)
    out += [("γ0.1 λ0.3 TVs", "gradient", {"gamma": 0.1, "lam": 0.3, "tv_weighting": "samples"})]
    out += [(f"γ{g:g} λ0.3{tvs} V4{w}", "gradient",
             {"gamma": g, "lam": 0.3, "tv_weighting": tv, "view_k": 4, "grad_weighting": gw})
            for g, tvs, tv, w, gw in ((0.1, "", "uniform", "", "visibility"), (0.25, "", "uniform", "", "visibility"),
                                      (0.1, "", "uniform", " W", "W"), (0.1, " TVs", "samples", "", "visibility"))]
    # the diagonally preconditioned solver (precond=True: same energy, another metric)
    out += [(f"γ{g:g} λ{l:g} P", "gradient", {"gamma": g, "lam": l, "tv_weighting": "uniform", "precond": True})
            for g, l in ((0.0, 0.3), (0.1, 0.1), (0.1, 0.3), (0.25, 0.3))]
    # the preconditioned solver with the view prior over a wider grid: since the colour term is
    # divided by the prior-weighted density (docs/explanation/renderer.md, "Density with the view prior")
    # the same (gamma, lam) weigh the colour term up to a few times more
    out += [(f"γ{g:g} λ{l:g} P V4", "gradient", {"gamma": g, "lam": l, "tv_weighting": "uniform", "precond": True,
                                                 "view_k": 4})
            for g in PV4_GAMMAS for l in PV4_LAMS]
    # the same with the gradient term's consistency weights (docs/explanation/renderer.md, "The gradient
    # term's consistency weights"), and two other scales at (0.2, 0.6)
    pc = {"tv_weighting": "uniform", "precond": True, "view_k": 4}
    out += [(f"γ{g:g} λ{l:g} P V4 C", "gradient", {"gamma": g, "lam": l, **pc, "grad_consistency": CONSISTENCY})
            for g in PV4_GAMMAS for l in PV4_LAMS]
    out += [(f"γ0.2 λ0.6 P V4 C{c:g}", "gradient", {"gamma": 0.2, "lam": 0.6, **pc, "grad_consistency": c})
            for c in CONSISTENCY_OTHERS]
    # the TV weight against the data's sum and the holes filled by push-pull (docs/explanation/renderer.md,
    # "Few views: lam against the data's sum, holes by push-pull")
    out += [(f"γ{g:g} λ{l:g} P V4 C D", "gradient", {"gamma": g, "lam": l, **pc, "grad_consistency": CONSISTENCY,
                                                     "lam_density": LAM_DENSITY, "hole_fill": "push-pull"})
            for g in D_GAMMAS for l in D_LAMS]
    return out


def nogeo_cases():
    """The sweep's no-geometry family (not in ``_common.sweep_cases``): the middle of 7 synthetic
    views of 256×192 from the 6 others with depth estimated from them, seed 0 *choose*, seed 1
    *choose* (procedural)."""
    return [dict(kind="nogeo", layout=lo, seed=sd, name=f"no geometry {lo} seed {sd}", family="no geometry",
                 split=scene_split("nogeo"))
            for lo in NOGEO_LAYOUTS for sd in NOGEO_SEEDS]


def far_cases():
    """The sweep's far-background family: as :func:`nogeo_cases`, in the world with a far façade
    past the back wall's corner (``_common.FAR_DEPTH``), which stereo mostly leaves without
    depth, free and hand-held layouts, seeds 0 and 1 (procedural: *choose*)."""
    return [dict(kind="far", layout=lo, seed=sd, name=f"far background {lo} seed {sd}", family="far background",
                 split=scene_split("far"))
            for lo in FAR_LAYOUTS for sd in (0, 1)]


def own_camera_cases():
    """The sweep's own-camera family: a render at a source's own camera should give its
    photograph back (a fly-through starts and ends at photographs). Views 0 and 3 of
    ``_common.holed_scene`` (seeds 0 and 1: 7 free-layout views of 192×160, exact depth with a
    fifth of it unknown in blobs) from all 7 views, the fallback where the depth is unknown
    (procedural: *choose*)."""
    return [dict(kind="own camera", seed=sd, target=t, name=f"own camera seed {sd} view {t}", family="own camera",
                 split=scene_split("own camera"))
            for sd in (0, 1) for t in (0, 3)]


def ring_cases():
    """The sweep's object-on-a-backdrop family: views 4 and 11 of each :func:`vibr.synthetic.ring_scene`
    (a textureless object on black, a textured one on grey) from their 4 best views, the depth a
    matcher would find (unknown on the backdrop and the flat faces), the fallback where it is
    unknown (procedural: *choose*)."""
    return [dict(kind="ring", ring=k, target=t, name=f"ring {k} {t}", family="ring", split=scene_split("ring"))
            for k in ("textureless", "textured") for t in RING_TARGETS]


def run_case(cache, case):
    """Render one case with every setting and the auto weights; return its measurements."""
    from vibr.metrics import psnr, sharpness
    from vibr.render import shared_geometry
    from vibr.render.autotune import tune
    from vibr.render.methods import DEFAULTS

    t0 = time.perf_counter()
    src, tv = sweep_sources(cache, case, CAPTURE)
    t_depth = time.perf_counter() - t0
    # the grid and samples vibr render / vibr eval would use (gamma / s² for coarser sources)
    todo = [(lab, m, kw) for lab, m, kw in settings() if lab in case.get("labels", [lab])]
    geo = shared_geometry(src, tv, [(m, kw) for _, m, kw in todo])
    imgs, covs, secs = {}, [], []
    for label, m, kw in todo:
        t = time.perf_counter()
        r = geo.render(m, **kw)
        if m == "gradient":
            secs.append(time.perf_counter() - t)
        imgs[label] = r.image
        covs.append(np.asarray(r.coverage, bool))
    # the auto weights, tuned on the sources (the target's camera only); the budget's
    # reference: the median full-size render time of the gradient settings above
    auto = None
    if case["split"] == "choose":  # the auto weights' budget is settled on the choose half
        t = time.perf_counter()
        tuned = tune(src, tv.camera, "gradient")
        t_tune = time.perf_counter() - t
        r = geo.render("gradient", gamma=tuned.gamma, lam=tuned.lam)
        imgs["auto"] = r.image
        covs.append(np.asarray(r.coverage, bool))
        auto = {"gamma": tuned.gamma, "lam": tuned.lam, "probes": tuned.probes, "scale": tuned.scale,
                "tune_seconds": t_tune, "render_seconds": float(np.median(secs)),
                "ratio": t_tune / float(np.median(secs))}
    cover = np.logical_and.reduce(covs)
    ref = tv.image
    res = {k: {"all": float(psnr(im, ref, border=BORDER)), "covered": float(psnr(im, ref, mask=cover, border=BORDER)),
               "sharpness": float(sharpness(np.clip(im, 0, 1), ref, cover, BORDER))}
           for k, im in imgs.items()}
    rep = {**case, "size": [int(tv.camera.width), int(tv.camera.height)], "n_sources": len(src),
            "covered_fraction": float(cover.mean()), "results": res, "depth_seconds": round(t_depth, 2),
            "auto": auto, "capture": CAPTURE,
            "default_at_run": {k: DEFAULTS[k] for k in ("gamma", "lam", "tv_weighting")},
            "seconds": round(time.perf_counter() - t0, 1), "commit": git_commit()}
    if case.get("file"):  # each case as it completes: a partial run keeps what it measured
        from vibr.eval.protocol import write_report

        write_report(rep, case["file"])
    return rep


# ---------------------------------------------------------------------------------------------
def choose(reps):
    """The gradient setting the "choose" cases make the default: the best mean all-pixel PSNR
    over them (:func:`best_mean`), unless that leads the library's default by no more than the
    noise of the cases (``_common.replaces_default``: the mean gain, paired by case, at most its
    standard error); then the default stays, so that it does not follow differences the cases
    do not support."""
    ch = [r for r in reps if r["split"] == "choose"]
    best, lib = best_mean(ch), library_label()
    if best != lib and lib in gradient_labels(ch) and not replaces_default(*_scores(ch, best, lib)):
        return lib
    return best


def best_mean(reps):
    """The gradient setting with the best mean all-pixel PSNR over ``reps``."""
    return max(gradient_labels(reps), key=lambda lab: np.mean([r["results"][lab]["all"] for r in reps]))


def _scores(reps, a, b):
    """Settings ``a``'s and ``b``'s all-pixel PSNR over ``reps``, case by case (dB)."""
    return ([r["results"][a]["all"] for r in reps], [r["results"][b]["all"] for r in reps])


def gradient_labels(reps):
    """The gradient settings every report in ``reps`` rendered, in table order."""
    return [lab for lab, m, _ in settings() if m == "gradient" and all(lab in r["results"] for r in reps)]


def library_label():
    """The label of the setting equal to the library's defaults (``vibr.render.methods.DEFAULTS``)."""
    from vibr.render.methods import DEFAULTS

    for lab, m, kw in settings():
        if m == "gradient" and all(DEFAULTS[k] == v for k, v in kw.items()):
            return lab
    raise SystemExit("sweep_defaults.py: no setting of the sweep equals the library's defaults")


def grid_edges(chosen, labels):
    """The parameters ("gamma", "lam") whose value in ``chosen`` is the smallest or the largest
    its grid tried (the settings of ``labels`` equal to it but for that parameter): there the
    sweep has not located the optimum."""
    params = {lab: kw for lab, m, kw in settings() if lab in labels}
    c = params[chosen]
    edges = []
    for p in ("gamma", "lam"):
        vals = {kw[p] for kw in params.values() if all(kw.get(k) == v for k, v in c.items() if k != p)}
        if len(vals) > 1 and c[p] in (min(vals), max(vals)):
            edges.append(f"{p} {c[p]:g} is the {'largest' if c[p] == max(vals) else 'smallest'} of {sorted(vals)}")
    return edges


def report_labels(chosen):
    """What a *report* case renders: the chosen setting beside ULR, BVS, the library's default
    and the previous one (:data:`PREVIOUS`)."""
    return list(dict.fromkeys(["ULR", "BVS", chosen, library_label(), PREVIOUS]))


def table(reps, chosen):
    """The markdown block (between the q23b markers)."""
    from vibr.render.methods import DEFAULTS

    lib = library_label()

    params = {lab: kw for lab, _, kw in settings()}
    labs = gradient_labels([r for r in reps if r["split"] == "choose"])
    L = [BEGIN, "", "### Defaults chosen on procedural scenes, reported on photographs, generated by "
         "`benchmarks/quality/sweep_defaults.py`", "",
         "Chosen on the *choose* half (best mean all-pixel PSNR; the library's default stays unless the best "
         f"leads it by more than the standard error of their difference, paired by case): **{chosen}** "
         f"({', '.join(f'{k} {v}' for k, v in params[chosen].items())}). "
         "Labels: γ gamma, λ lam, TVs `tv_weighting=\"samples\"` (else uniform), V4 `view_k=4` "
         "(ULR's view prior), W `grad_weighting=\"W\"`, P `precond=True` (variable-metric FISTA), "
         f"C `grad_consistency={CONSISTENCY:g}` with the library's `grad_coverage` "
         f"{DEFAULTS['grad_coverage']:g} (C12, C48: other scales; without C: 0), "
         f"D `lam_density={LAM_DENSITY:g}` and `hole_fill=\"push-pull\"` (without D: 0 and \"solve\"). "
         "PSNR dB over all pixels / over the covered pixels (2-px border excluded). *oracle*: the best "
         "gradient setting of the sweep for that case (all pixels; *choose* cases only, the only ones that "
         "render every setting). *auto*: `gamma=\"auto\", lam=\"auto\"` "
         "(its choice; *tune / render*: its tuning time over the median full-size render time of the case's "
         "gradient settings).", "",
         f"Command: `python3 benchmarks/quality/sweep_defaults.py --workers 2 --write-docs`; "
         f"{len(reps)} cases. Split by scene, fixed before the sweep: every scene generated by "
         "`vibr.synthetic` is *choose* (every setting rendered; its sources photographed by "
         "`vibr.synthetic.photograph` with `benchmarks/_common.py`'s `CAPTURE`), every photographed scene is "
         "*report* (rendered after the choice with the chosen setting, ULR, BVS and the library's default only). "
         f"*library*: the library's default setting ({lib}). "
         "Estimated depth: from the sources only, cached (`vibr.stereo.cache`).", "",
         f"*previous*: the library's default before the last change of defaults ({PREVIOUS}).", "",
         "| case | split | ULR | BVS | chosen | library | previous | auto (γ, λ) | oracle (setting) | chosen − BVS | "
         "chosen − ULR | tune / render |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    f = lambda d: f"{d['all']:.2f} / {d['covered']:.2f}"  # noqa: E731
    for r in reps:
        R = r["results"]
        a = r["auto"]
        o = "—"
        if all(lab in R for lab in labs):
            orc = max(labs, key=lambda lab: R[lab]["all"])
            o = f"{R[orc]['all']:.2f} ({orc})"
        au = f"{f(R['auto'])} ({a['gamma']:g}, {a['lam']:g})" if a else "—"
        ratio = f"{a['ratio']:.2f}" if a else "—"
        prev = f(R[PREVIOUS]) if PREVIOUS in R else "—"
        L.append(f"| {r['name']} | {r['split']} | {f(R['ULR'])} | {f(R['BVS'])} | {f(R[chosen])} | "
                 f"{f(R[lib])} | {prev} | {au} | {o} | "
                 f"{R[chosen]['all'] - R['BVS']['all']:+.2f} | {R[chosen]['all'] - R['ULR']['all']:+.2f} | "
                 f"{ratio} |")
    L.append("")
    for split in ("choose", "report"):
        sub = [r for r in reps if r["split"] == split]
        if not sub:
            continue
        mean = lambda k: np.mean([r["results"][k]["all"] for r in sub])  # noqa: E731
        line = (f"* mean over {split} ({len(sub)} cases), all pixels: ULR {mean('ULR'):.2f}, BVS {mean('BVS'):.2f}, "
                f"chosen {mean(chosen):.2f}, library {mean(lib):.2f}")
        if all(PREVIOUS in r["results"] for r in sub):
            line += f", previous {mean(PREVIOUS):.2f}"
        if split == "choose":
            orc = np.mean([max(r["results"][lab]["all"] for lab in labs) for r in sub])
            line += f", auto {mean('auto'):.2f}, oracle {orc:.2f}"
        L.append(line + ".")
    ch = [r for r in reps if r["split"] == "choose"]
    best = best_mean(ch)
    if best != lib and lib in labs:
        gain, se = paired_gain(*_scores(ch, best, lib))
        L += ["", f"The best mean is {best}'s: {gain:+.3f} dB over the library's default ({lib}), standard error "
              f"{se:.3f} over the *choose* cases, paired by case: "
              + ("within the cases' noise, so the default stays." if chosen == lib else "beyond it: the new default.")]
    edges = grid_edges(chosen, labs)
    if edges and chosen != lib:
        L += ["", f"The choice lies on the edge of the grid ({'; '.join(edges)}): the optimum is not located, "
              f"so the library's default ({lib}) stays until a wider grid is swept."]
    L += ["", "The targets (all pixels, on the *report* half):", "",
          f"* chosen: {_targets(reps, chosen)}", f"* library: {_targets(reps, lib)}"]
    if all(PREVIOUS in r["results"] for r in reps if r["split"] == "report"):
        L.append(f"* previous: {_targets(reps, PREVIOUS)}")
    ratios = [r["auto"]["ratio"] for r in reps if r["auto"]]
    over = sum(x > 1.0 for x in ratios)
    L.append(f"* auto: tuning time / full-size render on the *choose* half: median {np.median(ratios):.2f}, "
             f"over the budget of 1× on {over} of {len(ratios)} cases: "
             + ("within budget." if over == 0 else "over budget, so not a default."))
    L += sharpness_table(reps, lib)
    ch = [r for r in reps if r["split"] == "choose"]
    L += ["", "Every setting on the *choose* cases, all-pixel PSNR (dB):", "",
          "| case | " + " | ".join(labs) + " |", "|---|" + "---|" * len(labs)]
    for r in ch:
        L.append(f"| {r['name']} | " + " | ".join(f"{r['results'][lab]['all']:.2f}" for lab in labs) + " |")
    L += ["", END]
    return "\n".join(L)


def sharpness_table(reps, lib):
    """How sharp the renders of the *report* half are against their photographs
    (:func:`vibr.metrics.sharpness` on the pixels every method covers), as page lines; none
    when the reports predate the measure."""
    rep = [r for r in reps if r["split"] == "report"]
    cols = ("ULR", "BVS", lib)
    if not rep or not all("sharpness" in r["results"][k] for r in rep for k in cols):
        return []
    L = ["", "Sharpness on the *report* half: the render's high-frequency energy (squared Laplacian) over the "
         "photograph's on the covered pixels (`vibr.metrics.sharpness`): 1 as sharp as the photograph, below 1 "
         "blurred, above 1 noisier.", "",
         "| case | ULR | BVS | library |", "|---|---|---|---|"]
    for r in rep:
        L.append(f"| {r['name']} | " + " | ".join(f"{r['results'][k]['sharpness']:.2f}" for k in cols) + " |")
    med = {k: np.median([r["results"][k]["sharpness"] for r in rep]) for k in cols}
    L += ["", "* median: " + ", ".join(f"{k if k != lib else 'library'} {v:.2f}" for k, v in med.items()) + "."]
    return L


def _targets(reps, k):
    """The targets for setting ``k`` on the report half, as text (a missed one says MISSED)."""
    R = {r["name"]: r["results"] for r in reps if r["split"] == "report"}
    if not R:
        return "no report case"
    out = []
    for ref, floor in (("ULR", -0.1), ("BVS", -0.05)):
        worst = min(R, key=lambda n: R[n][k]["all"] - R[n][ref]["all"])
        d = R[worst][k]["all"] - R[worst][ref]["all"]
        out.append(f"worst case − {ref} {d:+.2f} ({worst}; {'ok' if d >= floor else 'MISSED'}, ≥ {floor:+g})")
    d = np.mean([R[n][k]["all"] - R[n]["ULR"]["all"] for n in R])
    out.append(f"mean − ULR {d:+.2f} ({'ok' if d >= 0.5 else 'MISSED'}, ≥ +0.5)")
    return "; ".join(out)


def _read_done(path, case):
    """The report of ``case`` in ``path`` if it exists and rendered the settings ``case`` asks
    from sources photographed as :data:`_common.CAPTURE` says."""
    if not path.is_file():
        return None
    rep = json.loads(path.read_text())
    want = case["labels"]
    same = rep["split"] == case["split"] and rep.get("capture") == CAPTURE
    return rep if same and all(lab in rep["results"] for lab in want) else None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    ap.add_argument("--out", default=str(ROOT / "out" / "sweep_defaults"), help="JSON reports")
    ap.add_argument("--workers", type=int, metavar="N", help="run the cases on N local processes")
    ap.add_argument("--only", default="", help="comma list of case-name prefixes (e.g. cotton,synthetic)")
    ap.add_argument("--choose-only", action="store_true", help="run the choose half only and print the choice")
    ap.add_argument("--write-docs", action="store_true", help="write the table into docs/results/defaults.md")
    ap.add_argument("--resume", action="store_true",
                    help="keep the cases already reported in --out with the same settings")
    ap.add_argument("--report-only", action="store_true", help="rebuild the table from the JSON in --out")
    ap.add_argument("--all-settings", action="store_true",
                    help="the former families too (no view prior, TVs, plain FISTA, no consistency weights)")
    a = ap.parse_args(argv)
    from vibr.executor import run_tasks

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    cases = [c for c in sweep_cases() + sparse_cases() + nogeo_cases() + far_cases() + ring_cases()
             + own_camera_cases()
             if not a.only or any(c["name"].startswith(p) for p in a.only.split(","))]
    fname = lambda c: out / (c["name"].replace(" ", "_") + ".json")  # noqa: E731
    choose_cases = [c for c in cases if c["split"] == "choose"]
    report_cases = [] if a.choose_only else [c for c in cases if c["split"] == "report"]
    if a.report_only:
        reps = [json.loads(fname(c).read_text()) for c in choose_cases + report_cases if fname(c).is_file()]
        chosen = choose([r for r in reps if r["split"] == "choose"])
    else:
        # the choice first, on the procedural scenes only; the photographs are rendered after it
        t0 = time.perf_counter()
        def run(cs, desc):
            # a case whose report is on disk with the same settings is not run again (--resume)
            done = {c["name"]: _read_done(fname(c), c) for c in cs} if a.resume else {}
            todo = [{**c, "file": str(fname(c))} for c in cs if done.get(c["name"]) is None]
            new = run_tasks(run_case, todo, setup=SceneCache, setup_args=(str(data_dir(a.data)),),
                            executor=a.workers, desc=desc) if todo else []
            by = {r["name"]: r for r in new}
            return [done.get(c["name"]) or by[c["name"]] for c in cs]

        reps = run([{**c, "labels": sweep_labels(a.all_settings)} for c in choose_cases], "sweep: choose")
        chosen = choose(reps)
        print(f"# chosen on {len(reps)} procedural cases: {chosen}", file=sys.stderr)
        if report_cases:
            reps += run([{**c, "labels": report_labels(chosen)} for c in report_cases], "sweep: report")
        print(f"# {len(reps)} cases in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    block = table(reps, chosen)
    print(block)
    if a.write_docs:
        if a.only or a.choose_only:
            sys.exit("--write-docs needs the whole case list (no --only, no --choose-only)")
        replace_block(PAGE, BEGIN, END, block, title="Defaults chosen across scenes")
    missed = [x for x in _targets(reps, chosen).split("; ") if "MISSED" in x]
    if missed and not (a.only or a.choose_only):  # the targets are over the whole case list
        sys.exit(f"sweep_defaults.py: the chosen setting {chosen} is below a floor: " + "; ".join(missed))


if __name__ == "__main__":
    main()
