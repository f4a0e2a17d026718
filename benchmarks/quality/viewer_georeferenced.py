"""The viewer on a scene in georeferenced coordinates (docs/explanation/viewer.md, "Far from the
origin"): the hand-held synthetic scene (9 views of 240×180) as it is and moved by
(5·10⁵, −1.7·10⁵, 7·10⁴) units, each shown in headless Chromium with the point cloud always
drawn, from the same camera behind the inputs; then the moved scene again with the viewer's
display origin forced to the world origin (vibr before 2026-11-27). Prints the mean absolute
difference (grey levels) of each screenshot of the moved scene from that of the scene at the
origin (largest over the channels) and the share of pixels off by more than 32, and writes
the three side by side.

    python benchmarks/quality/viewer_georeferenced.py [-o /tmp/viewer_georeferenced.png]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _shot(scene, out, force_zero=False):
    from PIL import Image

    from vibr.camera import Camera
    from vibr.viewer import Viewer, ViewerOptions, ViewSettings
    from vibr.viewer.browser import free_port, open_page

    viewer = Viewer(scene, ViewerOptions(port=free_port(), points="always",
                                         settings=ViewSettings(n_views=6, full_long_side=480)))
    if force_zero:
        viewer.origin = np.zeros(3)
    c0 = scene.views[0].camera
    back = Camera.from_centre(c0.K, c0.R, c0.centre - 1.6 * c0.optical_axis - 0.5 * c0.R[1], c0.width, c0.height)
    url = viewer.start()
    try:
        with open_page(url, 640, 400) as page:
            first = viewer.wait_for_image(kind="full", timeout=120)
            viewer.move_client(next(iter(viewer.clients().values())), back)
            viewer.wait_for_image(kind="full", after_seq=first.seq, timeout=120)
            time.sleep(4.0)  # software GL repaints slowly
            page.screenshot(path=out)
    finally:
        viewer.stop()
    return np.asarray(Image.open(out).convert("RGB")).astype(np.float64)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-o", "--output", default="/tmp/viewer_georeferenced.png")
    a = ap.parse_args(argv)
    from PIL import Image

    from vibr.camera import Camera
    from vibr.synthetic import make_scene

    sc = make_scene("handheld", n_views=9, width=240, height=180)
    off = np.array([5e5, -1.7e5, 7e4])
    far = sc.replace(views=[v.replace(camera=Camera.from_centre(v.camera.K, v.camera.R, v.camera.centre + off,
                                                               v.camera.width, v.camera.height))
                            for v in sc.views])
    ref = _shot(sc, a.output + ".a.png")
    moved = _shot(far, a.output + ".b.png")
    former = _shot(far, a.output + ".c.png", force_zero=True)
    for label, img in (("moved scene", moved), ("moved scene drawn in world coordinates", former)):
        d = np.abs(ref - img).max(axis=-1)
        print(f"{label}: mean |difference| from the scene at the origin {d.mean():.3f} grey levels, "
              f"{100 * (d > 32).mean():.2f} % of the pixels off by more than 32")
    Image.fromarray(np.concatenate([ref, moved, former], 1).astype(np.uint8)).save(a.output)
    print(f"wrote {a.output}")


if __name__ == "__main__":
    main()
