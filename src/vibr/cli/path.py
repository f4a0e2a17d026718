"""``vibr path``: make a camera path (nerfstudio camera_path.json) through or around a scene."""

from __future__ import annotations

import argparse

from . import add_deprecated_alias, count, fill
from ._options import add_overwrite_option, names

_DESC = """\
Write a camera path for a fly-through of SCENE in nerfstudio's camera_path.json schema
(camera_to_world 4x4 row-major in OpenGL camera axes, vertical fov in degrees; docs/explanation/flythrough.md),
to render with 'vibr render SCENE --path PATH.json -o video.mp4'; with --dataparser-transforms
the path is written in the normalised frame of a nerfstudio model of the scene, for ns-render.
"""

_EPILOG = """\
examples:
  vibr path interpolate ../shared/data/strecha_fountain-P11 -o fountain.json --frames 60 --scale 0.25
  vibr path orbit ../shared/data/middlebury_templeSparseRing -o orbit.json --seconds 4 --fps 24
  vibr path spiral SCENE -o spiral.json --frames 90 --size 640x480
  vibr path interpolate SCENE -o p.json --through 0003,0005,0004 --order proximity
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
    from ..paths.kinds import PATH_KINDS

    p = sub.add_parser("path", help="make a camera path (nerfstudio camera_path.json) for a fly-through",
                       description=_DESC, epilog=_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    kind_parsers = p.add_subparsers(dest="kind", metavar="KIND", required=True,
                                    help="kind of path; 'vibr path KIND --help' for its options")
    for kind in PATH_KINDS.values():
        _add_kind(kind_parsers, kind)
    p.set_defaults(func=run)


def _add_kind(kind_parsers, kind) -> None:
    """``vibr path KIND``: the options every kind takes, then the kind's own (vibr.paths.kinds);
    the other kinds' options are accepted unseen, to be refused by name in :func:`run`."""
    from ..paths.kinds import PATH_KINDS

    examples = [line for line in _EPILOG.splitlines()[1:] if line.split()[:3] == ["vibr", "path", kind.name]]
    k = kind_parsers.add_parser(kind.name, help=kind.summary, description=fill(kind.description or kind.summary),
                                epilog="\n".join(["examples:", *examples]) if examples else None,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    k.add_argument("scene", metavar="SCENE", help="scene folder (any supported format)")
    k.add_argument("-o", "--output", required=True, help="camera path file to write (.json)")
    add_overwrite_option(k, "an -o file vibr did not write")
    k.add_argument("--frames", type=int, help="number of frames (default: --seconds x --fps)")
    k.add_argument("--seconds", type=float, default=None, help="duration in seconds (default 4 without --frames)")
    k.add_argument("--fps", type=float, default=24.0, help="frames per second (default 24)")
    k.add_argument("--size", type=_size, metavar="WxH", help="frame size (default: the first view's, after --scale; "
                   "W and H swapped when its photograph is turned upright by a quarter turn, see --roll)")
    k.add_argument("--scale", type=float, default=1.0, help="image scale of the scene, e.g. 0.25 (default 1)")
    own = {o.flag for o in kind.options}
    for o in kind.options:
        _add_option(k, o, o.help)
    for other in PATH_KINDS.values():
        for o in other.options:
            if o.flag not in own:
                own.add(o.flag)
                _add_option(k, o, argparse.SUPPRESS)
    k.add_argument("--dataparser-transforms", metavar="JSON",
                   help="write the path in the normalised frame of a nerfstudio model trained on SCENE (its "
                        "dataparser_transforms.json), the frame ns-render renders in; vibr render --path reads "
                        "such a file with the same option")
    if "--through" in k._option_string_actions:
        add_deprecated_alias(k, "--views", "--through")


def _add_option(p, o, help_text) -> None:
    """A :class:`vibr.paths.kinds.PathOption` as an argparse option (None when not given)."""
    if o.switch:
        p.add_argument(o.flag, dest=o.keyword, action="store_const", const=True, default=None, help=help_text)
        return
    p.add_argument(o.flag, dest=o.keyword, type=names if o.comma_list else o.type, default=None,
                   choices=list(o.choices) if o.choices is not None else None, metavar=o.metavar, help=help_text)


def run(args) -> int:
    from ..errors import VibrInputError
    from ..paths import camera_path as P
    from ..paths.kinds import PATH_KINDS
    from ..pipeline import load_scene_cached

    if not args.output.lower().endswith(".json"):
        raise VibrInputError("the camera path file must end in .json", args.output)
    from ..io.outputs import check_not_scene_file, check_output, record_file

    check_output(args.output, "file", overwrite=args.overwrite, what="-o")  # as every command: its folder must exist
    if args.frames is not None and args.seconds is not None:
        raise VibrInputError("give --frames or --seconds, not both")
    if args.scale <= 0:
        raise VibrInputError(f"--scale must be positive, got {args.scale}")
    kind = PATH_KINDS[args.kind]
    given = _given_options(args, kind)
    if args.dataparser_transforms:
        P.read_dataparser_transforms(args.dataparser_transforms)  # a bad file fails before the work
    seconds = 4.0 if args.frames is None and args.seconds is None else args.seconds
    scene = load_scene_cached(args.scene, scale=args.scale)  # the same cache as render --path
    check_not_scene_file(args.output, scene, "-o")
    w, h = args.size if args.size else (None, None)
    kw = dict(n_frames=args.frames, seconds=seconds, fps=args.fps, width=w, height=h)
    path = kind.function(scene, **kw, **given)
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


def _given_options(args, kind) -> dict:
    """The options of ``kind`` given on the command line, as keyword arguments, their values
    checked; an option of another kind is refused, not ignored (before the scene is read)."""
    from ..errors import VibrInputError
    from ..paths.kinds import PATH_KINDS

    accepted = {o.flag: (kind, o) for o in kind.options}  # as _add_kind: its own, then the others' first
    for other in PATH_KINDS.values():
        for o in other.options:
            accepted.setdefault(o.flag, (other, o))
    for owner, o in accepted.values():  # every value checked first, then any refused
        value = getattr(args, o.keyword, None)
        if value is not None and o.check is not None:
            o.check(value)
    for owner, o in accepted.values():
        if owner is not kind and getattr(args, o.keyword, None) is not None:
            raise VibrInputError(f"{o.flag} applies to 'vibr path {owner.name}' only, not to {args.kind}")
    return {o.keyword: getattr(args, o.keyword) for o in kind.options if getattr(args, o.keyword) is not None}
