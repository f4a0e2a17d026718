"""vibr's undistortion at load against COLMAP's own ``image_undistorter`` on real photographs.

``vibr calibrate`` on fountain-P11's photographs (``--scale 0.25``, 768x512, the default
SIMPLE_RADIAL camera) keeps its work folder: the mapper's distorted model with the resized
photographs, and COLMAP's undistorted copy (``pycolmap.undistort_images``). Loading the first
(vibr undistorts at load, docs/explanation/calibration.md "Distorted cameras from elsewhere") and the
second must give the same cameras and the same images up to 8-bit rounding.

    python benchmarks/quality/undistort_vs_colmap.py [--scale 0.25] [--data DIR]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import data_dir  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scale", type=float, default=0.25)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    args = ap.parse_args(argv)
    from vibr.io import load_scene
    from vibr.metrics import psnr

    photos = data_dir(args.data) / "strecha_fountain-P11" / "images"
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp) / "work"
        subprocess.run([sys.executable, "-m", "vibr", "-q", "calibrate", str(photos), str(Path(tmp) / "scene"),
                        "--scale", str(args.scale), "--work", str(work)], check=True)
        t0 = time.perf_counter()
        a = load_scene(work)
        t_load = time.perf_counter() - t0
        b = load_scene(work / "undistorted")
        print(f"# fountain-P11 photographs at x{args.scale:g}: {a.meta['undistorted']}; loading the raw "
              f"model took {t_load:.2f} s\n")
        print("| view | size (vibr / COLMAP) | max abs K difference | max abs R difference | PSNR vibr vs COLMAP dB |")
        print("|---|---|---|---|---|")
        for va, vb in zip(a.views, b.views):
            p = psnr(va.image, vb.image, border=2) if va.camera.shape == vb.camera.shape else float("nan")
            print(f"| {va.name} | {va.camera.width}x{va.camera.height} / {vb.camera.width}x{vb.camera.height} | "
                  f"{np.abs(va.camera.K - vb.camera.K).max():.1e} | {np.abs(va.camera.R - vb.camera.R).max():.1e} "
                  f"| {p:.2f} |")


if __name__ == "__main__":
    main()
