"""The browser viewer: a viser server showing a scene and vibr's render of the view.

Threads: viser runs its event loop on its own thread and calls synchronous callbacks on a
thread pool; those callbacks only record the camera and hand it to the client's
:class:`~vibr.viewer.worker.LatestRequestWorker`, whose thread renders (preview, then full
size once the camera is still) and sends the image as the client's background.
"""

from __future__ import annotations

import contextlib
import io
import logging
import socket
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..camera import Camera
from ..errors import RenderStopped, VibrInputError
from ..eval.sigma_figures import colourise, sigma_scale
from ..io.outputs import check_not_scene_file, check_output
from ..paths.camera_path import interpolate, orient_keys, write_camera_path
from ..render.methods import METHODS
from ..scene import Scene, View
from .convert import camera_from_viser, viser_pose_from_camera
from .geometry import display_origin, frustum_size, point_cloud, scene_scale, thumbnail, world_up
from .renderer import SHOW, ViewRenderer, ViewSettings
from .worker import LatestRequestWorker, Request

logger = logging.getLogger(__name__)

__all__ = ["Viewer", "ViewerOptions", "SentImage", "CameraState", "POINT_MODES", "check_port_free", "encode_png",
           "send_background"]

#: When the point cloud is drawn: while the camera moves (hidden once the preview of the
#: camera's resting place is shown, or when the full-size render starts if no preview came
#: first: the render is then seen whole, and a browser drawing the points without a GPU
#: leaves the server's cores to it), always, never.
POINT_MODES = ("while moving", "always", "never")
#: The side of a drawn point, as a fraction of the scene's size (:func:`.geometry.scene_scale`):
#: 0.004 until 2026-11-28; a browser without a GPU rasterises every point of the frames it
#: draws after a move, which overlap the full render (docs/explanation/viewer.md, "The heap's top")
POINT_SIDE = 0.002

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
        return cls(tuple(map(float, cam.wxyz)), tuple(map(float, cam.position)), float(cam.fov),
                   float(cam.aspect))

    def camera(self, long_side: int, origin=None) -> Camera:
        """The vibr camera of this viewport, its long side ``long_side`` pixels; ``origin``:
        the world point the viewer's positions are relative to (:func:`display_origin`)."""
        pos = self.position if origin is None else np.add(self.position, origin)
        return camera_from_viser(self.wxyz, pos, self.fov, self.aspect, long_side)


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
        with client.atomic():
            client.camera.fov = fov
            client.camera.up_direction = tuple(self.up)
            client.camera.position = pos
            client.camera.wxyz = wxyz
        client.flush()

    # ------------------------------------------------------------------ GUI
    def _add_gui(self) -> None:
        gui = self.server.gui
        s = self.settings
        g = self.gui
        n = len(self.scene)
        g["method"] = gui.add_dropdown("method", METHODS, initial_value=s.method)
        g["gamma"] = gui.add_slider("gamma", 0.0, 5.0, 0.05, s.gamma, hint="gradient-term weight")
        g["lam"] = gui.add_number("lambda", s.lam, min=0.0, max=100.0, step=0.01, hint="TV weight ([0,255] scale)")
        g["n_views"] = gui.add_slider("source views", 1, n, 1, min(s.n_views, n))
        g["preview"] = gui.add_slider("preview size", 64, 768, 32, s.preview_long_side, hint="long side (px) while moving")
        g["full"] = gui.add_number("full size", s.full_long_side, min=16, max=4096, step=16, hint="long side (px) when still")
        g["show"] = gui.add_dropdown("show", tuple(SHOW), initial_value=s.show,
                                     hint="; ".join(f"{k}: {v}" for k, v in SHOW.items()))
        for key in ("method", "gamma", "lam", "n_views", "preview", "full", "show"):
            g[key].on_update(lambda _e: self._settings_changed())
        g["show_sources"] = gui.add_checkbox("show sources used", True)
        g["show_sources"].on_update(lambda _e: self._colour_sources(None))
        g["points"] = gui.add_dropdown("points", POINT_MODES, initial_value=self.options.points,
                                       hint="when the point cloud is drawn over the render")
        g["points"].on_update(lambda _e: self._set_visible("points"))
        g["show_cameras"] = gui.add_checkbox("show cameras", True)
        g["show_cameras"].on_update(lambda _e: self._set_visible("cameras"))
        g["status"] = gui.add_markdown("waiting for a camera")
        g["add_keyframe"] = gui.add_button("add keyframe")
        g["add_keyframe"].on_click(lambda e: self.add_keyframe(e.client))
        out = Path(self.options.path_out)
        g["path_out"] = gui.add_text("path file", out.name, hint=f"file name, written in {out.parent.resolve()}")
        g["export"] = gui.add_button("export path")
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
        st = client_or_state if isinstance(client_or_state, CameraState) else CameraState.of(client_or_state.camera)
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

        out = check_output(path, "file", overwrite=True, what="path file")  # said in the panel, not a traceback
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
        with self._lock:
            self._workers[cid] = worker
            self.sent[cid] = []
        client.camera.on_update(self._on_camera)
        self.move_client(client, self.scene.views[0].camera)

    def _on_disconnect(self, client) -> None:
        with self._lock:
            w = self._workers.pop(client.client_id, None)
            self._states.pop(client.client_id, None)
            self._moving.discard(client.client_id)
        if w is not None:
            w.stop(timeout=0.1)

    def _on_camera(self, cam) -> None:
        t = time.perf_counter()
        st = CameraState.of(cam)
        cid = cam.client.client_id
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
        self.gui["status"].content = (f"{kind} {cam.width}×{cam.height}, {settings.method}, "
                                      f"{len(out.sources)} sources, {dt:.2f} s{what}")

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

