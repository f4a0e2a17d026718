"""The viewer in a real browser: headless Chromium (Debian's package) driven by playwright.

Starts :class:`vibr.viewer.Viewer` on a free 127.0.0.1 port on a small synthetic scene,
loads the page, and checks that

* the browser's camera, reported back through viser, is the input camera the viewer moved
  it to (the viser ↔ vibr conversion, end to end);
* the full-size image sent for it is ``vibr.render``'s image for that camera (bit for bit up
  to 1 grey level) and close to the input photograph (PSNR);
* the browser received exactly those PNG bytes (websocket frames) and shows them: the
  screenshot of the canvas matches the image resized to the canvas.

The screenshot is kept as ``viewer.png`` in the test's tmp dir.
"""

from __future__ import annotations

import io
import time

import numpy as np
import pytest

from vibr.viewer.browser import free_port

pytestmark = pytest.mark.slow


def _need_browser():
    from vibr.viewer.browser import chromium_path

    if chromium_path() is None:
        pytest.skip("chromium not found ($VIBR_CHROMIUM, /usr/bin/chromium or PATH; Debian: "
                    "apt-get install -y chromium, which .ci/run does)")
    import playwright.sync_api

    return playwright.sync_api


def png_images_in(frames) -> list[bytes]:
    """Every complete PNG file inside binary websocket frames (viser appends binary
    payloads raw after its compressed message header)."""
    out = []
    for f in frames:
        if not isinstance(f, (bytes, bytearray)):
            continue
        i = 0
        while (i := f.find(b"\x89PNG\r\n\x1a\n", i)) >= 0:
            j = f.find(b"IEND", i)
            if j < 0:
                break
            out.append(bytes(f[i:j + 8]))  # IEND chunk type + 4-byte CRC
            i = j + 8
    return out


#: Width (CSS px) of viser's collapsed control panel, docked at the right of the canvas.
PANEL_RAIL_PX = 40

#: Mean absolute difference (grey levels) between the canvas and the sent image resized to
#: it bilinearly: the browser's texture filtering differs from skimage's resize at edges.
SCREEN_TOL = 6.0


def _screen_error(shot, image) -> float:
    """Mean |screenshot − image resized to the canvas| over the canvas's lower left, which
    the control panel (right) and the notification (top left) do not cover."""
    import imageio.v3 as iio
    from skimage.transform import resize

    shown = iio.imread(shot)[..., :3].astype(np.float64)
    expected = resize(image.astype(np.float64), shown.shape[:2], order=1)
    region = (slice(150, 470), slice(60, 290))
    return float(np.abs(shown[region] - expected[region]).mean())


@pytest.fixture(scope="module")
def small_scene():
    from vibr.synthetic import make_scene

    return make_scene("handheld", n_views=6, width=128, height=96)


def test_viewer_in_chromium(small_scene, tmp_path):
    sync_api = _need_browser()
    import imageio.v3 as iio

    from vibr.metrics import psnr
    from vibr.viewer import Viewer, ViewerOptions, ViewRenderer, ViewSettings
    from vibr.viewer.browser import launch_chromium

    t_start = time.perf_counter()
    settings = ViewSettings(method="gradient", n_views=4, preview_long_side=64, full_long_side=128)
    viewer = Viewer(small_scene, ViewerOptions(port=free_port(), settings=settings, settle_s=0.3))
    url = viewer.start()
    frames = []
    try:
        with sync_api.sync_playwright() as pw:
            browser = launch_chromium(pw)
            try:
                # 640 × 480 for the canvas, beside the collapsed control panel's rail
                page = browser.new_page(viewport={"width": 640 + PANEL_RAIL_PX, "height": 480})
                page.set_default_timeout(30_000)
                page.on("websocket", lambda ws: ws.on("framereceived", lambda f: frames.append(f)))
                page.goto(url, timeout=30_000)
                rec = viewer.wait_for_image(kind="full", timeout=40)
                assert rec is not None, "no full-size image was sent within 40 s"
                # the viewer moved the browser to view 0; a render for exactly that camera
                # arrives once the browser echoed it (earlier renders: its default camera)
                cam0 = small_scene.views[0].camera
                deadline = time.monotonic() + 45
                # (and, once the panel has collapsed to its rail, at the canvas's 4:3); the
                # viewer alone brings the browser there: its reports are handled in order, and
                # its start camera, reported before it applied the move, is no drag
                while not (np.allclose(rec.camera.R, cam0.R, atol=1e-4)
                           and np.allclose(rec.camera.centre, cam0.centre, atol=1e-4)
                           and (rec.camera.width, rec.camera.height) == (128, 96)):
                    left = deadline - time.monotonic()
                    assert left > 0, f"no render at view 0's camera: last {rec.camera}"
                    rec = viewer.wait_for_image(kind="full", after_seq=rec.seq, timeout=left) or rec
                box = page.locator("canvas").first.bounding_box()
                assert (box["width"], box["height"]) == (640, 480), box
                page.screenshot(path=str(tmp_path / "viewer_scene.png"), timeout=30_000)
                err = _bare_screenshot_error(viewer, page, box, tmp_path / "viewer.png", rec.image, _screen_error)
            finally:
                browser.close()
    finally:
        viewer.stop()

    # the camera: the browser's report is view 0's camera, at the canvas' 4:3 aspect
    assert (rec.camera.width, rec.camera.height) == (128, 96)
    assert np.allclose(rec.camera.K, cam0.K, atol=1e-6)
    # the image: vibr.render for that camera (1 grey level for float reductions)
    ref = ViewRenderer(small_scene).render(rec.camera, viewer.settings)
    ref8 = np.clip(ref.image * 255 + 0.5, 0, 255).astype(np.uint8)
    assert ref.sources == rec.sources
    diff = np.abs(ref8.astype(int) - rec.image.astype(int))
    assert diff.max() <= 1, f"sent image differs from vibr.render by up to {diff.max()} grey levels"
    assert psnr(rec.image / 255.0, small_scene.views[0].image) > 30.0
    # the browser got those bytes
    pngs = [iio.imread(io.BytesIO(b)) for b in png_images_in(frames)]
    assert any(p.shape[:2] == rec.image.shape[:2] and np.array_equal(p[..., :3], rec.image) for p in pngs), \
        f"the browser never received the sent image ({len(pngs)} PNG images received)"
    # and shows them (the browser stretches the 128×96 image over the 640×480 canvas)
    iio.imwrite(tmp_path / "sent.png", rec.image)
    assert err < SCREEN_TOL, f"screenshot differs from the sent image by {err:.1f} grey levels on average"
    assert time.perf_counter() - t_start < 120



def _bare_screenshot_error(viewer, page, box, shot, image, error) -> float:
    """Hide what is drawn over the background (points, frustums) and screenshot the canvas
    until the browser has repainted (software GL: up to seconds): ``error(shot, image)``."""
    viewer.gui["points"].value = "never"
    viewer.gui["show_cameras"].value = False
    viewer._set_visible("points")
    viewer._set_visible("cameras")
    deadline = time.monotonic() + 20
    while True:
        time.sleep(1.0)
        page.screenshot(path=str(shot), clip=box, timeout=30_000)
        err = error(shot, image)
        if err < SCREEN_TOL or time.monotonic() > deadline:
            return err

def _latest_full(viewer, after_seq: int, quiet_s: float = 1.5, timeout: float = 30.0):
    """The last full-size image sent once the camera has settled: no newer one for
    ``quiet_s`` seconds (the browser's last reports and the viewer's corrections done)."""
    rec = viewer.wait_for_image(kind="full", after_seq=after_seq, timeout=timeout)
    assert rec is not None, "no full-size image after the drag"
    while (newer := viewer.wait_for_image(kind="full", after_seq=rec.seq, timeout=quiet_s)) is not None:
        rec = newer
    return rec


def _drag(page, box, x0: float, x1: float, steps: int = 12) -> None:
    """A left-button drag across the canvas at mid-height, from ``x0`` to ``x1`` (fractions
    of the canvas width), at about a hand's pace."""
    y = box["y"] + 0.5 * box["height"]
    page.mouse.move(box["x"] + x0 * box["width"], y)
    page.mouse.down()
    for i in range(1, steps + 1):
        page.mouse.move(box["x"] + (x0 + (x1 - x0) * i / steps) * box["width"], y)
        time.sleep(0.03)
    page.mouse.up()


def test_camera_moves_at_the_scale_of_the_scene(small_scene, tmp_path):
    """At 1280 × 800: the control panel starts collapsed and covers none of the render (the
    screenshot of the whole canvas is the sent image); the first image is of view 0, with
    the full view's tone; a drag of 10 % of the canvas width moves the scene's centre by
    5–25 % of the width; a drag across the whole canvas keeps the camera within twice the
    capture's extent (the largest distance of a camera from the cameras' mean centre)."""
    sync_api = _need_browser()
    from vibr.viewer import Viewer, ViewerOptions, ViewSettings
    from vibr.viewer.browser import launch_chromium
    from vibr.viewer.geometry import point_cloud

    t_start = time.perf_counter()
    settings = ViewSettings(method="gradient", n_views=4, preview_long_side=64, full_long_side=128)
    viewer = Viewer(small_scene, ViewerOptions(port=free_port(), settings=settings, settle_s=0.3))
    C = np.array([v.camera.centre for v in small_scene.views])
    extent = float(np.max(np.linalg.norm(C - C.mean(axis=0), axis=1)))
    P, _ = point_cloud(small_scene, 20_000)
    centre = np.median(P.astype(np.float64), axis=0)  # the scene's centre
    cam0 = small_scene.views[0].camera
    url = viewer.start()
    try:
        with sync_api.sync_playwright() as pw:
            browser = launch_chromium(pw)
            try:
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.set_default_timeout(30_000)
                page.goto(url, timeout=30_000)
                rec = _latest_full(viewer, 0, timeout=40)
                assert np.allclose(rec.camera.centre, cam0.centre, atol=1e-4), [(r.kind, r.camera.centre) for r in next(iter(viewer.sent.values()))]
                first = next(iter(viewer.sent.values()))[0]
                # the first image is of view 0 (not of the browser's camera before the viewer
                # moved it), and a preview has the full view's tone
                assert np.allclose(first.camera.centre, cam0.centre, atol=1e-4), first.camera.centre
                aspect = rec.camera.width / rec.camera.height
                previews = [r for r in next(iter(viewer.sent.values())) if r.kind == "preview"
                            and np.allclose(r.camera.centre, cam0.centre, atol=1e-4)
                            and abs(r.camera.width / r.camera.height - aspect) < 0.03]
                assert previews, "no preview of the full view's camera"
                pv = previews[0].image.astype(np.float64)
                assert abs(pv.mean() - rec.image.mean()) < 3.0 and abs(pv.std() / rec.image.std() - 1) < 0.1

                # the panel: collapsed, beside the canvas, not over it
                box = page.locator("canvas").first.bounding_box()
                assert box["x"] == 0 and box["width"] >= 0.95 * 1280 and box["height"] == 800, box
                err = _bare_screenshot_error(viewer, page, box, tmp_path / "viewer_1280.png", rec.image,
                                             _whole_screen_error)
                assert err < SCREEN_TOL, f"the canvas differs from the render by {err:.1f} grey levels"

                # a drag of 10 % of the canvas width
                xy0 = rec.camera.project(centre[None])[0][0]
                _drag(page, box, 0.45, 0.55)
                rec = _latest_full(viewer, rec.seq)
                xy1 = rec.camera.project(centre[None])[0][0]
                moved = float(np.linalg.norm(xy1 - xy0)) / rec.camera.width
                assert 0.05 <= moved <= 0.25, f"the scene's centre moved {moved:.1%} of the width"

                # a drag across the whole canvas, twice
                for _ in range(2):
                    _drag(page, box, 0.0, 1.0, steps=24)
                    rec = _latest_full(viewer, rec.seq)
                    away = float(np.linalg.norm(rec.camera.centre - C.mean(axis=0)))
                    assert away <= 2 * extent, f"the camera went {away / extent:.2f} extents away"
                client = next(iter(viewer.clients().values()))
                browser_away = np.linalg.norm(client.camera.position + viewer.origin - C.mean(axis=0))
                assert browser_away <= 2 * extent  # the browser's own camera too
            finally:
                browser.close()
    finally:
        viewer.stop()
    assert time.perf_counter() - t_start < 90


def _whole_screen_error(shot, image) -> float:
    """Mean |screenshot − image resized to it| over the whole canvas but its top-left corner
    (where the browser may say it draws without a GPU) and its bottom-left one (the axes)."""
    import imageio.v3 as iio
    from skimage.transform import resize

    shown = iio.imread(shot)[..., :3].astype(np.float64)
    expected = resize(image.astype(np.float64), shown.shape[:2], order=1)
    h, w = shown.shape[:2]
    keep = np.ones((h, w), bool)
    keep[: int(0.2 * h), : int(0.3 * w)] = False
    keep[int(0.9 * h):, : int(0.06 * w)] = False
    return float(np.abs(shown - expected)[keep].mean())
