"""From a shaky video to a fly-through, measured against the truth.

A hand-held video of the synthetic world (`vibr.synthetic`, ray-cast, so every frame of the
fly-through has a true image): ``--frames-in`` frames of 320×240 walking along a 40° arc
round the scene, the hand swaying (a slow random turn of ±1.5° and a drift of ±2 % of the
distance, smooth from frame to frame) and, on about two frames in three, shaking during the
exposure (the frame is the mean of 5 renders across a turn of 0.3–2.5°: motion blur of
2–15 pixels). Encoded as H.264 (crf 18), then run through vibr as a user would:

1. ``vibr calibrate VIDEO SCENE --frames N`` (vibr's choice), or the middle frame of each
   stretch calibrated as a folder (``--choice middle``, what ``ffmpeg -vf fps=...`` gives);
2. ``vibr path interpolate SCENE -o PATH --frames 48 [--smooth S]`` (time order);
3. ``vibr render SCENE --path PATH -o FRAMES/`` (depth estimated from the frames).

Each rendered frame is compared with the ray-cast truth at its camera (the path mapped into
the world by the similarity that best aligns the calibrated cameras with the true ones):
PSNR over all pixels (2-pixel border), and the path's mean turn from one frame to the next.

    python benchmarks/quality/video_flythrough.py [--frames-in 90] [--frames 30] [--smooth 0,2]
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
import time
from pathlib import Path

import numpy as np


def shaky_video(path: Path, n: int, seed: int = 0, size=(320, 240)) -> list:
    """Write the video; return each frame's true camera (the middle of its exposure)."""
    from scipy.ndimage import gaussian_filter1d
    from scipy.spatial.transform import Rotation

    from vibr.camera import Camera
    from vibr.io.video import write_video
    from vibr.synthetic import arc_cameras, default_world, render_view

    rng = np.random.default_rng(seed)
    world = default_world(0)
    base = arc_cameras(n, arc_deg=40.0, width=size[0], height=size[1])
    sway = gaussian_filter1d(rng.normal(0, 1, (n, 3)), 6, axis=0)
    sway = np.radians(1.5) * sway / np.abs(sway).max()
    drift = gaussian_filter1d(rng.normal(0, 1, (n, 3)), 6, axis=0)
    drift = 0.02 * 3.6 * drift / np.abs(drift).max()

    def turned(cam, rv, dC=0.0):
        Rc2w = Rotation.from_rotvec(rv).as_matrix() @ cam.R.T
        return Camera.from_centre(cam.K, Rc2w.T, cam.centre + dC, cam.width, cam.height)

    frames, truth = [], []
    for i, cam in enumerate(base):
        c = turned(cam, sway[i], drift[i])
        truth.append(c)
        if rng.random() < 2 / 3:  # shaken during the exposure
            axis = rng.normal(0, 1, 3)
            axis /= np.linalg.norm(axis)
            amp = np.radians(rng.uniform(0.3, 2.5))
            imgs = [render_view(world, turned(c, axis * amp * (k / 4 - 0.5)), supersample=1)[0] for k in range(5)]
            frames.append(np.mean(imgs, axis=0))
        else:
            frames.append(render_view(world, c)[0])
    write_video(path, frames, fps=30, crf=18)
    return truth


def middle_frames(video: Path, n: int, out: Path) -> Path:
    """The middle frame of each of ``n`` stretches, as a folder of photos."""
    from vibr.calib.video_frames import extract_frames

    every = extract_frames(video, out / "every", 10 ** 6)
    total = len(every.files)
    folder = out / "middle"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    for k in range(n):
        i = int((k + 0.5) * total / n)
        shutil.copy(every.files[i], folder / every.files[i].name)
    return folder


def flythrough(scene_dir: Path, truth: list, smooth: float, out: Path) -> dict:
    """Path, render, comparison with the ray-cast truth."""
    import imageio.v3 as iio

    from vibr.calib.colmap import align_cameras
    from vibr.camera import Camera
    from vibr.cli import main
    from vibr.io import load_scene
    from vibr.metrics import psnr
    from vibr.paths.camera_path import read_camera_path
    from vibr.synthetic import default_world, render_view

    scene = load_scene(scene_dir)
    kept = [int(n.split("_")[1]) for n in scene.names]
    s, Rs, t = align_cameras([v.camera for v in scene.views], [truth[k] for k in kept])
    pj, frames = out / f"path_{smooth:g}.json", out / f"frames_{smooth:g}"
    shutil.rmtree(frames, ignore_errors=True)
    assert main(["path", "interpolate", str(scene_dir), "-o", str(pj), "--frames", "48", "--smooth", str(smooth),
                 "-q"]) == 0
    t0 = time.perf_counter()
    assert main(["render", str(scene_dir), "--path", str(pj), "-o", f"{frames}/", "-q", "--overwrite"]) == 0
    seconds = time.perf_counter() - t0
    cams = read_camera_path(pj).cameras
    world = default_world(0)
    values = []
    for k, cam in enumerate(cams):
        w = Camera.from_centre(cam.K, cam.R @ Rs.T, s * Rs @ cam.centre + t, cam.width, cam.height)
        img = iio.imread(sorted(frames.glob("*.png"))[k]).astype(np.float32) / 255
        values.append(psnr(img, render_view(world, w)[0], border=2))
    turn = np.mean([np.degrees(np.arccos(np.clip((np.trace(a.R @ b.R.T) - 1) / 2, -1, 1)))
                    for a, b in zip(cams, cams[1:])])
    return {"psnr_median": float(np.median(values)), "psnr_min": float(np.min(values)), "turn": float(turn),
            "render_s": seconds}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames-in", type=int, default=90)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--smooth", default="0,2")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="/tmp/vibr_video_flythrough")
    args = ap.parse_args(argv)

    from vibr.calib.colmap import calibrate, pose_errors
    from vibr.errors import VibrInputError

    logging.getLogger("vibr").setLevel(logging.WARNING)
    out = Path(args.out)
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    video = out / "walk.mp4"
    t0 = time.perf_counter()
    truth = shaky_video(video, args.frames_in, args.seed)
    print(f"video: {args.frames_in} frames of 320x240 made in {time.perf_counter() - t0:.1f} s", flush=True)
    rows = []
    for choice in ("sharpest", "middle"):
        t0 = time.perf_counter()
        scene_dir = out / f"scene_{choice}"
        try:
            if choice == "sharpest":
                calibrate(video, scene_dir, frames=args.frames)
            else:
                calibrate(middle_frames(video, args.frames, out), scene_dir, matcher="sequential")
        except VibrInputError as exc:
            print(f"{choice}: calibration failed: {exc}", flush=True)
            continue
        info = json.loads((scene_dir / "calibration.json").read_text())
        from vibr.io import load_scene

        sc = load_scene(scene_dir)
        kept = [int(n.split("_")[1]) for n in sc.names]
        e = pose_errors([v.camera for v in sc.views], [truth[k] for k in kept])
        cal = {"registered": len(info["registered"]), "of": len(info["registered"]) + len(info["unregistered"]),
               "rot": float(e["rot_deg"].max()), "centre": 100 * float(e["centre_rel"].max()),
               "calib_s": time.perf_counter() - t0}
        for smooth in (float(x) for x in args.smooth.split(",")):
            r = flythrough(scene_dir, truth, smooth, out)
            rows.append((choice, smooth, cal, r))
            print(f"{choice} smooth {smooth:g}: {json.dumps(cal)} {json.dumps(r)}", flush=True)
    print("\n| frames | --smooth | registered | max rotation error ° | max centre error % | fly-through PSNR dB, "
          "median (min) | mean turn a frame ° | render s (the first with depth) |\n|---|---|---|---|---|---|---|---|")
    for choice, smooth, cal, r in rows:
        print(f"| {choice} | {smooth:g} | {cal['registered']}/{cal['of']} | {cal['rot']:.3f} | {cal['centre']:.2f} | "
              f"{r['psnr_median']:.2f} ({r['psnr_min']:.2f}) | {r['turn']:.3f} | {r['render_s']:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
