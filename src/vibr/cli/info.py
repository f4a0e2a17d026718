"""``vibr info``: load a scene and print what vibr sees in it."""

from __future__ import annotations

import argparse

from . import add_deprecated_alias, fill, scene_formats
from ._options import names

_DESC = (
    "Load a scene (format detected: {formats}) and print a summary: format, number and size of views, "
    "light-field grid, depth coverage and range, sparse points, and one line per camera (focal lengths and "
    "principal point in pixels with the centre of the top-left pixel at (0,0); camera centre in scene units), "
    "and photographs taken rolled or sharing a pose (which a fly-through path turns upright or leaves out). "
    "Use it to check that a dataset loads before rendering. Only the images' headers are read (their sizes), "
    "not their pixels."
)

_EPILOG = """\
examples:
  vibr info ../shared/data/hci2016_cotton                   81-view 9x9 light field, centre depth
  vibr info ../shared/data/strecha_fountain-P11 --scale 0.25
  vibr info ../shared/data/middlebury_templeSparseRing/templeSR_par.txt
  vibr info out/transforms.json --only 0,4,8                a few views of a converted scene
"""


def register(sub) -> None:
    p = sub.add_parser("info", help="summarise a scene (views, sizes, cameras, depth)",
                       description=fill(_DESC.format(formats=scene_formats())) + "\n", epilog=_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", metavar="SCENE", help="scene folder, transforms.json or *_par.txt file")
    p.add_argument("--scale", type=float, default=1.0,
                   help="image scale the scene is loaded at, e.g. 0.25 (default: 1)")
    p.add_argument("--only", type=names, default=None, metavar="VIEW,...",
                   help="comma-separated view names or indices to load (default: all)")
    add_deprecated_alias(p, "--views", "--only")
    p.set_defaults(func=run)


def describe(scene) -> str:
    """``scene.summary()`` plus light-field and loader details."""
    import numpy as np

    lines = [scene.summary()]
    extra = []
    m = scene.meta
    if m.get("grid_pos"):
        rows, cols = scene.grid or (None, None)
        present = len(m["grid_pos"])
        line = f"grid     {present} of {rows * cols if rows else '?'} positions present"
        if m.get("centre_view"):
            line += f"; centre view {m['centre_view']} (row {rows // 2}, col {cols // 2})"
        extra.append(line)
        missing = sorted(m.get("missing_views") or {})
        if missing:
            shown = ", ".join(missing[:8]) + (", ..." if len(missing) > 8 else "")
            extra.append(f"missing  {shown} (no photograph; 'vibr render --target NAME' renders one)")
    if "focal_px" in m:
        extra.append(f"camera   f = {m['focal_px']:.6g} px, baseline {m['baseline']:.6g}, "
                     f"focus distance Z0 = {m['focus_distance']:.6g} ({m.get('camera_rule')})")
    masked = [v for v in scene.views if v.mask is not None]
    if masked:
        out = np.mean([1.0 - v.mask.mean() for v in masked])
        extra.append(f"masks    {len(masked)} of {len(scene.views)} views masked ({100 * out:.1f} % of their "
                     "pixels on average not used)")
    if m.get("undistorted"):
        extra.append(f"lens     {m['undistorted']}")
    if m.get("depth_source"):
        extra.append(f"depth    from {m['depth_source']}")
    extra += _calibration_lines(scene)
    extra += _pose_lines(scene)
    for v in scene.views:
        if v.depth is not None:
            known = np.isfinite(v.depth)
            extra.append(f"depth    {v.name}: {100 * known.mean():.1f}% known, "
                         f"range {np.nanmin(v.depth):.6g} .. {np.nanmax(v.depth):.6g}"
                         if known.any() else f"depth    {v.name}: no known values")
    if m.get("scale", 1.0) != 1.0:
        extra.append(f"scale    loaded at {m['scale']:g}x")
    if extra:
        lines += [""] + extra
    return "\n".join(lines)


def _calibration_lines(scene) -> list:
    """What ``vibr calibrate`` wrote beside the scene (calibration.json): from what, how many
    photographs or frames registered, and the reprojection error."""
    import json
    from pathlib import Path

    f = Path(scene.root) / "calibration.json" if getattr(scene, "root", None) else None
    if f is None or not f.is_file():
        return []
    try:
        c = json.loads(f.read_text())
        reg, unreg = len(c["registered"]), len(c["unregistered"])
        video = c.get("video")
        src = Path(c["photos"]).name
        what = (f"{src}, {len(video['frames_kept'])} of its {video['frames_read']} frames (the sharpest of each "
                f"stretch)" if video else f"the photos of {src}")
        lines = [f"calib    {c.get('tool', 'COLMAP')} from {what}: {reg} of {reg + unreg} registered, "
                 f"mean reprojection error {c['mean_reprojection_error_px']:.3f} px"]
        if c.get("turned_on_the_spot"):
            lines.append("calib    turned on the spot: one centre for every photo, the rotations and focal length "
                         "fitted to the matches (" + c.get("one_centre", {}).get("why", "as asked") + ")")
        return lines
    except (OSError, ValueError, KeyError, TypeError):  # another tool's file, or an older one: not ours to read
        return []


def _pose_lines(scene) -> list:
    """Photographs taken rolled (the quarter turns a path gives them, vibr.paths.camera_path.orient_keys)
    and views with the same pose as another (a path leaves them out)."""
    import numpy as np

    from ..errors import VibrInputError
    from ..paths.camera_path import orient_keys, scene_up, turns_text

    cams = [v.camera for v in scene.views]
    if len(cams) < 2:
        return []
    out = []
    try:
        _, turns = orient_keys(cams, "snap", scene_up(cams))
    except VibrInputError:  # no common up
        turns = []
    if any(turns):
        out.append(f"rolled   {sum(1 for k in turns if k)} of {len(cams)} photographs not upright (to turn "
                   f"clockwise: {turns_text(turns)}); 'vibr path' turns them upright (--roll)")
    C = np.array([c.centre for c in cams])
    size = max(float(np.ptp(C, axis=0).max()), 1e-12)
    keys = np.round(np.hstack([C / size, [c.R.ravel() for c in cams]]) * 1e9).astype(np.int64)
    groups: dict = {}
    for v, k in zip(scene.views, keys):
        groups.setdefault(k.tobytes(), []).append(v.name)
    same = [g for g in groups.values() if len(g) > 1]
    if same:
        out.append("poses    the same pose: " + "; ".join(" = ".join(g) for g in same[:6])
                   + ("; ..." if len(same) > 6 else ""))
    return out


def run(args) -> int:
    from ..io import load_scene
    from ..io.images import headers_only

    with headers_only():
        scene = load_scene(args.scene, scale=args.scale, views=args.only)
    try:
        print(describe(scene), flush=True)
    except BrokenPipeError:  # `vibr info ... | head`: the reader has gone, not an error
        import os
        import sys

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0
