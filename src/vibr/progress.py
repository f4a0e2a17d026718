"""Progress bars (tqdm) that the CLI's ``--quiet`` switches off globally."""

from __future__ import annotations

import sys

from tqdm.auto import tqdm

_QUIET = False


def set_quiet(quiet: bool) -> None:
    global _QUIET
    _QUIET = bool(quiet)


def is_quiet() -> bool:
    return _QUIET


def progress(iterable=None, *, desc: str | None = None, total: int | None = None, **kw):
    """A tqdm bar on stderr; disabled by ``--quiet`` (:func:`set_quiet`)."""
    return tqdm(iterable, desc=desc, total=total, disable=_QUIET, file=sys.stderr,
                leave=False, dynamic_ncols=True, **kw)


def log(msg: str) -> None:
    """A status line on stderr unless quiet."""
    if not _QUIET:
        print(msg, file=sys.stderr, flush=True)
