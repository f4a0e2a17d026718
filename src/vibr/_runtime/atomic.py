"""Write files atomically: to a temporary name in the same folder, then rename."""

from __future__ import annotations

import contextlib
import os
import secrets

from ..errors import OutputFailed, VibrInputError

#: temporary files of the writes in progress in this process (:func:`remove_partial`)
_ACTIVE: set = set()


def _new_temporary(folder: str, base: str, suffix: str) -> str:
    """Create an empty private file ``.BASE.RANDOM.partSUFFIX`` in ``folder``, registered in
    ``_ACTIVE`` *before* it exists: a signal handler calling :func:`remove_partial` at any
    moment then finds it (with ``tempfile.mkstemp`` the name was known only once the file
    existed, and a SIGTERM in between left it behind)."""
    for _ in range(100):
        tmp = os.path.join(folder, f".{base}.{secrets.token_hex(8)}.part{suffix}")
        _ACTIVE.add(tmp)
        try:
            fd = os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
        except FileExistsError:
            _ACTIVE.discard(tmp)  # someone else's file: never ours to remove
            continue
        except BaseException:
            _ACTIVE.discard(tmp)
            raise
        os.close(fd)
        return tmp
    raise FileExistsError(f"{folder}: no free temporary name for {base}")


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path beside ``path``; on success rename it to ``path``.

    On an exception the temporary file is removed and ``path`` is left untouched, so a
    failed command never leaves a partial output file. ``suffix`` defaults to the
    extension of ``path`` so that writers choosing a format by extension still work.
    """
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if suffix is None:
        suffix = os.path.splitext(path)[1]
    try:
        os.makedirs(folder, exist_ok=True)
        tmp = _new_temporary(folder, os.path.basename(path), suffix)
    except OSError as exc:
        raise write_failed(exc, path) from exc
    try:
        yield tmp
        # the temporary file is private (0600); give it the mode a plain open() would
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        if isinstance(exc, OSError) and not isinstance(exc, VibrInputError):
            raise write_failed(exc, path) from exc
        raise
    finally:
        _ACTIVE.discard(tmp)


def _umask() -> int:
    """The process's umask (read by setting it, then set back)."""
    umask = os.umask(0)
    os.umask(umask)
    return umask


def temporary_folder(parent, name: str) -> str:
    """Create a folder ``.NAME.RANDOM.part`` in ``parent`` to be renamed to ``NAME`` once
    complete, with the mode a plain ``mkdir`` would give it (``tempfile.mkdtemp`` makes it
    private, 0700, and the renamed output stayed unreadable to the user's group)."""
    import tempfile

    tmp = tempfile.mkdtemp(prefix=f".{name}.", suffix=".part", dir=parent)
    os.chmod(tmp, 0o777 & ~_umask())
    return tmp


def write_failed(exc: OSError, path) -> OutputFailed:
    """The one-line error for an output that could not be written: the system's reason
    (``No space left on device``, ``Read-only file system``, ...), or, for a short write
    that set no error number (numpy's ``tofile``), the free space left."""
    reason = exc.strerror or str(exc)
    if not exc.strerror:
        import shutil

        with contextlib.suppress(OSError):
            free = shutil.disk_usage(os.path.dirname(os.path.abspath(path)) or ".").free
            reason += f"; {free / 2**20:.1f} MiB free on its disk"
    return OutputFailed(f"cannot write: {reason}", path)


def remove_partial() -> None:
    """Remove the temporary files of this process's writes in progress: for a process about
    to end without unwinding its stack (a signal handler followed by ``os._exit``)."""
    for tmp in list(_ACTIVE):
        with contextlib.suppress(OSError):
            os.remove(tmp)
