"""Colours of vibr's videos as players show them (docs/explanation/flythrough.md, "Video"): a 1280×720
frame of saturated colour bars encoded by :func:`vibr.io.video.write_video` (BT.709) and as
vibr encoded it before 2026-11-27 (ffmpeg's default BT.601 matrix, untagged), each decoded
as a player reads HD video (the BT.709 matrix). Prints the largest error per encoding and
the decoded bars.

    python benchmarks/quality/video_colours.py
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
from pathlib import Path

import numpy as np

COLOURS = [(255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 255, 0), (0, 255, 255), (255, 0, 255),
           (200, 120, 60), (128, 128, 128)]


def main(argv=None):
    argparse.ArgumentParser(description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args(argv)
    import imageio_ffmpeg

    from vibr.io.video import write_video

    ff = imageio_ffmpeg.get_ffmpeg_exe()
    W, H = 1280, 720
    img = np.zeros((H, W, 3), np.uint8)
    for i, c in enumerate(COLOURS):
        img[:, i * W // 8:(i + 1) * W // 8] = c
    d = Path(tempfile.mkdtemp(prefix="vibr-colours-"))
    write_video(d / "now.mp4", [img] * 3, fps=24)
    subprocess.run([ff, "-y", "-f", "rawvideo", "-vcodec", "rawvideo", "-s", f"{W}x{H}", "-pix_fmt", "rgb24",
                    "-r", "24", "-i", "-", "-an", "-vcodec", "libx264", "-pix_fmt", "yuv420p", "-crf", "18",
                    "-v", "error", str(d / "former.mp4")], input=img.tobytes() * 3, check=True)
    for name in ("now", "former"):
        raw = subprocess.run([ff, "-i", str(d / f"{name}.mp4"), "-vf", "scale=in_color_matrix=bt709", "-f", "rawvideo",
                              "-pix_fmt", "rgb24", "-v", "error", "-"], capture_output=True, check=True).stdout
        dec = np.frombuffer(raw, np.uint8)[:img.size].reshape(img.shape)
        got = [tuple(int(x) for x in dec[H // 2, i * W // 8 + W // 16]) for i in range(8)]
        err = max(int(np.abs(np.array(g) - np.array(c)).max()) for g, c in zip(got, COLOURS))
        print(f"{name}: largest error {err} grey levels; decoded {got}")


if __name__ == "__main__":
    main()
