"""Output paths: checked before the work, and replaced only when vibr wrote them.

Two rules keep a command from losing the user's data or time:

* :func:`check_output` is called by every subcommand on each of its outputs (``-o``,
  ``--json``, ``--figures``, an output folder) *before* loading or computing anything: an
  empty name, a folder where a file is expected (or the reverse), a missing parent folder or
  one vibr cannot write to is a one-line :class:`~vibr.errors.VibrInputError` at once, not
  a traceback after the computation.
* A folder written by vibr holds a marker file :data:`MARKER` (JSON) listing every file vibr
  wrote there. :func:`replace_folder` replaces an existing output folder only when it has
  that marker and holds nothing else than the files the marker lists (and empty folders),
  and never when it is, or contains, one of the command's inputs. Anything else is refused:
  ``--overwrite`` never deletes what vibr did not write.
* A single output file (``render -o``, ``path -o``, ``eval --json``, a video) is vibr's when
  the marker of its folder lists its name with the SHA-256 of its content
  (:func:`record_file`, :func:`written_by_vibr`): a file changed since is no longer vibr's.
  :func:`check_output` refuses an existing file that is not vibr's unless ``overwrite``.
* A folder of fly-through frames (:func:`check_frames_folder`) holds the marker and the
  frames and σ maps vibr writes; a folder holding anything else is refused unless
  ``overwrite``.
"""

from __future__ import annotations

import contextlib
import fnmatch
import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path

from ..errors import OutputExists, VibrInputError

#: Name of the marker file vibr writes into every output folder it creates.
MARKER = ".vibr-output"


def _probe_writable(folder: Path, path) -> None:
    """Create and remove a temporary file in ``folder`` (os.access is wrong for root and
    read-only mounts)."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=".vibr-probe.", dir=folder)
    except OSError as exc:
        raise VibrInputError(f"cannot write in folder {folder} ({exc.strerror or 'permission denied'})",
                             path) from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.remove(tmp)


def check_output(path, kind: str = "file", *, overwrite: bool = True, what: str = "output") -> Path:
    """Check that ``path`` can be written, before any work is done.

    Parameters
    ----------
    path : str or Path
        The output file or folder.
    kind : {"file", "dir"}
        ``"file"``: ``path`` must not be a folder; its parent folder must exist and be
        writable; a symbolic link there, even to nothing, is an existing file. ``"dir"``:
        ``path`` must not be a file; an existing folder is accepted only with ``overwrite``
        (its replacement is then checked by :func:`check_replaceable`); its parent must
        exist and be writable. Either is refused when named :data:`MARKER`.
    overwrite : bool
        Whether an existing output may be replaced. A file vibr wrote (:func:`written_by_vibr`)
        may always be replaced; a folder never without ``overwrite``.
    what : str
        Name of the output in messages (``"-o"``, ``"--json"``).

    Returns
    -------
    Path
        ``path`` as a Path.

    Raises
    ------
    VibrInputError
        One line naming the path and the problem.
    """
    if kind not in ("file", "dir"):
        raise ValueError(f"kind must be 'file' or 'dir', got {kind!r}")
    if path is None or not str(os.fspath(path)).strip():
        raise VibrInputError(f"{what}: the output name is empty")
    p = Path(os.fspath(path))
    if p.name == MARKER:  # record_file would write the marker over the output
        raise VibrInputError(f"{what}: {MARKER} is the name of vibr's marker file; choose another name", p)
    if kind == "file":
        if p.is_dir():
            raise VibrInputError(f"{what} is a folder, a file name is expected", p)
        if os.path.lexists(p) and not overwrite and not written_by_vibr(p):  # a link to nothing too
            raise OutputExists(f"{what} already exists and vibr did not write it", p)
        if str(os.fspath(path)).endswith(("/", os.sep)):
            raise VibrInputError(f"{what} ends with a path separator, a file name is expected", p)
    else:
        if os.path.lexists(p) and not p.is_dir():
            raise VibrInputError(f"{what} exists and is not a folder", p)
        if p.is_dir() and not overwrite:
            raise OutputExists(f"{what} folder already exists", p)
    parent = p.absolute().parent
    if not parent.exists():
        raise VibrInputError(f"{what}: parent folder {parent} does not exist", p)
    if not parent.is_dir():
        raise VibrInputError(f"{what}: {parent} is not a folder", p)
    _probe_writable(parent, p)
    if kind == "dir" and p.is_dir():
        _probe_writable(p, p)
    return p


# ----------------------------------------------------------------------------- marker
def write_marker(folder, files=None, sha256=None) -> None:
    """Write the marker into ``folder`` listing ``files`` (relative paths); by default every
    file now under ``folder`` (use only on a folder vibr has just created). ``sha256``:
    name → digest of the single files vibr wrote there (:func:`record_file`)."""
    folder = Path(folder)
    if files is None:
        files = [f.relative_to(folder).as_posix() for f in sorted(folder.rglob("*"))
                 if f.is_file() and f.name != MARKER]
    doc = {"written_by": "vibr", "files": sorted(set(files))}
    if sha256:
        doc["sha256"] = dict(sorted(sha256.items()))
    with open(folder / MARKER, "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=1)
        fh.write("\n")


def _read_marker_doc(folder) -> dict | None:
    try:
        with open(Path(folder) / MARKER, encoding="utf-8") as fh:
            doc = json.load(fh)
        if doc.get("written_by") != "vibr" or not isinstance(doc["files"], list):
            return None
        return doc
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def read_marker(folder) -> set[str] | None:
    """The files listed by ``folder``'s marker, or None when it has no valid marker."""
    doc = _read_marker_doc(folder)
    return None if doc is None else {str(f) for f in doc["files"]}


# ----------------------------------------------------------------------------- single files
def file_digest(path) -> str:
    """SHA-256 of a file's content (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def written_by_vibr(path) -> bool:
    """Whether the file ``path`` is one vibr wrote: its folder's marker lists its name with
    the SHA-256 of its present content (:func:`record_file`)."""
    p = Path(path)
    if not p.is_file() or p.is_symlink():
        return False
    doc = _read_marker_doc(p.absolute().parent)
    sha = (doc or {}).get("sha256")
    if not isinstance(sha, dict) or p.name not in sha:
        return False
    try:
        return file_digest(p) == sha[p.name]
    except OSError:
        return False


@contextlib.contextmanager
def _locked(folder: Path):
    """An exclusive lock on ``folder``'s marker (POSIX ``flock``; none elsewhere): two vibr
    commands writing into one folder do not lose each other's entries."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    fd = os.open(folder / MARKER, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


def record_file(path) -> None:
    """Note in the marker of ``path``'s folder that vibr wrote this file (its name and the
    SHA-256 of its content), so that a later command may replace it without ``--overwrite``.
    A folder that cannot take the marker is left as it is (the file is then not vibr's)."""
    p = Path(path).absolute()
    folder = p.parent
    try:
        digest = file_digest(p)
        with _locked(folder):
            doc = _read_marker_doc(folder) or {}
            files = set(doc.get("files", [])) | {p.name}
            sha = dict(doc.get("sha256") or {}, **{p.name: digest})
            write_marker(folder, files, sha)
    except OSError:
        pass


def _inside(a: Path, b: Path) -> bool:
    """Whether ``a`` is ``b`` or lies inside ``b`` (both resolved)."""
    return a == b or b in a.parents


def check_not_input(out, inputs=()) -> None:
    """Refuse an output folder that is, or contains, one of ``inputs`` (paths of the scene
    the command reads)."""
    o = Path(out).resolve()
    for i in inputs:
        if i is None:
            continue
        ip = Path(i).resolve()
        if _inside(ip, o):
            raise VibrInputError(f"the output folder {'is' if ip == o else 'contains'} the input {ip}: "
                                 "choose an output folder outside the scene", out)


#: Files a scene folder of each format may hold besides its images (vibr.io's loaders).
_SCENE_FILE_GLOBS = ("transforms*.json", "*_par.txt", "*_ang.txt", "parameters.cfg", "gt_*.pfm", "*.camera",
                     "*.geometric.bin", "cameras.*", "images.bin", "images.txt", "points3D.*", "frames.*",
                     "rigs.*", "sparse_pc.ply")


def is_scene_file(path, scene) -> bool:
    """Whether the existing file ``path`` is one ``scene`` was, or may have been, read from:
    one of its views' images, or, inside its folder, a file a scene format reads (by name:
    definitions, cameras, depth maps; a generous list)."""
    import fnmatch

    p = Path(path).resolve()
    if not p.is_file():
        return False
    if any(v.path and Path(v.path).resolve() == p for v in scene.views):
        return True
    for key in ("transforms", "par_file"):
        if scene.meta.get(key) and Path(scene.meta[key]).resolve() == p:
            return True
    roots = [Path(r).resolve() for r in (scene.root, scene.meta.get("model")) if r]
    if not any(_inside(p, r) for r in roots):
        return False
    if any(fnmatch.fnmatch(p.name, g) for g in _SCENE_FILE_GLOBS) or p.parent.name in ("depth", "sigma_z"):
        return True
    return p in _transforms_references(scene.meta.get("transforms"))


def _transforms_references(tf) -> set:
    """The files a transforms.json names (images, depth, sigma_z, masks, points), resolved."""
    if not tf:
        return set()
    try:
        with open(tf, encoding="utf-8-sig") as f:
            doc = json.load(f)
        base = Path(tf).parent
        refs = [fr.get(k) for fr in doc.get("frames", []) for k in fr if k.endswith("_path")]
        refs += [v for k, v in doc.items() if k.endswith("_path")]
        return {(base / r).resolve() for r in refs if isinstance(r, str)}
    except (OSError, ValueError, AttributeError):
        return set()


def check_not_scene_file(out, scene, what: str = "-o") -> None:
    """Refuse an output file that is one of the files ``scene`` was read from
    (:func:`is_scene_file`): ``vibr eval SCENE --json SCENE/transforms.json`` replaced the
    scene's cameras with a report."""
    if out is not None and is_scene_file(out, scene):
        raise VibrInputError(f"{what} would overwrite a file of the input scene: choose another name", out)


def check_replaceable(out) -> None:
    """Refuse to replace ``out`` unless vibr wrote it and it holds only vibr's files."""
    out = Path(out)
    listed = read_marker(out)
    if listed is None:
        raise VibrInputError(f"not replaced: the folder was not written by vibr (no {MARKER} marker); "
                             "remove it yourself or choose another output folder", out)
    for f in sorted(out.rglob("*")):
        rel = f.relative_to(out).as_posix()
        if f.is_dir() and not f.is_symlink():
            continue
        if rel != MARKER and rel not in listed:
            raise VibrInputError(f"not replaced: the folder holds {rel}, which vibr did not write; "
                                 "move it away or choose another output folder", out)


def replace_folder(tmp, out, *, overwrite: bool) -> None:
    """Move the complete new folder ``tmp`` (with its marker) to ``out``.

    An existing ``out`` is replaced only with ``overwrite`` and when
    :func:`check_replaceable` accepts it; the old folder is removed only after the new one
    is in place.
    """
    tmp, out = Path(tmp), Path(out)
    if not (tmp / MARKER).is_file():
        write_marker(tmp)
    if out.exists() or out.is_symlink():
        if not overwrite:
            raise OutputExists("output folder already exists", out)
        if out.is_symlink() or not out.is_dir():
            raise VibrInputError("output path exists and is not a folder", out)
        check_replaceable(out)
        trash = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.absolute().parent))
        os.replace(out, trash / "old")
        os.replace(tmp, out)
        shutil.rmtree(trash, ignore_errors=True)
    else:
        os.replace(tmp, out)


# ----------------------------------------------------------------------------- frames folders
def check_frames_folder(folder, owned, *, overwrite: bool, what: str = "frames folder") -> None:
    """Refuse, before the work, a folder of numbered outputs (a fly-through's frames) that
    holds files vibr did not write, unless ``overwrite``.

    ``owned(path)`` says whether a file with one of the names the command writes is vibr's
    (True / False: a frame with or without vibr's text chunk), None for any other name: such
    a file is vibr's when ``folder``'s marker lists it. The marker and vibr's half-written
    temporary files (``.NAME.*.part*``) are vibr's too. A missing or empty folder is accepted;
    a file (or a link to none) in its place is refused, ``overwrite`` or not.
    """
    folder = Path(folder)
    if os.path.lexists(folder) and not folder.is_dir():
        raise VibrInputError(f"{what} exists and is not a folder", folder)
    if not folder.is_dir() or overwrite:
        return
    listed = read_marker(folder) or set()
    for f in sorted(folder.rglob("*")):
        rel = f.relative_to(folder).as_posix()
        if (f.is_dir() and not f.is_symlink()) or rel == MARKER:
            continue
        mine = owned(f) if f.is_file() and not f.is_symlink() else False
        if mine is None:
            mine = rel in listed or fnmatch.fnmatch(f.name, ".*.part*")
        if not mine:
            raise OutputExists(f"{what} holds {rel}, which vibr did not write; move it away or choose another "
                               "folder", folder)
