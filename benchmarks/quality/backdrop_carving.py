"""Backgrounds from the photographs: each view's backdrop, and silhouette carving
(docs/explanation/renderer.md, "Fallback proxy"), against the former rule.

``fallback="auto"`` (:func:`vibr.geometry.apply_fallback`) gives the far plane only to each
view's backdrop (:func:`vibr.geometry.proxy.backdrop_pixels`: unknown depth, flat photograph,
connected to the image border), completes the view's other unknown pixels from its known
depth, and drops every sample whose point lands, at every depth within its ±sigma_z, on
another view's backdrop (:func:`vibr.geometry.proxy.carve_silhouettes`). The backdrop is
the whole of its flat windows; "centres" is the same rule with the backdrop its windows'
centres only (the rim within a window's radius of each silhouette completed instead);
"spread" is the same rule with the completed pixels' sigma_z widened by the spread of their
neighbourhood's depths (``complete_depth(..., spread=True)``).
"before" is the former rule: the plane at every unknown pixel of the views at least half
unknown, and at the flat unknown pixels of the others, the textured ones completed.

Protocol, fixed before any measurement. The rule has one constant of its own, the
backdrop plane's sigma_z (``BACKDROP_SIGMA_Z_REL``, ``--backdrop-sigma`` sweeps it: "after
σ=X" rows); the flat limit is ``FALLBACK_FLAT_STD`` (chosen on the depth benchmarks), the
carving tests a sample's ±sigma_z and the whole bilinear cell it lands in. Anything chosen
is chosen on the procedural rings only (:func:`vibr.synthetic.ring_scene`: a textureless object on
black, a textured object on a uniform grey backdrop, 16 views, ray-cast truth, depth
unknown where the photograph is flat or the ray misses the object); the real scenes are
reported without tuning:

* rings: views 4 and 11 from their 4 best views (given depth);
* ``--nogeo``: the sweep's no-geometry scenes (``_common.nogeo_scene``: arc, free,
  hand-held, seeds 0 and 1, the middle of 7 views from the 6 others, estimated depth),
  procedural as well, without a backdrop;
* ``--real``: Middlebury templeSR0004, 0008 and 0012 from their 4 best views (estimated
  depth); fountain-P11 at scale 0.25, views 0002, 0005, 0008 from the 10 others (estimated
  depth): a scene without a backdrop, where nothing may get worse.

Columns: PSNR (dB) of the default ``gradient`` method over all pixels and over the pixels
both renders cover (2-px border), the mean absolute error in grey levels (0-255) over the
backdrop pixels of the reference (rings: the rays that miss the object; photographs:
every channel at most 10 grey levels), and ULR's all-pixel PSNR. Targets on the temple:
backdrop error <= 2 grey levels, all-pixel PSNR >= 23 dB.

``--photographed``: the procedural sources as the defaults' sweep photographs them
(``_common.CAPTURE``: blur, exposure, sensor noise, 8 bits), the targets ray-cast.

    python3 benchmarks/quality/backdrop_carving.py [--nogeo] [--real] [--photographed] [--out DIR]   # DIR: PNGs target | before | after | ULR
    python3 benchmarks/quality/backdrop_carving.py --backdrop-sigma 0.25,0.05,0.01,0   # the sweep on the rings
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import CAPTURE, NOGEO_LAYOUTS, NOGEO_SEEDS, data_dir, nogeo_scene  # noqa: E402

BLACK = 10  # grey levels: a photograph's pixel is black when every channel is at most this


def rules(sigmas=()):
    """name → function(raw sources) → sources with that fallback ("after σ=X": "auto" with
    the backdrop plane's sigma_z X times its depth)."""
    from vibr.geometry import apply_fallback
    from vibr.geometry.proxy import (
        BACKDROP_SIGMA_Z_REL,
        FALLBACK_FLAT_STD,
        carve_silhouettes,
        fallback_depth,
    )

    def auto_with(rel=BACKDROP_SIGMA_Z_REL, core=False, spread=False):
        def rule(s):
            out = fallback_depth(s, backdrop=True, complete="spread" if spread else True, backdrop_sigma_rel=rel,
                                 backdrop_core=core)
            return carve_silhouettes(out, {n: i["backdrop_core"] for n, i in out.meta.get("fallback", {}).items()
                                           if "backdrop_core" in i})
        return rule

    out = {"before": lambda s: fallback_depth(s, min_fraction=0.5, flat_std=FALLBACK_FLAT_STD, complete=True),
           "centres": auto_with(core=True), "spread": auto_with(spread=True),
           "after": lambda s: apply_fallback(s, "auto")}
    out.update({f"after σ={x:g}": auto_with(x) for x in sigmas})
    return out


def cases(real: bool, nogeo: bool = False, capture: dict | None = None):
    """(name, raw sources, target view, backdrop mask of the target); ``capture``: the
    procedural sources photographed so (:func:`vibr.synthetic.photograph`), the targets kept."""
    from vibr.io import load_scene
    from vibr.pipeline import prepare
    from vibr.stereo.cache import scene_with_depth
    from vibr.synthetic import RING_KINDS, photograph, ring_scene

    for kind in RING_KINDS:
        sc = ring_scene(kind)
        shot = sc if capture is None else photograph(sc, **capture)
        for t in (4, 11):
            raw, tv = prepare(shot, t, n_views=4, fallback=False)
            tv = tv.replace(image=sc[tv.name].image)
            yield f"ring {kind} {t}", raw, tv, ~np.isfinite(sc.meta["truth_depth"][tv.name])
    for layout, seed in [(lo, sd) for lo in NOGEO_LAYOUTS for sd in NOGEO_SEEDS] if nogeo else []:
        src, tv, _ = nogeo_scene(layout, seed, capture)
        yield f"no geometry {layout} seed {seed}", scene_with_depth(src, depth="estimated", fallback="never"), tv, None
    if not real:
        return
    temple = load_scene(data_dir() / "middlebury_templeSparseRing")
    for t in ("templeSR0004", "templeSR0008", "templeSR0012"):
        raw, tv = prepare(temple, t, n_views=4, depth="estimated", fallback=False)
        yield t, raw, tv, tv.image.max(-1) <= BLACK / 255
    fountain = load_scene(data_dir() / "strecha_fountain-P11", scale=0.25)
    for t in ("0002", "0005", "0008"):
        raw, tv = prepare(fountain, t, depth="estimated", fallback=False)
        yield f"fountain {t}", raw, tv, None


def measure(raw, tv, backdrop, sigmas=()):
    """rule → (all-pixel PSNR, covered PSNR, backdrop grey-level error, ULR PSNR, image, ULR image)."""
    from vibr.metrics import psnr
    from vibr.render import shared_geometry

    renders = {}
    for name, rule in rules(sigmas).items():
        geo = shared_geometry(rule(raw), tv, [("gradient", {}), ("ulr", {})])
        renders[name] = (geo.render("gradient"), geo.render("ulr"))
    cover = np.logical_and.reduce([g.coverage for g, _ in renders.values()])
    out = {}
    for name, (g, u) in renders.items():
        img = np.clip(g.image, 0, 1)
        err = float(255 * np.abs(img - tv.image)[backdrop].mean()) if backdrop is not None and backdrop.any() else np.nan
        out[name] = (psnr(img, tv.image, border=2), psnr(img, tv.image, mask=cover, border=2), err,
                     psnr(u.image, tv.image, border=2), img, np.clip(u.image, 0, 1))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--real", action="store_true", help="also the temple and fountain views (estimated depth)")
    ap.add_argument("--nogeo", action="store_true", help="also the procedural scenes without depth (estimated)")
    ap.add_argument("--photographed", action="store_true",
                    help="the procedural sources photographed as the defaults' sweep's (_common.CAPTURE)")
    ap.add_argument("--out", help="folder for the PNGs target | before | after | ULR (after)")
    ap.add_argument("--backdrop-sigma", default="", metavar="X,...",
                    help="also the rule with the backdrop plane's sigma_z X times its depth (rows 'after σ=X')")
    args = ap.parse_args(argv)
    sigmas = [float(x) for x in args.backdrop_sigma.split(",") if x.strip()]
    print("| case | rule | PSNR all | PSNR covered | backdrop error (grey levels) | ULR all |")
    print("|---|---|---|---|---|---|")
    for name, raw, tv, backdrop in cases(args.real, args.nogeo, CAPTURE if args.photographed else None):
        res = measure(raw, tv, backdrop, sigmas)
        for rule, (pa, pc, err, pu, *_) in res.items():
            print(f"| {name} | {rule} | {pa:.2f} | {pc:.2f} | {err:.2f} | {pu:.2f} |", flush=True)
        if args.out:
            from PIL import Image

            strip = np.concatenate([tv.image, res["before"][4], res["after"][4], res["after"][5]], axis=1)
            Path(args.out).mkdir(parents=True, exist_ok=True)
            Image.fromarray((np.clip(strip, 0, 1) * 255 + 0.5).astype(np.uint8)).save(
                Path(args.out) / f"{name.replace(' ', '_')}.png")


if __name__ == "__main__":
    main()
