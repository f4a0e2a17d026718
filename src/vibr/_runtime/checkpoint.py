"""Per-view checkpoints of long jobs (``vibr depth``): a job killed midway and run again
keeps the views it had finished.

Each finished view is written atomically (:func:`vibr._runtime.atomic.atomic_path`) to
``folder/NAME.npz`` with a key: the SHA-1 of everything its result depends on (the view's
image and camera, its partners', the job's parameters, vibr's code). A file is read back
only when its key matches and it loads completely; anything else (another run's
parameters, other code, a damaged file) is recomputed, never trusted.
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import shutil
from pathlib import Path

import numpy as np

from .atomic import atomic_path

logger = logging.getLogger(__name__)


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """SHA-1 of vibr's own source files (names and contents): results saved under a key
    that includes it are recomputed by other code, never mixed with its own."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha1()
    for f in sorted(root.rglob("*.py")):
        h.update(f.relative_to(root).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def digest(*parts) -> str:
    """SHA-1 of arrays (dtype, shape, bytes) and JSON-able values, in order."""
    h = hashlib.sha1()
    for p in parts:
        if isinstance(p, np.ndarray):
            h.update(str((p.dtype, p.shape)).encode())
            h.update(np.ascontiguousarray(p).tobytes())
        else:
            h.update(json.dumps(p, sort_keys=True, default=str).encode())
        h.update(b"|")
    return h.hexdigest()


class ViewCheckpoint:
    """Store and read back per-view results under ``folder`` (created on first save)."""

    def __init__(self, folder, params: dict):
        self.folder = Path(folder)
        self.params = params
        self.n_loaded = 0
        self.unwritable = False

    def key(self, view, camera, partners) -> str:
        masks = [m for m in [getattr(view, "mask", None)] + [getattr(p, "mask", None) for p in partners]
                 if m is not None]  # the sweep leaves masked pixels out
        bits = np.concatenate([np.packbits(m) for m in masks]) if masks else np.zeros(0, np.uint8)
        return digest(code_fingerprint(), self.params, view.name, camera.K, camera.R, camera.t,
                      list(camera.shape), view.image, bits,
                      [(p.name, p.camera.K, p.camera.R, p.camera.t, getattr(p, "mask", None) is not None)
                       for p in partners], getattr(view, "mask", None) is not None)

    def _path(self, name: str) -> Path:
        safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
        return self.folder / f"{safe}.npz"

    def load(self, name: str, key: str):
        """(arrays dict, info dict) saved for ``name`` under ``key``, or None."""
        p = self._path(name)
        if not p.is_file():
            return None
        try:
            with np.load(p, allow_pickle=False) as z:
                if str(z["key"]) != key:
                    return None
                arrays = {k[2:]: z[k] for k in z.files if k.startswith("a_")}
                info = json.loads(str(z["info"]))
        except Exception:  # noqa: BLE001 - a damaged checkpoint is recomputed, never trusted
            logger.info("checkpoint %s is unreadable: recomputed", p)
            return None
        self.n_loaded += 1
        return arrays, info

    def save(self, name: str, key: str, arrays: dict, info: dict) -> None:
        """Keep ``name``'s result; a folder that cannot be written only costs the resumption
        (one warning, then nothing more is tried)."""
        if self.unwritable:
            return
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            with atomic_path(self._path(name), suffix=".npz") as tmp:
                with open(tmp, "wb") as fh:
                    np.savez(fh, key=np.array(key), info=np.array(json.dumps(info, default=float)),
                             **{f"a_{k}": v for k, v in arrays.items() if v is not None})
        except OSError as exc:
            self.unwritable = True
            logger.warning("cannot keep per-view results in %s (%s): an interrupted run will start over",
                           self.folder, exc.strerror or getattr(exc, "problem", exc))

    def remove(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


def resume_folder(out) -> Path:
    """The checkpoint folder of a job writing ``out``: a hidden sibling."""
    out = Path(os.path.abspath(out))
    return out.parent / f".{out.name}.vibr-resume"
