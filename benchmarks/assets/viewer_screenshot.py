"""The README's viewer screenshot (docs/img/viewer.png) from the synthetic scene.

Starts ``vibr.viewer.Viewer`` on a hand-held synthetic scene (9 views of 384×288), opens it
in headless Chromium (:mod:`vibr.viewer.browser`), moves the camera behind the input
cameras so that their frustums and the rendered view both show, waits for the full-size
render and saves a screenshot (palette PNG, 256 colours, to keep it small).

    python benchmarks/assets/viewer_screenshot.py [-o docs/img/viewer.png]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

_REPO = Path(__file__).resolve().parents[2]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", default=str(_REPO / "docs" / "img" / "viewer.png"))
    a = ap.parse_args(argv)
    from PIL import Image

    from vibr.camera import Camera
    from vibr.synthetic import make_scene
    from vibr.viewer import Viewer, ViewerOptions, ViewSettings
    from vibr.viewer.browser import free_port, open_page

    scene = make_scene("handheld", n_views=9, width=384, height=288)
    # the default point-cloud mode ("while moving"): hidden once the camera is still
    viewer = Viewer(scene, ViewerOptions(port=free_port(), settings=ViewSettings(n_views=6, full_long_side=640)))
    c0 = scene.views[0].camera
    back = Camera.from_centre(c0.K, c0.R, c0.centre - 1.6 * c0.optical_axis - 0.5 * c0.R[1], c0.width, c0.height)
    url = viewer.start()
    out = Path(a.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        with open_page(url, 960, 540) as page:
            first = viewer.wait_for_image(kind="full", timeout=120)
            client = next(iter(viewer.clients().values()))
            viewer.move_client(client, back)
            rec = viewer.wait_for_image(kind="full", after_seq=first.seq, timeout=120)
            time.sleep(2.0)
            rec = viewer.wait_for_image(kind="full", after_seq=rec.seq, timeout=0.1) or rec
            try:  # headless Chromium has no GPU: dismiss viser's software-rendering notice
                page.locator("button.mantine-Notification-closeButton").first.click(timeout=3000)
            except Exception:
                pass
            time.sleep(3.0)  # software GL repaints slowly
            tmp = out.with_suffix(".tmp.png")
            page.screenshot(path=str(tmp))
    finally:
        viewer.stop()
    img = Image.open(tmp).convert("RGB")
    img.quantize(256, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)
    tmp.unlink()
    print(f"wrote {out} ({out.stat().st_size // 1024} KiB; render {rec.camera.width}x{rec.camera.height}, "
          f"sources {', '.join(rec.sources)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
