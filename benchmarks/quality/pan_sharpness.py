"""How sharp the photographs are decides the few-view pans' gap to ULR (docs/explanation/renderer.md,
"Known gaps"): the few-view cases of ``sweep_defaults.py`` (the middle of 7 synthetic views
of 256×192 from its 2 and its 4 best views; the pan without depth, on the sphere round its
shared centre) with every image, sources and held-out view alike, blurred by a Gaussian of
``sigma`` pixels, as a lens and a demosaicing blur a photograph (``vibr.synthetic`` renders
with 2×2 supersampling: its object edges are sharper than a camera's). ULR against the
default ``gradient``; PSNR dB over all pixels, 2-px border.

    python benchmarks/quality/pan_sharpness.py [--sigmas 0,0.5,0.8] [--layouts pan,grid,arc,free,handheld] [--seeds 0,1]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def blurred(scene, sigma: float, depth: bool):
    """``scene`` with every image blurred by a Gaussian of ``sigma`` px (0: as is); without
    depth maps unless ``depth``."""
    from scipy import ndimage

    def one(v):
        img = ndimage.gaussian_filter(v.image, (sigma, sigma, 0)).astype(v.image.dtype) if sigma > 0 else v.image
        return v.replace(image=img) if depth else v.replace(image=img, depth=None, sigma_z=None)

    return scene.replace(views=[one(v) for v in scene.views])


def run(layout: str, n: int, seed: int, sigmas) -> list[tuple[float, float]]:
    """(ULR, default) PSNR of the middle view from its ``n`` best, per sigma."""
    from vibr.metrics import psnr
    from vibr.pipeline import prepare
    from vibr.render import render
    from vibr.synthetic import make_scene

    base = make_scene(layout, n_views=7, width=256, height=192, seed=seed)
    out = []
    for s in sigmas:
        src, tv = prepare(blurred(base, s, depth=layout != "pan"), 3, n_views=n)
        out.append(tuple(float(psnr(render(src, tv.camera, m).image, tv.image, border=2)) for m in ("ulr", "gradient")))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sigmas", default="0,0.5,0.8", help="blur sigmas in pixels (comma list)")
    ap.add_argument("--layouts", default="pan,grid,arc,free,handheld")
    ap.add_argument("--seeds", default="0,1")
    a = ap.parse_args(argv)
    sigmas = [float(x) for x in a.sigmas.split(",")]
    t0 = time.perf_counter()
    print("| case | " + " | ".join(f"σ {s:g}: ULR / default (diff)" for s in sigmas) + " |")
    print("|---|" + "---|" * len(sigmas))
    diffs: dict[str, list] = {}
    for layout in a.layouts.split(","):
        for n in (2, 4):
            for seed in (int(x) for x in a.seeds.split(",")):
                res = run(layout, n, seed, sigmas)
                diffs.setdefault(layout, []).append([d - u for u, d in res])
                cells = " | ".join(f"{u:.2f} / {d:.2f} ({d - u:+.2f})" for u, d in res)
                print(f"| {layout} from {n}, seed {seed} | {cells} |", flush=True)
    print("\nmean default − ULR (dB) per layout: " + "; ".join(
        f"{k} " + " / ".join(f"{m:+.2f}" for m in np.mean(v, axis=0)) for k, v in diffs.items())
        + f" (σ {' / '.join(f'{s:g}' for s in sigmas)})")
    print(f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
