"""How much ``vibr path interpolate --smooth SIGMA`` calms a hand-held capture.

A steady walk (:func:`vibr.synthetic.walk_cameras`: ``--keys`` keys 0.1 scene units apart
along x, turning 1° a key, as one frame a second of a walking video would be) is shaken by a
hand: every key's centre moved by
N(0, ``--jitter``) per axis and its orientation turned by N(0, ``--deg``°) about each axis,
``--seeds`` draws. For each SIGMA the path through the shaken keys
(:func:`vibr.paths.camera_path.interpolate`, ``order="given"``, 10 frames a key) is compared with the
path through the steady keys: the RMS distance and angle between their frames, and the mean
turn from one frame to the next (the steady path's: 0.1°).

    python benchmarks/quality/path_smoothing.py [--keys 40] [--jitter 0.02] [--deg 2] [--seeds 5]
"""

from __future__ import annotations

import argparse

import numpy as np


def scene_of(cams):
    from vibr.scene import Scene, View

    return Scene([View(f"f{k:03d}", np.zeros((120, 160, 3), np.float32), c) for k, c in enumerate(cams)])


def angle(a, b) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(a.R @ b.R.T) - 1) / 2, -1, 1))))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--keys", type=int, default=40)
    ap.add_argument("--jitter", type=float, default=0.02)
    ap.add_argument("--deg", type=float, default=2.0)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--sigmas", default="0,1,2,3")
    args = ap.parse_args(argv)

    from vibr.paths.camera_path import interpolate
    from vibr.synthetic import walk_cameras

    sigmas = [float(s) for s in args.sigmas.split(",")]
    rows = {s: [] for s in sigmas}
    n_frames = 10 * args.keys
    for seed in range(args.seeds):
        steady = walk_cameras(args.keys, seed)
        shaken = walk_cameras(args.keys, seed, jitter=args.jitter, jitter_deg=args.deg)
        truth = interpolate(scene_of(steady), order="given", n_frames=n_frames).cameras
        for s in sigmas:
            cams = interpolate(scene_of(shaken), order="given", n_frames=n_frames, smooth=s).cameras
            d = np.sqrt(np.mean([np.sum((a.centre - b.centre) ** 2) for a, b in zip(cams, truth)]))
            a = np.sqrt(np.mean([angle(x, y) ** 2 for x, y in zip(cams, truth)]))
            turn = np.mean([angle(x, y) for x, y in zip(cams, cams[1:])])
            rows[s].append((d, a, turn))
    print(
        f"{args.keys} keys, jitter {args.jitter} scene units and {args.deg}° per axis, {args.seeds} seeds "
        f"(medians; the steady path turns {np.mean([angle(x, y) for x, y in zip(truth, truth[1:])]):.3f}° a frame)\n"
    )
    print("| --smooth | RMS distance to the steady path | RMS angle to it ° | mean turn a frame ° |")
    print("|---|---|---|---|")
    for s in sigmas:
        d, a, t = np.median(np.array(rows[s]), axis=0)
        print(f"| {s:g} | {d:.4f} | {a:.2f} | {t:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
