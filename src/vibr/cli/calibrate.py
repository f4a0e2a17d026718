"""``vibr calibrate PHOTOS_DIR|VIDEO OUT_SCENE``: cameras from raw photos or a video with
COLMAP (CPU)."""

from __future__ import annotations

import argparse
import shlex

from ..calib.colmap import CAMERA_MODELS, MATCHERS
from ..calib.video_frames import DEFAULT_FRAMES
from ..errors import VibrInputError
from ..io.video import VIDEO_INPUTS, is_video_input
from . import count

_EPILOG = """\
stages: [a video: the sharpest frame near the middle of each of --frames stretches ->]
resize -> SIFT features -> matching -> incremental mapping [or one centre for photos turned
on the spot: --pan] -> undistortion to pinhole;
the scene is written as transforms.json + images + sparse_pc.ply (the sparse points bound the
depth range of 'vibr depth'). The reconstruction's scale and orientation are arbitrary.

examples:
  vibr calibrate photos/ scene/ --scale 0.5
  vibr calibrate walk.mp4 scene/ --frames 40 --scale 0.5
  vibr calibrate panorama/ scene/ --pan yes              photos from a tripod, turned on the spot
  vibr depth scene/ && vibr render scene/ --target 5 -o view5.png
"""


def register(sub) -> None:
    p = sub.add_parser(
        "calibrate",
        help="calibrate cameras from a folder of photos or a video (COLMAP SfM, CPU)",
        description="Calibrate a folder of photos (or a video) of one static scene with COLMAP "
        "(pycolmap, CPU): features, matching, incremental mapping, undistortion; write a vibr scene.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("photos", metavar="PHOTOS_DIR|VIDEO",
                   help="folder of photos (jpg/png/tif), not recursive, or a video ("
                   + ", ".join(VIDEO_INPUTS) + "): its sharpest frames become the photos")
    p.add_argument("out", metavar="OUT_SCENE", help="output scene folder (must not exist unless --overwrite)")
    p.add_argument("--scale", type=float, default=1.0,
                   help="image scale the photos are calibrated at, e.g. 0.5: 3072x2048 -> 1536x1024 "
                        "(default 1)")
    p.add_argument("--frames", type=int, default=None,
                   help="from a video: how many frames become photos, the sharpest of each of as "
                   f"many equal stretches of it (default {DEFAULT_FRAMES})")
    p.add_argument("--matcher", choices=list(MATCHERS), default=None,
                   help="exhaustive: all pairs (the default for photos, best up to ~100); "
                   "sequential: neighbours in file-name order (the default for a video)")
    p.add_argument("--camera-model", default="SIMPLE_RADIAL",
                   choices=list(CAMERA_MODELS),
                   help="COLMAP camera model to estimate (default SIMPLE_RADIAL)")
    p.add_argument("--per-image-cameras", action="store_true",
                   help="one intrinsic camera per photo (default: one shared camera)")
    p.add_argument("--principal-point", choices=["auto", "fixed", "refine"], default="auto",
                   help="fixed: at the image centre; refine: by bundle adjustment throughout; "
                   "auto (default): refined by a final bundle adjustment, kept only if its "
                   "covariance shows the photos determine it")
    p.add_argument("--pan", choices=["auto", "yes", "no"], default="auto",
                   help="photos turned on the spot (a panorama, a video panned from one place): one "
                   "centre for every camera, rotations and focal length fitted to the matches. auto "
                   "(default): when most image pairs are related by homographies and COLMAP's mapper, "
                   "with a centre per photo, explains its points no better or registers fewer photos")
    p.add_argument("--min-registered", type=int, default=3,
                   help="fail if fewer photos register (default 3)")
    p.add_argument("--max-features", type=int, default=8192, help="SIFT features per photo (default 8192)")
    p.add_argument("--threads", type=int, default=2, help="COLMAP threads, -1 for every core (default 2)")
    p.add_argument("--seed", type=int, default=0, help="random seed of COLMAP's RANSAC and mapper (default 0)")
    p.add_argument("--work", metavar="DIR", default=None,
                   help="keep COLMAP's database, model and undistorted images here")
    p.add_argument("--overwrite", action="store_true", help="replace OUT_SCENE if it exists")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..calib.colmap import calibrate
    from ..io.outputs import check_output
    from . import verbosity

    if args.frames is not None and not is_video_input(args.photos):
        raise VibrInputError("--frames is for a video; this is a folder of photos (all of them are calibrated)",
                             args.photos)
    check_output(args.out, "dir", overwrite=args.overwrite, what="OUT_SCENE")
    if args.work is not None:
        check_output(args.work, "dir", what="--work")
    scene = calibrate(
        args.photos,
        args.out,
        overwrite=args.overwrite,
        scale=args.scale,
        matcher=args.matcher,
        frames=DEFAULT_FRAMES if args.frames is None else args.frames,
        camera_model=args.camera_model,
        single_camera=not args.per_image_cameras,
        refine_principal_point={"auto": None, "fixed": False, "refine": True}[args.principal_point],
        pan={"auto": None, "yes": True, "no": False}[args.pan],
        min_registered=args.min_registered,
        max_features=args.max_features,
        num_threads=args.threads,
        seed=args.seed,
        work_dir=args.work,
        verbose=verbosity(args) > 0,  # -v shows COLMAP's own log
    )
    print(f"calibrate: wrote {count(len(scene), 'view')} to {args.out}")
    if scene.meta["calibration"].get("turned_on_the_spot"):
        print("calibrate: turned on the spot: one centre for every photo, the focal length fitted to the "
              "rotations (renders need no depth; --pan no for COLMAP's mapper)")
    out = shlex.quote(str(args.out))
    if scene.meta["calibration"].get("turned_on_the_spot"):
        smooth = " --smooth 2" if scene.meta.get("capture") == "video" else ""
        print(f"next: vibr path interpolate {out} -o pan.json{smooth} && "
              f"vibr render {out} --path pan.json -o pan.mp4 (one centre: no depth to estimate)")
    elif scene.meta.get("capture") == "video":
        print(f"next: vibr path interpolate {out} -o walk.json --smooth 2 && "
              f"vibr render {out} --path walk.json -o walk.mp4")
    else:
        print(f"next: vibr render {out} --target {shlex.quote(scene.names[0])} -o view.png (depth is estimated "
              f"on the way), or vibr path interpolate {out} -o path.json")
    return 0
