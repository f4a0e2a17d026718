"""Renders at the sources' own cameras, and held-out views, with depth that has holes
(docs/explanation/renderer.md, "Fallback proxy", "A source's own camera").

Stereo leaves source pixels without depth. Before, ``fallback="auto"`` gave only the flat
ones (and the views mostly unknown) the fallback plane and dropped the textured ones, and
every fallback pixel was hidden wherever a known surface landed: a render at a source's own
camera lost what that photograph shows there. After, the textured ones are completed from
their view's known depth (:func:`vibr.geometry.proxy.complete_depth`), and a pixel the target sees along its own
ray (:func:`vibr.geometry.sampling.same_ray`) is placed with the known geometry and never
hidden.

Cases:

* fountain-P11 at scale 0.25, depth estimated (:func:`vibr.stereo.cache.estimated_depth`,
  through the depth cache): photos 0000 and 0010 rendered at their own cameras from all 11
  photos; views 0002, 0005, 0008 held out, from the other 10 with depth estimated without
  them;
* a synthetic free layout of 7 views (seeds 0, 1), exact depth with a fifth of every view's
  pixels unknown in blobs (:func:`vibr.synthetic.degrade_depth`): views 0 and 3 at their
  own cameras from all 7, view 3 held out from the 6 others.

Each row: covered % (pixels some sample reaches), the default ``gradient`` render's PSNR on
the covered pixels and on all pixels, ULR's PSNR on all pixels (dB, 2-px border), before
and after.

Then the fly-through (docs/explanation/flythrough.md, "The path file"): the path of
``vibr path interpolate SCENE --frames 2 --scale 0.25`` (frames at photos 0000 and 0010),
rendered by :func:`vibr.paths.flythrough.render_path` (8 soft-weighted sources per frame,
the default) from all 11 photos: covered % and all-pixel PSNR against the
photo at scale 0.25 (the frames are 8-bit PNGs), each frame with the centred pinhole of its vertical fov (before: what
a camera_path.json frame was) and with the photo's K (after), and the frame's sources and
weights.

    python3 benchmarks/quality/input_views.py [--cache-dir DIR] [--skip-fountain] [--size 192]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import ROOT, data_dir, holed_scene  # noqa: E402


def variants():
    """name → (the fallback rule applied to raw sources, geometry_kw of the render)."""
    from vibr.geometry import apply_fallback
    from vibr.geometry.proxy import FALLBACK_FLAT_STD, fallback_depth

    return {
        "before": (lambda s: fallback_depth(s, min_fraction=0.5, flat_std=FALLBACK_FLAT_STD),
                   {"same_ray_px": 0.0}),
        "after": (lambda s: apply_fallback(s, "auto"), {}),
    }


def fountain_cases(cache_dir):
    """(name, raw sources (NaN where stereo left no depth), target, reference view)."""
    from vibr.io import load_scene
    from vibr.stereo.cache import estimated_depth

    fo = load_scene(data_dir() / "strecha_fountain-P11", scale=0.25)
    every = estimated_depth(fo, None, cache_dir)
    for t in ("0000", "0010"):
        yield f"fountain {t} at its camera", every, fo[t].camera, fo[t]
    for t in ("0002", "0005", "0008"):
        src, tv = fo.split(t)
        yield f"fountain {t} held out", estimated_depth(src, None, cache_dir), tv, tv


def flythrough_rows(cache_dir, out_dir):
    """Per path frame: (name, before, after, sources) with before / after (covered %,
    all-pixel PSNR) and the sources ``[(name, weight), ...]`` of the frame."""
    from vibr.camera import Camera
    from vibr.io import load_scene, read_image
    from vibr.metrics import psnr
    from vibr.paths.camera_path import CameraPath, interpolate
    from vibr.paths.flythrough import render_path
    from vibr.stereo.cache import estimated_depth

    full = load_scene(data_dir() / "strecha_fountain-P11")
    fo = load_scene(data_dir() / "strecha_fountain-P11", scale=0.25)
    every = estimated_depth(fo, None, cache_dir)
    path = interpolate(full, n_frames=2, scale=0.25)
    names = [path.meta["views"][0], path.meta["views"][-1]]
    centred = [Camera(Camera.intrinsics(c.K[1, 1], c.width, c.height), c.R, c.t, c.width, c.height)
               for c in path.cameras]
    res = {}
    for variant, cams in (("before", centred), ("after", path.cameras)):
        d = Path(out_dir) / variant
        r = render_path(every, CameraPath(cams, path.fps), d, cache_dir=cache_dir, executor=None, progress=False,
                        overwrite=True)
        res[variant] = (d, r.frames)
    for i, name in enumerate(names):
        ref = fo[name].image
        row = []
        for variant in ("before", "after"):
            d, frames = res[variant]
            img = read_image(d / f"frame_{i:05d}.png")
            cov = frames[i]["coverage"]
            row.append((100 * cov, psnr(img, ref, border=2)))
        fr = res["after"][1][i]
        yield f"fountain path frame at {name}", row[0], row[1], list(zip(fr["views"], fr["weights"]))


def synthetic_cases(size: int, seeds=(0, 1)):
    for seed in seeds:
        holed = holed_scene(seed, size)
        for t in (0, 3):
            yield f"synthetic seed {seed} view {t} at its camera", holed, holed.views[t].camera, holed.views[t]
        src, tv = holed.split(3)
        yield f"synthetic seed {seed} view 3 held out", src, tv, tv


def measure(raw, target, ref):
    """variant → (covered %, covered PSNR, all-pixel PSNR, ULR all-pixel PSNR)."""
    from vibr.metrics import psnr
    from vibr.render import render

    out = {}
    for name, (rule, gkw) in variants().items():
        src = rule(raw)
        g = render(src, target, "gradient", geometry_kw=gkw)
        u = render(src, target, "ulr", geometry_kw=gkw)
        out[name] = (100 * float(np.mean(g.coverage)), psnr(g.image, ref.image, g.coverage, border=2),
                     psnr(g.image, ref.image, border=2), psnr(u.image, ref.image, border=2))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache-dir", default=None, help="depth cache folder (default: vibr's)")
    ap.add_argument("--size", type=int, default=192, help="synthetic image width")
    ap.add_argument("--skip-fountain", action="store_true")
    ap.add_argument("--frames-dir", default=str(ROOT / "out" / "input_views"),
                    help="where the fly-through's frames go (before/, after/; default out/input_views, git-ignored)")
    args = ap.parse_args(argv)
    cases = [] if args.skip_fountain else list(fountain_cases(args.cache_dir))
    cases += list(synthetic_cases(args.size))
    names = list(variants())
    print("covered % / covered-pixel PSNR / all-pixel PSNR / ULR all-pixel PSNR (dB, 2-px border)\n")
    print("| case | " + " | ".join(names) + " |")
    print("|---|" + "---|" * len(names))
    for case, raw, target, ref in cases:
        row = measure(raw, target, ref)
        print(f"| {case} | " + " | ".join("{:.1f} / {:.2f} / {:.2f} / {:.2f}".format(*row[n]) for n in names) + " |",
              flush=True)
    if args.skip_fountain:
        return 0
    print("\nfly-through frames at photos: covered % / all-pixel PSNR (dB, 2-px border), the frame as a centred "
          "pinhole of its fov (before) and with the photo's K (after); the frame's sources (weight)\n")
    print("| frame | before | after | sources |")
    print("|---|---|---|---|")
    for case, before, after, src in flythrough_rows(args.cache_dir, args.frames_dir):
        used = ", ".join(f"{n} ({w:.2f})" for n, w in src)
        print(f"| {case} | {before[0]:.1f} / {before[1]:.2f} | {after[0]:.1f} / {after[1]:.2f} | {used} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
