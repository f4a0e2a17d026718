"""Motion-compensated flicker of a fly-through over fountain-P11: ``gradient`` against ULR.

The path is :func:`vibr.paths.camera_path.interpolate` through fountain-P11's cameras (its
default key views and order), ``--frames`` frames, the photographs loaded at ``--scale`` (the
frames are their size), depth estimated from all 11 photos (the depth cache,
:func:`vibr.stereo.cache.scene_with_depth`, with ``vibr render``'s fallback rule). Both methods
render it with :func:`vibr.paths.flythrough.render_path`; the default method also writes each
frame's depth (``depth_out``).

Flicker is measured after motion compensation by the geometry, the same warp for both
methods: each pixel of frame t+1 with a surface in the default render's depth is
back-projected, projected into frame t's camera and frame t sampled there bilinearly. A pixel
is left out when it lands outside frame t or is occluded there (its projected depth differs
from frame t's depth at the nearest pixel by more than 2 %). The flicker is the mean absolute
difference in grey levels (0-255, Rec. 601 luma of the 8-bit frames) between frame t+1 and the
warped frame t over the kept pixels, averaged over t.

"Region without stereo depth": the frame's render exposes no mask of where its depth came
from the fallback proxy, so it is rebuilt from the sources: a kept pixel of frame t+1 is in
the region when its 3D point lands, in at least one source, on a fallback pixel
(:attr:`vibr.scene.View.fallback`) whose depth agrees within 2 %, and in no source on a
measured (stereo) pixel that agrees. The region's flicker is the same mean over those pixels.

    python3 benchmarks/quality/path_flicker.py [--frames 24] [--scale 0.125] [--cache-dir DIR]
        [--work DIR] [--png DIR]

Prints a table (method | flicker overall | flicker in the region | frames) and writes
``out/path_flicker/results.json``. A measurement: exits 0 whatever the figures.
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
from _common import ROOT, data_dir  # noqa: E402

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


def sample_bilinear(img: np.ndarray, xy: np.ndarray) -> np.ndarray:
    from scipy.ndimage import map_coordinates

    return map_coordinates(img, [xy[..., 1], xy[..., 0]], order=1, mode="nearest")


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
    args = ap.parse_args(argv)

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
    per = {m: {"all": [], "region": [], "n_region": []} for m in METHODS}
    strips = {}
    mid = len(cams) // 2 - 1
    for t in range(len(cams) - 1):
        xy, keep, X = warp_to_next(cams[t], cams[t + 1], depth[t], depth[t + 1])
        region = fallback_region(sources, X, keep)
        for m in METHODS:
            g0, g1 = grey(frames[m][t]), grey(frames[m][t + 1])
            diff = np.abs(g1 - sample_bilinear(g0, xy))
            per[m]["all"].append(float(diff[keep].mean()) if keep.any() else float("nan"))
            per[m]["region"].append(float(diff[region].mean()) if region.any() else float("nan"))
            per[m]["n_region"].append(int(region.sum()))
            if t == mid:
                strips[m] = (frames[m][t], frames[m][t + 1], np.where(keep, diff, 0.0), region)
        kept = float(keep.mean())
        per.setdefault("kept", []).append(kept)
        per.setdefault("region_fraction", []).append(float(region.mean()))

    print(f"fountain-P11, {len(cams)} frames at scale {args.scale} ({cams[0].width}×{cams[0].height}); "
          f"warp kept {100 * np.mean(per['kept']):.1f} % of the pixels, region without stereo depth "
          f"{100 * np.mean(per['region_fraction']):.1f} % (mean over frames)\n")
    print("| method | flicker overall (grey levels) | flicker in the region | frames |")
    print("|---|---:|---:|---:|")
    for m in METHODS:
        a, r = np.array(per[m]["all"]), np.array(per[m]["region"])
        out[m].update(flicker_all=float(np.nanmean(a)), flicker_region=float(np.nanmean(r)),
                      per_step_all=per[m]["all"], per_step_region=per[m]["region"],
                      region_pixels=per[m]["n_region"])
        print(f"| {m} | {out[m]['flicker_all']:.2f} | {out[m]['flicker_region']:.2f} | {len(cams)} |")
    out["kept_fraction"] = per["kept"]
    out["region_fraction"] = per["region_fraction"]
    out["settings"] = {"frames": len(cams), "scale": args.scale, "depth_tol": DEPTH_TOL}
    (work / "results.json").write_text(json.dumps(out, indent=1))
    print(f"\nJSON in {work / 'results.json'}")

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
