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
"""

from __future__ import annotations

import contextlib
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
        writable. ``"dir"``: ``path`` must not be a file; an existing folder is accepted
        only with ``overwrite`` (its replacement is then checked by
        :func:`check_replaceable`); its parent must exist and be writable.
    overwrite : bool
        Whether an existing output may be replaced.
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
    if kind == "file":
        if p.is_dir():
            raise VibrInputError(f"{what} is a folder, a file name is expected", p)
        if p.exists() and not overwrite:
            raise OutputExists(f"{what} already exists", p)
        if str(os.fspath(path)).endswith(("/", os.sep)):
            raise VibrInputError(f"{what} ends with a path separator, a file name is expected", p)
    else:
        if p.exists() and not p.is_dir():
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
def write_marker(folder, files=None) -> None:
    """Write the marker into ``folder`` listing ``files`` (relative paths); by default every
    file now under ``folder`` (use only on a folder vibr has just created)."""
    folder = Path(folder)
    if files is None:
        files = [f.relative_to(folder).as_posix() for f in sorted(folder.rglob("*"))
                 if f.is_file() and f.name != MARKER]
    doc = {"written_by": "vibr", "files": sorted(set(files))}
    with open(folder / MARKER, "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=1)
        fh.write("\n")


def read_marker(folder) -> set[str] | None:
    """The files listed by ``folder``'s marker, or None when it has no valid marker."""
    m = Path(folder) / MARKER
    try:
        with open(m, encoding="utf-8") as fh:
            doc = json.load(fh)
        files = doc["files"]
        if doc.get("written_by") != "vibr" or not isinstance(files, list):
            return None
        return {str(f) for f in files}
    except (OSError, ValueError, KeyError, TypeError):
        return None


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
