"""``vibr render``: render one view of a scene (a held-out view or a camera file)."""

from __future__ import annotations

import argparse
import logging
import os

from ..io.video import VIDEO_FORMATS, is_video
from ..pipeline import ALL_VIEWS
from . import count
from ._executor import add_executor_args, executor_from_args
from ._options import (
    METRIC_RULE,
    add_bit_depth_option,
    add_depth_options,
    add_method_option,
    add_render_params,
    add_source_options,
    cache_dir_from_args,
    check_depth_args,
    names,
    refuse_ignored_params,
    render_params,
)

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
    p.add_argument("scene", metavar="SCENE", help="scene folder (any supported format)")
    p.add_argument("--target", metavar="VIEW|CAMERA.json",
                   help="view name / index to hold out and render, or a camera JSON file (K, R, t, "
                        "width, height at the scene's original resolution: --scale applies to it too)")
    p.add_argument("-o", "--output", required=True,
                   help="output image (.png; .tif, .jpg, .webp, .bmp or .ppm by its extension); with --path a video "
                        f"({', '.join(VIDEO_FORMATS)}: " + "; ".join(f"{e} {f.what}" for e, f in VIDEO_FORMATS.items())
                        + ") or a folder for the frames")
    add_bit_depth_option(p)
    add_method_option(p)
    add_render_params(p)
    add_source_options(p)
    add_depth_options(p)
    p.add_argument("--scale", type=float, default=1.0,
                   help="image scale the scene is loaded at, e.g. 0.5; a camera-file target is scaled "
                        "with it (default 1)")
    _add_path_options(p)
    p.add_argument("--uncertainty", metavar="OUT_STD.png|.npy|VIDEO",
                   help="also write the per-pixel standard deviation (grey levels of 255): a colour-mapped "
                        "PNG with a scale bar, or the raw float32 array (.npy); with --path a video of every "
                        "frame's, on one colour scale")
    p.add_argument("--depth-out", metavar="DEPTH.npy|.pfm|.png|DIR",
                   help="also write the rendered view's depth (orthogonal, scene units, 0 where no source "
                        "surface lands), as vibr reads depth maps: .npy or .pfm (float32) or a 16-bit .png "
                        "(1 level = 0.001 scene units); with --path a folder of depth_00000.npy, ... (one per frame)")
    p.set_defaults(func=run)


def _add_path_options(p) -> None:
    """Fly-through options (``--path``; vibr.paths.flythrough, docs/explanation/flythrough.md)."""
    g = p.add_argument_group("fly-through (--path)")
    g.add_argument("--path", metavar="PATH.json",
                   help="render every camera of a camera path (nerfstudio camera_path.json, as written by "
                        "'vibr path' or nerfstudio's viewer) to -o OUT.mp4 or -o FRAMES_DIR/ instead of --target")
    g.add_argument("--frames-dir", metavar="DIR",
                   help="where the numbered PNG frames go (default: OUT_frames/ beside the video)")
    g.add_argument("--crf", type=int, default=None,
                   help="video quality (H.264's and VP9's constant rate factor), 0 (lossless) .. 51 (default 18; "
                        "a GIF has none)")
    g.add_argument("--fps", type=float, help="video frame rate (default: the path file's)")
    g.add_argument("--dataparser-transforms", metavar="JSON",
                   help="nerfstudio's dataparser_transforms.json: the path is in nerfstudio's normalised frame")
    g.add_argument("--overwrite", action="store_true",
                   help="replace an -o or --uncertainty file vibr did not write, write frames into a folder holding "
                        "other files; with --path also render frames already written again (default: skip them)")
    g.add_argument("--exclude", type=names, default=(), metavar="VIEW,...",
                   help="views never used (neither as sources nor for depth estimation), e.g. a held-out view")
    g.add_argument("--shard", metavar="I/N",
                   help="render only shard I of N (frames f with f %% N == I-1; one process of a job array, "
                        "e.g. --shard $SLURM_ARRAY_TASK_ID/N), no video: --assemble encodes it when all are done")
    g.add_argument("--assemble", action="store_true",
                   help="encode the video -o from the complete frames folder the shards wrote (renders nothing; "
                        "an error lists the frames still missing)")
    # frames on local processes or Dask (vibr.executor, docs/explanation/scale-out.md)
    add_executor_args(g, default="auto: one process per core for a long path of large frames, "
                                  "else here (vibr.executor.auto_workers)")


def run(args) -> int:
    from ..errors import VibrInputError
    from ..io import load_scene, write_image
    from ..io.images import check_image_ext
    from ..io.outputs import check_not_scene_file, check_output, record_file
    from ..pipeline import prepare
    from ..render import RenderParams, render

    refuse_ignored_params(args)
    # every parameter checked before the work ("auto" is resolved by render())
    params = RenderParams.from_kwargs(args.method, **render_params(args))
    if (args.path is None) == (args.target is None):
        raise VibrInputError("give exactly one of --target VIEW|CAMERA.json and --path PATH.json")
    if args.path is not None:
        check_output(args.output, "file" if is_video(args.output) else "dir",
                     overwrite=args.overwrite or not is_video(args.output), what="-o")
        return _run_path(args, params)
    _refuse_path_options(args)
    check_output(args.output, "file", overwrite=args.overwrite, what="-o")
    if args.uncertainty:
        check_output(args.uncertainty, "file", overwrite=args.overwrite, what="--uncertainty")
    check_image_ext(args.output, args.bit_depth)  # before the work: out.npy was a TIFF under that name
    _check_depth_out(args)
    check_depth_args(args)
    if args.uncertainty and os.path.splitext(args.uncertainty)[1].lower() not in (".png", ".npy"):
        raise VibrInputError("--uncertainty output must end in .png or .npy", args.uncertainty)
    scene = load_scene(args.scene, scale=args.scale)
    check_not_scene_file(args.output, scene, "-o")  # before the work, as every output check
    check_not_scene_file(args.uncertainty, scene, "--uncertainty")
    check_not_scene_file(args.depth_out, scene, "--depth-out")
    sources, target = prepare(scene, _target(args, scene), sources=args.sources, depth=args.depth,
                              depth_files=args.depth_files, n_views=args.views, fallback=args.fallback,
                              cache_dir=cache_dir_from_args(args))
    res = render(sources, target, args.method, params=params, progress_bar=True,
                 uncertainty=bool(args.uncertainty), supersample=args.supersample)  # -v: per pass
    write_image(args.output, res.image, bits=args.bit_depth or 8)
    record_file(args.output)  # vibr's: a later render may replace it without --overwrite
    if args.uncertainty:
        from ..eval.sigma_figures import write_sigma

        write_sigma(args.uncertainty, res.uncertainty)
        record_file(args.uncertainty)
        print(f"wrote {args.uncertainty}")
    if args.depth_out:
        _write_depth_out(args.depth_out, res.depth)
    _report(args.method, res)
    print(f"wrote {args.output}")
    return 0


#: What --depth-out writes for one view (vibr.io.depthfiles.write_depth), read back by vibr.
_DEPTH_OUT_EXTS = (".npy", ".pfm", ".png")


def _check_depth_out(args) -> None:
    """--depth-out of one view: a file vibr reads depth from, not there yet."""
    from ..errors import VibrInputError
    from ..io.outputs import check_output

    if args.depth_out is None:
        return
    if os.path.splitext(args.depth_out)[1].lower() not in _DEPTH_OUT_EXTS:
        raise VibrInputError(f"--depth-out must end in {', '.join(_DEPTH_OUT_EXTS)} (a folder with --path only)",
                             args.depth_out)
    check_output(args.depth_out, "file", what="--depth-out")


def _write_depth_out(path, depth) -> None:
    """The render's depth to ``path`` (:func:`vibr.io.depthfiles.write_depth`): a depth too
    far for a 16-bit PNG's range is a one-line error naming the formats that hold it."""
    from ..errors import VibrInputError
    from ..io.depthfiles import write_depth

    try:
        write_depth(path, depth)
    except ValueError as exc:
        raise VibrInputError(f"{exc}: write .npy or .pfm (float32) instead", path) from None
    print(f"wrote {path} (depth, scene units)")


def _target(args, scene):
    """The render's target: a camera file's camera (scaled with --scale), a light field's
    absent grid position (by name), or a view of the scene (by name or index)."""
    from ..errors import VibrInputError
    from ..io import read_camera_json
    from ..pipeline import missing_view_camera

    tgt = args.target
    if tgt.lower().endswith(".json") or (os.path.isfile(tgt) and not tgt.isdigit()):
        target = read_camera_json(tgt)
        return target.scaled(args.scale) if args.scale != 1.0 else target
    if missing_view_camera(scene, tgt) is not None:  # a light field's absent position: a novel view
        return tgt
    target = scene[tgt].name
    if args.sources and target in [scene[s].name for s in args.sources]:
        raise VibrInputError(f"target view {target} is also listed as a source", args.scene)
    return target


def _report(method: str, res) -> None:
    """The render's status line (the log) and its metrics when the target has a photograph."""
    t = res.times
    k, g = res.params.get("supersample", 1), res.params.get("coarsen", 1.0)
    grid = f" on a grid {k}x finer" if k > 1 else f" on a grid {g:.3g}x coarser, enlarged" if g > 1 else ""
    logger.info(f"rendered {res.image.shape[1]}x{res.image.shape[0]} with {method} from "
                f"{res.n_samples} samples{grid}, coverage {100 * res.coverage.mean():.1f} %, "
                f"{t.get('total', 0):.2f} s (geometry {t.get('geometry', 0):.2f}, solve {t.get('solve', 0):.2f})")
    if res.metrics:
        print(f"PSNR {res.metrics['psnr']:.2f} dB  DSSIM {res.metrics['dssim']:.1f}  "
              f"(SSIM {res.metrics['ssim']:.4f}; {METRIC_RULE}, {100 * res.coverage.mean():.1f} % of the "
              f"image); PSNR {res.metrics['psnr_all']:.2f} dB over all pixels".replace("nan", "n/a"))


#: the fly-through's options (attribute, flag), refused with --target rather than ignored
_PATH_ONLY = (("frames_dir", "--frames-dir"), ("crf", "--crf"), ("fps", "--fps"),
              ("dataparser_transforms", "--dataparser-transforms"),
              ("exclude", "--exclude"), ("workers", "--workers"), ("dask", "--dask"), ("shard", "--shard"),
              ("assemble", "--assemble"))


def _refuse_path_options(args) -> None:
    """With --target: any of :data:`_PATH_ONLY` given is an error (one line)."""
    from ..errors import VibrInputError

    given = [flag for attr, flag in _PATH_ONLY if getattr(args, attr, None) not in (None, False, (), [])]
    if given:
        hint = "; with --target, choose the sources with --sources" if "--exclude" in given else ""
        raise VibrInputError(f"{', '.join(given)} {'apply' if len(given) > 1 else 'applies'} to --path only{hint}")


def _path_views(views):
    """``--views`` of a fly-through: 8 per frame by default, "all" every view (None)."""
    return 8 if views is None else (None if views == ALL_VIEWS else views)


def _run_path(args, params) -> int:
    """``--path``: a thin layer over :func:`vibr.paths.flythrough.render_path`."""
    from ..errors import VibrInputError
    from ..io.outputs import check_output, record_file
    from ..paths.camera_path import read_camera_path, scene_processing_transform
    from ..paths.flythrough import render_path
    from ..pipeline import load_scene_cached

    out = args.output
    if args.crf is not None and out.lower().endswith(".gif"):
        raise VibrInputError("--crf does not apply to a GIF (one 256-colour palette, no rate factor)", out)
    if not (is_video(out) or not os.path.splitext(out)[1]):
        raise VibrInputError(f"with --path, -o is a video ({', '.join(VIDEO_FORMATS)}) or a folder for the frames",
                             out)
    for flag in ("sources", "depth_files", "bit_depth"):  # frames are 8-bit colour only
        if getattr(args, flag, None):
            raise VibrInputError(f"--{flag.replace('_', '-')} does not apply to --path")
    if args.depth not in ("auto", "gt", "given", "estimated"):
        raise VibrInputError(f"--depth {args.depth} does not apply to --path (auto, gt or estimated)")
    if args.uncertainty:
        if not is_video(args.uncertainty):
            raise VibrInputError(f"with --path, --uncertainty is a video ({', '.join(VIDEO_FORMATS)})",
                                 args.uncertainty)
        check_output(args.uncertainty, "file", overwrite=args.overwrite, what="--uncertainty")
    shard = _check_shard_args(args)
    applied, applied_scale = (scene_processing_transform(args.scene) if args.dataparser_transforms
                              else (None, 1.0))
    cpath = read_camera_path(args.path, dataparser_transforms=args.dataparser_transforms,
                             applied_transform=applied, applied_scale=applied_scale)
    if args.assemble:
        return _assemble(args, cpath)
    executor = executor_from_args(args, default="auto")  # a bad scheduler fails before the work
    cache_dir = cache_dir_from_args(args)
    scene = load_scene_cached(args.scene, scale=args.scale, cache_dir=cache_dir)
    res = render_path(scene, cpath, out, method=args.method,
                      n_views=_path_views(args.views), params=params,
                      overwrite=args.overwrite, depth="gt" if args.depth == "given" else args.depth,
                      cache_dir=cache_dir, exclude=args.exclude, frames_dir=args.frames_dir,
                      crf=18 if args.crf is None else args.crf, fps=args.fps, executor=executor,
                      uncertainty=args.uncertainty or None, supersample=args.supersample, shard=shard,
                      depth_out=args.depth_out)
    for f in (res.video, res.sigma_video):
        if f:
            record_file(f)
    t = res.times
    what = f"{res.video} ({count(res.video_frames, 'frame')}, {res.video_size[0]}x{res.video_size[1]})" if res.video \
        else res.frames_dir
    if shard:
        what += f" (shard {shard[0]}/{shard[1]}: {count(len(res.frames), 'frame')} of {res.n_frames})"
    per = f", {res.seconds_per_frame:.2f} s per frame" if res.rendered else ""
    print(f"rendered {count(res.rendered, 'frame')} ({res.skipped} already there) in {t['frames']:.1f} s {res.engine}"
          f"{per}; total {t['total']:.1f} s (depth: {res.depth_source} "
          f"({t['depth']:.1f} s); video {t['video']:.1f} s); wrote {what}")
    ks = sorted({f.get("supersample", 1) for f in res.frames if not f.get("skipped")} - {1})
    if ks:
        print(f"the photographs are finer than the frames: rendered on a grid {'-'.join(map(str, ks))}x finer and "
              "averaged back (--supersample 1: on the frames' own grid, faster)")
    gs = sorted({f.get("coarsen", 1.0) for f in res.frames if not f.get("skipped")} - {1.0})
    if gs:
        print(f"the photographs are coarser than the frames: rendered on a grid {'-'.join(f'{g:.3g}' for g in gs)}x "
              "coarser and enlarged (--supersample 1: on the frames' own grid)")
    if res.sigma_video:
        print(f"wrote {res.sigma_video} (sigma of every frame, 0 to {res.sigma_vmax:g} grey levels)")
    if res.depth_dir:
        print(f"wrote the frames' depth to {res.depth_dir}/ (depth_00000.npy, ...; scene units)")
    if shard and is_video(out):
        print("when every shard is done, encode the video: the same command with --assemble instead of --shard")
    return 0


def _check_shard_args(args):
    """``--shard`` as ``(I, N)`` (None without it); --shard with --assemble, and --assemble
    to a folder or with --overwrite, refused."""
    from ..errors import VibrInputError
    from ..executor import parse_shard

    if args.assemble and args.shard:
        raise VibrInputError("--assemble encodes the frames every --shard wrote: give one or the other")
    if args.assemble and not is_video(args.output):
        raise VibrInputError(f"--assemble writes a video ({', '.join(VIDEO_FORMATS)})", args.output)
    if args.assemble and args.overwrite:
        raise VibrInputError("--assemble renders nothing: --overwrite does not apply")
    if args.depth_out is not None and os.path.splitext(args.depth_out)[1]:
        raise VibrInputError("with --path, --depth-out is a folder (depth_00000.npy, ... one per frame)",
                             args.depth_out)
    return None if args.shard is None else parse_shard(args.shard)


def _assemble(args, cpath) -> int:
    """``--path ... --assemble``: the video from the frames folder (vibr.paths.flythrough.assemble_path)."""
    from ..io.outputs import record_file
    from ..paths.flythrough import assemble_path

    res = assemble_path(cpath, args.output, frames_dir=args.frames_dir, fps=args.fps,
                        crf=18 if args.crf is None else args.crf, uncertainty=args.uncertainty or None,
                        depth_out=args.depth_out)
    for f in (res.video, res.sigma_video):
        if f:
            record_file(f)
    print(f"assembled {count(res.video_frames, 'frame')} from {res.frames_dir} in {res.times['total']:.1f} s; "
          f"wrote {res.video} ({res.video_size[0]}x{res.video_size[1]})")
    if res.sigma_video:
        print(f"wrote {res.sigma_video} (sigma of every frame, 0 to {res.sigma_vmax:g} grey levels)")
    return 0
