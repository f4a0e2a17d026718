"""Calibration from a hand-held video: does keeping the sharpest frame of each stretch pay?

A video of fountain-P11 as a shaking hand would film it, made from the scene's 11 real
photographs (``--scale``, default 0.25 → 768×512): each photograph becomes a stretch of
``--per-view`` frames (default 5), one of them sharp at a random place in the stretch, the
others blurred by a motion of 6–24 pixels in a random direction (horizontal, vertical or
diagonal). The video is encoded as H.264 (crf 18) and calibrated twice, alternately:

* **sharpest**: ``vibr calibrate VIDEO --frames 11`` (vibr's choice in each stretch);
* **middle**: the middle frame of each stretch, the frames a fixed-rate extraction
  (``ffmpeg -vf fps=...``) gives, calibrated as a folder with the same sequential matcher.

and, once, the 11 photographs themselves at the same size (no blur, no video coding) as a
folder with the same matcher: the floor. Each is compared with the ground-truth cameras of
the photographs behind its frames
(:func:`vibr.calib.colmap.pose_errors`, similarity fitted to the poses): registered frames,
sparse points, reprojection error, largest rotation and centre errors, time.

``--speed`` measures instead how fast a video is read: 240 frames of 1920×1080 (fountain's
photographs at ×0.625, cropped, each shown for 22 frames with a 0–6 pixel shake), H.264 at
crf 20, read with :func:`vibr.calib.video_frames.extract_frames` keeping 60 (three runs).

    python benchmarks/quality/video_calibration.py [--data ../shared/data] [--seeds 0,1,2] [--speed]
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
DIRECTIONS = ((0, 1), (1, 0), (1, 1), (1, -1))


def motion_blur(img: np.ndarray, length: int, direction) -> np.ndarray:
    """The mean of ``img`` shifted 0 … length−1 pixels along ``direction`` (edges repeated)."""
    dy, dx = direction
    pad = length
    p = np.pad(img, ((pad, pad), (pad, pad), (0, 0)), mode="edge")
    acc = np.zeros_like(p)
    for s in range(length):
        acc += np.roll(p, (s * dy - length // 2 * dy, s * dx - length // 2 * dx), axis=(0, 1))
    return (acc / length)[pad:-pad, pad:-pad]


def make_video(scene, path: Path, per_view: int, rng) -> list[int]:
    """Write the shaken video; return the frame number of each stretch's sharp frame."""
    from vibr.io.video import write_video

    frames, sharp = [], []
    for k, v in enumerate(scene.views):
        at = int(rng.integers(per_view))
        sharp.append(k * per_view + at)
        for j in range(per_view):
            if j == at:
                frames.append(v.image)
            else:
                length = int(rng.integers(6, 25))
                frames.append(motion_blur(v.image, length, DIRECTIONS[int(rng.integers(4))]))
    write_video(path, frames, fps=10, crf=18)
    return sharp


def calibrate_variant(name, video, scene, per_view, out: Path) -> dict:
    """Calibrate one variant; return its figures (``frames``: the frame numbers chosen,
    ``registered``: how many of them COLMAP placed)."""
    from vibr.calib.colmap import pose_errors
    from vibr.errors import VibrInputError

    dst = out / f"calibrated_{name}"
    t0 = time.perf_counter()
    frames = (list(range(per_view // 2, per_view * len(scene), per_view)) if name == "middle" else
              list(range(0, per_view * len(scene), per_view)) if name == "photographs" else None)
    try:
        calib = _calibrate(name, video, scene, per_view, out, dst)
    except VibrInputError as exc:  # too few frames registered: a result, not a crash
        return {"registered": 0, "points": 0, "reproj_px": float("nan"), "rot_deg": float("nan"),
                "centre_pct": float("nan"), "seconds": time.perf_counter() - t0, "frames": frames,
                "error": str(exc)}
    seconds = time.perf_counter() - t0
    info = json.loads((dst / "calibration.json").read_text())
    if frames is None:
        frames = info["video"]["frames_kept"]
    photo = [int(n.split("_")[1]) // per_view for n in calib.names]
    e = pose_errors([v.camera for v in calib.views], [scene.views[k].camera for k in photo])
    return {"registered": len(info["registered"]), "points": info["num_points"],
            "reproj_px": info["mean_reprojection_error_px"], "rot_deg": float(e["rot_deg"].max()),
            "centre_pct": 100 * float(e["centre_rel"].max()), "seconds": seconds,
            "frames": frames}


def _calibrate(name, video, scene, per_view, out: Path, dst: Path):
    import imageio.v3 as iio

    from vibr.calib.colmap import calibrate
    from vibr.calib.video_frames import extract_frames

    if name == "sharpest":
        return calibrate(video, dst, overwrite=True, frames=len(scene))
    if name == "photographs":  # named as frames would be, frame = photograph × per_view
        folder = out / "photograph_files"
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir()
        for k, v in enumerate(scene.views):
            iio.imwrite(folder / f"frame_{k * per_view:06d}.png", (np.clip(v.image, 0, 1) * 255 + 0.5).astype(np.uint8))
        return calibrate(folder, dst, overwrite=True, matcher="sequential")
    every = extract_frames(video, out / "all_frames", 10 ** 6)
    folder = out / "middle_frames"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    for f, i in zip(every.files, every.indices):
        if i % per_view == per_view // 2:
            shutil.copy(f, folder / f.name)
    return calibrate(folder, dst, overwrite=True, matcher="sequential")


def reading_speed(data: Path, out: Path) -> int:
    """Time :func:`extract_frames` on a 1080p video (three runs)."""
    from vibr.calib.video_frames import extract_frames
    from vibr.io import load_scene
    from vibr.io.video import write_video

    scene = load_scene(data / "strecha_fountain-P11", scale=0.625)  # 1920×1280
    frames = [scene.views[k // 22 % len(scene)].image[100 + k % 7:1180 + k % 7, :1920] for k in range(240)]
    video = out / "hd.mp4"
    write_video(video, frames, fps=30, crf=20, preset="veryfast")
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        kept = extract_frames(video, out / "hd_frames", 60)
        times.append(time.perf_counter() - t0)
    print(f"read 240 frames of 1920x1080, kept {len(kept.files)}: {statistics.median(times):.2f} s "
          f"(runs {', '.join(f'{t:.2f}' for t in times)}), {240 / statistics.median(times):.0f} frames a second")
    import imageio.v3 as iio

    frame = iio.imread(kept.files[0])
    for name, kw in (("BMP", {}), ("PNG, zlib level 1", {"compress_level": 1}), ("PNG, Pillow's default", {})):
        f = out / ("one.bmp" if name == "BMP" else "one.png")
        ts = []
        for _ in range(5):
            t0 = time.perf_counter()
            iio.imwrite(f, frame, **kw)
            ts.append(time.perf_counter() - t0)
        print(f"writing one 1920x1080 frame as {name}: {1000 * statistics.median(ts):.0f} ms (median of 5)")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"))
    ap.add_argument("--scale", type=float, default=0.25)
    ap.add_argument("--per-view", type=int, default=5)
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--out", default="/tmp/vibr_video_calibration")
    ap.add_argument("--speed", action="store_true", help="measure the reading speed on a 1080p video instead")
    args = ap.parse_args(argv)

    import logging

    from vibr.io import load_scene

    logging.getLogger("vibr").setLevel(logging.WARNING)
    scene = load_scene(Path(args.data) / "strecha_fountain-P11", scale=args.scale)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.speed:
        return reading_speed(Path(args.data), out)
    rows = [(None, "photographs", calibrate_variant("photographs", None, scene, args.per_view, out))]
    print(f"photographs: {json.dumps(rows[0][2])}", flush=True)
    for seed in (int(s) for s in args.seeds.split(",")):
        video = out / f"shaken_{seed}.mp4"
        sharp = make_video(scene, video, args.per_view, np.random.default_rng(seed))
        order = ("sharpest", "middle") if seed % 2 == 0 else ("middle", "sharpest")  # alternate
        for name in order:
            r = calibrate_variant(name, video, scene, args.per_view, out)
            r["sharp_frames_kept"] = sum(f in sharp for f in r["frames"])
            rows.append((seed, name, r))
            print(f"seed {seed} {name}: {json.dumps(r)}", flush=True)
    print(f"\nfountain-P11 at x{args.scale:g}, {len(scene)} photographs, {args.per_view} frames each "
          "(one sharp), H.264 crf 18; 'vibr calibrate VIDEO --frames 11' against the middle frame of each stretch\n")
    print("| seed | frames kept | sharp among them | registered | sparse points | reprojection px | "
          "max rotation error ° | max centre error % of span | time s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for seed, name, r in rows[:1] + sorted(rows[1:], key=lambda t: (t[0], t[1] != "sharpest")):
        sharp = "—" if seed is None else f"{r['sharp_frames_kept']}/{len(scene)}"
        fail = " (too few registered)" if "error" in r else ""
        print(f"| {'—' if seed is None else seed} | {name} | {sharp} | {r['registered']}/{len(scene)}{fail} | "
              f"{r['points']} | {r['reproj_px']:.3f} | {r['rot_deg']:.3f} | {r['centre_pct']:.3f} | "
              f"{r['seconds']:.1f} |")
    for name in ("sharpest", "middle"):
        rs = [r for _, n, r in rows if n == name]
        ok = [r for r in rs if "error" not in r]
        print(f"{name}: registered {', '.join(str(r['registered']) for r in rs)} of {len(scene)}; over the "
              f"{len(ok)} runs that made a model, median rotation error "
              f"{statistics.median(r['rot_deg'] for r in ok):.3f}°, centre "
              f"{statistics.median(r['centre_pct'] for r in ok):.3f} %"
              if ok else f"{name}: no run made a model")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
