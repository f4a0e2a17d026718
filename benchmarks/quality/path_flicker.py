"""Motion-compensated flicker of a fly-through over fountain-P11: ``gradient`` against ULR.

The path is :func:`vibr.paths.camera_path.interpolate` through fountain-P11's cameras (its
default key views and order), ``--frames`` frames, the photographs loaded at ``--scale`` (the
frames are their size), depth estimated from all 11 photos (the depth cache,
:func:`vibr.stereo.cache.scene_with_depth`, with ``vibr render``'s fallback rule). Both methods
render it with :func:`vibr.paths.flythrough.render_path`; the default method also writes each
frame's depth (``depth_out``).

Flicker is measured after motion compensation by the geometry, the same warp for both
methods: each pixel of frame t+1 with a surface in the default render's depth is
back-projected, projected into frame t's camera and frame t sampled there. A pixel is left out
when it lands outside frame t or is occluded there (its projected depth differs from frame t's
depth at the nearest pixel by more than 2 %). The flicker is the mean absolute difference in
grey levels (0-255, Rec. 601 luma of the 8-bit frames) between frame t+1 and the warped frame t
over the kept pixels, averaged over t.

Two measures are printed. The *former* samples frame t bilinearly, which blurs it by the
sub-pixel phase, so a sharper frame differs more from its warped predecessor: it counts
sharpness as flicker (``--procedural``: the ray-cast truth flickers more than the truth
blurred). The *measure* samples frame t by cubic splines and low-passes both frames by a
Gaussian of :data:`MEASURE_BLUR` px first, what a viewer sees as a change of the surface
rather than of its finest texture. Its blur was chosen on the procedural truths alone: the
smallest of 0.7, 1 and 1.5 px at which blurring the truth (0.5, 0.8, 1.2 px) never lowers
the flicker on either path (``--procedural`` prints both measures).

"Region without stereo depth": the frame's render exposes no mask of where its depth came
from the fallback proxy, so it is rebuilt from the sources: a kept pixel of frame t+1 is in
the region when its 3D point lands, in at least one source, on a fallback pixel
(:attr:`vibr.scene.View.fallback`) whose depth agrees within 2 %, and in no source on a
measured (stereo) pixel that agrees. The region's flicker is the same mean over those pixels.

``--classes`` also splits the flicker by region class. Each kept pixel of frame t+1 falls in one:
**no depth** (the region above); **silhouette band**, within 2 px of a depth edge of frame t+1
(neighbours whose log-depth differs by more than 0.03) or of a pixel the warp leaves out;
**known, textured / flat**, the rest, split by the Sobel gradient of ULR's frame t+1 (above /
at most 4 grey levels per pixel). It prints each class's share of the kept pixels, its mean
flicker per method and its contribution to the overall figure (the class's sum over the kept
pixels), then the region's flicker per step: the region's figure is an unweighted mean over
steps, so one step with a large region can carry it.

``--procedural`` measures the flicker of a *perfect* render: the ray-cast truth
(:func:`vibr.synthetic.render_view`) along a ``--frames``-frame path (:func:`interpolate`)
through procedural scenes (``make_scene`` free seed 0 with 6 views, handheld seed 1 with 7;
192×144), warped by the true depth, as is and blurred by a Gaussian of 0.5, 0.8 and 1.2 px,
with the blurred frames' PSNR against the truth. A measure that a blur lowers while the PSNR
falls counts sharpness as flicker.

    python3 benchmarks/quality/path_flicker.py [--frames 24] [--scale 0.125] [--cache-dir DIR]
        [--work DIR] [--png DIR] [--classes] [--procedural]
    python3 benchmarks/quality/path_flicker.py --far

Prints a table (method | flicker overall | flicker in the region | frames) and writes
``out/path_flicker/results.json``. A measurement: exits 0 whatever the figures.
``--far`` measures the same failure where a truth exists, instead of fountain: procedural
scenes whose far façade, seen past the back wall's corner, stereo mostly leaves without depth
(:func:`vibr.synthetic.default_world` with ``far``, the defaults' sweep's far-background
family), 7 views photographed as the sweep photographs its sources, a path through them
rendered with depth estimated from them, and the same paths with the last key turned 25° to
the right, so that it alone sees the right of its frame (as photo 0010 alone sees fountain's
tower), and those turned paths again in the standard world (no façade: what the turned key
alone sees is the back wall continued, whose completed depth is nearly right). The warp is the
truth's depth; the frames are also scored against the ray-cast truth.

``--png DIR`` writes, per method, two consecutive frames of the middle of the path and their
motion-compensated difference as one strip.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import CAPTURE, FAR_DEPTH, ROOT, data_dir  # noqa: E402

#: relative depth disagreement beyond which a warped pixel is occluded (or a source disagrees)
DEPTH_TOL = 0.02
METHODS = ("gradient", "ulr")


def grey(img: np.ndarray) -> np.ndarray:
    """Rec. 601 luma of an 8-bit RGB frame, as float grey levels (0-255)."""
    return img[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])


def warp_to_next(cam_t, cam_n, depth_t: np.ndarray, depth_n: np.ndarray):
    """For every pixel of frame t+1 (camera ``cam_n``, depth ``depth_n``, 0: no surface): where
    it lands in frame t (``xy``, H×W×2) and whether it is kept (H×W: a surface, in front of
    camera t, inside frame t for bilinear sampling, and not occluded there), plus its world
    points (H×W×3)."""
    H, W = depth_n.shape
    X = cam_n.backproject(cam_n.pixel_grid(), np.where(depth_n > 0, depth_n, 1.0))
    xy, z = cam_t.project(X)
    inside = (depth_n > 0) & (z > 0) & (xy[..., 0] >= 0) & (xy[..., 0] <= W - 1) & \
        (xy[..., 1] >= 0) & (xy[..., 1] <= H - 1)
    u = np.clip(np.rint(xy[..., 0]), 0, W - 1).astype(int)
    v = np.clip(np.rint(xy[..., 1]), 0, H - 1).astype(int)
    dt = depth_t[v, u]
    visible = (dt > 0) & (np.abs(z - dt) <= DEPTH_TOL * np.maximum(z, 1e-12))
    return xy, inside & visible, X


#: Gaussian (px) both frames are low-passed by before the measure's difference (module docstring)
MEASURE_BLUR = 1.0
#: the two measures by label: (spline order of the warp's sampling, low-pass in px)
MEASURES = {"measure": (3, MEASURE_BLUR), "former": (1, 0.0)}


def sample(img: np.ndarray, xy: np.ndarray, order: int) -> np.ndarray:
    from scipy.ndimage import map_coordinates

    return map_coordinates(img, [xy[..., 1], xy[..., 0]], order=order, mode="nearest")


def frame_difference(g0: np.ndarray, g1: np.ndarray, xy: np.ndarray, order: int = 3,
                     blur: float = MEASURE_BLUR) -> np.ndarray:
    """|frame t+1 − frame t warped| (H×W grey levels) for the grey frames ``g0``, ``g1``: both
    low-passed by a Gaussian of ``blur`` px, frame t sampled at ``xy`` by splines of ``order``
    (:data:`MEASURES`)."""
    from scipy.ndimage import gaussian_filter

    if blur:
        g0, g1 = gaussian_filter(g0, blur), gaussian_filter(g1, blur)
    return np.abs(g1 - sample(g0, xy, order))


def fallback_region(sources, X: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Pixels (of ``keep``) whose world point ``X`` lands on a fallback pixel of some source
    with agreeing depth and on no agreeing measured pixel of any source."""
    on_fallback = np.zeros(keep.shape, bool)
    on_measured = np.zeros(keep.shape, bool)
    P = X[keep]
    for v in sources.views:
        if v.depth is None:
            continue
        c = v.camera
        xy, z, ins = c.sees(P)
        u = np.clip(np.rint(xy[:, 0]), 0, c.width - 1).astype(int)
        w = np.clip(np.rint(xy[:, 1]), 0, c.height - 1).astype(int)
        d = v.depth[w, u]
        with np.errstate(invalid="ignore"):
            agree = ins & np.isfinite(d) & (np.abs(z - d) <= DEPTH_TOL * np.maximum(z, 1e-12))
        fb = v.fallback[w, u] if v.fallback is not None else np.zeros(len(P), bool)
        on_fallback[keep] |= agree & fb
        on_measured[keep] |= agree & ~fb
    return on_fallback & ~on_measured


#: log-depth step between neighbours that makes a depth edge
EDGE_LOG_DEPTH = 0.03
#: half-width (px) of the silhouette band
BAND_PX = 2
#: Sobel gradient (grey levels per pixel) above which a pixel is textured
TEXTURED = 4.0
CLASSES = ("known, textured", "known, flat", "silhouette band", "no depth")


def region_classes(depth_n: np.ndarray, keep: np.ndarray, region: np.ndarray, ref_grey: np.ndarray) -> dict:
    """Boolean masks (H×W) of the four classes (module docstring) among the kept pixels."""
    from scipy.ndimage import binary_dilation, sobel

    with np.errstate(divide="ignore", invalid="ignore"):
        ld = np.log(np.where(depth_n > 0, depth_n, np.nan))
    edge = np.zeros(depth_n.shape, bool)
    for ax in (0, 1):
        j = ~(np.abs(np.diff(ld, axis=ax)) <= EDGE_LOG_DEPTH)  # a NaN (no depth) is an edge too
        if ax == 0:
            edge[:-1] |= j
            edge[1:] |= j
        else:
            edge[:, :-1] |= j
            edge[:, 1:] |= j
    band = binary_dilation(edge | ~keep, iterations=BAND_PX) & keep & ~region
    known = keep & ~region & ~band
    tex = np.hypot(sobel(ref_grey, 0), sobel(ref_grey, 1)) / 8 > TEXTURED
    return {CLASSES[0]: known & tex, CLASSES[1]: known & ~tex, CLASSES[2]: band, CLASSES[3]: region}


def class_tables(cams, frames, depth, sources, measure: str = "measure") -> None:
    """Print the flicker per region class (``--classes``) and the region's per step, by
    ``measure`` (:data:`MEASURES`)."""
    print(f"\n{measure}:")
    share = {c: [] for c in CLASSES}
    mean = {m: {c: [] for c in CLASSES} for m in METHODS}
    contrib = {m: {c: [] for c in CLASSES} for m in METHODS}
    steps = []
    for t in range(len(cams) - 1):
        xy, keep, X = warp_to_next(cams[t], cams[t + 1], depth[t], depth[t + 1])
        cls = region_classes(depth[t + 1], keep, fallback_region(sources, X, keep), grey(frames["ulr"][t + 1]))
        n = max(int(keep.sum()), 1)
        row = [t, int(cls[CLASSES[3]].sum())]
        for m in METHODS:
            diff = frame_difference(grey(frames[m][t]), grey(frames[m][t + 1]), xy, *MEASURES[measure])
            for c, msk in cls.items():
                mean[m][c].append(float(diff[msk].mean()) if msk.any() else np.nan)
                contrib[m][c].append(float(diff[msk].sum()) / n)
            row.append(mean[m][CLASSES[3]][-1])
        for c, msk in cls.items():
            share[c].append(msk.sum() / n)
        steps.append(row)
    print("\n| class | share of kept pixels | " + " | ".join(f"{m}: mean / contribution" for m in METHODS) + " |")
    print("|---|---:|" + "---:|" * len(METHODS))
    for c in CLASSES:
        cells = " | ".join(f"{np.nanmean(mean[m][c]):.2f} / {np.mean(contrib[m][c]):.2f}" for m in METHODS)
        print(f"| {c} | {100 * np.mean(share[c]):.1f} % | {cells} |")
    print("\n| step | region pixels | " + " | ".join(METHODS) + " |")
    print("|---:|---:|" + "---:|" * len(METHODS))
    for r in steps:
        print(f"| {r[0]}→{r[0] + 1} | {r[1]} | " + " | ".join(f"{v:.2f}" for v in r[2:]) + " |")
    reg = np.array([r[2:] for r in steps], float)
    print("| mean, every step | | " + " | ".join(f"{v:.2f}" for v in np.nanmean(reg, 0)) + " |")
    print("| mean, last step left out | | " + " | ".join(f"{v:.2f}" for v in np.nanmean(reg[:-1], 0)) + " |")


def procedural_table(frames: int) -> None:
    from scipy.ndimage import gaussian_filter

    from vibr.metrics import psnr
    from vibr.paths.camera_path import interpolate
    from vibr.synthetic import default_world, make_scene, render_view

    print(f"\nray-cast truth along a {frames}-frame path, 192×144: flicker (grey levels) of the truth "
          "blurred by a Gaussian of σ px (PSNR against the truth), by the former measure and by cubic "
          "sampling after a low-pass of 0.7, 1 and 1.5 px (the measure's candidates)\n")
    blurs = (0.0, 0.5, 0.8, 1.2)
    candidates = (("former", 1, 0.0),) + tuple(("cubic, low-pass %g" % b, 3, b) for b in (0.7, 1.0, 1.5))
    print("| scene | measure | " + " | ".join(f"σ = {s}" for s in blurs) + " |")
    print("|---|---|" + "---:|" * len(blurs))
    for layout, seed, n in (("free", 0, 6), ("handheld", 1, 7)):
        sc = make_scene(layout, n_views=n, width=192, height=144, seed=seed)
        cams = list(interpolate(sc, n_frames=frames).cameras)
        world = default_world(seed)
        truth = [render_view(world, c) for c in cams]
        depth = [np.nan_to_num(d, nan=0.0) for _, d in truth]
        warps = [warp_to_next(cams[t], cams[t + 1], depth[t], depth[t + 1])[:2] for t in range(len(cams) - 1)]
        blurred = [[np.clip(gaussian_filter(img, (s, s, 0)) if s else img, 0, 1) for img, _ in truth] for s in blurs]
        grey_frames = [[grey((im * 255 + 0.5).astype(np.uint8)) for im in imgs] for imgs in blurred]
        q = [np.mean([psnr(im, img, border=2) for im, (img, _) in zip(imgs, truth)]) for imgs in blurred]
        for label, order, lp in candidates:
            cells = []
            for g, qs in zip(grey_frames, q):
                flk = np.mean([frame_difference(g[t], g[t + 1], xy, order, lp)[keep].mean()
                               for t, (xy, keep) in enumerate(warps)])
                cells.append(f"{flk:.3f} ({qs:.1f})")
            print(f"| {layout} seed {seed} | {label} | " + " | ".join(cells) + " |")


#: ``--far``'s procedural scenes: (layout, seed) of :func:`vibr.synthetic.make_scene`, 7 views,
#: the degrees the path's last key is turned right by (:func:`turned_last`) and the depth of the
#: far façade (None: the standard world, whose back wall the turned key alone sees the right of)
FAR_SCENES = tuple((lo, sd, turn, far) for turn, far in ((0.0, FAR_DEPTH), (25.0, FAR_DEPTH), (25.0, None))
                   for lo in ("free", "handheld") for sd in (0, 1))
#: truth depth beyond which a pixel shows the far façade
FAR_PIXEL = 20.0


def turned_last(scene, world, deg: float):
    """(scene, key order) for ``interpolate``: the keys in proximity order, the last one
    turned right by ``deg`` degrees about its vertical and ray-cast again, so that it alone
    sees the right of its frame (fountain's photo 0010 and its tower)."""
    import math

    from vibr.camera import Camera
    from vibr.paths.camera_path import order_by_proximity
    from vibr.synthetic import render_view

    order = order_by_proximity([v.camera for v in scene.views])
    names = [scene.views[i].name for i in order]
    if not deg:
        return scene, names
    a = math.radians(deg)
    turn = np.array([[math.cos(a), 0, -math.sin(a)], [0, 1, 0], [math.sin(a), 0, math.cos(a)]])
    last = scene.views[order[-1]]
    c = last.camera
    cam = Camera.from_centre(c.K, turn @ c.R, c.centre, c.width, c.height)
    img, depth = render_view(world, cam, scene.meta.get("supersample", 2))
    views = [v.replace(camera=cam, image=img, depth=depth) if v.name == last.name else v for v in scene.views]
    return scene.replace(views=views), names


def far_table(frames: int, work: Path, size=(192, 144)) -> dict:
    """``--far``: the fountain's failure where it can be measured against a truth. For each of
    :data:`FAR_SCENES` (the standard world, mostly with a far façade seen past the back wall's
    corner, which stereo mostly leaves without depth), the 7 views photographed as the defaults' sweep
    photographs its sources (``_common.CAPTURE``), depth estimated from them, a
    ``frames``-frame path through them rendered by each method; the warp between frames is the
    ray-cast truth's depth. Prints, per scene and method, the flicker overall, in the region
    without stereo depth (:func:`fallback_region`) and on the façade, the truth's own flicker
    on the same pixels, and the frames' mean PSNR against the ray-cast truth, all pixels and
    the façade's (2-px border)."""
    from PIL import Image

    from vibr.metrics import psnr
    from vibr.paths.camera_path import interpolate
    from vibr.paths.flythrough import frame_name
    from vibr.stereo.cache import scene_with_depth
    from vibr.synthetic import default_world, make_scene, photograph, render_view

    print(f"\nfar background: {len(FAR_SCENES)} procedural scenes, {frames} frames of {size[0]}×{size[1]}, "
          "flicker (grey levels, the measure) and PSNR against the ray-cast truth (dB)\n")
    cols = ("flicker", "no depth", "façade", "PSNR all", "PSNR façade")
    print("| scene | method | " + " | ".join(cols) + " |")
    print("|---|---|" + "---:|" * len(cols))
    out = {}
    for layout, seed, turn, far in FAR_SCENES:
        world = default_world(seed, far=far)
        sc, keys = turned_last(make_scene(layout, n_views=7, width=size[0], height=size[1], seed=seed, world=world),
                               world, turn)
        sc = photograph(sc, seed=seed, **CAPTURE)
        bare = sc.replace(views=[v.replace(depth=None, sigma_z=None) for v in sc.views])
        path = interpolate(bare, keys, n_frames=frames)
        cams = list(path.cameras)
        truth = [render_view(world, c) for c in cams]
        depth = [np.nan_to_num(d, nan=0.0) for _, d in truth]
        sources = scene_with_depth(bare, depth="estimated")
        warps = []
        for t in range(len(cams) - 1):
            xy, keep, X = warp_to_next(cams[t], cams[t + 1], depth[t], depth[t + 1])
            warps.append((xy, keep, fallback_region(sources, X, keep), keep & (depth[t + 1] > FAR_PIXEL)))
        name = (f"{layout} seed {seed}" + (f", last key turned {turn:g}°" if turn else "")
                + ("" if far else ", no façade"))
        rows = {"truth": [np.clip(img, 0, 1) for img, _ in truth]}
        for m in METHODS:
            _, fdir = render(bare, path, m, work / f"far_{layout}{seed}_{turn:g}_{far or 0:g}", None, False)
            rows[m] = [np.asarray(Image.open(fdir / frame_name(i)).convert("RGB"), np.float32) / 255
                       for i in range(len(cams))]
        out[name] = {}
        for m, imgs in rows.items():
            g = [grey((np.clip(im, 0, 1) * 255 + 0.5).astype(np.uint8)) for im in imgs]
            flk = {k: [] for k in ("all", "region", "facade")}
            for t, (xy, keep, region, facade) in enumerate(warps):
                d = frame_difference(g[t], g[t + 1], xy)
                for k, msk in (("all", keep), ("region", region), ("facade", facade)):
                    if msk.any():
                        flk[k].append(float(d[msk].mean()))
            q_all = [psnr(im, img, border=2) for im, (img, _) in zip(imgs, truth)]
            q_far = [psnr(im, img, mask=dz > FAR_PIXEL, border=2) for im, (img, _), dz in zip(imgs, truth, depth)
                     if (dz > FAR_PIXEL).any()]
            nan = float("nan")
            r = {"flicker": float(np.mean(flk["all"])), "no depth": float(np.mean(flk["region"])),
                 "façade": float(np.mean(flk["facade"])) if flk["facade"] else nan, "PSNR all": float(np.mean(q_all)),
                 "PSNR façade": float(np.mean(q_far)) if q_far else nan, "per_step_facade": flk["facade"],
                 "per_frame_psnr": q_all}
            out[name][m] = r
            cells = " | ".join("" if (m == "truth" and c.startswith("PSNR")) or np.isnan(r[c]) else f"{r[c]:.2f}"
                               for c in cols)
            print(f"| {name} | {m} | {cells} |")
    for m in METHODS:  # over the scenes that have the column
        print(f"| mean | {m} | " + " | ".join(f"{np.nanmean([out[n][m][c] for n in out]):.2f}" for c in cols) + " |")
    return out


def render(scene, path, method: str, work: Path, cache_dir, with_depth: bool):
    from vibr.paths.flythrough import render_path

    fdir = work / method
    ddir = work / "depth" if with_depth else None
    res = render_path(scene, path, fdir, method=method, depth="estimated", depth_out=ddir,
                      cache_dir=cache_dir, executor=None, progress=False)
    return res, fdir


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=24, help="frames of the path (default 24)")
    ap.add_argument("--scale", type=float, default=0.125, help="photographs' scale (default 0.125)")
    ap.add_argument("--cache-dir", default=None, help="depth cache folder (default: vibr's)")
    ap.add_argument("--work", default=str(ROOT / "out" / "path_flicker"),
                    help="frames, depth and results.json (default out/path_flicker)")
    ap.add_argument("--png", default=None, help="folder for the two-frame strips")
    ap.add_argument("--data", default=None, help="data folder (default $VIBR_DATA or ../shared/data)")
    ap.add_argument("--classes", action="store_true", help="the flicker per region class and per step")
    ap.add_argument("--procedural", action="store_true", help="the measure on a ray-cast truth, blurred")
    ap.add_argument("--far", action="store_true",
                    help="only the procedural far-background paths, against their truth (no fountain)")
    args = ap.parse_args(argv)
    if args.far:
        work = Path(args.work)
        res = far_table(args.frames, work)
        work.mkdir(parents=True, exist_ok=True)
        (work / "far.json").write_text(json.dumps(res, indent=1))
        print(f"\nJSON in {work / 'far.json'}")
        return 0

    from PIL import Image

    from vibr.io import load_scene
    from vibr.paths.camera_path import interpolate
    from vibr.paths.flythrough import depth_name, frame_name, views_for_path
    from vibr.stereo.cache import scene_with_depth

    scene = load_scene(data_dir(args.data) / "strecha_fountain-P11", scale=args.scale)
    path = interpolate(scene, n_frames=args.frames)
    cams = list(path.cameras)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    out = {}
    frames = {}
    for method in METHODS:
        res, fdir = render(scene, path, method, work, args.cache_dir, with_depth=method == "gradient")
        frames[method] = [np.asarray(Image.open(fdir / frame_name(i)).convert("RGB")) for i in range(len(cams))]
        out[method] = {"rendered": res.rendered, "seconds": res.times.get("frames")}
    # the sources as the renders saw them (same cache entry, same fallback rule)
    sources = scene_with_depth(scene, depth="estimated", cache_dir=args.cache_dir,
                               views=views_for_path(scene, cams, 8))
    depth = [np.load(work / "depth" / depth_name(i)) for i in range(len(cams))]
    per = {m: {"all": [], "region": [], "n_region": [], "former_all": [], "former_region": []} for m in METHODS}
    strips = {}
    mid = len(cams) // 2 - 1
    for t in range(len(cams) - 1):
        xy, keep, X = warp_to_next(cams[t], cams[t + 1], depth[t], depth[t + 1])
        region = fallback_region(sources, X, keep)
        for m in METHODS:
            g0, g1 = grey(frames[m][t]), grey(frames[m][t + 1])
            diffs = {name: frame_difference(g0, g1, xy, *how) for name, how in MEASURES.items()}
            for key, d in (("", diffs["measure"]), ("former_", diffs["former"])):
                per[m][key + "all"].append(float(d[keep].mean()) if keep.any() else float("nan"))
                per[m][key + "region"].append(float(d[region].mean()) if region.any() else float("nan"))
            diff = diffs["measure"]
            per[m]["n_region"].append(int(region.sum()))
            if t == mid:
                strips[m] = (frames[m][t], frames[m][t + 1], np.where(keep, diff, 0.0), region)
        kept = float(keep.mean())
        per.setdefault("kept", []).append(kept)
        per.setdefault("region_fraction", []).append(float(region.mean()))

    print(f"fountain-P11, {len(cams)} frames at scale {args.scale} ({cams[0].width}×{cams[0].height}); "
          f"warp kept {100 * np.mean(per['kept']):.1f} % of the pixels, region without stereo depth "
          f"{100 * np.mean(per['region_fraction']):.1f} % (mean over frames)\n")
    print("| method | flicker overall (grey levels) | flicker in the region | former measure: overall | "
          "former: region | frames |")
    print("|---|---:|---:|---:|---:|---:|")
    for m in METHODS:
        a, r = np.array(per[m]["all"]), np.array(per[m]["region"])
        out[m].update(flicker_all=float(np.nanmean(a)), flicker_region=float(np.nanmean(r)),
                      former_flicker_all=float(np.nanmean(per[m]["former_all"])),
                      former_flicker_region=float(np.nanmean(per[m]["former_region"])),
                      per_step_all=per[m]["all"], per_step_region=per[m]["region"],
                      region_pixels=per[m]["n_region"])
        print(f"| {m} | {out[m]['flicker_all']:.2f} | {out[m]['flicker_region']:.2f} | "
              f"{out[m]['former_flicker_all']:.2f} | {out[m]['former_flicker_region']:.2f} | {len(cams)} |")
    out["kept_fraction"] = per["kept"]
    out["region_fraction"] = per["region_fraction"]
    out["settings"] = {"frames": len(cams), "scale": args.scale, "depth_tol": DEPTH_TOL, "measure_blur": MEASURE_BLUR}
    (work / "results.json").write_text(json.dumps(out, indent=1))
    print(f"\nJSON in {work / 'results.json'}")
    if args.classes:
        for measure in MEASURES:
            class_tables(cams, frames, depth, sources, measure)
    if args.procedural:
        procedural_table(len(cams))

    if args.png and strips:
        d = Path(args.png)
        d.mkdir(parents=True, exist_ok=True)
        for m, (f0, f1, diff, region) in strips.items():
            dimg = np.repeat(np.clip(diff * 4, 0, 255)[..., None], 3, -1).astype(np.uint8)  # ×4 to see it
            dimg[region & (diff == 0)] = (0, 0, 96)
            dimg[region, 2] = np.maximum(dimg[region, 2], 96)  # the region tinted blue
            strip = np.concatenate([f0[..., :3], f1[..., :3], dimg], 1)
            Image.fromarray(strip).save(d / f"{m}_frames_{mid:02d}_{mid + 1:02d}.png")
        print(f"strips in {d}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
