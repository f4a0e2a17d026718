"""``vibr eval``: the paper's protocol — hold out a view, render it, measure PSNR / DSSIM."""

from __future__ import annotations

import argparse
import logging

from ..eval.protocol import GAMMAS
from ..metrics import METRIC_BORDER
from ..render.methods import REGISTRY
from ._executor import add_executor_args, executor_from_args
from ._options import (
    add_depth_options,
    add_method_options,
    add_overwrite_option,
    add_source_options,
    cache_dir_from_args,
    check_depth_args,
    method_help,
    names,
    refuse_ignored_params,
    render_params,
)

#: The method options that take comma lists: one setting (a row of the table) per value.
GRID = ("alpha", "gamma", "lam")

logger = logging.getLogger(__name__)

_DESC = f"""\
Hold one view of SCENE out, render it from the other views (or --sources) with each method
and setting, and compare with the real photograph: PSNR (dB, higher is better) and
DSSIM = 1e4 * (1 - SSIM) (Wang et al. 2004, Gaussian window sigma 1.5; lower is better),
over the pixels every method reconstructed (--mask reconstructed, as in the paper) or over
the whole image, a {METRIC_BORDER}-px border excluded (--border): the rule of vibr render. The target
never takes part in depth estimation.
"""

_EPILOG = """\
examples:
  vibr eval ../shared/data/hci2016_cotton --target input_Cam040 \\
      --sources input_Cam030,input_Cam031,input_Cam032,input_Cam039,input_Cam041,input_Cam048,input_Cam049,input_Cam050 \\
      --depth gt --json cotton.json --figures figs/
  vibr eval ../shared/data/strecha_fountain-P11 --target 0005 --scale 0.25 --depth estimated \\
      --method bvs,gradient --alpha 0.1 --gamma 1 --lam 0.002 --intensity-scale 255 --json fountain5.json

--scale is the IMAGE scale (0.25: 3072x2048 -> 768x512); --intensity-scale is the scale of the
intensities the parameters refer to (255: lam, sigma_s in grey levels). Both are recorded in
the report (top-level "scale" and "intensity_scale"). The geometry (depth, then the warped
samples) is computed once and shared by every method and setting.

Views are named by file stem (input_Cam040, 0005) or index. --gamma applies to the
'gradient' method (one row per value); --alpha and --lam (comma lists allowed) apply to every
variational method, and default to the renderer's documented defaults.
"""




def register(sub) -> None:
    p = sub.add_parser("eval", help="render held-out views and measure PSNR / DSSIM (paper protocol)",
                       description=_DESC, epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", metavar="SCENE", help="scene folder or transforms.json")
    p.add_argument("--target", required=True,
                   help="view to hold out and render (name or index); 'all' or a comma list: "
                        "leave-one-out over those views (one task each, see --workers / --dask), "
                        "--json then holds per-view results and their mean / median")
    add_source_options(p)
    add_depth_options(p)
    p.add_argument("--method", type=names, default=list(REGISTRY),
                   help=f"comma-separated methods among {', '.join(REGISTRY)} (default: all). {method_help()}")
    add_method_options(p, lists=GRID, defaults={"gamma": f"{','.join(f'{g:g}' for g in GAMMAS)}: the paper's and "
                                                          "vibr's default"})
    p.add_argument("--scale", type=float, default=1.0,
                   help="IMAGE scale the scene is loaded at, e.g. 0.25 (default: 1)")
    p.add_argument("--step-px", type=float, default=None,
                   help="--depth estimated: parallax step between sweep planes, px (default: the estimator's)")
    p.add_argument("--max-planes", type=int, default=None,
                   help="--depth estimated: most sweep planes per view (default: the estimator's)")
    p.add_argument("--depth-range", type=float, nargs=2, metavar=("NEAR", "FAR"), default=None,
                   help="--depth estimated: orthogonal depth range of the sweep, scene units "
                        "(default: the estimator's coarse sweep)")
    p.add_argument("--mask", choices=["reconstructed", "all"], default="reconstructed",
                   help="pixels the metrics are taken over (default: reconstructed)")
    p.add_argument("--border", type=int, default=METRIC_BORDER,
                   help=f"pixels excluded at each image edge (default: {METRIC_BORDER}, as vibr render)")
    p.add_argument("--json", required=True, metavar="REPORT.json", help="where to write the report")
    add_overwrite_option(p, "a --json report vibr did not write")
    p.add_argument("--figures", metavar="DIR", help="write comparison figures (PNG) here")
    p.add_argument("--uncertainty", action="store_true",
                   help="also score each render's per-pixel std. dev.: AUSE, Spearman rho and the "
                        "sparsification curves in the report, the sparsification plot in --figures")
    add_executor_args(p)
    p.add_argument("--shard", metavar="I/N",
                   help="with several targets: evaluate only shard I of N (targets k with k %% N == I-1, one process "
                        "of a job array), writing their per-view reports; --assemble writes --json when all are done")
    p.add_argument("--assemble", action="store_true",
                   help="with several targets: write --json and the table from the per-view reports the shards "
                        "wrote (evaluates nothing; an error lists the targets still missing)")
    p.set_defaults(func=run)


def render_kw(args) -> dict | None:
    """The method options given, but the settings grid (:data:`GRID`) and the intensity scale
    (``EvalOptions.intensity_scale``): ``EvalOptions.render_kw``."""
    kw = {k: v for k, v in render_params(args, skip=GRID + ("scale",)).items() if v is not None}
    return kw or None


def _refuse_unused_estimate_options(args, scene, estimate_kw: dict) -> None:
    """--step-px, --max-planes, --depth-range where no depth is estimated, or the plane
    sweep's two on a light field: refused, not ignored."""
    from ..errors import VibrInputError
    from ..pipeline import depth_mode
    from ..stereo.api import depth_method

    flags = {"step_px": "--step-px", "max_planes": "--max-planes", "depth_range": "--depth-range"}
    mode = depth_mode(scene, args.depth)
    given = [flags[k] for k in estimate_kw] if mode != "estimated" else \
        [flags[k] for k in ("step_px", "max_planes") if k in estimate_kw and depth_method(scene) == "lightfield"]
    if given:
        why = f"this evaluation's depth is {mode!r} (--depth {args.depth})" if mode != "estimated" else \
            "this scene's depth is estimated as a light field"
        raise VibrInputError(f"{', '.join(given)} {'apply' if len(given) > 1 else 'applies'} to "
                             f"{'estimated depth' if mode != 'estimated' else 'the MVS estimate'} only, and {why}",
                             args.scene)


def run(args) -> int:
    from ..eval.protocol import format_table, run_evaluation, write_report
    from ..io import load_scene
    from ..io.outputs import check_not_scene_file, record_file

    settings, estimate_kw, executor = _checked_request(args)
    scene = load_scene(args.scene, scale=args.scale)
    check_not_scene_file(args.json, scene, "--json")
    scene.meta.setdefault("scale", args.scale)
    _refuse_unused_estimate_options(args, scene, estimate_kw)
    if args.target.strip().lower() == "all" or "," in args.target:
        return _run_all(args, scene, settings, executor, estimate_kw)
    if args.shard or args.assemble:
        from ..errors import VibrInputError

        raise VibrInputError(f"{'--shard' if args.shard else '--assemble'} applies to several targets "
                             "(--target all or a comma list)")
    if executor is not None:
        logger.warning("--workers and --dask run several targets (--target all or a list) in parallel; "
                       "one target is evaluated here")
    ev = run_evaluation(scene, args.target, settings, sources=args.sources, depth=args.depth,
                        depth_files=args.depth_files, n_views=args.views, mask=args.mask, fallback=args.fallback,
                        border=args.border, estimate_kw=estimate_kw or None,
                        intensity_scale=args.intensity_scale, cache_dir=cache_dir_from_args(args),
                        render_kw=render_kw(args), uncertainty=args.uncertainty)
    report = ev.report
    if args.figures:
        report["figures"] = _write_figures(args, ev)
    write_report(report, args.json)
    record_file(args.json)  # vibr's: a later evaluation may replace it without --overwrite
    print(format_table(report))
    print(f"wrote {args.json}")
    return 0


def _checked_request(args):
    """``(settings, estimate_kw, executor)``, every option checked before the scene is
    loaded: the outputs, the depth options, each setting's parameters, the scheduler."""
    from ..errors import VibrInputError
    from ..eval.protocol import setting_params, settings_grid
    from ..io.outputs import check_output
    from ..stereo.checks import check_depth_params

    check_output(args.json, "file", overwrite=args.overwrite, what="--json")
    if args.figures is not None:
        check_output(args.figures, "dir", what="--figures")
    check_depth_args(args)
    refuse_ignored_params(args, args.method)
    settings = settings_grid(args.method, list(GAMMAS) if args.gamma is None else args.gamma, args.alpha, args.lam)
    if args.intensity_scale is not None and not args.intensity_scale > 0:
        raise VibrInputError(f"--intensity-scale must be > 0, got {args.intensity_scale:g}")
    executor = executor_from_args(args)
    for st in settings:
        setting_params(st, args.intensity_scale, render_kw(args))
    estimate_kw = {k: v for k, v in (("step_px", args.step_px), ("max_planes", args.max_planes),
                                     ("depth_range", args.depth_range)) if v is not None}
    check_depth_params(**estimate_kw)
    if args.border < 0:
        raise VibrInputError(f"--border must be >= 0, got {args.border}")
    return settings, estimate_kw, executor


def _write_figures(args, ev) -> dict:
    """The evaluation's figures in --figures (and the sparsification plot with --uncertainty)."""
    from ..eval.figures import write_evaluation_figures

    figures = write_evaluation_figures(ev, args.figures)
    if args.uncertainty:
        from ..eval.sigma_figures import write_sparsification_figure

        figures["sparsification"] = write_sparsification_figure(args.figures, ev.report["results"],
                                                                prefix=ev.prefix)
    return figures


def _run_all(args, scene, settings, executor, estimate_kw) -> int:
    """``--target all`` / a comma list: one leave-one-out task per view (vibr.eval.leave_one_out)."""
    from pathlib import Path

    from ..errors import VibrInputError
    from ..eval.leave_one_out import assemble_all, evaluate_all, format_all_table, resolve_targets
    from ..eval.protocol import write_report
    from ..executor import parse_shard
    from ..io.outputs import record_file

    if args.shard and args.assemble:
        raise VibrInputError("--assemble gathers the reports every --shard wrote: give one or the other")
    shard = None if args.shard is None else parse_shard(args.shard)
    targets = resolve_targets(scene, args.target)
    # every target has sources of its own, each estimate is used once, and the per-view
    # reports already let a rerun resume: the depth cache only with an explicit --cache-dir
    cache_dir = cache_dir_from_args(args) if args.cache_dir is not None else False
    out = Path(args.json)
    views_dir = out.with_name(out.stem + "_views")
    eval_kw = dict(sources=args.sources, depth=args.depth, depth_files=args.depth_files, n_views=args.views,
                   mask=args.mask, fallback=args.fallback, border=args.border, figures=args.figures,
                   estimate_kw=estimate_kw or None, intensity_scale=args.intensity_scale, cache_dir=cache_dir,
                   render_kw=render_kw(args), uncertainty=args.uncertainty)
    if args.assemble:
        report = assemble_all(args.scene, targets, settings, views_dir=views_dir, scale=args.scale, **eval_kw)
    else:
        report = evaluate_all(args.scene, targets, settings, views_dir=views_dir, scale=args.scale,
                              executor=executor, shard=shard, **eval_kw)
    if shard:
        print(f"shard {shard[0]}/{shard[1]}: {len(report['targets'])} of {len(targets)} targets "
              f"({', '.join(report['targets']) or 'none'}); per-view reports in {views_dir}/")
        print("when every shard is done, write the report: the same command with --assemble instead of --shard")
        return 0
    write_report(report, out)
    record_file(out)
    print(format_all_table(report))
    print(f"wrote {out} (per-view reports in {views_dir}/)")
    return 0
