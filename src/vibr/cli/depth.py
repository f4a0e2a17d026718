"""``vibr depth``: estimate per-view depth maps and sigma_z (light field or plane-sweep MVS)."""

from __future__ import annotations

import argparse
from pathlib import Path

from . import add_deprecated_alias
from ._executor import add_executor_args, executor_from_args
from ._options import add_overwrite_option, names

_DESC = """\
Estimate orthogonal depth maps and their uncertainty sigma_z for the views of a scene, on
the CPU: light fields (scene with a grid) by the EPI structure tensor refined by a fine
plane sweep over the grid and TV-L1; other scenes by plane-sweep multi-view stereo (ZNCC
over the nearest views, slanted-plane PatchMatch refinement, a colour-guided weighted
median of the planes, cross-view consistency check). Pixels whose depth is unreliable or
inconsistent are written as unknown (0 in the .npy files).

The result is the scene saved as a nerfstudio transforms.json folder (OUT/transforms.json,
OUT/depth/*.npy, OUT/sigma_z/*.npy). Without -o, a SCENE that is itself a transforms.json
folder is updated in place (the new folder replaces it only once complete).
"""

_EPILOG = """\
examples:
  vibr depth ../shared/data/strecha_fountain-P11 -o fountain_depth/ --scale 0.25
  vibr depth ../shared/data/strecha_fountain-P11 -o f/ --scale 0.25 --refine-iter 1   (faster)
  vibr depth ../shared/data/hci2016_cotton -o cotton_depth/ --targets input_Cam040
  vibr depth fountain_depth/ --targets 5 --exclude 4        update in place, never using view 4
  vibr depth SCENE -o out/ --depth-scale 0.5 --depth-range 4 20   estimate at half resolution
"""


def register(sub) -> None:
    p = sub.add_parser("depth", help="estimate depth maps and sigma_z (light field / MVS)",
                       description=_DESC, epilog=_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", metavar="SCENE", help="scene folder, transforms.json or *_par.txt file")
    p.add_argument("-o", "--out", default=None,
                   help="output folder (default: update SCENE in place if it is a transforms.json scene)")
    p.add_argument("--targets", type=names, default=None, metavar="VIEW,...",
                   help="comma-separated views whose depth is estimated; the others still serve as stereo "
                        "partners (default: all)")
    add_deprecated_alias(p, "--views", "--targets")
    p.add_argument("--exclude", type=names, default=None, metavar="VIEW,...",
                   help="comma-separated views never used as inputs")
    p.add_argument("--scale", type=float, default=1.0,
                   help="image scale the scene is loaded at, e.g. 0.25; the output has that size (default 1)")
    p.add_argument("--resize", dest="scale", type=float, help=argparse.SUPPRESS)  # the old name
    p.add_argument("--depth-scale", type=float, default=1.0,
                   help="scale of the estimation relative to the loaded scene; the maps are "
                        "upsampled back to its size (default 1)")
    p.add_argument("--method", choices=["auto", "mvs", "lightfield"], default="auto",
                   help="auto: lightfield when the scene is a grid, else mvs")
    p.add_argument("--neighbours", type=int, default=None,
                   help="nearest stereo partners per view (MVS, default 4; views that see what "
                   "they miss are added)")
    p.add_argument("--depth-range", type=float, nargs=2, metavar=("NEAR", "FAR"), default=None,
                   help="depth range in scene units (default: from sparse points or a coarse sweep)")
    p.add_argument("--step-px", type=float, default=None,
                   help="parallax between consecutive planes on the farthest partner, px "
                   "(MVS; default that of vibr.stereo.estimate_depth, 3)")
    p.add_argument("--max-planes", type=int, default=None,
                   help="most planes per view (MVS; default that of estimate_depth, 128)")
    p.add_argument("--refine-iter", type=int, default=None,
                   help="slanted-plane refinement iterations after the sweep, 0 for none "
                   "(default that of estimate_depth, 2)")
    p.add_argument("--median-radius", type=int, default=None,
                   help="window half-size of the colour-guided weighted median of the refined "
                   "planes, 0 for none (default that of estimate_depth: 9 for MVS, none "
                   "for light fields)")
    p.add_argument("--sweep-scale", type=float, default=None,
                   help="image scale of the coarse level (the plane sweep and --coarse-iter "
                   "refinement iterations), in (0, 1]; 1: sweep at full size, no coarse level "
                   "(default that of estimate_depth, 0.5: docs/explanation/depth.md)")
    p.add_argument("--coarse-iter", type=int, default=None,
                   help="refinement iterations at the coarse level before the full-size ones "
                   "(default that of estimate_depth, 1; light fields: the first of --refine-iter)")
    p.add_argument("--no-consistency", action="store_true", help="skip the cross-view consistency check")
    p.add_argument("--consensus-tol", type=float, default=None, metavar="FRACTION",
                   help="light fields: each pixel's depth becomes the mean of the views' depths that agree "
                   "within this fraction, 0 for none (default that of LightFieldOptions, 0.35)")
    # the views' sweeps (MVS) on local processes or a Dask cluster (docs/explanation/scale-out.md)
    add_executor_args(p, default="here: the sweeps' kernels already use every core of this machine")
    p.add_argument("--fill-segments", action="store_true",
                   help="dense output (MVS): fill unknown pixels from the planes of their colour "
                   "segments, then re-run the weighted median (docs/explanation/depth.md). Better depth "
                   "maps; the renderer does better with the unknown pixels left out")
    add_overwrite_option(p, "OUT (only a folder vibr wrote)")
    p.set_defaults(func=run)


def _refuse_mvs_options(args, scene) -> None:
    """The plane sweep's options (n_neighbours, step_px, max_planes, consistency,
    fill_segments: read by vibr.stereo.api's MVS path only) given for a light-field estimate
    (vibr.stereo.api.depth_method), and the light field's consensus_tol given for MVS:
    refused, not ignored."""
    from ..errors import VibrInputError
    from ..stereo.api import depth_method

    if depth_method(scene, args.method) != "lightfield":
        if args.consensus_tol is not None:
            raise VibrInputError("--consensus-tol applies to a light field's estimate only, and this scene's depth "
                                 "is estimated by the plane sweep (MVS)", args.scene)
        return
    given = [f for f, v in (("--neighbours", args.neighbours), ("--step-px", args.step_px),
                            ("--max-planes", args.max_planes), ("--no-consistency", args.no_consistency),
                            ("--fill-segments", args.fill_segments)) if v not in (None, False)]
    if given:
        how = "" if args.method == "lightfield" else " (its light-field grid; --method mvs for a plane sweep)"
        raise VibrInputError(f"{', '.join(given)} {'apply' if len(given) > 1 else 'applies'} to the MVS "
                             f"estimate only, and this scene's depth is estimated as a light field{how}", args.scene)


def run(args) -> int:
    import shutil

    from .._runtime.checkpoint import resume_folder
    from ..io import load_scene, save_scene
    from ..stereo import estimate_depth
    from ..stereo.checks import check_depth_params

    opt = _depth_options(args)
    check_depth_params(scale=args.depth_scale, depth_range=args.depth_range, **opt)  # before loading the scene
    executor = executor_from_args(args)  # a bad scheduler fails before the work
    out, in_place = _output_folder(args)
    scene = load_scene(args.scene, scale=args.scale)
    _refuse_mvs_options(args, scene)
    est = estimate_depth(scene, views=args.targets, scale=args.depth_scale,
                         depth_range=args.depth_range, method=args.method,
                         exclude=args.exclude or (),
                         consistency=not args.no_consistency, fill_segments=args.fill_segments,
                         checkpoint=resume_folder(out), executor=executor, **opt)  # a rerun after a kill resumes
    save_scene(est, out, overwrite=in_place or args.overwrite, in_place=in_place)
    shutil.rmtree(resume_folder(out), ignore_errors=True)  # the job is complete
    print(_summary(out, est.meta["depth_estimation"]))
    return 0


def _depth_options(args) -> dict:
    """The estimator's options given on the command line (the others keep their defaults)."""
    return {k: v for k, v in (("n_neighbours", args.neighbours), ("step_px", args.step_px),
                              ("max_planes", args.max_planes), ("refine_iter", args.refine_iter),
                              ("median_radius", args.median_radius), ("sweep_scale", args.sweep_scale),
                              ("coarse_iter", args.coarse_iter), ("consensus_tol", args.consensus_tol))
            if v is not None}


def _output_folder(args):
    """``(out, in_place)``: ``-o OUT``, checked, or the scene's own folder when it is a
    transforms.json scene vibr wrote (updated in place)."""
    from ..errors import VibrInputError
    from ..io.outputs import check_not_input, check_output, check_replaceable

    if args.out is not None:
        out = check_output(args.out, "dir", overwrite=args.overwrite, what="-o")
        check_not_input(out, [args.scene])
        if out.is_dir():
            check_replaceable(out)
        return out, False
    src = Path(args.scene)
    tj = src if src.name == "transforms.json" else src / "transforms.json"
    if not tj.is_file():
        raise VibrInputError("give -o OUT: only a transforms.json scene is updated in place", src)
    if args.scale != 1.0:
        raise VibrInputError("--scale needs -o OUT (an in-place update keeps the scene's size)", src)
    out = tj.parent
    check_output(out, "dir", overwrite=True, what="SCENE")
    try:  # an in-place update replaces only a folder vibr wrote
        check_replaceable(out)
    except VibrInputError as exc:
        raise VibrInputError(f"not updated in place ({exc.problem}); give -o OUT", out) from None
    return out, True


def _summary(out: Path, info: dict) -> str:
    """The line printed when the depth is written: views, method, time, pixels kept."""
    resumed = sum(bool(v.get("resumed")) for v in info["views"].values())
    tv = [v for v in info["views"].values() if v.get("role") == "target"]
    kept = [v["kept"] for v in tv]
    filled = sum(v.get("filled", 0.0) for v in tv)
    return (f"wrote {out}/transforms.json: depth for {len(kept)} view(s) by {info['method']} "
            f"in {info['time_s']:.1f} s, {100 * sum(kept) / max(1, len(kept)):.1f} % of pixels kept"
            + (f", {100 * filled / max(1, len(tv)):.1f} % filled from segment planes" if filled else "")
            + (f" ({resumed} view(s) kept from an interrupted run)" if resumed else ""))
