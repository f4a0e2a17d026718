"""``vibr convert``: save any scene as a nerfstudio ``transforms.json`` folder."""

from __future__ import annotations

import argparse

from . import add_deprecated_alias, count
from ._options import add_overwrite_option, names

_DESC = """\
Load a scene in any supported format and write it as a nerfstudio / instant-NGP
transforms.json folder: OUT/transforms.json, OUT/images/*.png (8-bit when exact, else
16-bit), OUT/depth/*.npy (float32 orthogonal depth, 0 = unknown), OUT/sigma_z/*.npy and
OUT/sparse_pc.ply when the scene has them. Cameras are written in nerfstudio's conventions
(OpenGL camera-to-world, pixel corner at 0) and read back by vibr exactly. The output is
written to a temporary folder and renamed at the end: a failure leaves nothing behind.
"""

_EPILOG = """\
examples:
  vibr convert ../shared/data/hci2016_cotton cotton_ns/
  vibr convert ../shared/data/strecha_fountain-P11 fountain_q/ --scale 0.25
  vibr convert ../shared/data/hci2016_cotton centre_cross/ \\
      --only input_Cam031,input_Cam039,input_Cam040,input_Cam041,input_Cam049
  vibr convert SCENE out/ --overwrite               replace an out/ that vibr wrote
"""


def register(sub) -> None:
    p = sub.add_parser("convert", help="save any scene as nerfstudio transforms.json",
                       description=_DESC, epilog=_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", metavar="SCENE", help="scene folder, transforms.json or *_par.txt file")
    p.add_argument("out", metavar="OUT", help="output folder (must not exist unless --overwrite)")
    p.add_argument("--scale", type=float, default=1.0,
                   help="image scale the scene is loaded at, e.g. 0.25 (default: 1)")
    p.add_argument("--only", type=names, default=None, metavar="VIEW,...",
                   help="comma-separated view names or indices to keep (default: all)")
    add_deprecated_alias(p, "--views", "--only")
    add_overwrite_option(p, "OUT (only a folder vibr wrote)")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..io import load_scene, save_scene
    from ..io.outputs import check_not_input, check_output, check_replaceable

    out = check_output(args.out, "dir", overwrite=args.overwrite, what="OUT")
    check_not_input(out, [args.scene])
    if out.is_dir():
        check_replaceable(out)
    scene = load_scene(args.scene, scale=args.scale, views=args.only)
    out = save_scene(scene, out, overwrite=args.overwrite)
    nd = sum(v.depth is not None for v in scene.views)
    print(f"wrote {out}/transforms.json: {count(len(scene), 'view')} ({scene.meta.get('format', '?')}), "
          f"{nd} with depth" + (f", {len(scene.points)} sparse points" if scene.points is not None else ""))
    return 0
