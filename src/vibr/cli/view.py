"""``vibr view``: an interactive viewer of a scene in the web browser (viser)."""

from __future__ import annotations

import argparse
import logging
import math
import time

from . import count
from ._options import (
    add_cache_options,
    add_method_option,
    add_method_options,
    cache_dir_from_args,
    refuse_ignored_params,
    render_params,
)

logger = logging.getLogger(__name__)

_DESC = """\
Serve an interactive viewer of SCENE on http://HOST:PORT (viser): the input cameras as
frustums with thumbnails (click one to move there), a point cloud from the depth maps, and
vibr's render of the browser's view (a small preview while the camera moves, full size once
it is still). The camera moves at the scale of the scene and stays near the input cameras.
Controls (a panel docked at the right, collapsed at first): method, edge sharpness (gamma),
smoothing (lambda), source views, preview size; "add keyframe" and "export path" write a camera_path.json (nerfstudio's schema) that
'vibr render --path' renders. A scene without depth maps gets them estimated once at start.
The server listens on 127.0.0.1 only unless --host says otherwise. Stop with Ctrl-C.
Renders run on two numba threads per core that sleep between kernels, so that a browser
drawing on the same cores slows them less (NUMBA_NUM_THREADS and OMP_WAIT_POLICY, when set,
are kept).
"""

_EPILOG = """\
examples:
  vibr view ../shared/data/strecha_fountain-P11 --scale 0.25
  vibr view scene/ --port 8090 --path-out my_path.json
"""


def register(sub) -> None:
    p = sub.add_parser("view", help="interactive viewer in the web browser",
                       description=_DESC, epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", metavar="SCENE", help="scene folder (any supported format)")
    p.add_argument("--port", type=int, default=8080, help="port to listen on (default 8080)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1; 0.0.0.0 exposes the viewer to the network)")
    p.add_argument("--scale", type=float, default=1.0, help="image scale of the scene, e.g. 0.5 (default 1)")
    add_method_option(p)
    add_method_options(p)  # the GUI starts from --gamma / --lam and renders with the others
    p.add_argument("--views", type=int, default=8, metavar="K",
                   help="initial number of source views: the K best for the view shown (default 8)")
    from ..viewer.app import POINT_MODES, ViewerOptions

    p.add_argument("--max-points", type=int, default=ViewerOptions.max_points,
                   help=f"points in the point cloud (default {ViewerOptions.max_points}; a browser that draws "
                        "without a GPU spends most of a frame on them: fewer make its moves smoother)")

    p.add_argument("--points", choices=POINT_MODES, default=POINT_MODES[0],
                   help=f"when the point cloud is drawn over the render (default '{POINT_MODES[0]}': hidden "
                        "once the camera has stopped and the preview of where it stopped is shown)")
    add_cache_options(p)
    p.add_argument("--path-out", default=None, help="file 'export path' writes (default camera_path.json)")
    p.set_defaults(func=run)


#: views larger than this (pixels) make the viewer slow at --scale 1: a hint is printed
LARGE_VIEW_PIXELS = 2_500_000


def _hint_large_views(scene, scale: float) -> None:
    """A one-line hint when the views are large (docs/explanation/viewer.md, "Large photographs")."""
    w, h = max((v.camera.width, v.camera.height) for v in scene.views)
    if w * h > LARGE_VIEW_PIXELS:
        s = 2 ** round(math.log2(math.sqrt(500_000 / (w * h)) * scale))  # about half a megapixel
        logger.warning("the views are %dx%d: depth estimation takes minutes per view and each still "
                       "render seconds at this size; --scale %g keeps the viewer interactive", w, h, s)


def _settings(args, settings_cls):
    """The viewer's first :class:`~vibr.viewer.ViewSettings`: the method options given (gamma
    and lam start the GUI's controls; with --preset and without them, the preset's own)."""
    from ..errors import VibrInputError
    from ..render.params import AUTO, PRESET_DEFAULTS

    refuse_ignored_params(args)
    kw = {k: v for k, v in render_params(args).items() if v is not None}
    weights = {k: kw.pop(k) for k in ("gamma", "lam") if k in kw}
    if AUTO in weights.values():
        raise VibrInputError("--gamma/--lam auto does not apply to vibr view: the viewer's controls set them")
    start = {k: v for k, v in PRESET_DEFAULTS.get(kw.get("preset"), {}).items() if k in ("gamma", "lam")}
    return settings_cls(method=args.method, n_views=args.views, params=kw, **{**start, **weights})


def run(args) -> int:
    from ..errors import VibrInputError
    from ..pipeline import load_scene_cached
    from ..viewer import Viewer, ViewerOptions, ViewSettings, check_port_free, scene_with_depth

    if not 0 <= args.port <= 65535:
        raise VibrInputError(f"--port must be in 0..65535, got {args.port}")
    if args.views < 1 or args.max_points < 0:
        raise VibrInputError("--views must be >= 1 and --max-points >= 0")
    settings = _settings(args, ViewSettings)
    from ..io.outputs import check_not_scene_file, check_output

    if args.path_out is not None:  # given: checked now, not at the first 'export path'
        check_output(args.path_out, "file", overwrite=False, what="--path-out")
    check_port_free(args.host, args.port)  # fail before the (slow) loading
    # the resized photographs and the estimated depth come from the on-disk cache when there
    cache_dir = cache_dir_from_args(args)
    scene = load_scene_cached(args.scene, scale=args.scale, cache_dir=cache_dir)
    check_not_scene_file(args.path_out or "camera_path.json", scene, "--path-out")
    _hint_large_views(scene, args.scale)
    if not scene.has_depth:
        t0 = time.perf_counter()
        scene = scene_with_depth(scene, cache_dir=cache_dir)
        logger.info("depth ready in %.1f s", time.perf_counter() - t0)
    # a browser's aborted preconnect is logged with a traceback by websockets: not an error here
    logging.getLogger("websockets.server").setLevel(logging.CRITICAL)
    opts = ViewerOptions(host=args.host, port=args.port, max_points=args.max_points, points=args.points,
                         path_out=args.path_out or "camera_path.json", settings=settings)
    viewer = Viewer(scene, opts)
    url = viewer.start()
    import numba

    logger.debug("renders on %d numba threads (vibr._runtime.threads)", numba.config.NUMBA_NUM_THREADS)
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        logger.warning("listening on %s: anyone who reaches this machine at %s can use the viewer "
                       "(its photographs, and keyframe paths written beside --path-out)", args.host, url)
    try:
        print(f"vibr view: {scene.name} ({count(len(scene), 'view')}) at {url}  (Ctrl-C to stop)", flush=True)
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        return 0
    finally:
        viewer.stop()
