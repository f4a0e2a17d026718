"""Options shared by subcommands, built from the library's registries so that choices and
the defaults shown in ``--help`` are never written twice."""

from __future__ import annotations

import argparse

from ..metrics import METRIC_BORDER
from ..pipeline import ALL_VIEWS, DEPTH_MODES, ESTIMATED_SOURCES, PLANAR_SOURCES
from ..render.autotune import GAMMA_GRID, LAM_GRID
from ..render.methods import REGISTRY
from ..render.params import AUTO, PRESETS, default_text, param_fields, range_text

#: How ``vibr render`` and ``vibr eval`` measure (one rule: vibr.metrics.view_metrics).
METRIC_RULE = f"reconstructed pixels, {METRIC_BORDER}-px border excluded"

DEFAULT_METHOD = "gradient"


def method_default(key) -> str:
    """The default of ``key`` and the methods that override it, e.g. "2 (ulr: 0, savsr: 1)"."""
    f = next(f for f in param_fields() if f.name == key)
    return default_text(f, {m.name: m.overrides for m in REGISTRY.values()})


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


#: The grids ``auto`` searches, per parameter (:mod:`vibr.render.autotune`).
_AUTO_GRIDS = {"gamma": GAMMA_GRID, "lam": LAM_GRID}


def method_option_fields() -> tuple:
    """The :class:`~vibr.render.params.RenderParams` fields given on the command line (those
    with a ``flag`` in their metadata), in the order of ``--help``."""
    return tuple(f for f in param_fields() if f.metadata["flag"])


#: the command-line flag of each render parameter given on the command line
PARAM_FLAGS = {f.name: f.metadata["flag"] for f in method_option_fields()}


def _dest(f) -> str:
    return f.metadata["flag"][2:].replace("-", "_")


def _scalar_type(f):
    m = f.metadata
    base = int if m["kind"] == "int" else float
    if not m["auto"]:
        return base

    def weight(text: str):
        """A number, or "auto" (:mod:`vibr.render.autotune`)."""
        if text.strip().lower() == AUTO:
            return AUTO
        try:
            return base(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number or {AUTO!r}, got {text!r}") from None

    return weight


def _list_type(scalar):
    def values(text: str) -> list:
        """Comma-separated values of ``scalar``."""
        out = [scalar(x) for x in text.split(",") if x.strip()]
        if not out:
            raise argparse.ArgumentTypeError(f"expected comma-separated values, got {text!r}")
        return out

    return values


def _option_help(f, default: str | None = None) -> str:
    """A method option's help: description, units, range, default (and the methods that
    override it), the methods that read it."""
    m = f.metadata
    units = f"{m['units']}; " if m["units"] else ""
    text = f"{m['description']} ({units}{range_text(f)}; default {default or method_default(f.name)})"
    if m["auto"]:
        text += (f"; {AUTO}: chosen per scene by leave-one-source-out on the sources over "
                 f"{', '.join(f'{v:g}' for v in _AUTO_GRIDS[f.name])}")
    users = [x.name for x in REGISTRY.values() if f.name not in x.ignored_params()]
    if len(users) < len(REGISTRY):
        text += f"; method{'s' if len(users) > 1 else ''} {', '.join(users)} only"
    return text.replace("%", "%%")


def add_method_options(p: argparse.ArgumentParser, lists=(), defaults: dict | None = None) -> None:
    """The renderer's parameters, from :class:`~vibr.render.params.RenderParams`' fields and
    their metadata (flag, type, units, range, default), and ``--preset``: the same options
    for every command that renders. ``lists``: the fields that take comma-separated values
    (``vibr eval``'s settings grid); ``defaults``: a field's default as that command shows it."""
    g = p.add_argument_group("method options (docs/reference/parameters.md)")
    for f in method_option_fields():
        m = f.metadata
        kw = dict(dest=_dest(f), default=None, help=_option_help(f, (defaults or {}).get(f.name)))
        if m["kind"] == "bool":
            g.add_argument(m["flag"], action=argparse.BooleanOptionalAction, **kw)
            continue
        if m["kind"] == "choice":
            kw["choices"] = m["choices"]
        else:
            kw["type"] = _scalar_type(f)
            kw["metavar"] = m["metavar"] or _dest(f).upper()
        if f.name in lists:
            kw["type"] = _list_type(kw.pop("type", str))
            kw["metavar"] = kw.get("metavar", _dest(f).upper()) + ",..."
            kw["help"] = "comma-separated: one setting each. " + kw["help"]
        g.add_argument(m["flag"], **kw)
    g.add_argument("--preset", choices=tuple(PRESETS), default=None,
                   help="read --alpha/--gamma/--lam in these units: paper = the paper's symbols as the "
                        "authors' code applies them (gamma x 0.1/4, lam x 255 on [0, 1] intensities, "
                        "gradient term weighted by W, spatially varying TV; docs/explanation/renderer.md)")


def add_supersample_option(p: argparse.ArgumentParser) -> None:
    """``--supersample`` (:func:`vibr.render.render`'s ``supersample``)."""
    from ..geometry.resolution import SUPERSAMPLE_MAX

    p.add_argument("--supersample", type=_supersample, default=AUTO, metavar="K|" + AUTO,
                   help="render on a grid K times finer and average KxK blocks, for sources finer than the "
                        f"target (default {AUTO}: K from the sources' pixel size in the target, at most "
                        f"{SUPERSAMPLE_MAX}, and for sources coarser than the target a coarser grid, enlarged; "
                        "1: the target's own grid)")


def add_render_params(p: argparse.ArgumentParser) -> None:
    """The options of one render: :func:`add_method_options` and ``--supersample``."""
    add_method_options(p)
    add_supersample_option(p)


def render_params(args, skip=()) -> dict:
    """The keyword arguments of :meth:`vibr.render.params.RenderParams.from_kwargs` given on
    the command line (None: the method's default; ``preset`` when given), but the fields ``skip``."""
    params = {f.name: getattr(args, _dest(f), None) for f in method_option_fields() if f.name not in skip}
    if getattr(args, "preset", None) is not None:
        params["preset"] = args.preset
    return params


def refuse_ignored_params(args, methods=None) -> None:
    """A render parameter given for methods that none of them reads
    (:meth:`vibr.render.methods.Method.ignored_params`) is an error, not a silent no-op.
    ``methods``: the names rendered (default ``[args.method]``)."""
    from ..errors import VibrInputError
    from ..render.methods import get_method

    names = [args.method] if methods is None else list(methods)
    specs = [get_method(m) for m in names]  # an unknown name gives get_method's error
    given = [k for k, v in render_params(args).items() if k != "preset" and v is not None
             and all(k in m.ignored_params() for m in specs)]
    if given:
        flags = [PARAM_FLAGS[k] for k in given]
        users = [m.name for m in REGISTRY.values() if any(k not in m.ignored_params() for k in given)]
        raise VibrInputError(f"{', '.join(flags)} {'do' if len(flags) > 1 else 'does'} not apply to "
                             f"--method {','.join(names)}" + (f" (only to {', '.join(users)})" if users else ""))


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
    from ..geometry.proxy import FALLBACK_MODES

    p.add_argument("--fallback", choices=FALLBACK_MODES, default="auto",
                   help="source pixels of unknown depth (a black backdrop, the sky) get a plane "
                        "behind the view's known depth with a large sigma_z instead of being dropped: "
                        "at each view's backdrop (flat unknown pixels connected to the image border), the other "
                        "unknown pixels taking a depth completed from their view's, and the samples that land on "
                        "another view's backdrop dropped (auto, the default), at every unknown pixel (always), "
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
