"""Render threads for a viewer that shares its machine with the browser showing it.

numba's parallel loops split their iterations into equal parts, one per thread, fixed in
advance (libgomp's static schedule). When another process takes part of one core, the
thread on that core finishes last and every loop waits for it. Linux's autogroup
scheduling can make this worse: a browser's drawing process in a session of its own is
weighed against the whole render process, not against the one render thread beside it. A
browser without a GPU draws the viewer's page in software on the same cores, in bursts
after every message it receives.

With twice as many numba threads as cores, each with half the work, the operating system
can run the share of a delayed thread on the other core. Threads that outnumber the cores
must sleep at a loop's end (OpenMP's passive wait policy), not spin on a core another
thread needs. A render's result does not depend on the thread count (tested bit for bit).
Measurements: docs/explanation/viewer.md, "Render threads".

Only for processes vibr starts (``vibr view``, the viewer's benchmark), and only before
numba is imported: numba reads ``NUMBA_NUM_THREADS`` when it is imported, libgomp reads
``OMP_WAIT_POLICY`` when it is loaded. The ``vibr`` command therefore calls
:func:`oversubscribe_render_threads` before it builds its parser, whose choices come from
the library's registries (which import numba).
"""

from __future__ import annotations

import os
import sys

__all__ = ["THREADS_PER_CORE", "oversubscribe_render_threads", "cores"]

#: numba threads per core in a ``vibr view`` process
THREADS_PER_CORE = 2


def cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS tells): numba's own
    default thread count."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def oversubscribe_render_threads(per_core: int = THREADS_PER_CORE) -> int:
    """Ask numba for ``per_core`` threads per core, waiting passively (module doc).

    Call before numba is imported. The user's ``NUMBA_NUM_THREADS`` and ``OMP_WAIT_POLICY``
    are kept when set; once numba is imported nothing changes. Returns the number of threads
    numba starts (every kernel of the process runs on all of them unless its thread asks
    for fewer with ``numba.set_num_threads``).
    """
    if "numba" in sys.modules:
        return int(sys.modules["numba"].config.NUMBA_NUM_THREADS)
    if "NUMBA_NUM_THREADS" not in os.environ:
        os.environ["NUMBA_NUM_THREADS"] = str(max(1, per_core) * cores())
        os.environ.setdefault("OMP_WAIT_POLICY", "passive")
    return int(os.environ["NUMBA_NUM_THREADS"])
