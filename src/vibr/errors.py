"""Errors raised on bad input, and the one a render raises when told to stop.

Every problem with user data (a missing file, an unreadable image, bad depth, a
malformed camera) raises :class:`VibrInputError`, whose message is one line naming
the file and the problem. The CLI prints that line and exits with status 2.
:class:`RenderStopped` is not an error of the input: a render whose ``stop()`` returned
True (:func:`vibr.render.render`) ends with it.
"""

from __future__ import annotations

import math
import numbers
import os


class VibrInputError(ValueError):
    """Bad input data: the message names the file (when there is one) and the problem."""

    def __init__(self, problem: str, path: str | os.PathLike | None = None):
        self.path = None if path is None else os.fspath(path)
        self.problem = " ".join(str(problem).split())  # always one line
        super().__init__(self.problem if self.path is None else f"{self.path}: {self.problem}")


class OutputExists(VibrInputError):
    """An output that exists and is not to be replaced (``overwrite=False``)."""


class OutputFailed(VibrInputError, OSError):
    """An output that could not be written: the disk is full, the folder read-only or not
    ours (the message names the file and the system's reason). Also an :class:`OSError`,
    so that writers of optional files (the caches) that skip a failed write still do."""


class RenderStopped(Exception):
    """A render ended early because its ``stop()`` said so (:func:`vibr.render.render`'s
    ``stop``: a viewer whose camera has moved on)."""


def check_stop(stop) -> None:
    """Raise :class:`RenderStopped` when ``stop`` (a callable or None) returns True."""
    if stop is not None and stop():
        raise RenderStopped()


def require_file(path: str | os.PathLike) -> str:
    """Return ``path`` as a string, or raise :class:`VibrInputError` if it is not a file."""
    p = os.fspath(path)
    if not os.path.exists(p):
        raise VibrInputError("file not found", p)
    if not os.path.isfile(p):
        raise VibrInputError("not a regular file", p)
    return p


# ------------------------------------------------------------------ value checks
def check_real(name: str, v, *, lo: float | None = None, lo_open: bool = False, hi: float | None = None,
          none_ok: bool = False) -> None:
    if v is None and none_ok:
        return
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise VibrInputError(f"{name} must be a number, got {v!r}")
    x = float(v)
    if not math.isfinite(x):
        raise VibrInputError(f"{name} must be finite, got {x}")
    if lo is not None and (x <= lo if lo_open else x < lo):
        raise VibrInputError(f"{name} must be {'>' if lo_open else '>='} {lo:g}, got {x:g}")
    if hi is not None and x > hi:
        raise VibrInputError(f"{name} must be <= {hi:g}, got {x:g}")


def check_int(name: str, v, *, lo: int, none_ok: bool = False) -> None:
    if v is None and none_ok:
        return
    if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(float(v)) or int(v) != v:
        raise VibrInputError(f"{name} must be an integer, got {v!r}")
    if v < lo:
        raise VibrInputError(f"{name} must be >= {lo}, got {int(v)}")

