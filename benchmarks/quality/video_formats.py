"""The video formats of ``vibr render --path`` (``vibr.io.video.VIDEO_FORMATS``): encoding
time, file size and the frames' fidelity after decoding (PSNR of the decoded frames against
the rendered ones, all pixels), on one fly-through's frames.

The frames: the synthetic hand-held scene (7 views of 320x240) saved to a temporary folder,
an orbit of ``--frames`` frames rendered once by ``vibr render --path`` into a frames folder;
each format then encodes the same PNG frames (``write_video``) and is decoded back with
imageio-ffmpeg.

    python benchmarks/quality/video_formats.py [--frames 48] [--size 320x240]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--size", default="320x240")
    args = ap.parse_args(argv)
    import imageio.v3 as iio

    from vibr.io import save_scene
    from vibr.io.images import read_image
    from vibr.io.video import VIDEO_FORMATS, write_video
    from vibr.metrics import psnr
    from vibr.synthetic import make_scene

    w, h = (int(x) for x in args.size.split("x"))
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        save_scene(make_scene("handheld", n_views=7, width=w, height=h), t / "scene")
        vibr = [sys.executable, "-m", "vibr", "-q"]
        subprocess.run(vibr + ["path", "orbit", str(t / "scene"), "-o", str(t / "p.json"), "--frames",
                               str(args.frames)], check=True)
        subprocess.run(vibr + ["render", str(t / "scene"), "--path", str(t / "p.json"), "-o", str(t / "frames")],
                       check=True)
        frames = [read_image(p) for p in sorted((t / "frames").glob("frame_*.png"))]
        ref = np.array([np.rint(f * 255) / 255 for f in frames], np.float32)
        print(f"# {len(frames)} frames of {w}x{h} (an orbit of the synthetic hand-held scene), "
              "encoded by vibr.io.video.write_video and decoded with imageio-ffmpeg\n")
        print("| format | encoding s | size KiB | PSNR of the decoded frames dB (all pixels) |")
        print("|---|---|---|---|")
        for ext, fmt in VIDEO_FORMATS.items():
            out = t / f"v{ext}"
            t0 = time.perf_counter()
            write_video(out, frames, fps=24)
            dt = time.perf_counter() - t0
            dec = iio.imread(out, index=None)[..., :3].astype(np.float32) / 255
            dec = dec[:, :h, :w]
            p = np.mean([psnr(d, r, border=0) for d, r in zip(dec, ref)])
            print(f"| {ext} ({fmt.what}) | {dt:.2f} | {out.stat().st_size / 1024:.0f} | {p:.2f} |", flush=True)


if __name__ == "__main__":
    main()
