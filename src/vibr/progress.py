"""Progress of long stages: a tqdm bar on a terminal, one log line per stage otherwise.

The library reports through the standard :mod:`logging` module: every module logs on its
own ``logging.getLogger(__name__)``, children of the ``"vibr"`` logger, and never prints.
An application chooses what to see by configuring that logger (the ``vibr`` command line
installs a stderr handler at WARNING with ``-q``, INFO by default, DEBUG with ``-v``:
:func:`configure_logging`).

:func:`progress` draws a bar only when stderr is a terminal and the ``"vibr"`` logger shows
INFO; otherwise (a log file, a pipe, a notebook capturing stderr, ``-q``) it draws nothing
and logs one line when the stage ends, so a redirected stderr never fills with
carriage-return frames; a stage that has run :data:`LONG_S` also logs its count and the time
left (at the pace after the first update), at most once per :data:`EVERY_S`. A stage that starts while another is open (each view's
depth inside "depth views") logs its end at DEBUG: the outer stage's line already says how far
the work is, and a log should not fill with one line per view; a long one still says how far
it is.
"""

from __future__ import annotations

import logging
import sys
import threading
import time

from tqdm import tqdm

__all__ = ["progress", "configure_logging", "duration_text", "LOGGER_NAME"]

LOGGER_NAME = "vibr"
logger = logging.getLogger(LOGGER_NAME)

#: A stage without a bar says how far it is once it has run this long (s), then at most
#: once per :data:`EVERY_S`: a redirected stderr otherwise shows nothing for hours.
LONG_S = 10.0
EVERY_S = 60.0
#: Updates within this time (s) of the first count with it: the time left is taken at the pace
#: after that first batch.
FIRST_BATCH_S = 1.0


def duration_text(seconds: float) -> str:
    """``"42 s"``, ``"7 min"`` or ``"8.7 h"``: a duration as a person reads it."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


# the number of stages open now, process-wide (a view's stage may run on a worker thread
# of the outer one)
_open = [0]
_open_lock = threading.Lock()


def _bars_wanted() -> bool:
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(isatty and isatty()) and logger.isEnabledFor(logging.INFO)


class _StageLine:
    """tqdm's interface without drawing: one INFO line when the stage closes."""

    def __init__(self, iterable=None, desc=None, total=None):
        self.iterable, self.desc, self.n = iterable, desc, 0
        if total is None and iterable is not None and hasattr(iterable, "__len__"):
            total = len(iterable)
        self.total = total
        self._t0 = time.perf_counter()
        self._said = -float("inf")
        self._first = None  # (time, count) at the first update
        self._closed = False
        with _open_lock:
            self._level = logging.DEBUG if _open[0] else logging.INFO
            _open[0] += 1

    def __iter__(self):
        try:
            for x in self.iterable:
                yield x
                self.n += 1
        finally:
            self.close()

    def __len__(self):
        return self.total if self.total is not None else len(self.iterable)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def update(self, n=1):
        self.n += n
        now = time.perf_counter()
        if self._first is None or now - self._first[0] < FIRST_BATCH_S:
            # items finishing together (views estimated side by side) are one first batch
            self._first = (now if self._first is None else self._first[0], self.n)
        if (self.total and 0 < self.n < self.total and now - self._t0 >= LONG_S
                and now - self._said >= EVERY_S):
            self._said = now
            el = now - self._t0
            t1, n1 = self._first
            # the time left from the pace after the first update: the first item also paid
            # the one-off costs (compiling kernels, starting workers), 35 s of the first 47 s
            # of templeSparseRing's depth, whose first line said "about 12 min left" for 51 s
            left = f", about {duration_text((now - t1) * (self.total - self.n) / (self.n - n1))} left" \
                if self.n > n1 else ""
            logger.info("%s: %d/%d in %s%s", self.desc or "progress", self.n, self.total, duration_text(el), left)

    def set_postfix(self, *args, **kw):
        pass

    def set_postfix_str(self, *args, **kw):
        pass

    def set_description(self, desc=None, refresh=True):
        self.desc = desc

    def refresh(self, *args, **kw):
        pass

    def write(self, s, *args, **kw):
        logger.info("%s", s)

    def close(self):
        if self._closed:
            return
        self._closed = True
        with _open_lock:
            _open[0] -= 1
        of = f"/{self.total}" if self.total is not None else ""
        logger.log(self._level, "%s: %d%s in %.1f s", self.desc or "done", self.n, of,
                   time.perf_counter() - self._t0)


def progress(iterable=None, *, desc: str | None = None, total: int | None = None, **kw):
    """A progress bar over ``iterable`` (or a manual one with ``total``, ``update()`` and
    ``close()``): tqdm on stderr when it is a terminal and INFO is shown, else one log line
    ``"desc: n/total in t s"`` when the stage ends."""
    if _bars_wanted():
        return tqdm(iterable, desc=desc, total=total, file=sys.stderr, leave=False,
                    dynamic_ncols=True, **kw)
    return _StageLine(iterable, desc, total)


def configure_logging(verbosity: int = 0, stream=None) -> logging.Handler:
    """Show the ``"vibr"`` logger's records on ``stream`` (stderr): WARNING and above when
    ``verbosity < 0`` (quiet), INFO when 0, DEBUG when > 0. Replaces a handler installed by
    an earlier call; returns the handler. For applications (the CLI): the library itself
    never configures logging."""
    level = logging.WARNING if verbosity < 0 else logging.INFO if verbosity == 0 else logging.DEBUG
    for h in list(logger.handlers):
        if getattr(h, "_vibr_cli", False):
            logger.removeHandler(h)
    handler = logging.StreamHandler(stream if stream is not None else sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    handler._vibr_cli = True
    logger.addHandler(handler)
    logger.setLevel(level)
    logger.propagate = False
    return handler
