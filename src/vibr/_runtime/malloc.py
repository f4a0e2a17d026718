"""glibc malloc settings for the processes vibr owns (the CLI, its worker processes).

A render allocates and frees tens of arrays of 1–200 MB (sample fields, stencils, image
planes). glibc serves a block above its mmap threshold (adaptive: 128 KiB at start, raised
to at most 32 MiB as blocks are freed) with a fresh ``mmap``, and unmaps it again at
``free``: every page of every such array is then faulted in and zeroed by the kernel, once
per use. Frame after frame of a fly-through this is the same work again. Keeping those
blocks in the heap (mmap threshold 256 MiB) and not returning the heap's free top to the
kernel below 2 GiB (trim threshold) lets the next frame reuse the pages (measured with
``benchmarks/perf/bench_malloc.py``: docs/explanation/performance.md). The trim threshold is above what a
viewer's 768² render frees at the top of the heap (about 600 MiB): below it, glibc gave that
back and the next render faulted it in again (docs/explanation/viewer.md, "The heap's top").

Those settings hold for glibc's main heap only. A thread other than the main one (the
viewer's render worker) gets an arena of its own, whose heaps are at most 64 MiB: a larger
array is mapped and unmapped on every use whatever the threshold. One arena
(``M_ARENA_MAX`` 1) gives every thread the main heap; the few allocations numba's threads
make inside kernels then share its lock. Both measured with
``benchmarks/perf/bench_view.py --ab-arena`` and bench_render (docs/explanation/performance.md). The
user's ``MALLOC_ARENA_MAX`` is kept when set.

Only for processes vibr starts (a library should not change its host's allocator): the
``vibr`` command calls :func:`tune_malloc` first thing, and so do the worker processes of
:mod:`vibr.executor`. It does nothing on a C library other than glibc, where the user set
glibc's own variables (``MALLOC_MMAP_THRESHOLD_``, ``MALLOC_TRIM_THRESHOLD_``,
``GLIBC_TUNABLES``: Dask's nanny sets the trim threshold in its workers), or with
``VIBR_MALLOC=default``.
"""

from __future__ import annotations

import ctypes
import logging
import os
import platform

logger = logging.getLogger(__name__)

__all__ = ["ARENA_MAX", "MMAP_THRESHOLD", "TRIM_THRESHOLD", "tune_malloc"]

#: glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_M_ARENA_MAX = -8
#: blocks below this come from the heap (bytes)
MMAP_THRESHOLD = 256 * 2 ** 20
#: free memory at the top of the heap kept below this (bytes): the largest value glibc's
#: ``mallopt`` takes (a C int), so that a process rendering view after view keeps the pages
#: of its working set (about 600 MiB above the rest of the heap in a viewer's 768² render)
TRIM_THRESHOLD = 2 ** 31 - 1
#: malloc arenas: one, so that every thread allocates from the heap the thresholds govern
ARENA_MAX = 1
_USER_VARS = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES")

_done: bool | None = None


def tune_malloc() -> bool:
    """Raise glibc's mmap and trim thresholds for this process (module doc); True if set.

    Idempotent; a no-op (False) off glibc, with ``VIBR_MALLOC=default``, or where the
    environment already sets glibc's malloc variables."""
    global _done
    if _done is not None:
        return _done
    _done = False
    if os.environ.get("VIBR_MALLOC", "").strip().lower() in ("default", "0", "off", "no"):
        logger.debug("malloc: left at glibc's defaults (VIBR_MALLOC)")
        return False
    user = [v for v in _USER_VARS if v in os.environ]
    if user:
        logger.debug("malloc: left as set by %s", ", ".join(user))
        return False
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        ok = (libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
              and libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1)
        if ok and "MALLOC_ARENA_MAX" not in os.environ:
            ok = libc.mallopt(_M_ARENA_MAX, ARENA_MAX) == 1
    except (OSError, AttributeError):
        return False
    _done = bool(ok)
    logger.debug("malloc: mmap threshold %d MiB, trim threshold %d MiB, arenas %s: %s", MMAP_THRESHOLD >> 20,
                 (TRIM_THRESHOLD + 1) >> 20, os.environ.get("MALLOC_ARENA_MAX", ARENA_MAX), "set" if ok else "refused")
    return _done
