"""Options shared by subcommands, built from the library's registries so that choices and
the defaults shown in ``--help`` are never written twice."""

from __future__ import annotations

import argparse

from ..metrics import METRIC_BORDER
from ..pipeline import ALL_VIEWS, DEPTH_MODES, ESTIMATED_SOURCES, PLANAR_SOURCES
from ..render.autotune import AUTO, GAMMA_GRID, LAM_GRID
from ..render.methods import DEFAULTS, PRESETS, PSFS, REGISTRY

#: How ``vibr render`` and ``vibr eval`` measure (one rule: vibr.metrics.view_metrics).
METRIC_RULE = f"reconstructed pixels, {METRIC_BORDER}-px border excluded"

DEFAULT_METHOD = "gradient"


def _d(key) -> str:
    v = DEFAULTS[key]
    return "the geometry's" if v is None else f"{v:g}" if isinstance(v, float) else str(v)


def method_default(key) -> str:
    """The default of ``key`` and the methods that override it, e.g. "2; ulr: 0, savsr: 1"."""
    over = [f"{m.name}: {m.overrides[key]:g}" for m in REGISTRY.values() if key in m.overrides]
    return _d(key) + (f"; {', '.join(over)}" if over else "")


def _weight(text: str):
    """A non-negative number, or "auto" (:mod:`vibr.render.autotune`)."""
    if text.strip().lower() == AUTO:
        return AUTO
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or {AUTO!r}, got {text!r}") from None


def _supersample(text: str):
    """"auto" or an integer >= 1 (:func:`vibr.geometry.resolution.check_supersample`)."""
    from ..errors import VibrInputError
    from ..geometry.resolution import check_supersample

    try:
        return check_supersample(text)
    except VibrInputError as exc:
        raise argparse.ArgumentTypeError(exc.problem) from None


def method_help() -> str:
    return "; ".join(f"{m.name}: {m.summary}" for m in REGISTRY.values())


def add_method_option(p: argparse.ArgumentParser) -> None:
    """``--method`` (one of the registered methods)."""
    p.add_argument("--method", default=DEFAULT_METHOD, choices=tuple(REGISTRY),  # those registered by now
                   help=f"rendering method (default: {DEFAULT_METHOD}). {method_help()}")


def add_psf_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--psf", choices=PSFS, default=None,
                   help=f"image-formation model of the variational methods (default: {DEFAULTS['psf']}): "
                        "bilinear, or footprint (the source pixel's parallelogram: sources finer than the "
                        "target, on the target's own grid)")


def add_intensity_scale_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--intensity-scale", type=float, default=None, metavar="S",
                   help="INTENSITY scale the render parameters (lam, sigma_s, ...) refer to: 255 "
                        "means grey levels of 8-bit images, 1 means [0, 1] intensities "
                        f"(default: {_d('scale')})")


def add_render_params(p: argparse.ArgumentParser) -> None:
    """The renderer's parameters for one render (defaults from ``DEFAULTS``)."""
    p.add_argument("--alpha", type=float, help=f"colour-term weight (default {_d('alpha')})")
    p.add_argument("--gamma", type=_weight, metavar="G|" + AUTO,
                   help=f"gradient-term weight, method gradient only, or {AUTO}: chosen per scene by "
                        f"leave-one-source-out on the sources over {', '.join(map(str, GAMMA_GRID))} "
                        f"(default {_d('gamma')})")
    p.add_argument("--lam", type=_weight, metavar="L|" + AUTO,
                   help=f"TV weight, on the --intensity-scale, or {AUTO} (over {', '.join(map(str, LAM_GRID))}) "
                        f"(default {method_default('lam')})")
    p.add_argument("--grad-consistency", type=float, metavar="C",
                   help="gradient-term samples that the other views' gradients do not confirm weigh "
                        "1 / (1 + (residual / C)^2), C on the --intensity-scale per pixel; 0: every sample "
                        f"at full weight, the paper's term (default {_d('grad_consistency')}; method gradient only)")
    p.add_argument("--grad-coverage", type=float, metavar="N",
                   help="with --grad-consistency, a gradient-term sample landing where fewer than N samples "
                        "land weighs (samples there) / N; 0: full weight (default "
                        f"{_d('grad_coverage')}; method gradient only)")
    p.add_argument("--sigma-s", type=float, help=f"sensor noise, grey levels (default {_d('sigma_s')})")
    p.add_argument("--sigma-z", type=float,
                   help="depth std. dev., scene units (default: the scene's, else 1%% of the depth)")
    p.add_argument("--z-corr", type=float, metavar="RHO",
                   help="correlation in [0, 1] of the views' depth errors at a target pixel: the colour "
                        "term's weights then favour views whose misregistrations cancel; 0: independent, the "
                        "paper's model (default: the geometry's, 0.9 for a proxy such as --depth planar, "
                        "else 0; bvs: 0)")
    add_intensity_scale_option(p)
    p.add_argument("--outer", type=int, help=f"weight re-estimation passes (default {method_default('n_outer')})")
    p.add_argument("--iterations", type=int, help=f"FISTA iterations per pass at most (default {_d('max_iter')})")
    over = [m.name for m in REGISTRY.values() if m.solve and not m.overrides.get("precond", DEFAULTS["precond"])]
    p.add_argument("--precond", action=argparse.BooleanOptionalAction, default=None,
                   help="diagonally preconditioned FISTA, or plain FISTA with --no-precond (default: "
                        f"{'on' if DEFAULTS['precond'] else 'off'}" + (f"; off for {', '.join(over)}" if over else "")
                        + ")")
    p.add_argument("--preset", choices=tuple(PRESETS), default=None,
                   help="read --alpha/--gamma/--lam in these units: paper = the paper's symbols as the "
                        "authors' code applies them (gamma x 0.1/4, lam x 255 on [0, 1] intensities, "
                        "gradient term weighted by W, spatially varying TV; docs/explanation/renderer.md)")
    add_psf_option(p)
    from ..geometry.resolution import SUPERSAMPLE_MAX

    p.add_argument("--supersample", type=_supersample, default=AUTO, metavar="K|" + AUTO,
                   help="render on a grid K times finer and average KxK blocks, for sources finer than the "
                        f"target (default {AUTO}: K from the sources' pixel size in the target, at most "
                        f"{SUPERSAMPLE_MAX}, and for sources coarser than the target a coarser grid, enlarged; "
                        "1: the target's own grid)")


def render_params(args) -> dict:
    """The keyword arguments of :func:`vibr.render.render` given on the command line (None:
    the method's default)."""
    params = dict(alpha=args.alpha, gamma=args.gamma, lam=args.lam, sigma_s=args.sigma_s,
                  scale=args.intensity_scale, n_outer=args.outer, max_iter=args.iterations,
                  precond=args.precond, psf=args.psf, grad_consistency=args.grad_consistency,
                  grad_coverage=args.grad_coverage, z_corr=args.z_corr)
    if getattr(args, "preset", None) is not None:
        params["preset"] = args.preset
    if args.sigma_z is not None:
        params["sigma_z"] = args.sigma_z
    return params


#: the command-line flag of each render parameter (:func:`render_params`)
PARAM_FLAGS = {"alpha": "--alpha", "gamma": "--gamma", "lam": "--lam", "sigma_s": "--sigma-s",
               "sigma_z": "--sigma-z", "n_outer": "--outer", "max_iter": "--iterations",
               "precond": "--precond", "psf": "--psf", "grad_consistency": "--grad-consistency",
               "grad_coverage": "--grad-coverage", "z_corr": "--z-corr"}


def refuse_ignored_params(args) -> None:
    """A render parameter given for a method that does not read it
    (:meth:`vibr.render.methods.Method.ignored_params`) is an error, not a silent no-op."""
    from ..errors import VibrInputError
    from ..render.methods import get_method

    ignored = get_method(args.method).ignored_params()
    given = [PARAM_FLAGS[k] for k, v in render_params(args).items() if v is not None and k in ignored]
    if given:
        raise VibrInputError(f"{', '.join(given)} {'do' if len(given) > 1 else 'does'} not apply to "
                             f"--method {args.method}")


def add_depth_options(p: argparse.ArgumentParser) -> None:
    """``--depth`` (vibr.pipeline.DEPTH_MODES) and ``--depth-files``."""
    p.add_argument("--depth", default="auto", choices=DEPTH_MODES,
                   help="source geometry: the scene's depth maps (gt), depth estimated from the "
                        "sources (estimated; the target never takes part), a fronto-parallel plane of "
                        "the target at the depth it sees, or where the cameras' axes meet (planar), "
                        "NAME.npy/.pfm/.png files in --depth-files (files), or gt when the scene has "
                        "depth and estimated when it has none (auto, the default)")
    p.add_argument("--depth-files", metavar="DIR",
                   help="folder of per-view depth maps for --depth files (NAME.npy/.pfm/.png/.bin, orthogonal "
                        "depth, 0 = unknown; a map of the view's aspect at another size, e.g. full size with "
                        "--scale, is resized to it)")
    from ..geometry.proxy import FALLBACK_MIN_FRACTION, FALLBACK_MODES

    p.add_argument("--fallback", choices=FALLBACK_MODES, default="auto",
                   help="source pixels of unknown depth (a black backdrop, the sky) get a plane "
                        "behind the view's known depth with a large sigma_z instead of being dropped: "
                        f"in the views at least {100 * FALLBACK_MIN_FRACTION:.0f}%% unknown and, in the others, "
                        "where the photograph is flat, the other unknown pixels of those taking a depth completed "
                        "from their view's (auto, the default), at every unknown pixel (always), "
                        "or never (docs/explanation/renderer.md \"Fallback proxy\")")
    add_cache_options(p)


def add_cache_options(p: argparse.ArgumentParser) -> None:
    """``--cache-dir`` and ``--no-cache``: the on-disk cache of estimated depth and resized
    views (vibr.stereo.cache), one for every command that uses it."""
    p.add_argument("--cache-dir", metavar="DIR",
                   help="cache of estimated depth and of resized views: a rerun on the same sources loads "
                        "them instead of estimating again (default $VIBR_CACHE_DIR or ~/.cache/vibr)")
    p.add_argument("--no-cache", action="store_true", help="estimate depth again and keep nothing on disk")


def cache_dir_from_args(args):
    """``--cache-dir`` / ``--no-cache`` as the library reads them: a folder, None (the
    default folder) or False (no cache). A path that is, or lies under, a file is refused
    before any work."""
    from pathlib import Path

    from ..errors import VibrInputError

    if getattr(args, "no_cache", False):
        return False
    d = getattr(args, "cache_dir", None)
    if d is not None:
        p = Path(d).absolute()
        first = next(a for a in (p, *p.parents) if a.exists())
        if not first.is_dir():
            raise VibrInputError("--cache-dir is a file, a folder is expected" if first == p
                                 else f"--cache-dir cannot be made: {first} is a file", d)
    return d


def check_depth_args(args) -> None:
    """The depth options checked before any work (the scene not loaded yet)."""
    from ..errors import VibrInputError

    if args.depth == "files" and not args.depth_files:
        raise VibrInputError("--depth files needs --depth-files DIR")
    if args.depth_files and args.depth != "files":  # refused, not ignored
        raise VibrInputError(f"--depth-files applies to --depth files only, not to --depth {args.depth}")
    cache_dir_from_args(args)


def add_overwrite_option(p: argparse.ArgumentParser, what: str) -> None:
    """``--overwrite``: THE name for replacing existing outputs (``--force``: a hidden,
    deprecated alias)."""
    p.add_argument("--overwrite", action="store_true", help=f"replace {what} if it exists")
    p.add_argument("--force", dest="overwrite", action="store_true", help=argparse.SUPPRESS)


def add_bit_depth_option(p: argparse.ArgumentParser) -> None:
    """``--bit-depth 8|16`` of the images a subcommand writes (8 by default)."""
    p.add_argument("--bit-depth", type=int, choices=(8, 16), default=None,
                   help="bits per channel of the PNG written (default: 8; 16 keeps the solver's "
                        "precision)")


def names(text: str) -> list[str]:
    """'a, b,3' → ['a', 'b', '3'] (an argparse type; an empty list is refused: an option
    given with nothing in it is a mistake, not "all")."""
    out = [x.strip() for x in text.split(",") if x.strip()]
    if not out:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list, got {text!r}")
    return out


def add_source_options(p: argparse.ArgumentParser) -> None:
    """``--sources`` (a list) and ``--views K`` (the K best), as :func:`vibr.pipeline.prepare`."""
    p.add_argument("--sources", type=names, metavar="VIEW,...",
                   help="comma-separated source views (default: all others, see --views)")
    p.add_argument("--views", type=view_count, metavar="K|all",
                   help="render from the K best source views for the target, of --sources when given "
                        f"(ULR ranking), or '{ALL_VIEWS}' (default: all, but the {ESTIMATED_SOURCES} best "
                        f"when depth is estimated, one estimate per source, and the {PLANAR_SOURCES} best with "
                        "--depth planar, when no --sources are listed)")


def view_count(text: str):
    """``--views``: a positive integer or "all" (:data:`vibr.pipeline.ALL_VIEWS`)."""
    if text.strip().lower() == ALL_VIEWS:
        return ALL_VIEWS
    try:
        k = int(text)
    except ValueError:
        k = 0
    if k < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer or '{ALL_VIEWS}', got {text!r}")
    return k
