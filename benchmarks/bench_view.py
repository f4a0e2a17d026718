"""Viewer latency: server-side time from a camera update to the image handed to viser.

Drives ``vibr.viewer.Viewer`` with a real headless Chromium (Debian's package through
playwright): the server moves the browser's camera (viser's camera setters), the browser
reports its camera back, and the viewer's ``on_update`` callback stamps the update; the
time is taken when the rendered image has been encoded and queued to the client
(``SentImage.seconds``). Two measurements:

1. **synthetic 768² scene, 8 sources** (a hand-held layout of 9 views; the viewer renders
   from the 8 best for each camera): for each of ``--updates`` novel cameras (midway
   between view 0 and another view), the preview (long side 256) latency and the full-size
   (768²) latency. The full-size latency includes the ``settle_s`` = 0.3 s wait for a still
   camera and the preview rendered before it, as a user experiences it; the render time of
   the full image alone is given too.
2. **fountain at scale 0.25** (``../shared/data/strecha_fountain-P11``, 11 views of
   768×512, no depth maps): the time from loading the scene to the first full view sent,
   as ``vibr view --cache-dir CACHE`` does it, cold (photographs decoded and resized,
   depth estimated, into an empty cache) and warm (the scene and depth caches filled by
   the cold run), each in a fresh Python process (Chromium already open), with the time
   of each stage.

Medians with min and max; the machine is shared and noisy (say so when reporting).

    python benchmarks/bench_view.py [--updates 7] [--skip-fountain] [--skip-synthetic] [--encode]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from vibr.viewer.browser import free_port

_REPO = Path(__file__).resolve().parents[1]



def _stats(xs) -> str:
    xs = np.asarray(xs, dtype=float)
    return f"{np.median(xs):6.2f} s  (min {xs.min():.2f}, max {xs.max():.2f}, n={len(xs)})"


def _midway(a, b):
    """The camera halfway between two cameras (centre and rotation, same intrinsics)."""
    from scipy.spatial.transform import Rotation, Slerp

    from vibr.camera import Camera

    rots = Rotation.from_matrix(np.array([a.R, b.R]))
    R = Slerp([0, 1], rots)(0.5).as_matrix()
    return Camera.from_centre(a.K, R, 0.5 * (a.centre + b.centre), a.width, a.height)


def synthetic(updates: int) -> dict:
    from playwright.sync_api import sync_playwright

    from vibr.synthetic import make_scene
    from vibr.viewer import Viewer, ViewerOptions, ViewSettings
    from vibr.viewer.browser import launch_chromium

    t0 = time.perf_counter()
    scene = make_scene("handheld", n_views=9, width=768, height=768)
    print(f"synthetic scene: {len(scene)} views of 768x768 built in {time.perf_counter() - t0:.1f} s", flush=True)
    settings = ViewSettings(n_views=8, preview_long_side=256, full_long_side=768)
    viewer = Viewer(scene, ViewerOptions(port=free_port(), settings=settings))
    targets = [_midway(scene.views[0].camera, scene.views[1 + k % (len(scene) - 1)].camera)
               for k in range(updates + 1)]  # the first one warms up
    prev, prev_render, full, full_render = [], [], [], []
    url = viewer.start()
    try:
        with sync_playwright() as pw:
            browser = launch_chromium(pw)
            try:
                page = browser.new_page(viewport={"width": 800, "height": 800})
                page.goto(url, timeout=60_000)
                first = viewer.wait_for_image(kind="full", timeout=300)
                assert first is not None, "no first image"
                client = next(iter(viewer.clients().values()))
                seq = first.seq
                for k, cam in enumerate(targets):
                    viewer.move_client(client, cam)
                    p = viewer.wait_for_image(kind="preview", after_seq=seq, timeout=120)
                    f = viewer.wait_for_image(kind="full", after_seq=seq, timeout=120)
                    assert p is not None and f is not None, "no image for an update"
                    # settle: the browser's echoes of one move are several updates
                    time.sleep(0.5)
                    last = viewer.wait_for_image(kind="full", after_seq=f.seq, timeout=0.1)
                    seq = (last or f).seq
                    if k == 0:
                        continue
                    prev.append(p.seconds)
                    prev_render.append(p.render_seconds)
                    full.append(f.seconds)
                    full_render.append(f.render_seconds)
                    print(f"  update {k}: preview {p.camera.width}x{p.camera.height} {p.seconds:.2f} s "
                          f"(render {p.render_seconds:.2f} s), "
                          f"full {f.camera.width}x{f.camera.height} {f.seconds:.2f} s "
                          f"(render {f.render_seconds:.2f} s)", flush=True)
            finally:
                browser.close()
    finally:
        viewer.stop()
    return {"preview": prev, "preview_render": prev_render, "full": full, "full_render": full_render}


def _startup_once(scene_dir: str, scale: float, cache_dir: str) -> None:
    """In a fresh process, as ``vibr view --cache-dir CACHE`` does: load (scene cache),
    depth (depth cache), start, first full view in Chromium; the time of each stage."""
    t_proc = time.perf_counter()
    from playwright.sync_api import sync_playwright

    from vibr.depthcache import load_scene_cached
    from vibr.viewer import Viewer, ViewerOptions, ViewSettings, scene_with_depth
    from vibr.viewer.browser import launch_chromium

    stages = {"imports": time.perf_counter() - t_proc}
    with sync_playwright() as pw:
        browser = launch_chromium(pw)  # the user's browser is already open
        t0 = t = time.perf_counter()
        scene = load_scene_cached(scene_dir, scale=scale, cache_dir=cache_dir)
        stages["load scene"] = -t + (t := time.perf_counter())
        scene = scene_with_depth(scene, cache_dir=cache_dir)
        stages["depth"] = -t + (t := time.perf_counter())
        t_depth = t - t0
        viewer = Viewer(scene, ViewerOptions(port=free_port(), settings=ViewSettings(n_views=8)))
        try:
            url = viewer.start()
            stages["viewer start (scene drawn)"] = -t + (t := time.perf_counter())
            page = browser.new_page(viewport={"width": 900, "height": 600})
            page.goto(url, timeout=60_000)
            stages["page loaded"] = -t + (t := time.perf_counter())
            pre = viewer.wait_for_image(kind="preview", timeout=300)
            stages["first preview sent"] = -t + (t := time.perf_counter())
            rec = viewer.wait_for_image(kind="full", timeout=300)
            stages["first full view sent"] = -t + (t := time.perf_counter())
            t_first = t - t0
            if rec is not None:
                stages["  of which the full render"] = rec.render_seconds
            if pre is not None:
                stages["  of which the preview render"] = pre.render_seconds
        finally:
            viewer.stop()
            browser.close()
    print(json.dumps({"depth_s": t_depth, "first_full_s": t_first, "ok": rec is not None,
                      "size": [rec.camera.width, rec.camera.height] if rec else None,
                      "depth_source": scene.meta.get("depth_source"), "stages": stages}))


def fountain(scene_dir: Path, scale: float) -> dict:
    out = {}
    with tempfile.TemporaryDirectory(prefix="vibr-view-cache-") as cache:
        for label in ("cold", "warm"):
            r = subprocess.run([sys.executable, __file__, "--_startup", str(scene_dir), str(scale), cache],
                               capture_output=True, text=True, timeout=900)
            if r.returncode != 0:
                raise RuntimeError(f"{label} start failed: {r.stderr[-2000:]}")
            out[label] = json.loads(r.stdout.strip().splitlines()[-1])
            print(f"  {label}: {out[label]}", flush=True)
    return out


def encode_ab(repeat: int = 7) -> None:
    """The full view's PNG encoding: viser's own encoder (what ``set_background_image``
    does without OpenCV) against :func:`vibr.viewer.app.encode_png` (zlib level 1), on a
    768² image of the synthetic scene, alternating, medians."""
    import imageio.v3 as iio

    from vibr.synthetic import make_scene
    from vibr.viewer.app import encode_png

    img = np.clip(make_scene("handheld", n_views=1, width=768, height=768).views[0].image * 255 + 0.5,
                  0, 255).astype(np.uint8)
    fns = {"viser's encoder (imageio PNG, default level)": lambda: iio.imwrite("<bytes>", img, extension=".png"),
           "encode_png (Pillow, zlib level 1)": lambda: encode_png(img)}
    ts = {k: [] for k in fns}
    size = {}
    for _ in range(repeat):
        for k, f in fns.items():
            t0 = time.perf_counter()
            size[k] = len(f())
            ts[k].append(time.perf_counter() - t0)
    print("| 768² PNG encoding | median s (min-max) | bytes |\n|---|---|---|")
    for k in fns:
        print(f"| {k} | {np.median(ts[k]):.3f} ({min(ts[k]):.3f}-{max(ts[k]):.3f}) | {size[k]} |")
    a, b = fns
    print(f"\nratio {np.median(ts[a]) / np.median(ts[b]):.1f}x; load average {os.getloadavg()[0]:.1f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--updates", type=int, default=7, help="camera updates measured (default 7)")
    ap.add_argument("--skip-fountain", action="store_true")
    ap.add_argument("--skip-synthetic", action="store_true")
    ap.add_argument("--data", default=os.environ.get("VIBR_DATA", str(_REPO.parent / "shared" / "data")))
    ap.add_argument("--_startup", nargs=3, help=argparse.SUPPRESS)
    ap.add_argument("--encode", action="store_true", help="only the PNG encoding comparison")
    a = ap.parse_args(argv)
    if a.encode:
        encode_ab()
        return 0
    if a._startup:
        _startup_once(a._startup[0], float(a._startup[1]), a._startup[2])
        return 0
    print(f"cpus: {os.cpu_count()}, load average: {os.getloadavg()[0]:.1f} (shared machine)", flush=True)
    rows = []
    if not a.skip_synthetic:
        s = synthetic(a.updates)
        rows += [("synthetic 768², 8 sources: preview (256²), update → sent", _stats(s["preview"]), "≤ 0.3 s"),
                 ("  the preview's render itself (vibr.render + source choice)", _stats(s["preview_render"]), ""),
                 ("synthetic 768², 8 sources: full (768²), update → sent", _stats(s["full"]), "≤ 1.5 s"),
                 ("  the full render itself", _stats(s["full_render"]), "")]
    if not a.skip_fountain:
        f = fountain(Path(a.data) / "strecha_fountain-P11", 0.25)
        rows += [("fountain ×0.25: start → first full view, cold (depth estimated)",
                  f"{f['cold']['first_full_s']:6.1f} s  (depth {f['cold']['depth_s']:.1f} s)", "< 60 s"),
                 ("fountain ×0.25: start → first full view, depth cache",
                  f"{f['warm']['first_full_s']:6.1f} s  (depth {f['warm']['depth_s']:.2f} s)", "< 10 s")]
        for label in ("cold", "warm"):
            print(f"\nfountain start, {label}: " + ", ".join(f"{k} {v:.2f} s" for k, v in f[label]["stages"].items()))
    print(f"\n| measurement | median (spread) | target |\n|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1].strip()} | {r[2]} |")
    print(f"\nload average after: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
