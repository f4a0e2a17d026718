"""The browser viewer: a viser server showing a scene and vibr's render of the view.

Threads: viser runs its event loop on its own thread. A camera report is copied on that
loop as it arrives (:meth:`Viewer._on_report`) and handled on the client's own report thread,
one report after another in the order the browser sent them (:meth:`Viewer._on_camera`: the
camera governed, the render requested); the client's
:class:`~vibr.viewer.worker.LatestRequestWorker` thread renders (preview, then full size once
the camera is still) and sends the image as the client's background.

Why the copy and the order: viser hands every callback its live camera handle, whose state
is the newest report and is also what the server's own camera writes change in place
(:meth:`Viewer.move_client` sets the far-plane marker, the position and the look-at on it),
and runs synchronous callbacks on a pool in any order. Read late, a report could carry the
viewer's own correction as if the browser had applied it, or an older report could be
handled after a newer one; either left the render at a camera the browser had left.
"""

from __future__ import annotations

import contextlib
import io
import logging
import socket
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..camera import Camera
from ..errors import RenderStopped, VibrInputError
from ..eval.sigma_figures import colourise, sigma_scale
from ..io.outputs import check_not_scene_file, check_output, record_file
from ..paths.camera_path import interpolate, orient_keys, write_camera_path
from ..render.methods import METHODS
from ..scene import Scene, View
from .convert import camera_from_viser, viser_pose_from_camera
from .geometry import (
    CameraBounds,
    camera_bounds,
    display_origin,
    drag_gains,
    frustum_size,
    govern_move,
    look_at_wxyz,
    point_cloud,
    scene_scale,
    thumbnail,
    world_up,
)
from .renderer import SHOW, ViewRenderer, ViewSettings
from .worker import LatestRequestWorker, Request

logger = logging.getLogger(__name__)

__all__ = ["Viewer", "ViewerOptions", "SentImage", "CameraState", "POINT_MODES", "HINTS", "check_port_free",
           "encode_png", "send_background"]

#: When the point cloud is drawn: while the camera moves (hidden once the preview of the
#: camera's resting place is shown, or when the full-size render starts if no preview came
#: first: the render is then seen whole, and a browser drawing the points without a GPU
#: leaves the server's cores to it), always, never.
POINT_MODES = ("while moving", "always", "never")
#: The side of a drawn point, as a fraction of the scene's size (:func:`.geometry.scene_scale`):
#: small, since a browser without a GPU rasterises every point of the frames it draws after
#: a move, which overlap the full render (docs/explanation/viewer.md, "The heap's top")
POINT_SIDE = 0.002

#: What each render control does, said in the panel when the pointer rests on it.
HINTS = {
    "gamma": "γ, the weight of the sources' gradients (method gradient). Up: sharper edges and "
             "texture, and stronger ghost edges where sources disagree. Down: softer, smoother.",
    "lam": "λ, the weight of total variation (grey levels 0-255). Up: less noise and fewer small "
           "artefacts, flatter regions, fine texture lost. Down: more detail, more noise.",
    "n_views": "the input views blended, the best ones for this camera. Up: fewer holes, slower, "
               "blurrier where far views join in. Down: faster, more holes at the borders.",
}

_SOURCE_COLOUR = (255, 96, 0)
_FRUSTUM_COLOUR = (60, 60, 60)


@dataclass
class ViewerOptions:
    """Server and display options (the render settings are :class:`ViewSettings`).

    host, port : where to bind (127.0.0.1 by default: the viewer is not exposed)
    max_points : points in the point cloud (subsampled from the depth maps)
    points : when the point cloud is shown, one of :data:`POINT_MODES` (default "while
        moving")
    settle_s : seconds the camera must be still before the full-size render
    path_out : where "export path" writes camera_path.json (the panel may change its file
        name, not its folder)
    fps, seconds_per_keyframe : timing of the exported path (nerfstudio's fps / seconds)
    warm_up : at start, render a 32-px image on a background thread while the scene is
        drawn and the browser loads the page: numba loads its compiled kernels on a
        process's first render, which is then not the client's
    """

    host: str = "127.0.0.1"
    port: int = 8080
    max_points: int = 300_000
    points: str = "while moving"
    settle_s: float = 0.3
    path_out: str = "camera_path.json"
    fps: float = 24.0
    seconds_per_keyframe: float = 1.0
    warm_up: bool = True
    settings: ViewSettings = field(default_factory=ViewSettings)


@dataclass(frozen=True)
class CameraState:
    """A snapshot of a client's viewport camera, as viser reports it."""

    wxyz: tuple
    position: tuple
    fov: float
    aspect: float

    @classmethod
    def of(cls, cam) -> "CameraState":
        """The state of viser's camera handle ``cam`` (or of one of its reports)."""
        cam = getattr(cam, "_state", cam)  # one report: viser replaces it whole on the next
        aspect = cam.image_width / cam.image_height if hasattr(cam, "image_width") else cam.aspect
        return cls(tuple(map(float, cam.wxyz)), tuple(map(float, cam.position)), float(cam.fov),
                   float(aspect))

    def camera(self, long_side: int, origin=None) -> Camera:
        """The vibr camera of this viewport, its long side ``long_side`` pixels; ``origin``:
        the world point the viewer's positions are relative to (:func:`display_origin`)."""
        pos = self.position if origin is None else np.add(self.position, origin)
        return camera_from_viser(self.wxyz, pos, self.fov, self.aspect, long_side)


@dataclass(frozen=True)
class _Report:
    """One camera report of a browser, copied from viser's camera handle as it arrived: the
    handle's state is replaced by the next report and changed in place by the server's own
    camera writes, so it is read once, on viser's event loop (:meth:`Viewer._on_report`)."""

    client: object
    wxyz: tuple
    position: tuple
    fov: float
    aspect: float
    look_at: tuple | None
    up_direction: tuple | None
    far: float

    @classmethod
    def of(cls, cam) -> "_Report":
        st = cam._state
        vec = lambda a: tuple(map(float, a))  # noqa: E731 - copies, never the handle's arrays
        return cls(cam.client, vec(st.wxyz), vec(st.position), float(st.fov),
                   float(st.image_width) / max(1.0, float(st.image_height)), vec(st.look_at),
                   vec(st.up_direction), float(st.far))


@dataclass
class _Steer:
    """The viewer's camera for one client, governed (:meth:`Viewer._govern`): ``position`` and
    ``forward`` (display coordinates), the browser's last reported (position, look-at)
    ``raw``, and the correction sent to the browser that it has not yet applied: the far
    plane value ``pending`` that marks it and the (position, look-at) ``sent``."""

    position: np.ndarray
    forward: np.ndarray
    raw: tuple | None = None
    pending: float | None = None
    sent: tuple | None = None
    clamped: bool = False
    jump: bool = False  # the pending correction is a jump (to an input camera): moves before it are void


@dataclass
class SentImage:
    """What the viewer sent a client: the uint8 ``image``, the ``camera`` it was rendered
    for, ``kind`` ("preview" / "full"), the request ``seq``, the ``sources`` used and the
    server-side latency ``seconds`` from the camera update to the image handed to viser."""

    image: np.ndarray
    camera: Camera
    kind: str
    seq: int
    sources: list
    seconds: float
    render_seconds: float


def encode_png(img: np.ndarray, compress_level: int = 1) -> bytes:
    """Lossless PNG bytes of an H×W×3 uint8 image with zlib level ``compress_level``.

    viser's own encoder (Pillow's default level when OpenCV is absent) is several times
    slower for slightly smaller files (measured in docs/explanation/viewer.md, "Where the time goes")."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(img)).save(buf, format="PNG", compress_level=compress_level)
    return buf.getvalue()


def shown_image(out) -> tuple[np.ndarray, str]:
    """The uint8 image the viewer shows for a render (:class:`ViewImage`) and what the
    status line adds: the render itself, or its σ map through viridis on
    :func:`vibr.eval.sigma_figures.sigma_scale` (the scale said in the status line)."""
    if out.uncertainty is None:
        return np.clip(out.image * 255.0 + 0.5, 0, 255).astype(np.uint8), ""

    vmax = sigma_scale(out.uncertainty)
    return colourise(np.where(np.isfinite(out.uncertainty), out.uncertainty, vmax), vmax), \
        f"; sigma 0 (dark) to {vmax:g} grey levels (yellow)"


def send_background(client, img: np.ndarray, kind: str) -> None:
    """Show ``img`` (uint8) as ``client``'s background: a preview as JPEG (quality 90), a
    full-size view losslessly as PNG (:func:`encode_png`), queued as viser's own
    ``BackgroundImageMessage``; through ``set_background_image`` (slower PNG encoding)
    when this viser has no such message."""
    if kind == "preview":
        client.scene.set_background_image(img, format="jpeg", jpeg_quality=90)
        return
    try:
        from viser import _messages

        queue = client.scene._websock_interface.queue_message
        msg = _messages.BackgroundImageMessage(format="png", rgb_data=encode_png(img), depth_data=None)
    except (ImportError, AttributeError, TypeError):
        client.scene.set_background_image(img, format="png")
        return
    queue(msg)


def _log_failure(future) -> None:
    """Log the exception of a report handled on a client's report thread (else lost)."""
    if not future.cancelled() and future.exception() is not None:
        logger.error("camera report failed", exc_info=future.exception())


def check_port_free(host: str, port: int) -> None:
    """Raise :class:`VibrInputError` naming the port when something listens on it.

    (viser itself would silently move to the next free port.)"""
    s = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
    try:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server binds
        s.bind((host, int(port)))
    except OSError as exc:
        raise VibrInputError(f"port {port} on {host} is not available ({exc.strerror or exc})") from None
    finally:
        s.close()


class Viewer:
    """A running viewer of ``scene`` (every view with depth:
    :func:`vibr.viewer.scene_with_depth`).

    Use :meth:`start` (returns the URL) and :meth:`stop`; or ``with Viewer(...) as v:``.
    ``sent`` maps a client id to the list of :class:`SentImage` sent to it (the newest
    last, at most 64 kept); ``keyframes`` is the list of cameras added with "add keyframe".
    """

    def __init__(self, scene: Scene, options: ViewerOptions | None = None):
        self.scene = scene
        options = options or ViewerOptions()
        if options.points not in POINT_MODES:
            raise VibrInputError(f"points must be one of {', '.join(POINT_MODES)}, not {options.points!r}")
        s = options.settings
        if s.full_long_side is None:  # the scene's own resolution
            s = s.replace(full_long_side=max(max(v.shape) for v in scene.views))
        self.options = replace(options, settings=s)
        self.settings = s
        self.renderer = ViewRenderer(scene)
        self.server = None
        self.sent: dict[int, list[SentImage]] = {}
        self.keyframes: list[Camera] = []
        self._workers: dict[int, LatestRequestWorker] = {}
        self._report_threads: dict[int, ThreadPoolExecutor] = {}  # per client: its reports in order
        self._states: dict[int, CameraState] = {}
        self._lock = threading.Lock()
        self._frustums: dict[str, object] = {}
        self._points = None
        self._moving: set[int] = set()  # clients whose camera moved since their last full render
        self._points_shown: bool | None = None
        self.up = world_up(scene)  # the scene's up, that of the browser's orbit controls
        self._hidden: set[str] = set()  # frustums hidden because the viewport is inside them
        self._scale = 1.0
        self._frustum_size = 0.1
        self.origin = display_origin(scene)  # positions in the browser are relative to it
        self.gui: dict[str, object] = {}
        self.bounds: CameraBounds | None = None  # where the camera may go (display coordinates)
        self._steers: dict[int, _Steer] = {}
        self._markers = 0
        self._sent_event = threading.Condition()
        self.abandoned = 0  # renders stopped early because a newer camera arrived

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> str:
        """Bind the server, draw the scene, add the controls; returns the URL."""
        import viser

        o = self.options
        check_port_free(o.host, o.port)
        with contextlib.redirect_stdout(io.StringIO()):  # viser prints a banner regardless
            server = viser.ViserServer(host=o.host, port=o.port, verbose=False)
        if o.port != 0 and server.get_port() != o.port:
            # taken between the check and the bind: viser moved on to another port
            server.stop()
            raise VibrInputError(f"port {o.port} on {o.host} is not available")
        self.server = server
        if o.warm_up:
            threading.Thread(target=self._warm_up, name="vibr-view-warm-up", daemon=True).start()
        try:
            self._draw_scene()
            self._add_gui()
            self._set_visible("points")
            server.on_client_connect(self._on_connect)
            server.on_client_disconnect(self._on_disconnect)
        except Exception:
            self.stop()
            raise
        return self.url

    def _warm_up(self) -> None:
        """A 32-px render of the first view, discarded: the client's first render finds the
        compiled kernels loaded (it waits for this one on the renderer's lock)."""
        s = self.settings
        cam = self.scene.views[0].camera
        cam = cam.scaled(min(1.0, 32 / max(cam.width, cam.height)))
        t0 = time.perf_counter()
        try:
            self.renderer.render(cam, s)
        except Exception:  # noqa: BLE001 - only time is lost; the client's own render reports
            logger.debug("viewer warm-up render failed", exc_info=True)
            return
        logger.info("viewer: warm-up render in %.2f s", time.perf_counter() - t0)

    @property
    def port(self) -> int:
        return int(self.server.get_port())

    @property
    def url(self) -> str:
        host = self.options.host
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}:{self.port}"

    def stop(self) -> None:
        """Stop the render threads and the server."""
        with self._lock:
            workers = list(self._workers.values())
            self._workers.clear()
            threads = list(self._report_threads.values())
            self._report_threads.clear()
        for t in threads:
            t.shutdown(wait=False, cancel_futures=True)
        for w in workers:
            w.stop()
        if self.server is not None:
            self.server.stop()
            self.server = None

    def __enter__(self) -> "Viewer":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ scene
    def _draw_scene(self) -> None:
        sc = self.server.scene
        sc.set_up_direction(tuple(self.up))
        P, C = point_cloud(self.scene, self.options.max_points, origin=self.origin)
        size = scene_scale(self.scene, P.astype(np.float64) + self.origin)
        self._scale = size
        if len(P):
            self._points = sc.add_point_cloud("/points", P, C, point_size=size * POINT_SIDE,
                                              point_shape="square", point_shading="flat",
                                              precision="float32")
        else:
            self._points = None
        self.bounds = camera_bounds(self.scene, P.astype(np.float64) + self.origin, self.origin)
        fsize = frustum_size(self.scene, size)
        self._frustum_size = fsize
        for v in self.scene.views:
            wxyz, pos, fov, aspect = viser_pose_from_camera(v.camera)
            pos = pos - self.origin
            h = sc.add_camera_frustum(f"/cameras/{v.name}", fov=fov, aspect=aspect, scale=fsize,
                                      thickness=2.0, thickness_units="screen",
                                      image=thumbnail(v.image), format="jpeg", jpeg_quality=85,
                                      wxyz=wxyz, position=pos, color=_FRUSTUM_COLOUR)
            h.on_click(self._make_click(v.camera))
            self._frustums[v.name] = h
        logger.info("viewer: %d cameras, %d points", len(self.scene), len(P))

    def _make_click(self, camera: Camera):
        def cb(event) -> None:
            self.move_client(event.client, camera)

        return cb

    def move_client(self, client, camera: Camera) -> None:
        """Move ``client``'s viewport to ``camera``: its pose and vertical field of view,
        turned upright as a path's keys are (:func:`vibr.paths.camera_path.orient_keys`, "snap": a
        photograph taken rolled by 90° is seen turned; the orbit controls keep the scene's
        up, and would turn it on the first drag)."""

        (camera,), _ = orient_keys([camera], "snap", self.up)
        wxyz, pos, fov, _ = viser_pose_from_camera(camera)
        pos = pos - self.origin
        forward = np.asarray(camera.optical_axis, np.float64)
        look = pos + self._depth() * forward  # the orbit's centre: the scene, not a point near the camera
        with self._lock:
            marker = self._next_marker()
            self._steers[getattr(client, "client_id", None)] = _Steer(pos, forward, pending=marker, sent=(pos, look),
                                                                      jump=True)
        with client.atomic():
            client.camera.far = marker
            client.camera.fov = fov
            client.camera.up_direction = tuple(self.up)
            client.camera.position = pos
            client.camera.wxyz = wxyz
            client.camera.look_at = look
        client.flush()

    # ------------------------------------------------------------------ camera governor
    def _depth(self) -> float:
        return self.bounds.depth if self.bounds is not None else self._scale

    def _next_marker(self) -> float:
        """A far-plane value that marks the next correction sent to a browser (the browser
        reports its far plane with every camera, and keeps it until the server sets another):
        far beyond the scene, distinct from viser's default and from the last 999 markers
        (steps of 1e-4, ten times the tolerance under which viser's setter sends nothing),
        so that a report names the correction it was made after."""
        self._markers += 1
        return max(1000.0, 100.0 * self._depth()) * (1.0 + 1e-4 * (1 + self._markers % 999))

    def _govern(self, cid: int, report) -> tuple["CameraState", tuple | None]:
        """The camera to render for a client's camera report, and the correction to send it.

        viser's orbit controls move at a fixed rate whatever the scene (2π per canvas height
        dragged). Each reported move is scaled by :func:`.geometry.drag_gains` and kept
        within :attr:`bounds` (:func:`.geometry.govern_move`); the browser is then moved to
        the result, so its drawing of the cameras and points matches the render. A browser
        keeps moving from its own camera until the correction arrives: its moves are counted
        from its previous report until a report carries the correction's far-plane marker,
        then from the correction. The browser applies the server's messages in order and
        reports the marker with every camera after it, however long it took (a page still
        loading, a browser drawing without a GPU): a correction is waited for, never given
        up after a time, else the browser's start camera, reported before it applied the
        move to the first view, was taken for a drag away from that view. Returns (state,
        (position, look-at, marker) or None)."""
        raw_state = CameraState.of(report)
        if self.bounds is None or getattr(report, "look_at", None) is None:
            return raw_state, None
        P1 = np.asarray(report.position, np.float64)
        L1 = np.asarray(report.look_at, np.float64)
        if not np.all(np.isfinite(L1)) or np.allclose(L1, P1):
            return raw_state, None
        up = np.asarray(report.up_direction, np.float64)
        with self._lock:
            sv = self._steers.get(cid)
            if sv is None:
                sv = self._steers[cid] = _Steer(P1, (L1 - P1) / np.linalg.norm(L1 - P1))
            if sv.raw is not None or sv.pending is not None:
                base = sv.raw
                if sv.pending is not None and abs(float(report.far) - sv.pending) <= 1e-9 * sv.pending:
                    base, sv.pending, sv.jump = sv.sent, None, False  # the browser moved to the correction
                elif sv.jump:
                    base = None  # the browser's moves before it reached the input camera
                if base is not None:
                    gains = drag_gains(self.bounds, float(report.fov))
                    sv.position, sv.forward, sv.clamped = govern_move(base, (P1, L1), sv.position, sv.forward,
                                                                      gains, self.bounds)
            sv.raw = (P1, L1)
            f1 = (L1 - P1) / np.linalg.norm(L1 - P1)
            if (np.linalg.norm(sv.position - P1) <= 1e-6 * self.bounds.depth
                    and np.linalg.norm(sv.forward - f1) <= 1e-6):
                sv.position, sv.forward = P1, f1  # in step with the browser
                return raw_state, None
            look = sv.position + self.bounds.depth * sv.forward
            state = CameraState(tuple(map(float, look_at_wxyz(sv.position, look, up))),
                                tuple(map(float, sv.position)), raw_state.fov, raw_state.aspect)
            if sv.pending is not None:
                return state, None
            sv.pending, sv.sent = self._next_marker(), (sv.position, look)
            return state, (sv.position, look, sv.pending)

    def _send_pose(self, client, correction) -> None:
        position, look, marker = correction
        with client.atomic():
            client.camera.far = marker
            client.camera.position = position
            client.camera.look_at = look
        client.flush()

    # ------------------------------------------------------------------ GUI
    def _add_gui(self) -> None:
        """The control panel, docked at the right so that it never covers the render (the
        canvas is what is left of the window) and collapsed until the user opens it, its
        rarely used controls in closed folders."""
        gui = self.server.gui
        s = self.settings
        g = self.gui
        n = len(self.scene)
        gui.main_panel.dock_right()
        gui.main_panel.minimize()
        g["status"] = gui.add_markdown("waiting for a camera")
        with gui.add_folder("render"):
            g["method"] = gui.add_dropdown("method", METHODS, initial_value=s.method,
                                           hint="how the source views are blended (docs: explanation/method)")
            g["gamma"] = gui.add_slider("edge sharpness (γ)", 0.0, 5.0, 0.05, s.gamma, hint=HINTS["gamma"])
            g["lam"] = gui.add_number("smoothing (λ)", s.lam, min=0.0, max=100.0, step=0.01, hint=HINTS["lam"])
            g["n_views"] = gui.add_slider("source views", 1, n, 1, min(s.n_views, n), hint=HINTS["n_views"])
            g["show"] = gui.add_dropdown("show", tuple(SHOW), initial_value=s.show,
                                         hint="; ".join(f"{k}: {v}" for k, v in SHOW.items()))
        with gui.add_folder("display", expand_by_default=False):
            g["preview"] = gui.add_slider("preview size", 64, 768, 32, s.preview_long_side,
                                          hint="long side (px) while moving: up, sharper and slower previews")
            g["full"] = gui.add_number("full size", s.full_long_side, min=16, max=4096, step=16,
                                       hint="long side (px) when still: up, more detail, slower")
            g["show_sources"] = gui.add_checkbox("show sources used", True,
                                                 hint="the input cameras of the render drawn in orange")
            g["points"] = gui.add_dropdown("points", POINT_MODES, initial_value=self.options.points,
                                           hint="when the point cloud is drawn over the render")
            g["show_cameras"] = gui.add_checkbox("show cameras", True, hint="the input cameras' frustums")
        for key in ("method", "gamma", "lam", "n_views", "preview", "full", "show"):
            g[key].on_update(lambda _e: self._settings_changed())
        g["show_sources"].on_update(lambda _e: self._colour_sources(None))
        g["points"].on_update(lambda _e: self._set_visible("points"))
        g["show_cameras"].on_update(lambda _e: self._set_visible("cameras"))
        with gui.add_folder("camera path", expand_by_default=False):
            g["add_keyframe"] = gui.add_button("add keyframe", hint="record the current camera")
            g["add_keyframe"].on_click(lambda e: self.add_keyframe(e.client))
            out = Path(self.options.path_out)
            g["path_out"] = gui.add_text("path file", out.name,
                                         hint=f"file name, written in {out.parent.resolve()}")
            g["export"] = gui.add_button("export path", hint="a smooth path through the keyframes, for vibr render --path")
            g["export"].on_click(lambda e: self._export_clicked(e.client))
            g["keyframes"] = gui.add_markdown("0 keyframes")

    def _settings_changed(self) -> None:
        g = self.gui
        try:
            self.settings = self.settings.replace(method=str(g["method"].value), gamma=float(g["gamma"].value),
                                                  lam=float(g["lam"].value), n_views=int(g["n_views"].value),
                                                  preview_long_side=int(g["preview"].value),
                                                  full_long_side=int(g["full"].value), show=str(g["show"].value))
        except VibrInputError as exc:
            g["status"].content = f"invalid setting: {exc}"
            return
        with self._lock:
            items = [(cid, self._states.get(cid), w) for cid, w in self._workers.items()]
        for _cid, st, w in items:
            if st is not None:
                w.submit((st, self.settings))

    def _set_visible(self, what: str) -> None:
        if what == "points" and self._points is not None:
            with self._lock:
                mode = str(self.gui["points"].value) if "points" in self.gui else self.options.points
                on = mode == "always" or (mode == "while moving" and bool(self._moving))
                changed = on != self._points_shown
                self._points_shown = on
            if changed:  # one message per change, not per camera update
                self._points.visible = on
        if what == "cameras":
            on = bool(self.gui["show_cameras"].value)
            for name, h in self._frustums.items():
                h.visible = on and name not in self._hidden

    def _at_rest(self, client) -> None:
        """The client's camera has stopped: the points go in "while moving" mode."""
        with self._lock:
            self._moving.discard(client.client_id)
        self._set_visible("points")

    def _hide_frustums_at(self, centre) -> None:
        """Hide the frustums the viewport sits in (their thumbnail would fill the view)."""
        C = np.asarray(centre, dtype=np.float64)
        near = {v.name for v in self.scene.views
                if np.linalg.norm(v.camera.centre - C) < 1.5 * self._frustum_size}
        if near != self._hidden:
            self._hidden = near
            self._set_visible("cameras")

    def _colour_sources(self, used) -> None:
        if used is None:
            used = getattr(self, "_last_sources", [])
        self._last_sources = list(used)
        on = bool(self.gui["show_sources"].value)
        for name, h in self._frustums.items():
            h.color = _SOURCE_COLOUR if (on and name in used) else _FRUSTUM_COLOUR

    # ------------------------------------------------------------------ keyframes
    def add_keyframe(self, client_or_state) -> Camera:
        """Append the camera of a client (or of a :class:`CameraState`) at the full render
        size; every keyframe keeps the first one's image size (its vertical fov kept)."""
        if isinstance(client_or_state, CameraState):
            st = client_or_state
        else:  # the camera the client sees rendered (governed), else its own
            st = self._states.get(client_or_state.client_id) or CameraState.of(client_or_state.camera)
        if self.keyframes:
            w, h = self.keyframes[0].width, self.keyframes[0].height
            cam = st.camera(max(w, h), self.origin)
            if (cam.width, cam.height) != (w, h):
                f = cam.K[1, 1] * h / cam.height
                cam = Camera(Camera.intrinsics(f, w, h), cam.R, cam.t, w, h)
        else:
            cam = st.camera(self.settings.full_long_side, self.origin)
        self.keyframes.append(cam)
        if "keyframes" in self.gui:
            self.gui["keyframes"].content = f"{len(self.keyframes)} keyframes"
        return cam

    def _gui_path_file(self) -> Path:
        """The panel's "path file": a bare file name ending in .json, in the folder of
        ``options.path_out``. Whoever reaches the page types it (with ``--host 0.0.0.0``,
        anyone on the network): a path with folders could overwrite any file vibr may write."""
        default = Path(self.options.path_out)
        if "path_out" not in self.gui:
            return default
        name = str(self.gui["path_out"].value).strip()
        if Path(name).name != name or not name.lower().endswith(".json") or name.startswith("."):
            raise VibrInputError(f"the path file is a file name ending in .json, written in "
                                 f"{default.parent.resolve()}; got {name!r}")
        return default.parent / name

    def export_path(self, path=None, seconds: float | None = None) -> Path:
        """Write the keyframes as nerfstudio's camera_path.json: a C²-smooth path through
        them (:func:`vibr.paths.camera_path.interpolate`, ``seconds`` × fps frames; default
        ``seconds_per_keyframe`` per interval), written by
        :func:`vibr.paths.camera_path.write_camera_path`. Returns the file written."""

        if not self.keyframes:
            raise VibrInputError("no keyframes to export: add some first")
        if path is None:
            path = self._gui_path_file()

        # said in the panel, not a traceback; a file vibr did not write is never replaced
        out = check_output(path, "file", overwrite=False, what="path file")
        check_not_scene_file(out, self.scene, "the path file")
        fps = self.options.fps
        if seconds is None:
            seconds = max(len(self.keyframes) - 1, 1) * self.options.seconds_per_keyframe
        if len(self.keyframes) == 1:
            write_camera_path(out, self.keyframes, fps=fps, seconds=1.0 / fps)
        else:
            keys = Scene([View(f"key_{i:03d}", None, c) for i, c in enumerate(self.keyframes)], "keyframes")
            # the user posed the keyframes: their roll is theirs
            cpath = interpolate(keys, n_frames=max(2, int(round(seconds * fps))), fps=fps, roll="keep")
            write_camera_path(out, cpath.cameras, fps=fps, seconds=seconds)
        record_file(out)  # vibr's: the next export may replace it
        logger.info("wrote %s (%d keyframes)", out, len(self.keyframes))
        return out

    def _export_clicked(self, client) -> None:
        try:
            out = self.export_path()
        except VibrInputError as exc:
            self.gui["keyframes"].content = f"{len(self.keyframes)} keyframes: {exc}"
            return
        self.gui["keyframes"].content = f"{len(self.keyframes)} keyframes, written to `{out}`"
        client.send_file_download(out.name, out.read_bytes())

    # ------------------------------------------------------------------ clients
    def _on_connect(self, client) -> None:
        cid = client.client_id
        worker = LatestRequestWorker(lambda req, kind: self._render_for(client, req, kind),
                                     settle_s=self.options.settle_s, name=f"vibr-view-{cid}")
        reports = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"vibr-view-camera-{cid}")
        with self._lock:
            self._workers[cid] = worker
            self._report_threads[cid] = reports
            self.sent[cid] = []
        # moved before its reports are heard: a report handled before the move would be the
        # browser's start camera, governed from nothing, and its image the first one shown
        self.move_client(client, self.scene.views[0].camera)
        client.camera.on_update(self._on_report)

    def _on_disconnect(self, client) -> None:
        with self._lock:
            w = self._workers.pop(client.client_id, None)
            reports = self._report_threads.pop(client.client_id, None)
            self._states.pop(client.client_id, None)
            self._steers.pop(client.client_id, None)
            self._moving.discard(client.client_id)
        if reports is not None:
            reports.shutdown(wait=False, cancel_futures=True)
        if w is not None:
            w.stop(timeout=0.1)

    async def _on_report(self, cam) -> None:
        """viser's camera callback, on its event loop as the report arrives: the report is
        copied now (:class:`_Report`) and handled on the client's report thread, after the
        reports before it (:meth:`_on_camera`; nothing that waits runs on the loop)."""
        report = _Report.of(cam)
        reports = self._report_threads.get(report.client.client_id)
        if reports is None:
            return
        try:
            reports.submit(self._on_camera, report, time.perf_counter()).add_done_callback(_log_failure)
        except RuntimeError:  # shut down: the client left or the viewer stopped
            pass

    def _on_camera(self, cam, t: float | None = None) -> None:
        """Handle one camera report (a :class:`_Report`, or anything with its fields) made at
        time ``t``: govern it, correct the browser, request the render."""
        t = time.perf_counter() if t is None else t
        cid = cam.client.client_id
        st, correction = self._govern(cid, getattr(cam, "_state", cam))
        if correction is not None:
            self._send_pose(cam.client, correction)
        with self._lock:
            same = self._states.get(cid) == st
            self._states[cid] = st
            w = self._workers.get(cid)
        # the browser often reports one move several times: an identical camera would only
        # abandon or repeat the render of the request already made for it
        if w is not None and not same:
            w.submit((st, self.settings), t_update=t)
            with self._lock:
                self._moving.add(cid)
            self._set_visible("points")
        self._hide_frustums_at(np.add(st.position, self.origin))

    def request(self, client_id: int, state: CameraState, t_update: float | None = None) -> int:
        """Queue a render of ``state`` for a client as a camera update would (benchmarks)."""
        with self._lock:
            self._states[client_id] = state
            w = self._workers[client_id]
        return w.submit((state, self.settings), t_update=t_update)

    def _render_for(self, client, req: Request, kind: str) -> None:
        st, settings = req.payload
        long_side = settings.preview_long_side if kind == "preview" else settings.full_long_side
        if kind == "preview" and long_side >= settings.full_long_side:
            return  # the full render follows; a preview as large would only delay it
        cam = st.camera(long_side, self.origin)
        if kind == "full":  # the camera has been still for settle_s
            self._at_rest(client)
        worker = self._workers.get(client.client_id)
        stale = (lambda: worker.is_stale(req)) if worker is not None else None
        try:
            out = self.renderer.render(cam, settings, should_stop=stale, preview=kind == "preview")
        except RenderStopped:
            self.abandoned += 1
            return  # the camera moved on: the newer request is rendered next
        except VibrInputError as exc:  # a camera turned away from the scene: said in the panel
            logger.debug("%s render of request %d: %s", kind, req.seq, exc.problem)
            if "status" in self.gui:
                self.gui["status"].content = f"nothing to render from here: {exc.problem}"
            return
        if kind == "full" and stale is not None and stale():
            return
        img, what = shown_image(out)
        send_background(client, img, kind)
        if kind == "preview" and stale is not None and not stale():
            # no newer camera: hide the points with this image rather than when the full render
            # starts, so that the frames the browser draws for it fall before that render
            # (docs/explanation/viewer.md, "Points hidden with the preview")
            self._at_rest(client)
        client.flush()
        dt = time.perf_counter() - req.t_update
        rec = SentImage(img, cam, kind, req.seq, out.sources, dt, out.seconds)
        with self._sent_event:
            lst = self.sent.setdefault(client.client_id, [])
            lst.append(rec)
            del lst[:-64]
            self._sent_event.notify_all()
        self._colour_sources(out.sources)
        sv = self._steers.get(client.client_id)
        edge = "; kept near the input cameras" if sv is not None and sv.clamped else ""
        self.gui["status"].content = (f"{kind} {cam.width}×{cam.height}, {settings.method}, "
                                      f"{len(out.sources)} sources, {dt:.2f} s{what}{edge}")

    def wait_for_image(self, client_id=None, kind: str = "full", after_seq: int = 0,
                       timeout: float = 30.0) -> SentImage | None:
        """Block until an image of ``kind`` with ``seq > after_seq`` was sent (to any client
        when ``client_id`` is None); returns it, or None on timeout."""
        deadline = time.monotonic() + timeout
        with self._sent_event:
            while True:
                for cid, lst in self.sent.items():
                    if client_id is not None and cid != client_id:
                        continue
                    for rec in reversed(lst):
                        if rec.kind == kind and rec.seq > after_seq:
                            return rec
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._sent_event.wait(left)

    def clients(self) -> dict:
        return self.server.get_clients() if self.server is not None else {}

