"""``vibr render``: render one view of a scene (a held-out view or a camera file)."""

from __future__ import annotations

import argparse
import logging
import os

from . import add_quiet
from ._options import (METRIC_RULE, add_bit_depth_option, add_depth_options, add_method_option,
                       add_render_params, add_source_options, check_depth_args, render_params)

logger = logging.getLogger(__name__)

_DESC = """\
Render a novel view of SCENE with the variational method of Nieto, Devernay & Crowley (2016)
or a baseline. The target is a view of the scene (name or index; it is then held out of the
sources and PSNR / DSSIM against it are printed) or a camera file (JSON, Camera.to_dict
format: K, R, t, width, height). Parameters keep the paper's names and refer to
intensities in [0, 255] (--intensity-scale).
"""

_EPILOG = """\
examples:
  vibr render ../shared/data/hci2016_cotton --target input_Cam040 -o centre.png \\
      --sources input_Cam030,input_Cam031,input_Cam032,input_Cam039,input_Cam041,input_Cam048,input_Cam049,input_Cam050
  vibr render scene/ --target novel_camera.json -o novel.png --method bvs
  vibr render scene/ --target 3 -o v3.png --depth planar --gamma 3
  vibr render photos_scene/ --target 5 -o v5.png --depth estimated --views 8
"""


def register(sub) -> None:
    p = sub.add_parser("render", help="render a view (held-out view or camera file) of a scene",
                       description=_DESC, epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", help="scene folder (any supported format)")
    p.add_argument("--target", required=True, metavar="VIEW|CAMERA.json",
                   help="view name / index to hold out and render, or a camera JSON file (K, R, t, "
                        "width, height at the scene's original resolution: --scale applies to it too)")
    p.add_argument("-o", "--output", required=True, help="output image (PNG)")
    add_bit_depth_option(p)
    add_method_option(p)
    add_render_params(p)
    add_source_options(p)
    add_depth_options(p)
    p.add_argument("--scale", type=float, default=1.0,
                   help="image scale the scene is loaded at, e.g. 0.5; a camera-file target is scaled "
                        "with it (default 1)")
    add_quiet(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..errors import VibrInputError
    from ..io import load_scene, read_camera_json, write_image
    from ..pipeline import prepare
    from ..render import render

    check_depth_args(args)
    scene = load_scene(args.scene, scale=args.scale)
    tgt = args.target
    if tgt.lower().endswith(".json") or (os.path.isfile(tgt) and not tgt.isdigit()):
        target = read_camera_json(tgt)
        if args.scale != 1.0:
            target = target.scaled(args.scale)
    else:
        target = scene[tgt].name
        if args.sources and target in [scene[s].name for s in args.sources]:
            raise VibrInputError(f"target view {target} is also listed as a source", args.scene)
    if args.views is not None and args.views < 1:
        raise VibrInputError(f"--views must be at least 1, got {args.views}")
    sources, target = prepare(scene, target, sources=args.sources, depth=args.depth,
                              depth_files=args.depth_files, n_views=args.views)
    res = render(sources, target, args.method, progress_bar=True, **render_params(args))  # -v: per pass
    write_image(args.output, res.image, bits=args.bit_depth)
    t = res.times
    logger.info(f"rendered {res.image.shape[1]}x{res.image.shape[0]} with {args.method} from "
                f"{res.n_samples} samples, coverage {100 * res.coverage.mean():.1f} %, "
                f"{t.get('total', 0):.2f} s (geometry {t.get('geometry', 0):.2f}, solve {t.get('solve', 0):.2f})")
    if res.metrics:
        print(f"PSNR {res.metrics['psnr']:.2f} dB  DSSIM {res.metrics['dssim']:.1f}  "
              f"(SSIM {res.metrics['ssim']:.4f}; {METRIC_RULE})")
    print(f"wrote {args.output}")
    return 0
