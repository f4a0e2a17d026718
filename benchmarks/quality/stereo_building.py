"""Why the plane sweep leaves fountain-P11's right-hand building without depth, and what the
held-out view 0005 shows there (docs/explanation/depth.md, "Known limits").

View 0005 held out, the other 10 photos at scale 0.25 with depth estimated without it (through
the depth cache, :func:`vibr.stereo.cache.estimated_depth`). The building region is a fixed
rectangle of view 0005: right of the wall's corner and above the ground (:data:`REGION`,
fractions of the image). The script prints:

1. the default ``gradient`` render and ULR: all-pixel, covered-pixel and building-region PSNR
   (dB, 2-px border) and the covered fraction of the image and of the region, with the
   fallback rule of ``vibr render`` (:func:`vibr.geometry.apply_fallback`);
2. for the sources nearest 0005 (0004, 0006): the depth range their sweep used, the known
   fraction of their right-hand strip (where they see the building), and the fraction of that
   strip's unknown pixels onto which the other sources' checked depth lands
   (:func:`vibr.geometry.transfer.transfer_depth`, the nearest surface), with how much of it
   lies behind the wall (farther than the view's depth range);
3. for pixels of the building in view 0006: along the pixel's ray, the three lowest local minima
   of ``1 − ZNCC`` (7×7 window, fronto-parallel) against each of 0006's stereo partners, and
   whether the ray's point is inside the partner's image at each minimum ("out");
4. with ``--seen``: whether any source sees what the region shows. For a set of pixels of one
   view, each source's lowest region mean of ``1 − ZNCC`` (7×7 windows, the pixels whose
   window lands inside the source's frame, at least half of them) over 200 fronto-parallel
   planes of that view, depth 5–80 log-spaced: for 0005's building region (the held-out
   photograph, read here only to say what the sources could have matched), for the unknown
   pixels of 0006's right-hand strip, and, as the scale of a match, for a block of the wall
   in 0006, on those planes and at its estimated depth; and, with the building region's pixels of 0005 put on planes at depth
   10, 20 and 40, the fraction of them inside each source's frame and, of those, not behind
   the depth the source knows there (more than 20 % nearer hides them);
5. with ``--variants``: view 0006 estimated again (with its consistency partners) with a depth
   range out to 10⁴ (4–10⁴), with a 13×13 window (``radius=6``), and with the views left of it
   excluded (partners 0007–0010 only): the known fraction of its right-hand strip after the
   consistency check, and before it (the sweep's confident pixels).

    python3 benchmarks/quality/stereo_building.py [--cache-dir DIR] [--png DIR] [--seen] [--variants]

``--png DIR`` writes the photo, both renders and the sources' depth maps (NaN black) there.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import data_dir  # noqa: E402

#: The building region of view 0005: (x0, x1, y0, y1) as fractions of the width and height
#: (right of the wall's corner at x ≈ 0.915 W, above the ground at y ≈ 0.70 H).
REGION = (0.92, 1.0, 0.0, 0.70)

#: Pixels of the building in view 0006 at scale 0.25 (768×512) probed in part 3.
PROBES = ((720, 230), (735, 200), (725, 40))


def region_mask(shape) -> np.ndarray:
    H, W = shape
    m = np.zeros((H, W), bool)
    x0, x1, y0, y1 = REGION
    m[int(y0 * H):int(y1 * H), int(x0 * W):int(x1 * W)] = True
    return m


def ray_minima(ref, src, x: int, y: int, radius: int = 3, eps: float = 0.002, n: int = 1500,
               depths=(4.0, 80.0)):
    """The three lowest local minima of ``1 − ZNCC`` along the ray of pixel (x, y) of view
    ``ref`` against view ``src``: [(depth, cost, inside src)]."""
    from scipy.ndimage import map_coordinates

    from vibr.stereo.planesweep import to_grey

    I, J = to_grey(ref.image).astype(float), to_grey(src.image).astype(float)
    yy, xx = np.mgrid[y - radius:y + radius + 1, x - radius:x + radius + 1]
    a = I[yy, xx].ravel()
    a = a - a.mean()
    e2 = a.size * eps * eps
    zs = 1.0 / np.linspace(1.0 / depths[1], 1.0 / depths[0], n)
    xy = np.stack([xx.ravel(), yy.ravel()], 1).astype(float)
    costs, inside = np.empty(n), np.empty(n, bool)
    c = src.camera
    for k, z in enumerate(zs):
        p, zz = c.project(ref.camera.backproject(xy, np.full(len(xy), z)))
        inside[k] = bool(((zz > 0) & (p[:, 0] >= 0) & (p[:, 1] >= 0) & (p[:, 0] <= c.width - 1)
                          & (p[:, 1] <= c.height - 1)).all())
        b = map_coordinates(J, [p[:, 1], p[:, 0]], order=1, mode="nearest")
        b = b - b.mean()
        costs[k] = 1.0 - (a * b).sum() / np.sqrt(((a * a).sum() + e2) * ((b * b).sum() + e2))
    loc = [k for k in range(1, n - 1) if costs[k] <= costs[k - 1] and costs[k] <= costs[k + 1]]
    loc = sorted(loc, key=lambda k: costs[k])[:3]
    return [(float(zs[k]), float(costs[k]), bool(inside[k])) for k in loc]


def depth_png(d, lo=4.5, hi=30.0):
    """Inverse depth between ``lo`` and ``hi`` as a colour ramp (red near, blue far), NaN black."""
    w = np.clip(np.nan_to_num((1 / d - 1 / hi) / (1 / lo - 1 / hi), nan=0.0), 0, 1)
    rgb = np.stack([w, 1 - np.abs(w - 0.5) * 2, 1 - w], -1)
    rgb[~np.isfinite(d)] = 0
    return (rgb * 255).astype(np.uint8)


def region_cost(ref_image, ref_camera, mask, src, depths, radius: int = 3, eps: float = 0.002) -> np.ndarray:
    """(len(depths),) mean ``1 − ZNCC`` over the pixels of ``mask`` in view (``ref_image``,
    ``ref_camera``) against view ``src``, the region on each fronto-parallel plane of
    ``depths`` (an entry may be an (H, W) depth map of the reference view instead); only the pixels whose whole window lands inside ``src``'s frame count, NaN
    where fewer than half of them do."""
    from scipy.ndimage import map_coordinates, uniform_filter

    from vibr.stereo.planesweep import to_grey

    H, W = mask.shape
    ys, xs = np.nonzero(mask)
    y0, y1 = max(ys.min() - radius, 0), min(ys.max() + radius + 1, H)
    x0, x1 = max(xs.min() - radius, 0), min(xs.max() + radius + 1, W)
    I = to_grey(ref_image)[y0:y1, x0:x1].astype(float)
    J = to_grey(src.image).astype(float)
    m = mask[y0:y1, x0:x1]
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(float)
    xy = np.stack([xx, yy], -1)
    c = src.camera
    size, e2 = 2 * radius + 1, eps * eps

    def box(a):
        return uniform_filter(a, size, mode="nearest")

    out = np.full(len(depths), np.nan)
    for k, z in enumerate(depths):
        zb = np.broadcast_to(np.asarray(z, float), (H, W))[y0:y1, x0:x1] if np.ndim(z) else np.full(xy.shape[:2], z)
        p, zz = c.project(ref_camera.backproject(xy, zb))
        inside = (zz > 0) & (p[..., 0] >= 0) & (p[..., 1] >= 0) & (p[..., 0] <= c.width - 1) & (p[..., 1] <= c.height - 1)
        ok = (box(inside.astype(float)) > 0.999)[m]
        if ok.mean() < 0.5:
            continue
        Jw = map_coordinates(J, [p[..., 1], p[..., 0]], order=1, mode="nearest")
        mi, mj = box(I), box(Jw)
        cov = box(I * Jw) - mi * mj
        vi, vj = np.maximum(box(I * I) - mi * mi, 0), np.maximum(box(Jw * Jw) - mj * mj, 0)
        out[k] = float(np.mean((1 - cov / np.sqrt((vi + e2) * (vj + e2)))[m][ok]))
    return out


def seen(src, tv, region) -> None:
    """Part 4: each source's best region match (lowest mean 1 − ZNCC, and its depth) for the
    building region of 0005, the unknown part of 0006's right-hand strip, and a wall block."""
    depths = np.geomspace(5.0, 80.0, 200)
    v6 = src["0006"]
    w = v6.camera.width // 10
    strip = np.zeros(v6.camera.shape, bool)
    strip[:, -w:] = ~np.isfinite(v6.depth[:, -w:])
    wall = np.zeros(v6.camera.shape, bool)
    wall[100:300, 500:600] = True
    cases = (("0005 building region (photo)", tv, region), ("0006 strip, unknown pixels", v6, strip),
             ("0006 wall block 500–600 × 100–300", v6, wall), ("the same at its estimated depth", v6, wall))
    print("\nbest region match per source, 1 − ZNCC @ depth (fronto-parallel planes 5–80; 0 perfect, 1 uncorrelated)")
    for name, ref, mask in cases:
        cells = []
        for s in src.views:
            if s.name == ref.name:
                continue
            if name.startswith("the same"):
                c = region_cost(ref.image, ref.camera, mask, s, [np.nan_to_num(ref.depth, nan=8.0)])
                cells.append(f"{s.name} {c[0]:.2f}")
                continue
            c = region_cost(ref.image, ref.camera, mask, s, depths)
            cells.append(f"{s.name} {np.nanmin(c):.2f}@{depths[np.nanargmin(c)]:.1f}" if np.isfinite(c).any()
                         else f"{s.name} out")
        print(f"  {name}: " + "  ".join(cells), flush=True)
    ys, xs = np.nonzero(region)
    xy = np.stack([xs, ys], -1).astype(float)
    print("0005's building region on a plane: % in each source's frame / % of those not hidden by its known depth")
    for z in (10.0, 20.0, 40.0):
        X = tv.camera.backproject(xy, np.full(len(xy), z))
        cells = []
        for s in src.views:
            c = s.camera
            p, zz = c.project(X)
            inside = (zz > 0) & (p[:, 0] >= 0) & (p[:, 1] >= 0) & (p[:, 0] <= c.width - 1) & (p[:, 1] <= c.height - 1)
            q = np.round(p[inside]).astype(int)
            known = s.depth[q[:, 1], q[:, 0]]
            shown = ~(np.isfinite(known) & (known < 0.8 * zz[inside]))
            cells.append(f"{s.name} {100 * inside.mean():.0f}/{100 * shown.mean() if inside.any() else 0:.0f}")
        print(f"  depth {z:g}: " + "  ".join(cells))


def variants(src) -> None:
    """Part 5: view 0006's right-hand strip, known after and before the check, per variant."""
    from vibr.stereo import estimate_depth

    left = [v.name for v in src.views if v.name < "0006"]
    cases = {"default": ({}, ()), "range 4–10⁴": (dict(depth_range=(4.0, 1e4)), ()),
             "13×13 window": (dict(radius=6), ()), "partners 0007–0010": ({}, left)}
    print("\n| view 0006 estimated with | known % of its right 10 % | before the check |")
    print("|---|---:|---:|")
    for name, (kw, excl) in cases.items():
        on = estimate_depth(src, views=["0006"], exclude=excl, **kw)["0006"].depth
        off = estimate_depth(src, views=["0006"], exclude=excl, consistency=False, **kw)["0006"].depth
        w = on.shape[1] // 10
        print(f"| {name} | {100 * np.isfinite(on[:, -w:]).mean():.1f} | {100 * np.isfinite(off[:, -w:]).mean():.1f} |",
              flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache-dir", default=None, help="depth cache folder (default: vibr's)")
    ap.add_argument("--png", default=None, help="folder for the figures")
    ap.add_argument("--seen", action="store_true", help="which source sees the region (region matches)")
    ap.add_argument("--variants", action="store_true", help="estimate view 0006 again with other settings")
    args = ap.parse_args(argv)

    from vibr.geometry import apply_fallback
    from vibr.geometry.transfer import transfer_depth
    from vibr.io import load_scene
    from vibr.metrics import psnr
    from vibr.render import render
    from vibr.stereo.cache import estimated_depth

    fo = load_scene(data_dir() / "strecha_fountain-P11", scale=0.25)
    src, tv = fo.split("0005")
    raw = estimated_depth(src, None, args.cache_dir)
    region = region_mask(tv.camera.shape)
    print(f"view 0005 held out, scale 0.25; building region {REGION} = {100 * region.mean():.1f} % of the image\n")
    print("| method | all-pixel | covered | building region | covered % | of the region |")
    print("|---|---:|---:|---:|---:|---:|")
    srcs = apply_fallback(raw, "auto")
    renders = {}
    for method in ("gradient", "ulr"):
        r = render(srcs, tv, method)
        renders[method] = r.image
        print(f"| {method} | {psnr(r.image, tv.image, border=2):.2f} | "
              f"{psnr(r.image, tv.image, r.coverage, border=2):.2f} | "
              f"{psnr(r.image, tv.image, region, border=2):.2f} | {100 * float(np.mean(r.coverage)):.1f} | "
              f"{100 * float(np.mean(r.coverage[region])):.1f} |",
              flush=True)

    stats = raw.meta.get("depth_estimation", {}).get("views", {})
    print("\n| source | depth range | known % | known % of its right 10 % | unknown there, reached by "
          "the others' depth % | of which behind the wall % |")
    print("|---|---|---:|---:|---:|---:|")
    for n in ("0004", "0006"):
        d = raw[n].depth
        dr = stats.get(n, {}).get("depth_range", (float("nan"),) * 2)
        w = d.shape[1] // 10
        strip = d[:, -w:]
        z = transfer_depth(raw, raw[n].camera, from_views=[v for v in raw.views if v.name != n])[:, -w:]
        hole = ~np.isfinite(strip)
        reached = hole & np.isfinite(z)
        behind = reached & (z > dr[1])
        print(f"| {n} | {dr[0]:.2f}–{dr[1]:.2f} | {100 * np.isfinite(d).mean():.1f} | "
              f"{100 * np.isfinite(strip).mean():.1f} | {100 * reached.sum() / max(hole.sum(), 1):.1f} | "
              f"{100 * behind.sum() / max(reached.sum(), 1):.1f} |")

    ref = src["0006"]
    partners = stats.get("0006", {}).get("neighbours", ["0007", "0004", "0008", "0003"])
    print("\nview 0006: lowest local minima of 1 − ZNCC along the ray, depth:cost (out: outside the partner)")
    for x, y in PROBES:
        print(f"  pixel ({x}, {y})")
        for p in partners + ["0009"]:
            mins = ray_minima(ref, src[p], x, y)
            tag = "" if p in partners else " (not a partner)"
            print(f"    {p}{tag}: " + "  ".join(f"{z:.1f}:{c:.2f}{'' if ins else ' out'}" for z, c, ins in mins))

    if args.seen:
        seen(raw, tv, region)
    if args.variants:
        variants(src)

    if args.png:
        from PIL import Image

        out = Path(args.png)
        out.mkdir(parents=True, exist_ok=True)
        for name, img in (("photo", tv.image), *renders.items()):
            im = (np.clip(img, 0, 1) * 255).astype(np.uint8).copy()
            x0 = int(REGION[0] * im.shape[1])
            y1 = int(REGION[3] * im.shape[0])
            im[:y1, x0] = (255, 255, 0)  # the region's left edge
            im[y1, x0:] = (255, 255, 0)  # and its bottom edge
            Image.fromarray(im).save(out / f"0005_{name}.png")
        for n in ("0004", "0006", "0008"):
            Image.fromarray(np.concatenate([(np.clip(raw[n].image, 0, 1) * 255).astype(np.uint8),
                                            depth_png(raw[n].depth)], 1)).save(out / f"depth_{n}.png")
        print(f"\nfigures in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
