"""Distorted photographs (ns-process-data's OPENCV and OPENCV_FISHEYE frames): a held-out
pinhole view rendered from sources whose photographs were taken through a lens model.

The synthetic hand-held layout is ray-cast twice: as pinhole photographs (the reference
case) and through each distortion model (every pixel's 2×2 sub-pixel rays undistorted by
COLMAP's inverse of the model, ``pycolmap.Camera.cam_from_img``), with the ray-cast
orthogonal depth of each pixel centre. The distorted sources are written as a transforms.json
(``OPENCV`` k1 k2 p1 p2, or ``OPENCV_FISHEYE`` k1..k4; depth as ``depth_file_path``) and
loaded by vibr, which undistorts them (docs/explanation/calibration.md, "Distorted cameras from
elsewhere"); the same files with the distortion keys removed show what reading them as
pinhole costs. Each inner
view is held out (its pinhole photograph is the truth) and rendered by ULR and the default;
PSNR / DSSIM over the pixels both reconstruct, 2-px border, depth from the files (``gt``).

    python benchmarks/quality/distorted_sources.py [--views 7] [--size 192x144]
    python benchmarks/quality/distorted_sources.py --cost [--photo 4032x3024]
    python benchmarks/quality/distorted_sources.py --fountain [--data DIR]

``--fountain`` does it with real photographs and estimated depth: fountain-P11 at ×0.25, each
photograph resampled as taken through a barrel lens (OPENCV, k1 −0.1, k2 0.01), whose
corners see beyond the original photograph: those pixels are black and masked out
(``mask_path``). View 0005 (its original photograph the truth) from the 10 others, depth
estimated from the sources, against the same with the original photographs.

``--cost`` times the undistortion of one phone-sized photograph instead (OPENCV, f 3000 px):
the map, made once per camera, then the photograph's resampling; and the process's peak
resident memory.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import data_dir  # noqa: E402

MODELS = {
    "OPENCV": {"k1": -0.12, "k2": 0.03, "p1": 0.001, "p2": -0.0015},
    "OPENCV_FISHEYE": {"k1": 0.06, "k2": -0.02, "k3": 0.004, "k4": 0.0},
}


def distorted_photo(world, cam, model, k, ss=2):
    """The view of ``cam`` (a pinhole) taken through ``model``: image and depth."""
    from vibr.io.undistort import from_nerfstudio

    K = cam.K
    dist = from_nerfstudio(model, K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5, k, cam.width, cam.height, "")
    colmap = dist.colmap_camera()
    h, w = cam.shape
    yy, xx = np.mgrid[0:h, 0:w]
    offs = (np.arange(ss) + 0.5) / ss  # sub-pixel positions in COLMAP's pixel units
    img = np.zeros((h * w, 3), np.float64)
    for oy in offs:
        for ox in offs:
            rays = colmap.cam_from_img(np.stack([xx.ravel() + ox, yy.ravel() + oy], 1).astype(np.float64))
            d = np.concatenate([rays, np.ones((len(rays), 1))], 1) @ cam.R  # Rᵀ ray, row-wise
            _, _, col = world.raycast(cam.centre[None], d, 1.0 / np.sqrt(K[0, 0] * K[1, 1]))
            img += col / ss**2
    rays = colmap.cam_from_img(np.stack([xx.ravel() + 0.5, yy.ravel() + 0.5], 1).astype(np.float64))
    t, _, _ = world.raycast(cam.centre[None], np.concatenate([rays, np.ones((len(rays), 1))], 1) @ cam.R)
    depth = np.where(np.isfinite(t), t, 0.0).reshape(h, w).astype(np.float32)  # z of the ray is 1: t = z
    return np.clip(img.reshape(h, w, 3), 0, 1).astype(np.float32), depth


def write_scene(root: Path, views, model, k):
    from vibr.io.images import write_image

    (root / "images").mkdir(parents=True)
    frames = []
    for name, cam, img, depth in views:
        write_image(root / "images" / f"{name}.png", img, bits=16)
        np.save(root / "images" / f"{name}_depth.npy", depth)
        M = np.eye(4)
        M[:3, :3] = cam.R.T @ np.diag([1.0, -1.0, -1.0])
        M[:3, 3] = cam.centre
        K = cam.K
        frames.append({"file_path": f"images/{name}.png", "depth_file_path": f"images/{name}_depth.npy",
                       "depth_unit_scale_factor": 1.0, "transform_matrix": M.tolist(), "fl_x": K[0, 0],
                       "fl_y": K[1, 1], "cx": K[0, 2] + 0.5, "cy": K[1, 2] + 0.5, "w": cam.width,
                       "h": cam.height, "sigma_z": 0.01})
    doc = {"camera_model": model, **k, "frames": frames}
    (root / "transforms.json").write_text(json.dumps(doc))


def cost(size: str) -> None:
    import resource
    import time

    from vibr.io.undistort import _lookup, from_nerfstudio, undistort_array

    w, h = (int(x) for x in size.split("x"))
    d = from_nerfstudio("OPENCV", 3000.0, 3000.0, w / 2, h / 2, {"k1": 0.1, "k2": -0.05, "p1": 0.001}, w, h, "")
    img = np.random.default_rng(0).random((h, w, 3), dtype=np.float32)
    small = from_nerfstudio("OPENCV", 30.0, 30.0, 16.0, 16.0, {"k1": 0.1}, 32, 32, "")
    undistort_array(img[:32, :32], small)  # the compiled kernel loaded (or compiled) once
    t0 = time.perf_counter()
    _lookup(d)
    t1 = time.perf_counter()
    out = undistort_array(img, d)
    t2 = time.perf_counter()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{w}x{h} photograph -> {out.shape[1]}x{out.shape[0]} pinhole: map {t1 - t0:.2f} s (once per camera), "
          f"photograph {t2 - t1:.3f} s; peak resident memory {peak:.0f} MiB (the photograph and its copy included)")


def fountain(data) -> None:
    from scipy.ndimage import map_coordinates

    from vibr.eval.protocol import Setting, evaluate
    from vibr.io import load_scene
    from vibr.io.images import write_image
    from vibr.io.undistort import from_nerfstudio
    from vibr.scene import Scene


    orig = load_scene(data_dir(data) / "strecha_fountain-P11", scale=0.25)
    k = {"k1": -0.1, "k2": 0.01, "p1": 0.0, "p2": 0.0}
    settings = [Setting("ulr"), Setting("gradient")]
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "images").mkdir()
        (root / "masks").mkdir()
        frames = []
        for v in orig.views:
            K, (h, w) = v.camera.K, v.camera.shape
            d = from_nerfstudio("OPENCV", K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5, k, w, h, "")
            yy, xx = np.mgrid[0:h, 0:w]
            rays = d.colmap_camera().cam_from_img(np.stack([xx.ravel() + 0.5, yy.ravel() + 0.5], 1).astype(float))
            px = (K[0, 0] * rays[:, 0] + K[0, 2]).reshape(h, w)
            py = (K[1, 1] * rays[:, 1] + K[1, 2]).reshape(h, w)
            inside = (px >= 0) & (px <= w - 1) & (py >= 0) & (py <= h - 1)
            img = np.stack([map_coordinates(v.image[..., c], [py, px], order=1, mode="constant")
                            for c in range(3)], -1) * inside[..., None]
            write_image(root / "images" / f"{v.name}.png", img.astype(np.float32), bits=16)
            write_image(root / "masks" / f"{v.name}.png", inside.astype(np.float32), bits=8)
            M = np.eye(4)
            M[:3, :3] = v.camera.R.T @ np.diag([1.0, -1.0, -1.0])
            M[:3, 3] = v.camera.centre
            frames.append({"file_path": f"images/{v.name}.png", "mask_path": f"masks/{v.name}.png",
                           "transform_matrix": M.tolist(), "fl_x": K[0, 0], "fl_y": K[1, 1], "cx": K[0, 2] + 0.5,
                           "cy": K[1, 2] + 0.5, "w": w, "h": h})
        (root / "transforms.json").write_text(json.dumps({"camera_model": "OPENCV", **k, "frames": frames}))
        lens = load_scene(root)
        print(f"# fountain-P11 at x0.25, view 0005 from the 10 others (depth estimated from them); "
              f"{lens.meta['undistorted']}; masked: "
              f"{100 * np.mean([1 - u.mask.mean() for u in lens.views if u.mask is not None]):.1f} % of "
              "each photograph on average\n")
        print("| sources | ULR PSNR / DSSIM | default PSNR / DSSIM | evaluated % |")
        print("|---|---|---|---|")
        target = orig["0005"]
        for label, sc in (("original photographs", orig),
                          ("through the lens, undistorted at load, masked",
                           Scene([target] + [u for u in lens.views if u.name != "0005"], "fountain-lens"))):
            r = evaluate(sc, "0005", settings, depth="estimated", use_lpips=False)
            cells = " | ".join(f"{x['psnr']:.2f} / {x['dssim']:.0f}" for x in r["results"])
            print(f"| {label} | {cells} | {100 * r['evaluated_fraction']:.1f} |", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", type=int, default=7)
    ap.add_argument("--size", default="192x144")
    ap.add_argument("--cost", action="store_true", help="time one photograph's undistortion instead")
    ap.add_argument("--photo", default="4032x3024")
    ap.add_argument("--fountain", action="store_true", help="fountain-P11's photographs through a lens instead")
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    args = ap.parse_args(argv)
    if args.cost:
        return cost(args.photo)
    if args.fountain:
        return fountain(args.data)
    from vibr.eval.protocol import Setting, evaluate
    from vibr.io import load_scene
    from vibr.scene import Scene
    from vibr.synthetic import default_world, make_scene

    w, h = (int(x) for x in args.size.split("x"))
    exact = make_scene("handheld", n_views=args.views, width=w, height=h)
    world = default_world(0)
    settings = [Setting("ulr"), Setting("gradient")]
    print(f"# hand-held layout, {args.views} views of {w}x{h}; each inner view held out (its pinhole "
          "photograph the truth); PSNR dB / DSSIM (pixels both methods reconstruct, 2-px border)\n")
    print("| sources | " + " | ".join(f"{s.label} mean PSNR / DSSIM" for s in settings) + " | views evaluated |")
    print("|---|" + "---|" * (len(settings) + 1))
    cases = [("pinhole photographs", None, None)]
    for model, k in MODELS.items():
        cases += [(f"{model}, undistorted at load", model, k), (f"{model}, read as pinhole", model, None)]
    with tempfile.TemporaryDirectory() as tmp:
        for model, k in MODELS.items():
            views = [(v.name, v.camera, *distorted_photo(world, v.camera, model, k)) for v in exact.views]
            write_scene(Path(tmp) / model, views, model, k)
            write_scene(Path(tmp) / f"{model}-as-pinhole", views, "OPENCV", {})
        for label, model, k in cases:
            if model is None:
                sources = exact
            else:
                sources = load_scene(Path(tmp) / (model if k is not None else f"{model}-as-pinhole"))
            rows = []
            for t in range(1, args.views - 1):
                tv = exact.views[t]
                sc = Scene([tv] + [v for i, v in enumerate(sources.views) if i != t], "distorted")
                rep = evaluate(sc, tv.name, settings, depth="gt")
                res = {r["label"]: r for r in rep["results"]}
                rows.append([(res[s.label]["psnr"], res[s.label]["dssim"]) for s in settings])
            m = np.mean(rows, axis=0)
            cells = " | ".join(f"{p:.2f} / {d:.0f}" for p, d in m)
            print(f"| {label} | {cells} | {len(rows)} |", flush=True)


if __name__ == "__main__":
    main()
