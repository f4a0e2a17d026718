"""The ``vibr`` command line: a thin layer over the Python API.

Each subcommand lives in its own module ``vibr.cli.<name>`` exposing
``register(subparsers)``, which adds its parser and sets ``func`` to a function
``run(args) -> int``. Errors in the user's input (:class:`vibr.VibrInputError`) print one
line on stderr and exit with status 2; no traceback.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import importlib.util
import logging
import os
import signal
import sys
import threading

from .. import __version__
from .._runtime.malloc import tune_malloc
from .._runtime.threads import oversubscribe_render_threads
from ..errors import VibrInputError
from ..progress import configure_logging

logger = logging.getLogger(__name__)

# Order shown in --help.
_COMMANDS = ["demo", "info", "convert", "path", "render", "eval", "depth", "calibrate", "view"]

_EPILOG = """\
examples:
  vibr demo                                  render a held-out view of a built-in synthetic scene
  vibr info ../shared/data/hci2016_cotton    summarise a scene (views, sizes, cameras, depth)
  vibr convert SCENE out/                    save any scene as nerfstudio transforms.json
  vibr render SCENE --target 5 -o view.png   render view 5 from the other views

{formats}
Run 'vibr COMMAND --help' for each command's options.
"""


def scene_formats() -> str:
    """The registered scene formats (:data:`vibr.io.FORMATS`), in their detection order, for
    help texts: "nerfstudio/instant-NGP transforms.json, HCI light field, ..."."""
    from ..io import FORMATS

    return ", ".join(f.summary for f in FORMATS.values())


def fill(text: str) -> str:
    """``text`` wrapped at 90 columns, as the hand-wrapped help paragraphs."""
    import textwrap

    return textwrap.fill(text, 90, break_long_words=False, break_on_hyphens=False)


class _Parser(argparse.ArgumentParser):
    """Usage errors in one line (exit 2), like every other error of vibr."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {' '.join(str(message).split())} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="vibr",
        description="Variational image-based rendering with gradient constraints "
        "(Nieto, Devernay & Crowley 2016): novel views from calibrated photos and depth.",
        epilog=_EPILOG.format(formats=fill(f"SCENE is a folder in any supported format ({scene_formats()}); "
                                           "the format is detected.")),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_global_options(parser, top=True)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in _COMMANDS:
        modname = f"{__name__}.{name}"
        if importlib.util.find_spec(modname) is None:
            continue
        importlib.import_module(modname).register(sub)
    for p in _subparsers(sub):
        add_global_options(p, top=False)
    return parser


def _subparsers(sub) -> list:
    """Every parser below ``sub``, nested ones included (``vibr path KIND``); an alias names
    the same parser."""
    out = []
    for p in dict.fromkeys(sub.choices.values()):
        out.append(p)
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                out.extend(_subparsers(a))
    return out


#: Title of the argument group of the options every command accepts, before or after its name.
GLOBAL_OPTIONS = "global options (before or after COMMAND)"


def add_global_options(p: argparse.ArgumentParser, top: bool) -> None:
    """The top-level options (``--version``, ``-q``, ``-v``, ``--allow-outside-paths``), on
    the top-level parser (``top``) and on every subcommand's, so that they may be given
    before or after the subcommand. A subcommand's copy has no default (``SUPPRESS``): it
    sets the option when given and otherwise leaves the top-level value alone."""
    kw = {} if top else {"default": argparse.SUPPRESS}
    g = p.add_argument_group(GLOBAL_OPTIONS)
    g.add_argument("--version", action="version", version=f"vibr {__version__}")
    g.add_argument("-q", "--quiet", action="store_true", help="no progress bars or status lines "
                   "(warnings and errors only)", **kw)
    g.add_argument("-v", "--verbose", action="store_true", help="also debugging lines (each solver "
                   "pass, each stage's details)", **kw)
    g.add_argument("--allow-outside-paths", action="store_true",
                   help="accept transforms.json file paths that are absolute or lead out of the "
                   "scene folder (refused by default)", **kw)


def verbosity(args) -> int:
    """-1 with ``-q``, 1 with ``-v``, else 0."""
    return -1 if getattr(args, "quiet", False) else 1 if getattr(args, "verbose", False) else 0


#: Attribute of the parsed arguments listing the deprecated spellings used (logged once the
#: logging is configured).
DEPRECATED = "deprecated_spellings"


class _DeprecatedAlias(argparse.Action):
    """An old spelling of an option, hidden from ``--help``: it sets the new option's value
    and notes a warning naming the new spelling."""

    def __init__(self, option_strings, dest, new, **kw):
        super().__init__(option_strings, dest, default=argparse.SUPPRESS, help=argparse.SUPPRESS, **kw)
        self.new = new

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        notes = list(getattr(namespace, DEPRECATED, ()))
        setattr(namespace, DEPRECATED, notes + [f"{parser.prog} {option_string} is deprecated and will be "
                                                f"removed: use {self.new}"])


def add_deprecated_alias(p: argparse.ArgumentParser, old: str, new: str) -> None:
    """Accept ``old`` (hidden from ``--help``) as a deprecated spelling of the option ``new``
    already added to ``p``: the same destination and type; using it logs a warning."""
    action = p._option_string_actions[new]
    p.add_argument(old, dest=action.dest, type=action.type, action=_DeprecatedAlias, new=new)


#: Flag hints the CLI adds to library errors (the library's messages name no flag).
_HINTS = {"DepthUnavailable": "use --depth estimated or --depth planar",
          "OutputExists": "use --overwrite to replace it"}


def _message(exc: VibrInputError) -> str:
    hint = _HINTS.get(type(exc).__name__)
    return f"{exc}; {hint}" if hint else str(exc)


#: Process settings a command needs before numba is imported, which building the parser
#: does (its choices come from the library's registries).
_BEFORE_NUMBA = {"view": oversubscribe_render_threads}


def _command_in(argv) -> str | None:
    """The subcommand named in ``argv``: its first word that is not an option (the options
    before a subcommand take no value)."""
    return next((a for a in argv if not a.startswith("-")), None)


def interrupt_on_sigterm():
    """Read SIGTERM (``kill``, a job scheduler's stop) as Ctrl-C: the command then stops as it
    does on an interrupt (workers stopped, half-written outputs removed, exit 130) instead of
    dying at once and leaving its worker processes running. Main thread only (elsewhere a
    no-op); returns the handler it replaced (None when it did nothing)."""
    def _interrupt(signum, frame):
        raise KeyboardInterrupt

    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _interrupt)


def count(n: int, noun: str) -> str:
    """'1 view', '3 views': the number and the noun, singular for one."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


#: Errors of the machine rather than of vibr (a full disk, a read-only folder): one line.
_FULL_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG}
_MACHINE_ERRNOS = _FULL_ERRNOS | {errno.EACCES, errno.EPERM}


#: Per command that compiles numba kernels, one kernel it always compiles (module, name):
#: numba's cache index of that kernel (beside the module, in ``__pycache__/*.nbi``, or where
#: NUMBA_CACHE_DIR puts it) tells whether the kernels were compiled on this machine yet.
_KERNEL_PROBES = {"demo": ("vibr.geometry.visibility", "_visibility_kernel"),
                  "render": ("vibr.geometry.visibility", "_visibility_kernel"),
                  "eval": ("vibr.geometry.visibility", "_visibility_kernel"),
                  "view": ("vibr.geometry.visibility", "_visibility_kernel"),
                  "depth": ("vibr.stereo._kernels", "box_mean_std")}


def kernels_cold(command: str) -> bool:
    """Whether ``command``'s kernels have no numba cache on this machine yet (False when that
    cannot be told: a command that compiles nothing, another numba)."""
    probe = _KERNEL_PROBES.get(command)
    if probe is None:
        return False
    try:
        kernel = getattr(importlib.import_module(probe[0]), probe[1])
        return not os.path.isfile(kernel._cache._cache_file._index_path)
    except (AttributeError, ImportError):
        return False


def _note_cold_kernels(command: str) -> None:
    """One line before the first compilation on a machine (once: the kernels are cached)."""
    if kernels_cold(command):
        print("vibr compiles its kernels on first use on this machine (once, a few minutes on 2 cores; "
              "they are cached for every later run)", file=sys.stderr)


def main(argv=None) -> int:
    setup = _BEFORE_NUMBA.get(_command_in(sys.argv[1:] if argv is None else argv))
    if setup is not None:
        setup()
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    configure_logging(verbosity(args))
    for note in getattr(args, DEPRECATED, ()):
        logger.warning(note)
    tune_malloc()
    before = interrupt_on_sigterm()
    from .. import io as vio

    vio.ALLOW_OUTSIDE_PATHS = bool(getattr(args, "allow_outside_paths", False))
    if verbosity(args) >= 0:
        _note_cold_kernels(args.command)
    try:
        return int(args.func(args) or 0)
    except VibrInputError as exc:
        print(f"vibr {args.command}: error: {_message(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"vibr {args.command}: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:  # a write outside vibr._runtime.atomic: the machine's state, not a bug
        if exc.errno not in _MACHINE_ERRNOS:
            raise
        where = f"{exc.filename}: " if exc.filename else ""
        what = "cannot write: " if exc.errno in _FULL_ERRNOS else ""  # numba's cache, a temporary file
        print(f"vibr {args.command}: error: {where}{what}{exc.strerror}", file=sys.stderr)
        return 2
    finally:
        vio.ALLOW_OUTSIDE_PATHS = False
        if before is not None:
            signal.signal(signal.SIGTERM, before)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
