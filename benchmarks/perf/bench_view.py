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
   the full image alone is given too, and the CPU the client's processes took per update
   (Chromium's by process kind: its GPU process draws the page in software here). With
   ``--drag N`` each update is a drag of N moves 33 ms apart ending at the target, timed
   from its last camera update, with the camera updates, abandoned renders and point
   show/hide messages it caused and the preview of its last camera.
2. **fountain at scale 0.25** (``../shared/data/strecha_fountain-P11``, 11 views of
   768×512, no depth maps): the time from loading the scene to the first full view sent,
   as ``vibr view --cache-dir CACHE`` does it, cold (photographs decoded and resized,
   depth estimated, into an empty cache) and warm (the scene and depth caches filled by
   the cold run), each in a fresh Python process (Chromium already open), with the time
   of each stage.

Medians with min and max; the machine is shared and noisy (say so when reporting).

    python benchmarks/perf/bench_view.py [--updates 7] [--skip-fountain] [--skip-synthetic] [--numba-threads default]
                                    [--client chromium|remote] [--max-points N] [--drag N]
    python benchmarks/perf/bench_view.py --encode | --ab-settings | --ab-overhead | --ab-prepared
                                           | --browser-cpu | --browser-timeline | --ab-arena
                                           (A/B comparisons, alternating in one process)
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

_REPO = Path(__file__).resolve().parents[2]



def _stats(xs) -> str:
    xs = np.asarray(xs, dtype=float)
    return f"{np.median(xs):6.2f} s  (min {xs.min():.2f}, max {xs.max():.2f}, n={len(xs)})"


def _midway(a, b, t: float = 0.5):
    """The camera a fraction ``t`` of the way from ``a`` to ``b`` (centre and rotation, same
    intrinsics; halfway by default)."""
    from scipy.spatial.transform import Rotation, Slerp

    from vibr.camera import Camera

    rots = Rotation.from_matrix(np.array([a.R, b.R]))
    R = Slerp([0, 1], rots)(t).as_matrix()
    return Camera.from_centre(a.K, R, (1 - t) * a.centre + t * b.centre, a.width, a.height)


#: points in the benchmark viewer's cloud (``--max-points``; None: the viewer's default)
MAX_POINTS: int | None = None


def _viewer(scene, points: str):
    """The benchmark's viewer of ``scene``: 8 sources, full size 768, point-cloud mode
    ``points``, :data:`MAX_POINTS` points, on a free port (not started)."""
    from vibr.viewer import Viewer, ViewerOptions, ViewSettings
    from vibr.viewer.browser import free_port

    more = {} if MAX_POINTS is None else {"max_points": MAX_POINTS}
    return Viewer(scene, ViewerOptions(port=free_port(), points=points, **more,
                                       settings=ViewSettings(n_views=8, full_long_side=768)))


@contextlib.contextmanager
def _viewer_page(scene, points: str, on_load=None):
    """A viewer of ``scene`` (8 sources, full size 768, point-cloud mode ``points``) shown
    in headless Chromium (800×800) until its first full image: yields the viewer and that
    first image; closes both. ``on_load()`` runs once the page has loaded."""
    from playwright.sync_api import sync_playwright

    from vibr.viewer.browser import launch_chromium

    v = _viewer(scene, points)
    url = v.start()
    try:
        with sync_playwright() as pw:
            b = launch_chromium(pw)
            try:
                page = b.new_page(viewport={"width": 800, "height": 800})
                page.goto(url, timeout=60_000)
                if on_load is not None:
                    on_load()
                first = v.wait_for_image(kind="full", timeout=300)
                assert first is not None, "no first image"
                yield v, first
            finally:
                b.close()
    finally:
        v.stop()


class _RemoteClient:
    """A viser client in a child process that draws nothing here: it sends the viewport
    cameras it is given (viser's ``ViewerCameraMessage``, as a browser sends when its user
    moves) and reads whatever the server sends."""

    def __init__(self, viewer, size=(800, 800)):
        self.viewer, self.size = viewer, size
        self.proc = subprocess.Popen([sys.executable, __file__, "--_remote-client", str(viewer.options.port)],
                                     stdin=subprocess.PIPE, text=True)

    def move(self, camera) -> None:
        from vibr.viewer.convert import viser_pose_from_camera

        wxyz, pos, fov, _ = viser_pose_from_camera(camera)
        pos = pos - self.viewer.origin
        look = pos + camera.R[2]
        msg = {"wxyz": [float(x) for x in wxyz], "position": [float(x) for x in pos], "fov": float(fov),
               "near": 0.01, "far": 1000.0, "image_width": self.size[0], "image_height": self.size[1],
               "look_at": [float(x) for x in look], "up_direction": [float(x) for x in self.viewer.up]}
        self.proc.stdin.write(json.dumps(msg) + "\n")
        self.proc.stdin.flush()

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait(timeout=30)


def _remote_client_main(port: int) -> None:
    """The child of :class:`_RemoteClient`: one websocket to the viewer; each stdin line a
    camera to send; every message received is read and dropped."""
    import asyncio
    import threading

    import msgspec
    import viser
    from viser import _messages
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    async def run():
        async with connect(f"ws://127.0.0.1:{port}", subprotocols=[f"viser-v{viser.__version__}"],
                           max_size=None) as ws:
            loop = asyncio.get_running_loop()
            lines = asyncio.Queue()

            def read_stdin():
                for line in sys.stdin:
                    loop.call_soon_threadsafe(lines.put_nowait, line)
                loop.call_soon_threadsafe(lines.put_nowait, None)

            async def drain():
                try:
                    async for _ in ws:
                        pass
                except ConnectionClosed:
                    pass

            threading.Thread(target=read_stdin, daemon=True).start()
            reader = asyncio.create_task(drain())
            while (line := await lines.get()) is not None:
                d = json.loads(line)
                d = {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}
                await ws.send(msgspec.msgpack.encode(_messages.ViewerCameraMessage(**d).as_serializable_dict()))
            reader.cancel()

    asyncio.run(run())


@contextlib.contextmanager
def _viewer_remote(scene, points: str):
    """As :func:`_viewer_page`, with a :class:`_RemoteClient` in place of the browser; yields
    the viewer, its first image and the client's ``move(camera)``."""
    v = _viewer(scene, points)
    v.start()
    rc = _RemoteClient(v)
    try:
        deadline = time.monotonic() + 60
        first = None
        # viser counts a client from its first camera message, then adds the viewer's callbacks
        while first is None and time.monotonic() < deadline:
            rc.move(scene.views[0].camera)
            first = v.wait_for_image(kind="full", timeout=5)
        assert first is not None, "no first image"
        yield v, first, rc.move
    finally:
        rc.close()
        v.stop()


def _children_cpu() -> dict:
    """CPU seconds of this process's children by kind (Chromium's ``--type=`` of each
    process: gpu-process, renderer, ...; ``browser`` for Chromium's main process, else the
    process name), summed over the processes of each kind."""
    import psutil

    out: dict = {}
    for p in psutil.Process().children(recursive=True):
        try:
            cmd, c = p.cmdline(), p.cpu_times()
        except psutil.Error:
            continue
        kind = next((a.split("=", 1)[1] for a in cmd if a.startswith("--type=")), None)
        kind = kind or ("browser" if "chrom" in p.name() else p.name())
        out[kind] = out.get(kind, 0.0) + c.user + c.system
    return out


def _count_visibility(viewer) -> list:
    """A one-element list counting the point cloud's show/hide messages from now on (the
    viewer's handle wrapped; the messages still go out)."""
    count = [0]
    handle = viewer._points

    class Counted:
        def __setattr__(self, name, value):
            if name == "visible":
                count[0] += 1
            setattr(handle, name, value)

        def __getattr__(self, name):
            return getattr(handle, name)

    if handle is not None:
        viewer._points = Counted()
    return count


#: seconds between the camera moves of a drag (``--drag``): a pointer reported at 30 Hz
DRAG_STEP_S = 1 / 30


def synthetic(updates: int, points: str = "while moving", browser_nice: int | None = None,
              client: str = "chromium", drag: int = 1) -> dict:
    """Each update moves the camera to a new target: at once, or with ``drag`` > 1 in that many
    moves :data:`DRAG_STEP_S` apart from the previous target (the full view is then timed from
    the last camera update the viewer got)."""
    from vibr.synthetic import make_scene

    t0 = time.perf_counter()
    scene = make_scene("handheld", n_views=9, width=768, height=768)
    print(f"synthetic scene: {len(scene)} views of 768x768 built in {time.perf_counter() - t0:.1f} s", flush=True)
    targets = [_midway(scene.views[0].camera, scene.views[1 + k % (len(scene) - 1)].camera)
               for k in range(updates + 1)]  # the first one warms up
    prev, prev_render, full, full_render = [], [], [], []
    renice = None if browser_nice is None else (lambda: _renice_children(browser_nice))
    page = _viewer_remote(scene, points) if client == "remote" else _viewer_page(scene, points, on_load=renice)
    with page as (viewer, first, *mover):
        # the remote client moves itself; the browser's camera is moved through the server
        move = mover[0] if mover else functools.partial(viewer.move_client, next(iter(viewer.clients().values())))
        seq = first.seq
        ru0 = resource.getrusage(resource.RUSAGE_SELF)
        others = []  # CPU seconds of the client's processes from the move to the full image, by kind
        at = scene.views[0].camera
        toggles = _count_visibility(viewer)
        cid, worker = next(iter(viewer._workers.items()))
        for k, cam in enumerate(targets):
            c0, t0, r0, a0 = _children_cpu(), toggles[0], worker.submitted, viewer.abandoned
            for j in range(1, drag):
                move(_midway(at, cam, j / drag))
                time.sleep(DRAG_STEP_S)
            move(cam)
            at = cam
            p = viewer.wait_for_image(kind="preview", after_seq=seq, timeout=120)
            f = viewer.wait_for_image(kind="full", after_seq=seq, timeout=120)
            assert p is not None and f is not None, "no image for an update"
            c1 = _children_cpu()
            if k > 0:
                others.append({kind: c1[kind] - c0.get(kind, 0.0) for kind in c1})
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
            # the preview of the request the full image answers (a drag's last camera)
            pf = [im for im in viewer.sent[cid] if im.kind == "preview" and im.seq == f.seq] \
                if drag > 1 else []
            more = (f"; {worker.submitted - r0} camera updates, {viewer.abandoned - a0} renders abandoned, "
                    f"{toggles[0] - t0} point show/hide messages"
                    + (f", the last camera's preview {pf[0].seconds:.2f} "
                       f"s" if pf else ", no preview of the last camera")
                    if drag > 1 else "")
            print(f"  update {k}: preview {p.camera.width}x{p.camera.height} {p.seconds:.2f} s "
                  f"(render {p.render_seconds:.2f} s), "
                  f"full {f.camera.width}x{f.camera.height} {f.seconds:.2f} s "
                  f"(render {f.render_seconds:.2f} s){more}", flush=True)
        ru1 = resource.getrusage(resource.RUSAGE_SELF)
    n = len(targets)
    print(f"viewer process per update: user {(ru1.ru_utime - ru0.ru_utime) / n:.2f} s, system "
          f"{(ru1.ru_stime - ru0.ru_stime) / n:.2f} s, minor page faults {(ru1.ru_minflt - ru0.ru_minflt) / n:.0f}",
          flush=True)
    kinds = sorted({kind for o in others for kind in o}, key=lambda kd: -np.median([o.get(kd, 0.0) for o in others]))
    print(f"client ({client}) CPU per update, move → full image sent, medians: "
          + ", ".join(f"{kd} {np.median([o.get(kd, 0.0) for o in others]):.2f} s" for kd in kinds), flush=True)
    return {"preview": prev, "preview_render": prev_render, "full": full, "full_render": full_render}


def _renice_children(nice: int) -> None:
    """Set the scheduling priority of this process's children (the benchmark's Chromium;
    its GPU process raises its own to -8): with 19 the browser takes only the CPU the
    viewer leaves, as a browser on another machine or drawing on a GPU would. Linux
    schedules by session first when autogroup is on (``/proc/sys/kernel/sched_autogroup_enabled``)
    and Chromium runs in sessions of its own: their group's nice is set too, else the
    browser gets its group's fair share whatever its threads' nice."""
    import psutil

    def group(pid):
        try:
            with open(f"/proc/{pid}/autogroup") as f:
                return f.read().split()[0]
        except OSError:
            return None

    ours = group(os.getpid())
    for p in psutil.Process().children(recursive=True):
        try:
            for t in p.threads():  # Linux's priority is per thread
                os.setpriority(os.PRIO_PROCESS, t.id, nice)
        except (psutil.Error, OSError):
            pass
        # playwright's driver (node) shares this process's session: setting its group's
        # nice would demote the viewer as well
        if group(p.pid) in (None, ours):
            continue
        try:
            with open(f"/proc/{p.pid}/autogroup", "w") as f:
                f.write(str(nice))
        except OSError:
            pass


def _compiled_kernels() -> list:
    """The numba kernels this process compiled instead of loading them from the cache."""
    import gc

    from numba.core.registry import CPUDispatcher

    return [f"{d.py_func.__module__}.{d.__name__}" for d in gc.get_objects()
            if isinstance(d, CPUDispatcher) and d.stats.cache_misses]


def _startup_once(scene_dir: str, scale: float, cache_dir: str) -> None:
    """In a fresh process, as ``vibr view --cache-dir CACHE`` does: load (scene cache),
    depth (depth cache), start, first full view in Chromium; the time of each stage."""
    t_proc = time.perf_counter()
    from playwright.sync_api import sync_playwright

    from vibr.pipeline import load_scene_cached
    from vibr.viewer import Viewer, ViewerOptions, ViewSettings, scene_with_depth
    from vibr.viewer.browser import free_port, launch_chromium

    stages = {"imports": time.perf_counter() - t_proc}
    cpu = {}
    clock = [time.perf_counter(), time.process_time()]

    def _lap():
        """Wall seconds since the last lap (the process CPU seconds of all its threads,
        less sensitive to a loaded machine, go to ``cpu`` under the stage's name)."""
        w, c = time.perf_counter(), time.process_time()
        dw, dc = w - clock[0], c - clock[1]
        clock[:] = [w, c]
        cpu[len(cpu)] = dc
        return dw

    with sync_playwright() as pw:
        browser = launch_chromium(pw)  # the user's browser is already open
        t0 = time.perf_counter()
        clock[:] = [t0, time.process_time()]
        scene = load_scene_cached(scene_dir, scale=scale, cache_dir=cache_dir)
        stages["load scene"] = _lap()
        scene = scene_with_depth(scene, cache_dir=cache_dir)
        stages["depth"] = _lap()
        t_depth = time.perf_counter() - t0
        warm = os.environ.get("VIBR_BENCH_WARM_UP", "1") != "0"  # 0: ViewerOptions(warm_up=False)
        viewer = Viewer(scene, ViewerOptions(port=free_port(), settings=ViewSettings(n_views=8), warm_up=warm))
        try:
            url = viewer.start()
            stages["viewer start (scene drawn)"] = _lap()
            page = browser.new_page(viewport={"width": 900, "height": 600})
            page.goto(url, timeout=60_000)
            stages["page loaded"] = _lap()
            pre = viewer.wait_for_image(kind="preview", timeout=300)
            stages["first preview sent"] = _lap()
            rec = viewer.wait_for_image(kind="full", timeout=300)
            stages["first full view sent"] = _lap()
            t_first = time.perf_counter() - t0
            if rec is not None:
                stages["  of which the full render"] = rec.render_seconds
            if pre is not None:
                stages["  of which the preview render"] = pre.render_seconds
        finally:
            viewer.stop()
            browser.close()
    print(json.dumps({"depth_s": t_depth, "first_full_s": t_first, "ok": rec is not None,
                      "compiled_at_start": _compiled_kernels(),
                      "size": [rec.camera.width, rec.camera.height] if rec else None,
                      "depth_source": scene.meta.get("depth_source"), "stages": stages,
                      "cpu": dict(zip([k for k in stages if k != "imports" and not k.startswith(" ")], cpu.values()))}))


def fountain(scene_dir: Path, scale: float, numba_threads: str = "viewer") -> dict:
    out = {}
    with tempfile.TemporaryDirectory(prefix="vibr-view-cache-") as cache:
        for label in ("cold", "warm"):
            r = subprocess.run([sys.executable, __file__, "--_startup", str(scene_dir), str(scale), cache,
                                "--numba-threads", numba_threads],
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


def ab_settings(size: int = 768, cameras: int = 2) -> None:
    """The viewer's render with its former defaults (gamma 1.0, lam 0.1) against the
    renderer's defaults (:data:`vibr.render.methods.DEFAULTS`), alternating, on the
    benchmark's scene and cameras: FISTA iterations (deterministic) and times."""
    from vibr.render.methods import DEFAULTS
    from vibr.synthetic import make_scene
    from vibr.viewer import ViewSettings
    from vibr.viewer.renderer import ViewRenderer

    scene = make_scene("handheld", n_views=9, width=size, height=size)
    r = ViewRenderer(scene)
    cams = [_midway(scene.views[0].camera, scene.views[1 + k].camera) for k in range(cameras + 1)]
    variants = {"gamma 1.0, lam 0.1 (former ViewSettings)": ViewSettings(gamma=1.0, lam=0.1, n_views=8),
                f"gamma {DEFAULTS['gamma']}, lam {DEFAULTS['lam']} (DEFAULTS)":
                    ViewSettings(gamma=DEFAULTS["gamma"], lam=DEFAULTS["lam"], n_views=8)}
    r.render(cams[0], next(iter(variants.values())))  # warm-up
    print("| settings | camera | FISTA iterations | render s | solve s |\n|---|---|---|---|---|")
    for k, cam in enumerate(cams[1:]):
        for name, st in (variants.items() if k % 2 == 0 else reversed(variants.items())):
            out = r.render(cam, st)
            print(f"| {name} | {k + 1} | {out.iterations} | {out.seconds:.2f} | "
                  f"{out.times['solve']:.2f} |", flush=True)
    print(f"\nload average {os.getloadavg()[0]:.1f}")


def ab_overhead(size: int = 768, cameras: int = 2, repeat: int = 2) -> None:
    """Per-request overhead of the viewer: ``ViewRenderer.render`` against the bare
    ``compute_samples`` + ``render_samples`` (the viewer's gamma and lam) for the same camera
    and sources, and bench_render's case (grid 3×3, centre view from the other 8, same
    settings), alternating."""
    from vibr.geometry import compute_samples
    from vibr.render import render_samples
    from vibr.synthetic import make_scene
    from vibr.viewer import ViewSettings
    from vibr.viewer.renderer import ViewRenderer

    scene = make_scene("handheld", n_views=9, width=size, height=size)
    grid = make_scene("grid", width=size, height=size, grid=(3, 3))
    gsrc, gt = grid.subset([0, 1, 2, 3, 5, 6, 7, 8]), grid.views[4].camera
    r = ViewRenderer(scene)
    st = ViewSettings(n_views=8)
    cams = [_midway(scene.views[0].camera, scene.views[1 + k].camera) for k in range(cameras + 1)]

    def viewer(c):
        out = r.render(c, st)
        return out.seconds, out.iterations

    def direct(c, src=None, tgt=None):
        src = scene.subset(r.sources_for(c, 8)) if src is None else src
        t0 = time.perf_counter()
        res = render_samples(compute_samples(src, tgt or c), "gradient", gamma=st.gamma, lam=st.lam)
        return time.perf_counter() - t0, res.iterations

    fns = {"viewer (ViewRenderer.render)": viewer, "bare compute_samples + render_samples": direct,
           "bench_render's case (grid centre)": lambda c: direct(c, gsrc, gt)}
    viewer(cams[0]), direct(cams[0], gsrc, gt)  # warm-up
    print("| variant | camera | seconds | FISTA iterations |\n|---|---|---|---|")
    for _ in range(repeat):
        for name, f in fns.items():
            for k, c in enumerate(cams[1:]):
                t, it = f(c)
                print(f"| {name} | {k + 1} | {t:.2f} | {it} |", flush=True)
    print(f"\nload average {os.getloadavg()[0]:.1f}")


def ab_preview(size: int = 768, preview: int = 256, cameras: int = 12) -> None:
    """Previews (long side ``preview``) in one outer pass against two, alternating, on the
    benchmark's scene and cameras: render time, FISTA iterations and PSNR against the
    ray-cast truth at the preview's size (2-pixel border)."""
    import vibr.viewer.renderer as R
    from vibr.metrics import psnr
    from vibr.synthetic import default_world, make_scene, render_view

    scene = make_scene("handheld", n_views=9, width=size, height=size)
    world = default_world(0)  # make_scene's world
    r = R.ViewRenderer(scene)
    st = R.ViewSettings(n_views=8)
    cams = [_midway(scene.views[0].camera, scene.views[1 + k % 8].camera).scaled(preview / size)
            for k in range(cameras + 1)]
    r.render(cams[0], st, preview=True)
    r.render(cams[0], st)
    rows = {1: ([], [], []), 2: ([], [], [])}
    for k, cam in enumerate(cams[1:]):
        truth = render_view(world, cam)[0]
        for passes in ((1, 2) if k % 2 == 0 else (2, 1)):
            out = r.render(cam, st, preview=passes == 1)  # 2: the full view's passes at the preview's size
            rows[passes][0].append(out.seconds)
            rows[passes][1].append(out.iterations)
            rows[passes][2].append(psnr(out.image, truth, border=2))
    print(f"| preview {cams[1].width}x{cams[1].height}, {cameras} cameras | render s, median (min-max) | "
          "FISTA iterations, median | PSNR dB, median | PSNR, mean difference to two passes |")
    print("|---|---|---|---|---|")
    for passes in (2, 1):
        t, it, p = rows[passes]
        d = float(np.mean(np.subtract(p, rows[2][2])))
        print(f"| {passes} outer pass{'es' if passes > 1 else ''} | {np.median(t):.3f} ({min(t):.3f}-{max(t):.3f}) | "
              f"{np.median(it):g} | {np.median(p):.3f} | {d:+.4f} |")
    print(f"\nload average {os.getloadavg()[0]:.1f}")


def ab_prepared(size: int = 768, cameras: int = 4) -> None:
    """Full renders with each source's depth preparation kept for the session against
    prepared per request (``PREPARED_BUDGET_BYTES`` = 0), two renderers, alternating."""
    import vibr.viewer.renderer as R
    from vibr.synthetic import make_scene

    scene = make_scene("handheld", n_views=9, width=size, height=size)
    st = R.ViewSettings(n_views=8)
    cams = [_midway(scene.views[0].camera, scene.views[1 + k % 8].camera) for k in range(cameras + 1)]
    budget = R.PREPARED_BUDGET_BYTES
    rs = {"kept": R.ViewRenderer(scene), "per request": R.ViewRenderer(scene)}
    rs["kept"].render(cams[0], st)
    tot, geo, same = {k: [] for k in rs}, {k: [] for k in rs}, []
    for k in range(1, cameras + 1):
        imgs = []
        for mode in (("kept", "per request") if k % 2 else ("per request", "kept")):
            R.PREPARED_BUDGET_BYTES = budget if mode == "kept" else 0
            out = rs[mode].render(cams[k], st)
            tot[mode].append(out.seconds)
            geo[mode].append(out.times["geometry"])
            imgs.append(out.image)
        same.append(np.array_equal(*imgs))
    R.PREPARED_BUDGET_BYTES = budget
    for m in rs:
        print(f"{m}: render {_stats(tot[m])}; geometry stage {_stats(geo[m])}")
    print(f"identical images: {all(same)}; load average {os.getloadavg()[0]:.1f}")


def browser_cpu(seconds: float = 10.0) -> None:
    """CPU used by headless Chromium showing a still viewer page (its WebGL scene drawn by
    software on this machine: viser redraws on demand and once a second) while nothing is
    rendered: the share of the 2 cores the viewer's renders do not get while the browser
    runs on the same machine. The synthetic 768² scene of the latency measurement (its
    point cloud: the viewer's 300 000 points, or ``--max-points``), for each point-cloud
    mode. The page is drawn once a second: the cores it takes are the CPU seconds a frame
    costs."""
    import psutil

    from vibr.synthetic import make_scene
    from vibr.viewer import POINT_MODES

    scene = make_scene("handheld", n_views=9, width=768, height=768)
    me = psutil.Process()

    def children_cpu():
        return sum(_children_cpu().values())

    for mode in POINT_MODES:
        with _viewer_page(scene, mode):
            time.sleep(3)
            c0, w0, s0 = children_cpu(), time.perf_counter(), sum(me.cpu_times()[:2])
            time.sleep(seconds)
            c1, w1, s1 = children_cpu(), time.perf_counter(), sum(me.cpu_times()[:2])
        print(f"points {mode!r}: still viewer page for {w1 - w0:.0f} s: browser processes {c1 - c0:.1f} CPU s "
              f"({(c1 - c0) / (w1 - w0):.2f} cores), viewer process {s1 - s0:.1f} CPU s; "
              f"load average {os.getloadavg()[0]:.1f}", flush=True)


class _sample_cpu:
    """Samples ``proc``'s CPU seconds every 0.1 s on a thread, from just before ``start()``
    is called (``t0``) until :meth:`stop`; ``rows`` = [(time, CPU seconds)]."""

    def __init__(self, proc, start):
        import threading

        self.rows, self._stop = [], threading.Event()
        self._th = threading.Thread(target=self._run, args=(proc,))
        self._th.start()
        self.t0 = time.perf_counter()
        start()

    def _run(self, proc):
        while not self._stop.is_set():
            c = proc.cpu_times()
            self.rows.append((time.perf_counter(), c.user + c.system))
            time.sleep(0.1)

    def stop(self):
        self._stop.set()
        self._th.join()


def _busy(rows, t0: float, until: float) -> tuple[float, float]:
    """(end of the first run of ≥ 0.3 core from ``t0`` on, seconds after t0; CPU seconds
    taken before ``until`` s after t0): the once-a-second redraws later do not count."""
    busy_until, cpu_before, busy = 0.0, 0.0, True
    for (ta, ca), (tb, cb) in zip(rows, rows[1:]):
        if tb - t0 <= until:
            cpu_before += cb - ca
        busy = busy and (cb - ca) / (tb - ta) >= 0.3
        if busy:
            busy_until = tb - t0
    return busy_until, cpu_before


def browser_timeline(updates: int = 4, points_modes=("while moving", "never")) -> None:
    """When the browser takes the CPU during an update: the CPU of Chromium's GPU process
    (where it draws the WebGL scene, in software here) per 0.1 s from the camera move to
    1 s after the full image is sent, and when the preview and the full image were sent,
    for the synthetic 768² scene, per point-cloud mode. viser draws frames on demand, each
    message opening a 0.25 s window of continuous frames; a frame with the points drawn
    takes long in software, so the window stretches. The overlap of that busy time with
    the full render is the render's slowdown in the latency table against
    ``--ab-overhead``."""
    import psutil

    from vibr.synthetic import make_scene

    scene = make_scene("handheld", n_views=9, width=768, height=768)
    targets = [_midway(scene.views[0].camera, scene.views[1 + k % 8].camera) for k in range(updates + 1)]
    print("| points | update | preview sent s | full sent s | full render s | GPU process busy until s "
          "(≥ 0.3 core from the move on) | its CPU s before the full image |")
    print("|---|---|---|---|---|---|---|")
    for mode in points_modes:
        with _viewer_page(scene, mode) as (v, first):
            client = next(iter(v.clients().values()))
            gpu = next(p for p in psutil.Process().children(recursive=True) if "--type=gpu-process" in p.cmdline())
            seq = first.seq
            time.sleep(1.0)
            for k, cam in enumerate(targets):
                samples = _sample_cpu(gpu, lambda: v.move_client(client, cam))
                t0, pre = samples.t0, v.wait_for_image(kind="preview", after_seq=seq, timeout=120)
                full = v.wait_for_image(kind="full", after_seq=seq, timeout=120)
                time.sleep(1.0)
                samples.stop()
                seq = full.seq
                if k == 0:
                    continue  # warm-up
                busy_until, cpu_before = _busy(samples.rows, t0, full.seconds)
                print(f"| {mode} | {k} | {pre.seconds:.2f} | {full.seconds:.2f} | {full.render_seconds:.2f} | "
                      f"{busy_until:.1f} | {cpu_before:.2f} |", flush=True)
    print(f"\nload average {os.getloadavg()[0]:.1f}")


def _arena_child() -> None:
    """In a fresh process (tuned allocator): 6 renders of the viewer's 768² cameras on a
    thread, as the viewer's worker does; JSON: seconds, page faults and system CPU per render."""
    import resource
    import threading

    from vibr._runtime.malloc import tune_malloc
    from vibr.synthetic import make_scene
    from vibr.viewer import ViewSettings
    from vibr.viewer.renderer import ViewRenderer

    tune_malloc()
    scene = make_scene("handheld", n_views=9, width=768, height=768)
    r = ViewRenderer(scene)
    st = ViewSettings(n_views=8)
    cams = [_midway(scene.views[0].camera, scene.views[1 + k % 8].camera) for k in range(7)]
    r.render(cams[0], st)  # warm-up (main thread: loads the kernels)
    out = []

    def work():
        for c in cams[1:]:
            out.append(r.render(c, st).seconds)

    r0 = resource.getrusage(resource.RUSAGE_SELF)
    t = threading.Thread(target=work)
    t.start()
    t.join()
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    n = len(out)
    print(json.dumps({"seconds": out, "faults": (r1.ru_minflt - r0.ru_minflt) / n,
                      "sys_s": (r1.ru_stime - r0.ru_stime) / n}))


def ab_arena(rounds: int = 3) -> None:
    """The viewer's renders on a thread: vibr's one malloc arena against glibc's per-thread
    arenas (``MALLOC_ARENA_MAX=8``, which vibr._runtime.malloc keeps), alternating fresh processes."""
    rows = {"one arena (vibr)": [], "MALLOC_ARENA_MAX=8": []}
    print("| allocator | round | render s, median of 6 (min–max) | page faults / render | system CPU s / render |")
    print("|---|---|---|---|---|")
    for k in range(rounds):
        for label in rows:
            env = {key: v for key, v in os.environ.items() if key != "MALLOC_ARENA_MAX"}
            if label != "one arena (vibr)":
                env["MALLOC_ARENA_MAX"] = "8"
            res = subprocess.run([sys.executable, __file__, "--_arena-child"], env=env, capture_output=True,
                                 text=True, timeout=900)
            if res.returncode != 0:
                raise RuntimeError(res.stderr[-2000:])
            d = json.loads(res.stdout.strip().splitlines()[-1])
            xs = np.asarray(d["seconds"])
            rows[label].append(float(np.median(xs)))
            print(f"| {label} | {k + 1} | {np.median(xs):.2f} ({xs.min():.2f}–{xs.max():.2f}) | {d['faults']:.0f} | "
                  f"{d['sys_s']:.3f} |", flush=True)
    for label, v in rows.items():
        print(f"{label}: median of the rounds' medians {np.median(v):.2f} s")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--updates", type=int, default=7, help="camera updates measured (default 7)")
    ap.add_argument("--browser-nice", type=int, metavar="N",
                    help="renice the benchmark's Chromium to N (19: it only gets the CPU the viewer leaves; "
                         "default: as launched, its GPU process at -8)")
    ap.add_argument("--points", default="while moving",
                    help="the viewer's point-cloud mode (vibr.viewer.POINT_MODES; default 'while moving', "
                         "vibr view's): 'never' shows the server's latency without the browser "
                         "drawing 300 000 points in software on the same cores")
    ap.add_argument("--max-points", type=int, metavar="N",
                    help="points in the viewer's cloud (default: the viewer's, vibr.viewer.ViewerOptions)")
    ap.add_argument("--drag", type=int, default=1, metavar="N",
                    help="each update a drag of N camera moves, 33 ms apart, ending at the target (default 1: "
                         "a jump); the times are from the last move, the preview's from whichever came first")
    ap.add_argument("--client", choices=("chromium", "remote"), default="chromium",
                    help="what moves the camera: headless Chromium on this machine (default; it draws the "
                         "page in software on the same cores) or a client that draws nothing here "
                         "(a browser on another machine)")
    ap.add_argument("--_remote-client", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--skip-fountain", action="store_true")
    ap.add_argument("--skip-synthetic", action="store_true")
    ap.add_argument("--data", default=os.environ.get("VIBR_DATA", str(_REPO.parent / "shared" / "data")))
    ap.add_argument("--_startup", nargs=3, help=argparse.SUPPRESS)
    ap.add_argument("--encode", action="store_true", help="only the PNG encoding comparison")
    ap.add_argument("--ab-settings", action="store_true", help="only the render-settings comparison")
    ap.add_argument("--ab-overhead", action="store_true", help="only the viewer against the bare render")
    ap.add_argument("--ab-prepared", action="store_true", help="only kept against per-request depth preparation")
    ap.add_argument("--ab-preview", action="store_true", help="only previews in one outer pass against two")
    ap.add_argument("--browser-cpu", action="store_true", help="only the CPU an idle viewer page takes")
    ap.add_argument("--browser-timeline", action="store_true",
                    help="only the browser's CPU from a camera move to the full image, per point-cloud mode")
    ap.add_argument("--ab-arena", action="store_true",
                    help="only renders on a thread: one malloc arena against per-thread arenas")
    ap.add_argument("--_arena-child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--numba-threads", choices=("viewer", "default"), default="viewer",
                    help="'viewer' (default): two numba threads per core waiting passively, as `vibr view` "
                         "sets them (vibr._runtime.threads); 'default': numba's one per core, libgomp's spin wait")
    a = ap.parse_args(argv)
    global MAX_POINTS
    MAX_POINTS = a.max_points
    if a.numba_threads == "viewer":  # before vibr imports numba, as `vibr view` does
        from vibr._runtime.threads import oversubscribe_render_threads

        oversubscribe_render_threads()
    from vibr._runtime.malloc import tune_malloc

    tune_malloc()  # as `vibr view` does (VIBR_MALLOC=default: glibc's own settings)
    if a._remote_client:
        _remote_client_main(a._remote_client)
        return 0
    if a.browser_timeline:
        browser_timeline()
        return 0
    if a.browser_cpu:
        browser_cpu()
        return 0
    if a.ab_prepared:
        ab_prepared()
        return 0
    if a.ab_preview:
        ab_preview()
        return 0
    if a.ab_overhead:
        ab_overhead()
        return 0
    if a._arena_child:
        _arena_child()
        return 0
    if a.ab_arena:
        ab_arena()
        return 0
    if a.ab_settings:
        ab_settings()
        return 0
    if a.encode:
        encode_ab()
        return 0
    if a._startup:
        _startup_once(a._startup[0], float(a._startup[1]), a._startup[2])
        return 0
    import numba

    print(f"cpus: {os.cpu_count()}, load average: {os.getloadavg()[0]:.1f} (shared machine); numba threads "
          f"{numba.config.NUMBA_NUM_THREADS}, OMP_WAIT_POLICY {os.environ.get('OMP_WAIT_POLICY', 'unset')}",
          flush=True)
    rows = []
    if not a.skip_synthetic:
        s = synthetic(a.updates, a.points, a.browser_nice, a.client, a.drag)
        print(f"client: {a.client}; point cloud: {a.points}, "
              f"{'default' if a.max_points is None else a.max_points} points; "
              f"browser nice: {a.browser_nice}", flush=True)
        rows += [("synthetic 768², 8 sources: preview (256²), update → sent", _stats(s["preview"]), "≤ 0.3 s"),
                 ("  the preview's render itself (vibr.render + source choice)", _stats(s["preview_render"]), ""),
                 ("synthetic 768², 8 sources: full (768²), update → sent", _stats(s["full"]), "≤ 1.5 s"),
                 ("  the full render itself", _stats(s["full_render"]), "")]
    if not a.skip_fountain:
        f = fountain(Path(a.data) / "strecha_fountain-P11", 0.25, a.numba_threads)
        rows += [("fountain ×0.25: start → first full view, cold (depth estimated)",
                  f"{f['cold']['first_full_s']:6.1f} s  (depth {f['cold']['depth_s']:.1f} s)", "< 60 s"),
                 ("fountain ×0.25: start → first full view, depth cache",
                  f"{f['warm']['first_full_s']:6.1f} s  (depth {f['warm']['depth_s']:.2f} s)", "< 10 s")]
        for label in ("cold", "warm"):
            print(f"\nfountain start, {label}: " + ", ".join(f"{k} {v:.2f} s" for k, v in f[label]["stages"].items()))
            print("  process CPU seconds (all threads): "
                  "" + ", ".join(f"{k} {v:.2f}" for k, v in f[label]["cpu"].items()))
            print(f"  kernels compiled in that process (not loaded from numba's cache): "
                  f"{f[label]['compiled_at_start']}")
    print("\n| measurement | median (spread) | target |\n|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1].strip()} | {r[2]} |")
    print(f"\nload average after: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
