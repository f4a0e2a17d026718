"""A zoom in `vibr calibrate` (docs/explanation/calibration.md, "A zoom or a second camera"): 10 synthetic
480×360 photos on an arc, every other one zoomed ×1.5, saved as JPEG with EXIF focal lengths
24 and 36 mm; calibrated as vibr does (one camera per photo, from the EXIF) and with one
shared camera (what it did before 2026-11-27). Prints each photo's focal-length error and
the mean reprojection error.

    python benchmarks/quality/calibrate_zoom.py [--work DIR]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", help="folder for the photos (default: a temporary one)")
    a = ap.parse_args(argv)
    import vibr.calib.colmap as C
    from vibr.synthetic import zoom_photos

    folder = Path(a.work or tempfile.mkdtemp(prefix="vibr-zoom-"))
    folder.mkdir(parents=True, exist_ok=True)
    truth = zoom_photos(folder)
    lens_keys = C._lens_keys
    for label, keys in (("one camera per photo (EXIF)", lens_keys), ("one shared camera", lambda f: [None] * len(f))):
        C._lens_keys = keys
        try:
            scene, rep = C.calibrate_scene(folder)
        finally:
            C._lens_keys = lens_keys
        err = [v.camera.K[0, 0] / (truth[v.name] * v.camera.width / 480.0) - 1 for v in scene.views]
        print(f"{label}: {len(scene)} registered, focal-length error per photo (%) "
              f"{' '.join(f'{100 * e:+.1f}' for e in err)}, mean reprojection {rep.mean_reprojection_error_px:.3f} px")


if __name__ == "__main__":
    main()
