"""``vibr demo``: render a new view of a built-in synthetic scene, no download needed."""

from __future__ import annotations

import argparse
import logging
import os
import time

from ._options import add_bit_depth_option, add_method_option, add_overwrite_option

logger = logging.getLogger(__name__)

#: The demo's fly-through: frames and rate (3 s, slow enough to follow the parallax).
DEMO_FRAMES = 72
DEMO_FPS = 24.0

_DESC = """\
Build a synthetic scene (textured planes, a box and a sphere, ray-cast with exact depth),
render a new view between its cameras from all of them with the chosen method, and print
PSNR and DSSIM against the true image ray-cast there. This is the quickest check that vibr
works on a machine.
"""

_EPILOG = """\
examples:
  vibr demo                         3x3 light-field grid, 256x256, a new view halfway from the centre
                                    to a corner; a 3 s loop round the grid's views to vibr-demo.mp4
  vibr demo --layout arc --size 384 -o demo.png
  vibr demo --method bvs            compare with the Bayesian baseline
"""


def register(sub) -> None:
    p = sub.add_parser("demo", help="render a new view of a built-in synthetic scene",
                       description=_DESC, epilog=_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--layout", choices=["grid", "arc", "free"], default="grid",
                   help="camera layout of the synthetic scene (default: grid)")
    p.add_argument("--size", type=int, default=256, help="image width and height in pixels (default: 256)")
    add_method_option(p)
    p.add_argument("--seed", type=int, default=0, help="random seed of the scene (default: 0)")
    p.add_argument("-o", "--output", help="also write the rendered view to this PNG")
    v = p.add_mutually_exclusive_group()
    v.add_argument("--video", default="vibr-demo.mp4",
                   help="fly-through (3 s at 24 fps through the scene's views: a loop round the grid, a sweep "
                        "along the arc) written to this video, .mp4 or another format by its extension as "
                        "'vibr render --path' (default: vibr-demo.mp4)")
    v.add_argument("--no-video", action="store_true", help="skip the fly-through video")
    # for the tests: a shorter fly-through, its frames kept
    p.add_argument("--video-frames", type=int, default=DEMO_FRAMES, help=argparse.SUPPRESS)
    p.add_argument("--frames-dir", help=argparse.SUPPRESS)
    add_bit_depth_option(p)
    add_overwrite_option(p, "an -o or --video file vibr did not write")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..errors import VibrInputError
    from ..io import write_image
    from ..io.images import check_image_ext
    from ..io.outputs import check_output, record_file
    from ..metrics import dssim, psnr
    from ..render import render
    from ..synthetic import make_scene

    if args.output is not None:
        check_output(args.output, "file", overwrite=args.overwrite, what="-o")
        check_image_ext(args.output, args.bit_depth)
    elif args.bit_depth is not None:
        raise VibrInputError("--bit-depth applies to the PNG of -o only (the video is 8-bit)")
    if not args.no_video:  # before the work: a file vibr did not write is not replaced
        check_output(args.video, "file", overwrite=args.overwrite, what="--video")
    if not 16 <= args.size <= 4096:
        raise VibrInputError(f"--size must be between 16 and 4096 pixels, got {args.size}")
    t0 = time.perf_counter()
    n = 9 if args.layout == "grid" else 8
    scene = make_scene(layout=args.layout, n_views=n, width=args.size, height=args.size, seed=args.seed)
    name, cam, truth = demo_target(scene)
    t1 = time.perf_counter()
    logger.info(f"scene: {len(scene)} views ({args.layout}), {args.size}x{args.size}, made in {t1 - t0:.2f} s; "
                f"rendering {name} from all {len(scene)}")
    res = render(scene, cam, method=args.method, progress_bar=True)
    t2 = time.perf_counter()
    mask = res.coverage
    print(f"vibr demo: {args.method} rendering of {name} from {len(scene)} views "
          f"({args.size}x{args.size}) in {t2 - t1:.2f} s")
    print(f"  PSNR  {psnr(res.image, truth, mask=mask):6.2f} dB   (reconstructed pixels, "
          f"{100 * mask.mean():.1f}% of the image)")
    print(f"  DSSIM {dssim(res.image, truth, mask=mask):6.1f}      (1e4 * (1 - SSIM), lower is better)")
    print(f"  PSNR  {psnr(res.image, truth):6.2f} dB   (all pixels, holes filled by push-pull)")
    if args.output:
        write_image(args.output, res.image, bits=args.bit_depth or 8)
        record_file(args.output)
        print(f"  wrote {args.output}")
    if not args.no_video:
        _demo_video(scene, args)
    return 0


def demo_target(scene):
    """The demo's new view: (its name, its camera, the image ray-cast there). Halfway from the
    middle view to the next one along the layout (on the grid, its lower-right corner view):
    a camera none of the views stands at, where a render meets what a fly-through's frames
    meet. A held-out view of the grid would be a best case: its neighbours sit at whole-pixel
    offsets from it, and its silhouettes land where theirs do."""
    from ..paths.camera_path import interpolate
    from ..synthetic import default_world, render_view

    c = len(scene) // 2
    other = c + (scene.grid[1] + 1 if scene.grid else 1)
    a, b = scene.names[c], scene.names[min(other, len(scene) - 1)]
    cam = interpolate(scene, [a, b], n_frames=3).cameras[1]
    world = default_world(scene.meta.get("seed", 0))
    truth = render_view(world, cam, int(scene.meta.get("supersample", 2)))[0]
    return f"a new view halfway from {a} to {b}", cam, truth


def demo_path(scene, n_frames: int = DEMO_FRAMES, fps: float = DEMO_FPS):
    """The demo's fly-through: :func:`vibr.paths.camera_path.interpolate` through the scene's
    views — on the grid a loop round its border (corner to opposite corner at mid-path: the
    whole parallax the views cover), on the arc a sweep along it.

    Shrinking the loop into the grid (its spline bulges 6 % past the border between keys)
    did not raise its worst frame: a frame between views loses against the truth wherever it
    lies (tests/test_cli_demo.py measures the frames' PSNR and the parallax)."""
    from ..paths.camera_path import interpolate

    return interpolate(scene, n_frames=n_frames, fps=fps)


def frames_psnr(scene, path, frames_dir) -> list[float]:
    """PSNR (dB, all pixels) of each written frame of the demo's fly-through against the
    ray-cast truth at its camera (the synthetic world the scene was made from)."""
    from ..io import read_image
    from ..metrics import psnr
    from ..paths.flythrough import frame_name
    from ..synthetic import default_world, render_view

    world = default_world(scene.meta.get("seed", 0))
    ss = int(scene.meta.get("supersample", 2))
    return [psnr(read_image(os.path.join(frames_dir, frame_name(i))), render_view(world, cam, ss)[0])
            for i, cam in enumerate(path.cameras)]


def _demo_video(scene, args) -> None:
    """The demo's fly-through (:func:`demo_path`, docs/explanation/flythrough.md) to
    args.video, and its frames' PSNR against the ray-cast truth."""
    import shutil
    import tempfile

    from ..errors import VibrInputError
    from ..io.outputs import record_file
    from ..io.video import VIDEO_FORMATS, is_video
    from ..paths.flythrough import render_path

    if not is_video(args.video):
        raise VibrInputError(f"the demo video must be a video file ({', '.join(VIDEO_FORMATS)})", args.video)
    if args.video_frames < 2:
        raise VibrInputError(f"the demo video needs at least 2 frames, got {args.video_frames}")
    t0 = time.perf_counter()
    path = demo_path(scene, args.video_frames)
    tmp = args.frames_dir or tempfile.mkdtemp(prefix="vibr-demo-frames-")
    try:
        res = render_path(scene, path, args.video, method=args.method, n_views=4, frames_dir=tmp,
                          cache_dir=False, progress=True)
        scores = frames_psnr(scene, path, tmp)
    finally:
        if not args.frames_dir:
            shutil.rmtree(tmp, ignore_errors=True)
    record_file(res.video)
    what = "loop round the grid" if path.meta.get("closed") else "sweep through the views"
    print(f"vibr demo: fly-through ({res.video_frames} frames, {res.video_size[0]}x{res.video_size[1]}, "
          f"{path.seconds:.1f} s {what}) rendered in {time.perf_counter() - t0:.1f} s")
    worst = min(range(len(scores)), key=scores.__getitem__)
    print(f"  PSNR  {scores[worst]:6.2f} dB   (all pixels, its worst frame ({worst}) against the ray-cast truth; "
          f"{min(scores):.2f}-{max(scores):.2f} dB, mean {sum(scores) / len(scores):.2f})")
    print(f"  wrote {os.path.abspath(res.video)}")
