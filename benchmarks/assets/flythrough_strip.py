"""A strip of fly-through frames of the synthetic demo scene, for docs/explanation/flythrough.md.

    python3 benchmarks/assets/flythrough_strip.py [-o docs/img/flythrough_strip.png] [--size 160] [--frames 6]

Builds the scene of `vibr demo` (3x3 grid, exact depth), makes the 2 s orbit `vibr demo`
renders (vibr.paths.camera_path.orbit), renders every 8th frame with vibr.paths.flythrough.render_path and
tiles them left to right. No dataset photograph is involved.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from vibr.io import read_image, write_image
from vibr.paths.camera_path import CameraPath, orbit
from vibr.paths.flythrough import render_path
from vibr.synthetic import make_scene


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "-o", "--output", default=str(Path(__file__).resolve().parents[2] / "docs" / "img" / "flythrough_strip.png")
    )
    ap.add_argument("--size", type=int, default=160)
    ap.add_argument("--frames", type=int, default=6)
    a = ap.parse_args()
    scene = make_scene(layout="grid", n_views=9, width=a.size, height=a.size, seed=0)
    full = orbit(scene, n_frames=48, fps=24.0)
    step = len(full) // a.frames
    path = CameraPath(full.cameras[::step][: a.frames], full.fps)
    with tempfile.TemporaryDirectory() as tmp:
        render_path(scene, path, Path(tmp) / "frames", n_views=8, cache_dir=False, progress=False)
        imgs = [read_image(Path(tmp) / "frames" / f"frame_{i:05d}.png") for i in range(len(path))]
    gap = np.ones((a.size, 4, 3), np.float32)
    strip = np.concatenate(sum(([im, gap] for im in imgs), [])[:-1], axis=1)
    write_image(a.output, strip, bits=8)
    print(f"wrote {a.output}: frames {list(range(0, 48, step))[: a.frames]} of the 48-frame demo orbit")


if __name__ == "__main__":
    main()
