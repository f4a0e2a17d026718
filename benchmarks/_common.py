"""What the benchmark scripts share: the data folder, scene loading, the cases several studies
run, depth metrics, the machine's description and the generated pages' blocks.

A script imports this module and never another script::

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/
    from _common import SceneCache, data_dir  # noqa: E402

Everything here loads vibr lazily, so that ``--help`` stays fast.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: the generated pages (docs/results/*.md)
RESULTS = ROOT / "docs" / "results"
#: the PSNR border of the sweep's cases (pixels)
SWEEP_BORDER = 2
#: the case the studies on shared depth errors add to the sweep's (in neither half)
TEMPLE5 = "temple 0005 all 15"


# -- data, code and machine ------------------------------------------------------------------
def data_dir(arg=None) -> Path:
    """The data folder: ``arg``, else ``$VIBR_DATA``, else ``../shared/data`` beside the
    repository; exits with a one-line message when it does not exist."""
    d = Path(arg or os.environ.get("VIBR_DATA") or ROOT.parent / "shared" / "data")
    if not d.is_dir():
        sys.exit(f"data folder not found: {d} (give --data DIR or set VIBR_DATA)")
    return d


def sh(cmd) -> str:
    """A command's standard output, stripped ("" when it cannot run)."""
    try:
        return subprocess.run(cmd, capture_output=True, text=True, check=False, cwd=ROOT).stdout.strip()
    except OSError:
        return ""


def git_commit() -> str:
    """``git describe --always --dirty`` of the repository."""
    return sh(["git", "describe", "--always", "--dirty"])


def machine_description() -> list[str]:
    """The CPU lines of ``lscpu`` a reader needs to compare runs (model, cores, caches), and
    ``nproc``; ``platform.processor()`` where lscpu is missing."""
    import platform

    keep = ("Architecture", "CPU(s)", "On-line", "Model name", "Thread(s) per core", "Core(s) per",
            "Socket(s)", "CPU max MHz", "L2 cache", "L3 cache", "Hypervisor")
    lines = [ln for ln in sh(["lscpu"]).splitlines() if ln.split(":")[0].strip().startswith(keep)]
    if not lines:
        lines = [f"Model name: {platform.processor() or platform.machine()}", f"CPU(s): {os.cpu_count()}"]
    return lines + [f"nproc: {sh(['nproc']) or os.cpu_count()}"]


# -- scenes ----------------------------------------------------------------------------------
class SceneCache:
    """Per-worker context of a case runner: each scene (name, image scale) loaded once."""

    def __init__(self, data):
        self.data = Path(data)
        self.scenes = {}

    def get(self, name, scale):
        from vibr.io import load_scene

        if (name, scale) not in self.scenes:
            sc = load_scene(self.data / name, scale=scale)
            sc.meta["scale"] = scale
            self.scenes[(name, scale)] = sc
        return self.scenes[(name, scale)]


def cotton_neighbours(scene, s):
    """The 8 views around cotton's centre (input_Cam040) at stride ``s`` of the 9×9 grid."""
    inv = {rc: n for n, rc in scene.meta["grid_pos"].items()}
    return [inv[(4 + dr * s, 4 + dc * s)] for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)]


def grid_scene(rows: int, cols: int, size: int, seed: int = 0):
    """The synthetic grid of ``rows`` × ``cols`` views of ``size``² (exact depth)."""
    from vibr.synthetic import make_scene

    return make_scene("grid", width=size, height=size, seed=seed, grid=(rows, cols))


def centre_index(scene) -> int:
    """The index of a synthetic grid's centre view."""
    r, c = scene.grid
    return (r // 2) * c + c // 2


def synthetic_grid_case():
    """(name, sources, target): the synthetic 3×3 grid at 256², its centre from the 8 others."""
    from vibr.synthetic import make_scene

    sc = make_scene("grid", width=256, height=256)
    tgt = sc.views[4]
    src = sc.subset([v.name for v in sc.views if v.name != tgt.name])
    return "synthetic grid 256²", src, tgt


def cotton_gt_case(stride=2, data=None):
    """(name, sources, target): cotton's centre from its 8 neighbours at ``stride``, GT depth."""
    from vibr.io import load_scene
    from vibr.pipeline import prepare

    scene = load_scene(data_dir(data) / "hci2016_cotton")
    tgt = scene["input_Cam040"]
    src, _ = prepare(scene.subset(cotton_neighbours(scene, stride) + ["input_Cam040"]), tgt.name, depth="gt")
    return f"cotton stride {stride}, GT", src, tgt


# -- depth metrics ---------------------------------------------------------------------------
def hci_metrics(disp: np.ndarray, gt: np.ndarray, border: int = 15) -> tuple[float, float]:
    """HCI 4D LF benchmark metrics (Honauer et al. 2016): BadPix(0.07) in percent and
    MSE×100, on all pixels but a ``border``-pixel frame (the benchmark's 15 px)."""
    sl = (slice(border, -border), slice(border, -border)) if border else (slice(None),) * 2
    e = (disp - gt)[sl]
    return 100.0 * float(np.mean(np.abs(e) > 0.07)), 100.0 * float(np.mean(e ** 2))


def centre_disparity_model(sub, centre):
    """``(a, b)`` of ``d = −(a + b/z)`` for the view ``centre`` of the grid scene ``sub``."""
    from vibr.stereo.lightfield import _grid_disparity_model, grid_positions

    pos = grid_positions(sub)
    i = sub.index(centre)
    return _grid_disparity_model([v.camera for v in sub.views], i, [j for j in pos if j != i], pos)


def textured(img, r=3, thr=0.02):
    """Pixels whose (2r+1)² window has a grey-level std above ``thr`` (images in [0, 1])."""
    from scipy.ndimage import uniform_filter

    from vibr.stereo.planesweep import to_grey

    g = to_grey(img).astype(np.float64)
    m = uniform_filter(g, 2 * r + 1)
    return np.sqrt(np.maximum(uniform_filter(g * g, 2 * r + 1) - m * m, 0)) > thr


def surface_textured(img, depth, r=3, thr=0.02, tol=0.02):
    """Pixels whose own surface is textured: the grey-level std over the pixels of the
    (2r+1)² window whose exact depth is within ``tol`` (relative) of the centre's is above
    ``thr``. A flat background pixel next to a textured foreground passes :func:`textured`
    (its window holds the foreground's texture) but not this: its depth is not determined by
    local photo-consistency, since its window matches at the background's depth and at the
    foreground's alike (the "fattening" ambiguity)."""
    from vibr.stereo.planesweep import to_grey

    g = to_grey(img).astype(np.float64)
    H, W = g.shape
    d = np.where(np.isfinite(depth), depth, np.inf)
    gp = np.pad(g, r, mode="edge")
    dp = np.pad(d, r, mode="constant", constant_values=np.inf)
    s1 = np.zeros((H, W))
    s2 = np.zeros((H, W))
    n = np.zeros((H, W))
    with np.errstate(invalid="ignore"):
        for dy in range(2 * r + 1):
            for dx in range(2 * r + 1):
                m = np.abs(dp[dy:dy + H, dx:dx + W] - d) <= tol * d
                q = gp[dy:dy + H, dx:dx + W]
                s1 += m * q
                s2 += m * q * q
                n += m
    mu = s1 / np.maximum(n, 1)
    return (np.sqrt(np.maximum(s2 / np.maximum(n, 1) - mu * mu, 0)) > thr) & np.isfinite(depth)


def seen_count(scene, ref: int, views, tol: float = 0.02) -> np.ndarray:
    """How many of ``views`` see the exact 3D point of each pixel of view ``ref``: it
    projects inside the view and the view's exact depth at the nearest pixel agrees
    within ``tol`` (relative). (H, W) int."""
    cam, gt = scene[ref].camera, scene[ref].depth
    ok = np.isfinite(gt)
    X = cam.backproject(cam.pixel_grid()[ok], gt[ok])
    cnt = np.zeros(ok.sum(), int)
    for j in views:
        c, dj = scene[j].camera, scene[j].depth
        xy, zz = c.project(X)
        u = np.round(xy[:, 0]).astype(int)
        v = np.round(xy[:, 1]).astype(int)
        ins = (zz > 0) & (u >= 0) & (v >= 0) & (u < c.width) & (v < c.height)
        d = np.full(len(zz), np.nan)
        d[ins] = dj[v[ins], u[ins]]
        cnt += ins & (np.abs(d - zz) <= tol * zz)
    out = np.zeros(gt.shape, int)
    out[ok] = cnt
    return out


# -- the defaults sweep's cases (quality/sweep_defaults.py and the studies that share them) --
#: the case kinds built by ``vibr.synthetic``: the only scenes a setting is ever chosen on
PROCEDURAL_KINDS = ("synthetic", "sparse", "nogeo", "far", "ring", "own camera")


def scene_split(kind: str) -> str:
    """A case's half, by scene: every procedural scene is *choose*, every real scene *report*.

    Fixed before any sweep: a constant is chosen on scenes generated by ``vibr.synthetic`` and
    reported on the photographs, none of which takes part in the choice."""
    return "choose" if kind in PROCEDURAL_KINDS else "report"


def sweep_cases():
    """The sweep's cases, each with its family and split ("choose" / "report", by scene:
    :func:`scene_split`), in the fixed order."""
    fam = {}
    for depth in ("gt", "estimated", "planar"):
        fam[f"cotton {depth}"] = [dict(kind="cotton", depth=depth, stride=s, name=f"cotton {depth} s{s}")
                                  for s in (1, 2, 4)]
    # backgammon's ground truth covers its centre only: its sources' depth is estimated
    fam["backgammon"] = [dict(kind="backgammon", stride=s, name=f"backgammon estimated s{s}") for s in (1, 2)]
    fam["fountain"] = [dict(kind="fountain", target=t, name=f"fountain {t}") for t in ("0002", "0005", "0008")]
    fam["other"] = ([dict(kind="temple", name="temple 0004")]
                    + [dict(kind="synthetic", layout=lo, name=f"synthetic {lo}")
                       for lo in ("grid", "arc", "free", "handheld")])
    # every other view a source (what vibr eval does by default): cotton's 80, temple's 15
    fam["all views"] = [dict(kind="cotton", depth="gt", stride=0, name="cotton gt all 80"),
                        dict(kind="temple", all=True, name="temple 0004 all 15")]
    return [{**c, "family": f, "split": scene_split(c["kind"])} for f, cases in fam.items() for c in cases]


#: the layouts of the sweep's few-view family
SPARSE_LAYOUTS = ("grid", "arc", "free", "handheld", "pan")


def sparse_cases():
    """The sweep's few-view family (not in :func:`sweep_cases`, which other benchmarks share): the
    middle of 7 synthetic views of 256×192 from its 2 or 4 best, seeds 0 and 1 (procedural:
    *choose*)."""
    return [dict(kind="sparse", layout=lo, n=n, seed=sd, name=f"sparse {lo} from {n} seed {sd}", family="sparse",
                 split=scene_split("sparse"))
            for lo in SPARSE_LAYOUTS for n in (2, 4) for sd in (0, 1)]


#: the no-geometry family (:func:`nogeo_scene`): its layouts and seeds
NOGEO_LAYOUTS = ("arc", "free", "handheld")
NOGEO_SEEDS = (0, 1)


#: the far-background family: the depth of its façade (``vibr.synthetic.default_world``'s ``far``)
FAR_DEPTH = 30.0


def nogeo_scene(layout: str, seed: int, capture: dict | None = None, far: float | None = None):
    """(sources without depth, target View, the sources' exact depth by name) of a no-geometry
    case: the middle of 7 synthetic views of 256×192 and the 6 others, whose depth a user
    would have to estimate; ``capture``: the sources' images as
    :func:`vibr.synthetic.photograph` records them with these arguments (the target keeps the
    ray-cast image); ``far``: the world with a far façade past the back wall's corner at that
    depth (:func:`vibr.synthetic.default_world`)."""
    from vibr.synthetic import default_world, make_scene

    world = None if far is None else default_world(seed, far=far)
    src, tv = make_scene(layout, n_views=7, width=256, height=192, seed=seed, world=world).split(3)
    src = _captured(src, capture, seed)
    truth = {v.name: v.depth for v in src.views}
    return src.replace(views=[v.replace(depth=None, sigma_z=None) for v in src.views]), tv, truth


def holed_scene(seed: int, size: int = 192):
    """7 free-layout synthetic views of ``size`` × ``5·size/6`` whose exact depth has a fifth of
    its pixels unknown, in blobs (:func:`vibr.synthetic.degrade_depth`): what stereo leaves."""
    from vibr.synthetic import degrade_depth, make_scene

    sc = make_scene("free", n_views=7, width=size, height=size * 5 // 6, seed=seed)
    return sc.replace(views=[v.replace(depth=degrade_depth(v.depth, holes=0.2, hole_size=6, seed=i))
                             for i, v in enumerate(sc.views)])


#: How the sweep's procedural scenes are photographed (:func:`vibr.synthetic.photograph`): a
#: ray-cast image has no blur, noise or exposure difference, and photographs have all three.
#: Fixed before any sweep read them.
CAPTURE = dict(noise=2.0, blur=0.5, exposure=0.05)


def _captured(scene, capture: dict | None, seed: int = 0):
    """``scene`` photographed with ``capture`` (None: as ray-cast)."""
    from vibr.synthetic import photograph

    return scene if capture is None else photograph(scene, seed=seed, **capture)


def sweep_sources(cache, case, capture: dict | None = None):
    """(sources with depth, target View) of a sweep case; estimated depth through the depth
    cache. ``capture``: a procedural scene's sources as :func:`vibr.synthetic.photograph`
    records them with these arguments (e.g. :data:`CAPTURE`; None: as ray-cast); its target
    keeps the ray-cast image, what the render should show (an exposure or noise of its own
    would only add to every method's error), except at a source's own camera, where the
    render should give back the photograph."""
    from vibr.geometry.selection import select_views
    from vibr.pipeline import prepare
    from vibr.stereo.cache import scene_with_depth
    from vibr.synthetic import make_scene, ring_scene

    seed = case.get("seed", 0)
    if case["kind"] == "own camera":  # a source's own camera, every view a source
        from vibr.geometry import apply_fallback

        holed = _captured(holed_scene(seed), capture, seed)
        t = holed.views[case["target"]]  # renamed: a target View named as a source holds it out
        return apply_fallback(holed, "auto"), t.replace(name=f"{t.name} at its camera")
    if case["kind"] == "ring":  # the matcher-like depth of ring_scene, the fallback where unknown
        sc = ring_scene(case["ring"])
        src, tv = prepare(_captured(sc, capture), case["target"], n_views=4)  # the backdrop found in the photographs
        return src, tv.replace(image=sc[tv.name].image)
    if case["kind"] == "synthetic":
        sc = make_scene(case["layout"], width=128, height=128)
        src, tv = sc.split(len(sc) // 2)
        return _captured(src, capture), tv
    if case["kind"] == "sparse":
        sc = make_scene(case["layout"], n_views=7, width=256, height=192, seed=seed)
        if case["layout"] == "pan":  # a pan has no depth: the sphere round the shared centre
            sc = sc.replace(views=[v.replace(depth=None, sigma_z=None) for v in sc.views])
        src, tv = prepare(_captured(sc, capture, seed), 3, n_views=case["n"])
        return src, tv.replace(image=sc[tv.name].image)
    if case["kind"] in ("nogeo", "far"):
        src, tv, _ = nogeo_scene(case["layout"], seed, capture, FAR_DEPTH if case["kind"] == "far" else None)
        return scene_with_depth(src, depth="estimated"), tv
    if case["kind"] in ("cotton", "backgammon"):
        sc = cache.get(f"hci2016_{case['kind']}", 1.0)
        tname = "input_Cam040"
        names = ([v.name for v in sc.views if v.name != tname] if case["stride"] == 0
                 else cotton_neighbours(sc, case["stride"]))
    elif case["kind"] == "fountain":
        sc = cache.get("strecha_fountain-P11", 0.25)
        tname = case["target"]
        names = [v.name for v in sc.views if v.name != tname]
    else:
        sc = cache.get("middlebury_templeSparseRing", 1.0)
        tname = "templeSR0004"
        rest, tv = sc.split(tname)
        names = ([v.name for v in rest.views] if case.get("all")
                 else [rest.views[i].name for i in select_views(rest, tv.camera, 4)])
    depth = case.get("depth", "estimated")
    if depth != "estimated":
        return prepare(sc, tname, sources=names, depth=depth)
    tview = sc[tname]
    # the target takes no part; the fallback proxy where depth is unknown, as vibr eval renders it
    return scene_with_depth(sc.subset(names), depth="estimated"), tview


def temple5_sources(cache):
    """(sources, target) of :data:`TEMPLE5`: templeSR0005 from the 15 others, estimated depth,
    the fallback proxy where it is unknown."""
    from vibr.geometry import apply_fallback
    from vibr.stereo.cache import scene_with_depth

    rest, tv = cache.get("middlebury_templeSparseRing", 1.0).split("templeSR0005")
    return apply_fallback(scene_with_depth(rest, depth="estimated"), "auto"), tv


def planar_cases():
    """The sweep's cases with a plane: cotton planar, fountain, temple 0004 (4 views), synthetic."""
    keep = ("cotton planar", "fountain", "other")
    return [c for c in sweep_cases() if any(c["family"].startswith(k) for k in keep)]


def plane_sources(cache, case):
    """(sources on the plane with the default sigma_z, target view, D, that sigma_z)."""
    from vibr.geometry import planar_proxy

    src, tv = sweep_sources(cache, case)
    if case["kind"] != "cotton":  # cotton's sources are already on the plane
        src = planar_proxy(src, tv.camera)
    p = src.meta["proxy"]
    return src, tv, float(p["depth"]), float(p["sigma_z"])


#: (layout, number of views) of the planar-views study's synthetic cases
PLANAR_LAYOUTS = (("grid", 25), ("arc", 16), ("free", 16), ("handheld", 16))


def planar_view_cases(data=None):
    """(name, split, scene, target) of the planar-views study, in the fixed order: cotton's
    centre and two other views, then the synthetic layouts at seeds 0 and 1, alternating
    "choose" / "report"."""
    from vibr.synthetic import make_scene

    split = ("choose", "report")
    sc = SceneCache(data_dir(data)).get("hci2016_cotton", 1.0)
    for i, t in enumerate(("input_Cam040", "input_Cam020", "input_Cam060")):
        yield f"cotton {t}", split[i % 2], sc, t
    for i, (lo, n, seed) in enumerate((lo, n, seed) for lo, n in PLANAR_LAYOUTS for seed in (0, 1)):
        s = make_scene(lo, n_views=n, width=128, height=128, seed=seed)
        yield f"synthetic {lo} ({n} views, seed {seed})", split[i % 2], s, s.views[len(s) // 2].name


# -- the cross-scene studies of a default (shared depth errors, views that tie) ---------------
#: the three sets of cases, each with its own split
STUDY_SETS = ("sweep", "planar 4", "plane")


def study_cases():
    """The sweep's cases and :data:`TEMPLE5` (``sweep``), the planar-views cases from their 4
    best views on the plane (``planar 4``) and the plane cases but cotton's (``plane``)."""
    out = [{**c, "set": "sweep"} for c in sweep_cases()]
    out.append({"name": TEMPLE5, "split": "extra", "family": "extra", "set": "sweep"})
    out += [{"name": f"planar 4 #{i}", "index": i, "split": sp, "set": "planar 4"}
            for i, sp in enumerate(["choose", "report", "choose"] + ["choose", "report"] * 4)]
    out += [{**c, "set": "plane"} for c in planar_cases() if c["family"] != "cotton planar"]
    return out


def study_sources(cache, case):
    """(sources, target) of a :func:`study_cases` case."""
    from vibr.pipeline import prepare

    if case["set"] == "sweep":
        return temple5_sources(cache) if case["name"] == TEMPLE5 else sweep_sources(cache, case)
    if case["set"] == "plane":
        return plane_sources(cache, case)[:2]
    name, split, sc, t = list(planar_view_cases(cache.data))[case["index"]]
    assert split == case["split"]
    case["name"] = name
    return prepare(sc, t, depth="planar", n_views=4)


def run_study(run_case, summary, doc, argv=None) -> None:
    """Run ``run_case`` over :func:`study_cases` (``--workers`` processes), print the per-case
    PSNR table and ``summary(reports, labels)``."""
    from vibr.executor import run_tasks

    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    ap.add_argument("--workers", type=int, metavar="N", help="run the cases on N local processes")
    ap.add_argument("--json", help="write the per-case results here")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    reps = run_tasks(run_case, study_cases(), setup=SceneCache, setup_args=(str(data_dir(a.data)),),
                     executor=a.workers, desc="cases")
    if a.json:
        Path(a.json).write_text(json.dumps(reps, indent=1))
    labs = list(reps[0]["psnr"])
    print(md_table(["set", "case", "split", *labs],
                   [[r["set"], r["name"], r["split"], *(f"{r['psnr'][k]:.2f}" for k in labs)] for r in reps]))
    summary(reps, labs)
    print(f"\n{len(reps)} cases in {time.perf_counter() - t0:.0f} s")


# -- the choice of a default -------------------------------------------------------------------
def paired_gain(challenger, default) -> tuple[float, float]:
    """(mean, standard error) of ``challenger − default``, two scores per case paired by case
    (higher better: dB; pass AUSE negated)."""
    d = np.asarray(challenger, float) - np.asarray(default, float)
    return float(d.mean()), float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else float("inf")


def replaces_default(challenger, default) -> bool:
    """The studies' tie rule: a challenger with a better mean replaces the default only when its
    gain, paired by case, exceeds the gain's standard error (:func:`paired_gain`); settings near
    the optimum differ by far less than the cases do, and a default should not follow that."""
    gain, se = paired_gain(challenger, default)
    return gain > se


# -- tables and generated pages --------------------------------------------------------------
def md_table(header, rows) -> str:
    """A markdown table: ``header`` cells, then one line per row."""
    out = ["| " + " | ".join(map(str, header)) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(map(str, r)) + " |" for r in rows]
    return "\n".join(out)


def replace_block(path, begin: str, end: str, block: str, title: str = "") -> None:
    """Put ``block`` (which starts with ``begin`` and ends with ``end``) into the page
    ``path``: in place of the old block, else appended; a missing page is created with the
    heading ``title``. Nothing outside the markers changes."""
    path = Path(path)
    old = path.read_text() if path.exists() else (f"# {title}\n" if title else "")
    if begin in old and end in old:
        new = re.sub(re.escape(begin) + ".*?" + re.escape(end), lambda _: block, old, flags=re.S)
    else:
        new = old.rstrip("\n") + "\n\n" + block + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(new)
