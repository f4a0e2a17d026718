"""``vibr path``: make a camera path (nerfstudio camera_path.json) through or around a scene."""

from __future__ import annotations

import argparse

from . import add_quiet, count
from ._options import add_overwrite_option, names

_DESC = """\
Write a camera path for a fly-through of SCENE in nerfstudio's camera_path.json schema
(camera_to_world 4x4 row-major in OpenGL camera axes, vertical fov in degrees; docs/explanation/flythrough.md),
to render with 'vibr render SCENE --path PATH.json -o video.mp4'; with --dataparser-transforms
the path is written in the normalised frame of a nerfstudio model of the scene, for ns-render.
Kinds: interpolate (a C2-smooth spline through the scene's cameras: all, nearest next, or
--views in that order; on a light field's grid a loop round it through its corners and the
middles of its sides), orbit (an ellipse around the point the cameras look at, at their
mean height and distance; an arc swept back and forth when the cameras do not surround
it), spiral (an LLFF-style forward-facing spiral around the mean camera).
"""

_EPILOG = """\
examples:
  vibr path interpolate ../shared/data/strecha_fountain-P11 -o fountain.json --frames 60 --scale 0.25
  vibr path orbit ../shared/data/middlebury_templeSparseRing -o orbit.json --seconds 4 --fps 24
  vibr path spiral SCENE -o spiral.json --frames 90 --size 640x480
  vibr path interpolate SCENE -o p.json --views 0003,0005,0004 --order proximity
  vibr path interpolate ../shared/data/middlebury_templeSparseRing -o ring.json --frames 96 --roll level
"""


def _size(s):
    try:
        w, h = s.lower().split("x")
        w, h = int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must be WxH, e.g. 768x512, got {s!r}") from None
    if w <= 0 or h <= 0:
        raise argparse.ArgumentTypeError(f"size must be positive, got {s!r}")
    return w, h


def register(sub) -> None:
    from ..paths.camera_path import PATH_KINDS, ROLL_MODES

    p = sub.add_parser("path", help="make a camera path (nerfstudio camera_path.json) for a fly-through",
                       description=_DESC, epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("kind", choices=PATH_KINDS, help="kind of path")
    p.add_argument("scene", help="scene folder (any supported format)")
    p.add_argument("-o", "--output", required=True, help="camera path file to write (.json)")
    add_overwrite_option(p, "an -o file vibr did not write")
    p.add_argument("--frames", type=int, help="number of frames (default: --seconds x --fps)")
    p.add_argument("--seconds", type=float, default=None, help="duration in seconds (default 4 without --frames)")
    p.add_argument("--fps", type=float, default=24.0, help="frames per second (default 24)")
    p.add_argument("--size", type=_size, metavar="WxH", help="frame size (default: the first view's, after --scale; W and H swapped when its "
                        "photograph is turned upright by a quarter turn, see --roll)")
    p.add_argument("--scale", type=float, default=1.0, help="image scale of the scene, e.g. 0.25 (default 1)")
    p.add_argument("--views", type=names, help="interpolate: comma-separated views to pass through, in order (default: all)")
    p.add_argument("--order", choices=["given", "proximity"], default=None,
                   help="interpolate: keep the given order or reorder the views by proximity (default: "
                        "proximity through all the scene's views, the given order with --views or for the "
                        "frames of a video, from 'vibr calibrate VIDEO': time order)")
    p.add_argument("--roll", choices=list(ROLL_MODES), default=None,
                   help="interpolate: how the key cameras are turned about their axes: "
                        + "; ".join(f"{k}: {v}" for k, v in ROLL_MODES.items()) + " (default: snap)")
    p.add_argument("--smooth", type=float, default=None, metavar="SIGMA",
                   help="interpolate: smooth the key cameras along the path first, a Gaussian of SIGMA keys "
                        "(e.g. 2 for the frames of a hand-held video: the path no longer follows the hand's "
                        "sway, and passes near the photographs rather than through them; default: through them)")
    p.add_argument("--full", action="store_true", help="orbit: a full turn even when the cameras cover an arc")
    p.add_argument("--dataparser-transforms", metavar="JSON",
                   help="write the path in the normalised frame of a nerfstudio model trained on SCENE (its "
                        "dataparser_transforms.json), the frame ns-render renders in; vibr render --path reads "
                        "such a file with the same option")
    add_quiet(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..errors import VibrInputError
    from ..paths import camera_path as P
    from ..pipeline import load_scene_cached

    if not args.output.lower().endswith(".json"):
        raise VibrInputError("the camera path file must end in .json", args.output)
    from ..io.outputs import check_not_scene_file, check_output, record_file

    check_output(args.output, "file", overwrite=args.overwrite, what="-o")  # as every command: its folder must exist
    if args.frames is not None and args.seconds is not None:
        raise VibrInputError("give --frames or --seconds, not both")
    if args.scale <= 0:
        raise VibrInputError(f"--scale must be positive, got {args.scale}")
    if args.smooth is not None and not args.smooth >= 0:  # before the scene is read
        raise VibrInputError(f"--smooth must be a number of keys >= 0, got {args.smooth}")
    for flag, kind, value in (("--views", "interpolate", args.views), ("--order", "interpolate", args.order),
                              ("--roll", "interpolate", args.roll), ("--smooth", "interpolate", args.smooth),
                              ("--full", "orbit", args.full)):
        if value not in (None, False) and args.kind != kind:  # refused, not ignored
            raise VibrInputError(f"{flag} applies to 'vibr path {kind}' only, not to {args.kind}")
    if args.dataparser_transforms:
        P.read_dataparser_transforms(args.dataparser_transforms)  # a bad file fails before the work
    seconds = 4.0 if args.frames is None and args.seconds is None else args.seconds
    scene = load_scene_cached(args.scene, scale=args.scale)  # the same cache as render --path
    check_not_scene_file(args.output, scene, "-o")
    w, h = args.size if args.size else (None, None)
    kw = dict(n_frames=args.frames, seconds=seconds, fps=args.fps, width=w, height=h)
    if args.kind == "interpolate":
        path = P.interpolate(scene, args.views, order=args.order, roll=args.roll or "snap",
                             smooth=args.smooth or 0.0, **kw)
    elif args.kind == "orbit":
        path = P.orbit(scene, full=True if args.full else None, **kw)
    else:
        path = P.spiral(scene, **kw)
    path.meta["scene"] = str(args.scene)
    path.meta["scale"] = args.scale
    applied, applied_scale = (P.scene_processing_transform(args.scene) if args.dataparser_transforms
                              else (None, 1.0))
    P.write_camera_path(args.output, path, dataparser_transforms=args.dataparser_transforms,
                        applied_transform=applied, applied_scale=applied_scale)
    record_file(args.output)  # vibr's: a later 'vibr path' may replace it without --overwrite
    print(f"wrote {args.output}: {args.kind} path, {count(len(path), 'frame')} of {path.width}x{path.height} "
          f"at {path.fps:g} fps ({path.seconds:.2f} s)")
    return 0
