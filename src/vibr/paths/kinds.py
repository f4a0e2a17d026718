"""The kinds of camera path ``vibr path KIND`` makes: a registry users extend.

A kind is a :class:`PathKind`: a name, a one-line summary, the function that makes the path,
and the options that function takes beyond those every kind takes (:class:`PathOption`,
each with its flag and help text). :func:`register_path_kind` adds one to
:data:`PATH_KINDS`; the ``vibr path`` command builds one subcommand per registered kind, with
the kind's options, so a new kind is one file: its function and one ``register_path_kind``
call (docs/how-to/extend/add-a-path-kind.md).

Every kind's function is called as ``function(scene, n_frames=..., seconds=..., fps=...,
width=..., height=..., **options)`` and returns a
:class:`~vibr.paths.camera_path.CameraPath`: ``n_frames`` or ``seconds`` (one of them None;
:func:`~vibr.paths.camera_path.frame_count` turns them into a number of frames), ``width`` /
``height`` None for the kind's default size. An option the user leaves out is not passed, so
the function's own default applies.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from ..errors import VibrInputError
from .camera_path import ROLL_MODES, CameraPath, interpolate, orbit, spiral

__all__ = ["PathKind", "PathOption", "PATH_KINDS", "RESERVED_FLAGS", "register_path_kind", "unregister_path_kind",
           "get_path_kind"]

#: The flags ``vibr path`` takes for every kind: a kind's own options may not use them.
RESERVED_FLAGS = ("-h", "--help", "-o", "--output", "--frames", "--seconds", "--fps", "--size", "--scale",
                  "--dataparser-transforms", "-q", "--quiet", "-v", "--verbose")
#: The keyword arguments every kind's function receives.
COMMON_KEYWORDS = ("n_frames", "seconds", "fps", "width", "height")


@dataclass(frozen=True)
class PathOption:
    """An option of a path kind: a command-line flag and the keyword argument it fills.

    Attributes
    ----------
    flag : str
        The flag, ``"--smooth"``; the keyword is its name with ``_`` for ``-`` (``smooth``)
        unless ``dest`` names it.
    help : str
        Help text (name the default: the function's own default applies when the flag is
        left out).
    type : callable
        Reads the value (``str``, ``int``, ``float``).
    choices : tuple, optional
        The values allowed.
    metavar : str, optional
        The value's name in the help.
    comma_list : bool
        A comma-separated list (``a,b,c`` → ``["a", "b", "c"]``; an empty list is refused).
    switch : bool
        A flag without a value: ``True`` when given.
    check : callable, optional
        ``check(value)`` raises :class:`~vibr.errors.VibrInputError` for a bad value, before
        the scene is read.
    dest : str, optional
        The keyword argument, when it is not the flag's name (``--through`` fills ``views``).
    """

    flag: str
    help: str
    type: Callable[[str], Any] = str
    choices: tuple | None = None
    metavar: str | None = None
    comma_list: bool = False
    switch: bool = False
    check: Callable[[Any], None] | None = None
    dest: str | None = None

    @property
    def keyword(self) -> str:
        return self.dest or self.flag.lstrip("-").replace("-", "_")


@dataclass(frozen=True)
class PathKind:
    """A kind of camera path (``vibr path NAME``).

    Attributes
    ----------
    name : str
        The subcommand's name.
    summary : str
        One line for ``vibr path --help``.
    function : callable
        ``function(scene, *, n_frames, seconds, fps, width, height, **options) -> CameraPath``.
    options : tuple of PathOption
        The options the function takes beyond the common ones.
    description : str
        A paragraph for ``vibr path NAME --help`` (default: the summary).
    """

    name: str
    summary: str
    function: Callable[..., CameraPath]
    options: tuple[PathOption, ...] = ()
    description: str = ""


#: The registered path kinds by name, in the order ``vibr path --help`` shows them.
PATH_KINDS: dict[str, PathKind] = {}


def register_path_kind(kind: PathKind) -> PathKind:
    """Add ``kind`` to :data:`PATH_KINDS` (replacing a kind of the same name); returns it.

    Raises ValueError when one of its options uses a flag of :data:`RESERVED_FLAGS` or a
    keyword every kind already receives (:data:`COMMON_KEYWORDS`)."""
    if not isinstance(kind, PathKind):
        raise TypeError(f"register_path_kind takes a PathKind, got {type(kind).__name__}")
    for o in kind.options:
        if o.flag in RESERVED_FLAGS or o.keyword in COMMON_KEYWORDS or not o.flag.startswith("--"):
            raise ValueError(f"path kind {kind.name!r}: option {o.flag!r} is not a free '--name' flag "
                             f"(taken: {', '.join(RESERVED_FLAGS)})")
    PATH_KINDS[kind.name] = kind
    return kind


def unregister_path_kind(name: str) -> PathKind:
    """Remove the kind ``name`` from :data:`PATH_KINDS` (tests, a plugin's teardown); returns it."""
    kind = get_path_kind(name)
    del PATH_KINDS[name]
    return kind


def get_path_kind(name: str) -> PathKind:
    """The registered :class:`PathKind` named ``name``."""
    try:
        return PATH_KINDS[name]
    except (KeyError, TypeError):
        raise VibrInputError(f"unknown path kind {name!r} (choose from {', '.join(PATH_KINDS)})") from None


def _check_smooth(value) -> None:
    if not value >= 0:
        raise VibrInputError(f"--smooth must be a number of keys >= 0, got {value}")


register_path_kind(PathKind(
    "interpolate", "a C2-smooth spline through the scene's cameras", interpolate,
    description="A C2-smooth spline through the scene's cameras: all, nearest next, or --through in that order; on "
                "a light field's grid a loop round it through its corners and the middles of its sides.",
    options=(
        PathOption("--through", "comma-separated views to pass through, in order (default: all)", comma_list=True,
                   dest="views", metavar="VIEW,..."),
        PathOption("--order", "keep the given order or reorder the views by proximity (default: proximity through "
                              "all the scene's views, the given order with --views or for the frames of a video, "
                              "from 'vibr calibrate VIDEO': time order)", choices=("given", "proximity")),
        PathOption("--roll", "how the key cameras are turned about their axes: "
                             + "; ".join(f"{k}: {v}" for k, v in ROLL_MODES.items()) + " (default: snap)",
                   choices=tuple(ROLL_MODES)),
        PathOption("--smooth", "smooth the key cameras along the path first, a Gaussian of SIGMA keys (e.g. 2 for "
                               "the frames of a hand-held video: the path no longer follows the hand's sway, and "
                               "passes near the photographs rather than through them; default: through them)",
                   type=float, metavar="SIGMA", check=_check_smooth),
    )))
register_path_kind(PathKind(
    "orbit", "an ellipse around the point the cameras look at", orbit,
    description="An ellipse around the point the cameras look at, at their mean height and distance; an arc swept "
                "back and forth when the cameras do not surround it.",
    options=(PathOption("--full", "a full turn even when the cameras cover an arc", switch=True),)))
register_path_kind(PathKind(
    "spiral", "an LLFF-style forward-facing spiral around the mean camera", spiral,
    description="An LLFF-style forward-facing spiral around the mean camera."))
