"""Write files atomically: to a temporary name in the same folder, then rename."""

from __future__ import annotations

import contextlib
import os
import tempfile

#: temporary files of the writes in progress in this process (:func:`remove_partial`)
_ACTIVE: set = set()


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path beside ``path``; on success rename it to ``path``.

    On an exception the temporary file is removed and ``path`` is left untouched, so a
    failed command never leaves a partial output file. ``suffix`` defaults to the
    extension of ``path`` so that writers choosing a format by extension still work.
    """
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    if suffix is None:
        suffix = os.path.splitext(path)[1]
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".part" + suffix, dir=folder)
    os.close(fd)
    _ACTIVE.add(tmp)
    try:
        yield tmp
        # mkstemp makes the file private (0600); give it the mode a plain open() would
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise
    finally:
        _ACTIVE.discard(tmp)


def remove_partial() -> None:
    """Remove the temporary files of this process's writes in progress: for a process about
    to end without unwinding its stack (a signal handler followed by ``os._exit``)."""
    for tmp in list(_ACTIVE):
        with contextlib.suppress(OSError):
            os.remove(tmp)
