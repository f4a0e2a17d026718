"""The dataset formats :func:`vibr.io.load_scene` reads: a registry users extend.

A format is a :class:`Format`: a name, a one-line summary, ``detect(path) -> bool`` (whether
``path``, a file or a folder, is a scene of this format) and ``load(path, *, scale, views,
**options) -> Scene``. :func:`register_format` adds one to :data:`FORMATS`;
:func:`vibr.io.detect_format` asks the registered formats in increasing ``priority`` (ties
in the order they were registered) and takes the first that says yes. The built-in formats
register themselves beside their loaders (:mod:`vibr.io.transforms`, :mod:`vibr.io.hci`,
:mod:`vibr.io.colmap`, :mod:`vibr.io.middlebury`, :mod:`vibr.io.strecha`, priorities 10 to
50, in that order); a format registered with the default priority (100) is asked after them,
one with a lower priority before them. docs/how-to/extend/add-a-format.md shows a complete
example.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..errors import VibrInputError
from ..scene import Scene

__all__ = ["Format", "FORMATS", "register_format", "unregister_format", "get_format"]


@dataclass(frozen=True)
class Format:
    """A dataset format :func:`vibr.io.load_scene` detects and reads.

    Attributes
    ----------
    name : str
        Short name (``"transforms"``, ``"hci"``, ...): the key in :data:`FORMATS`.
    summary : str
        What a user knows the format by, for help texts (``"COLMAP sparse model"``).
    detect : callable
        ``detect(path: Path) -> bool``: whether ``path`` (an existing file or folder) is a
        scene of this format. Cheap: it looks at names, not at contents.
    load : callable
        ``load(path: Path, *, scale: float, views, **options) -> Scene``, ``path`` as the
        user gave it, ``scale`` already checked, ``views`` as :func:`vibr.io.load_scene`
        takes them (:func:`vibr.io.select_entries` reads them), ``options`` among
        :attr:`options`.
    looks_for : str
        What :attr:`detect` looks for, for the error when no format recognises a folder
        ("a COLMAP sparse model"); empty: not named there.
    options : tuple of str
        The keyword options :attr:`load` takes beyond ``scale`` and ``views``; any other is
        refused before loading. ``"allow_outside"`` receives
        :func:`vibr.io.load_scene`'s ``allow_outside``.
    priority : int
        Formats are asked in increasing priority (the built-ins: 10 to 50; default 100).
    """

    name: str
    summary: str
    detect: Callable[[Path], bool]
    load: Callable[..., Scene]
    looks_for: str = ""
    options: tuple[str, ...] = ()
    priority: int = 100


#: The registered formats by name, in the order :func:`vibr.io.detect_format` asks them.
FORMATS: dict[str, Format] = {}
_ORDER: dict[str, int] = {}  # registration order, for ties in priority
_COUNT = itertools.count()


def _sort() -> None:
    items = sorted(FORMATS.values(), key=lambda f: (f.priority, _ORDER[f.name]))
    FORMATS.clear()
    FORMATS.update((f.name, f) for f in items)


def register_format(fmt: Format) -> Format:
    """Add ``fmt`` to :data:`FORMATS` (replacing a format of the same name); returns it."""
    if not isinstance(fmt, Format):
        raise TypeError(f"register_format takes a Format, got {type(fmt).__name__}")
    _ORDER.setdefault(fmt.name, next(_COUNT))
    FORMATS[fmt.name] = fmt
    _sort()
    return fmt


def unregister_format(name: str) -> Format:
    """Remove the format ``name`` from :data:`FORMATS` (tests, a plugin's teardown); returns it."""
    fmt = get_format(name)
    del FORMATS[name]
    _ORDER.pop(name, None)
    return fmt


def get_format(name: str) -> Format:
    """The registered :class:`Format` named ``name``."""
    try:
        return FORMATS[name]
    except (KeyError, TypeError):
        raise VibrInputError(f"unknown scene format {name!r} (choose from {', '.join(FORMATS)})") from None
