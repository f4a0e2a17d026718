"""pycolmap, imported without changing how the process answers SIGTERM.

pycolmap starts Google's glog when it is first imported, and glog installs its failure
signal handler, SIGTERM included: a ``kill`` then prints a C++ stack trace and ends the
process at once, without the ``finally`` blocks that stop worker processes and remove
half-written files (the ``vibr`` command reads SIGTERM as Ctrl-C: docs/reference/errors-and-limits.md,
"Interrupted jobs"). Seen with ``vibr calibrate`` stopped by SIGTERM (exit -15, a stack
trace, its work folder left in /tmp). :func:`import_pycolmap` gives SIGTERM back the
handler it had before the import.
"""

from __future__ import annotations

import signal
import threading

__all__ = ["import_pycolmap"]


def import_pycolmap():
    """``import pycolmap``, the process's SIGTERM handler kept (main thread; elsewhere the
    handler cannot be set and the import is plain)."""
    import sys

    if "pycolmap" in sys.modules or threading.current_thread() is not threading.main_thread():
        import pycolmap

        return pycolmap
    before = signal.getsignal(signal.SIGTERM)
    try:
        import pycolmap
    finally:
        if before is not None:  # None: a handler Python did not install; nothing to restore
            signal.signal(signal.SIGTERM, before)
    return pycolmap
