"""Quality of the renders: PSNR, checkerboard energy and speckles, per setting.

Scenes:

* ``cotton``: HCI 2016 cotton, centre view input_Cam040 from its 3×3 block (the 8 neighbours
  at ``--strides``), ground-truth depth, full 512×512 unless ``--crop N`` (a centred N×N
  window of every view, intrinsics shifted: for quick iterations only).
* ``fountain``: Strecha fountain-P11 view 0005 at ``--fountain-scale`` (0.25) from the 10
  others, depth estimated from those 10 (vibr.stereo.estimate_depth defaults) and cached in
  ``--depth-cache`` (an .npz; estimated on first use).

Each setting is ``method [k=v ...]`` (render parameters; ``scheme=forward|central`` is the
gradient discretisation given to compute_samples). Columns: PSNR (dB, covered pixels, 2-px
border), DSSIM, checkerboard energy of the render over the reference photo's
(:func:`vibr.metrics.checkerboard_energy`), speckles per 10,000 px of the render minus the
reference's (:func:`vibr.metrics.speckle_density`), time.

    python benchmarks/quality/quality_table.py cotton --strides 2,4 \\
        --settings "bvs" "gradient" "gradient scheme=central"
    python benchmarks/quality/quality_table.py fountain --settings "ulr" "savsr" "bvs" "gradient"
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data"


def parse_setting(text):
    method, *kv = text.split()
    params = {
        k: eval(v, {})
        if v[:1].isdigit() or v[:1] in "-.[(" or v in ("True", "False", "None")  # noqa: S307
        else v
        for k, v in (t.split("=", 1) for t in kv)
    }
    scheme = params.pop("scheme", None)
    return method, params, scheme


def crop_view(view, n):
    """The centred n×n window of a view (image, depth, intrinsics shifted)."""
    from vibr.camera import Camera

    H, W = view.shape
    y0, x0 = (H - n) // 2, (W - n) // 2
    cam = view.camera
    K = cam.K.copy()
    K[0, 2] -= x0
    K[1, 2] -= y0
    c2 = Camera(K, cam.R, cam.t, n, n, cam.source)
    dep = None if view.depth is None else np.ascontiguousarray(view.depth[y0 : y0 + n, x0 : x0 + n])
    return view.replace(image=np.ascontiguousarray(view.image[y0 : y0 + n, x0 : x0 + n]), camera=c2, depth=dep)


def cotton_cases(args):
    from vibr.io import load_scene
    from vibr.pipeline import prepare

    scene = load_scene(DATA / "hci2016_cotton")
    inv = {rc: n for n, rc in scene.meta["grid_pos"].items()}
    for s in [int(x) for x in args.strides.split(",")]:
        names = [inv[(4 + dr * s, 4 + dc * s)] for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)]
        src, tgt = prepare(scene.subset(names + ["input_Cam040"]), "input_Cam040", depth="gt")
        if args.crop:
            src = src.replace(views=[crop_view(v, args.crop) for v in src.views])
            tgt = crop_view(tgt, args.crop)
        yield f"cotton s{s}" + (f" crop{args.crop}" if args.crop else ""), src, tgt


def fountain_cases(args):
    from vibr.io import load_scene
    from vibr.pipeline import prepare

    scene = load_scene(DATA / "strecha_fountain-P11", scale=args.fountain_scale)
    cache = Path(args.depth_cache)
    if cache.exists():  # depth and sigma_z, as prepare gave them
        z = np.load(cache)
        names = [str(n) for n in z["names"]]
        if not all(f"sz_{n}" in z for n in names):
            raise SystemExit(f"{cache}: a cache without sigma_z (older script): delete it")
        src = scene.subset(names)
        sz = {n: None if z[f"sz_{n}"].ndim == 0 and np.isnan(z[f"sz_{n}"]) else z[f"sz_{n}"] for n in names}
        src = src.replace(views=[v.replace(depth=z[v.name], sigma_z=sz[v.name]) for v in src.views])
        tgt = scene["0005"]
    else:
        src, tgt = prepare(scene, "0005", depth="estimated")
        np.savez(
            cache,
            names=np.array([v.name for v in src.views]),
            **{v.name: v.depth for v in src.views},
            **{
                f"sz_{v.name}": np.asarray(v.sigma_z if v.sigma_z is not None else np.nan, np.float32)
                for v in src.views
            },
        )
    yield f"fountain 5 @{args.fountain_scale:g}", src, tgt


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", choices=("cotton", "fountain"))
    ap.add_argument("--strides", default="2,4")
    ap.add_argument("--crop", type=int, default=0)
    ap.add_argument("--fountain-scale", type=float, default=0.25)
    ap.add_argument("--depth-cache", default="/tmp/vibr_fountain5_depth.npz")
    ap.add_argument("--settings", nargs="+", default=["ulr", "savsr", "bvs", "gradient"])
    a = ap.parse_args(argv)
    from vibr.geometry import compute_samples
    from vibr.metrics import checkerboard_energy, dssim, psnr, speckle_density
    from vibr.render.api import render_samples

    cases = cotton_cases(a) if a.scene == "cotton" else fountain_cases(a)
    print("| case | setting | PSNR dB | DSSIM | checkerboard ÷ ref | speckles − ref /1e4 | s |")
    print("|---|---|---|---|---|---|---|", flush=True)
    for label, src, tgt in cases:
        Cs = np.array([v.camera.centre for v in src.views])
        samples = {}
        ref = tgt.image
        for text in a.settings:
            method, params, scheme = parse_setting(text)
            if scheme not in samples:
                samples[scheme] = compute_samples(src, tgt.camera, grad_scheme=scheme)
            t0 = time.perf_counter()
            r = render_samples(samples[scheme], method, source_centres=Cs, target_centre=tgt.camera.centre, **params)
            dt = time.perf_counter() - t0
            m = r.coverage
            cb = checkerboard_energy(r.image, m, 2) / checkerboard_energy(ref, m, 2)
            sp = speckle_density(r.image, m, 2) - speckle_density(ref, m, 2)
            print(
                f"| {label} | {text} | {psnr(r.image, ref, mask=m, border=2):.2f} | "
                f"{dssim(r.image, ref, mask=m, border=2):.0f} | {cb:.2f} | {sp:.1f} | {dt:.1f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
