"""Dataset loaders and writers (IO at the edges of vibr).

:func:`load_scene` detects the format of a path and returns a :class:`~vibr.scene.Scene`:

=============================  ==========================================================
HCI 4D light field             folder with ``input_CamNNN.png`` [+ ``parameters.cfg``]
Strecha                        images + ``*.camera`` (beside, or ``gt_dense_cameras/``)
Middlebury                     ``*_par.txt`` (the file or its folder)
nerfstudio / instant-NGP       ``transforms.json`` (the file or its folder)
COLMAP                         sparse model (``root/sparse/0``, ``root/sparse`` or the model)
=============================  ==========================================================

:func:`save_scene` writes any scene as nerfstudio ``transforms.json`` (+ PNG images, float32
``.npy`` depth, sigma_z maps, sparse points), losslessly: loading the result gives the same
cameras (to 1e-9), images and depth (bit for bit; resized images are stored on the 16-bit
grid, see :func:`vibr.geometry.resample.quantise16`).
"""

from __future__ import annotations

from pathlib import Path

from ..errors import VibrInputError
from .camera_json import read_camera_json, write_camera_json
from .depthfiles import read_depth, read_pfm, write_depth, write_pfm
from .entries import select_entries
from .formats import FORMATS, Format, get_format, register_format, unregister_format
from .images import is_image_file, read_image, write_image
from .transforms import save_scene

# importing the loaders registers the built-in formats (each beside its loader, vibr.io.formats)
from . import colmap, hci, middlebury, strecha  # noqa: F401  isort: skip

__all__ = ["load_scene", "select_entries", "save_scene", "detect_format", "read_image", "write_image", "read_depth",
           "write_depth", "read_pfm", "write_pfm", "read_camera_json", "write_camera_json", "FORMATS", "Format",
           "register_format", "unregister_format", "get_format"]

#: The largest ``scale`` a scene loads at: enlarging photographs adds no detail, and the
#: memory grows with its square.
MAX_SCALE = 4.0

#: Default of ``load_scene(allow_outside=None)``; the CLI's ``--allow-outside-paths`` sets it.
ALLOW_OUTSIDE_PATHS = False


def detect_format(path) -> str:
    """Name of the scene format at ``path``: the first of :data:`FORMATS` (in their
    detection order, :mod:`vibr.io.formats`) whose ``detect`` recognises it.

    Raises :class:`VibrInputError` when the path is missing or nothing is recognised.
    """

    p = Path(path)
    if not p.exists():
        raise VibrInputError("file or folder not found", p)
    for fmt in FORMATS.values():
        if fmt.detect(p):
            return fmt.name
    if p.is_file():
        raise VibrInputError("not a scene: give a folder, a transforms.json or a *_par.txt file", p)
    photos = any(is_image_file(f) for f in p.iterdir())
    # a Blender / NeRF-synthetic folder: transforms_train.json, transforms_test.json, ...
    splits = sorted(f.name for f in p.glob("transforms_*.json") if f.is_file())
    hint = ""
    if splits:
        hint = f"; found {', '.join(splits)}: give one of these files as SCENE, e.g. {p / splits[0]}"
    elif photos:
        hint = "; photos without cameras are calibrated first: vibr calibrate (COLMAP)"
    raise VibrInputError(f"no supported scene found (looked for {_looked_for()})" + hint, p)


def _looked_for() -> str:
    """What the registered formats look for, as a list in prose ("a, b, or c")."""
    what = [f.looks_for for f in FORMATS.values() if f.looks_for]
    return what[0] if len(what) == 1 else ", ".join(what[:-1]) + ", or " + what[-1]


def load_scene(path, *, scale: float = 1.0, views=None, allow_outside: bool | None = None, **options):
    """Load a scene in any registered format (detected by :func:`detect_format`, read by
    that :class:`~vibr.io.formats.Format`'s ``load``).

    Parameters
    ----------
    path : str or Path
        A scene folder, ``transforms.json`` or ``*_par.txt`` file.
    scale : float
        Resize factor in (0, :data:`MAX_SCALE`] applied after reading (the memory it needs
        is checked first, from the image sizes: :func:`vibr.io.images.build_views`): images with anti-aliasing
        (skimage.transform.resize), cameras with :meth:`Camera.scaled`, depth by nearest
        neighbour (never mixes depths across edges).
    views : list of int or str, optional
        Load only these views, in this order (positions in the format's view order, or
        names = image stems); only their images are read.
    allow_outside : bool, optional
        Accept ``transforms.json`` file paths that are absolute or lead out of the scene
        folder (refused by default: a scene must not make vibr read arbitrary files).
        None: :data:`ALLOW_OUTSIDE_PATHS`.
    **options
        Format-specific options (:attr:`Format.options <vibr.io.formats.Format.options>`),
        e.g. ``grid=(rows, cols)`` for an HCI folder without ``parameters.cfg``.

    Returns
    -------
    Scene
        ``scene.meta["format"]`` names the format; light fields set ``scene.grid`` and
        ``scene.meta["grid_pos"]``.
    """
    try:
        scale = float(scale)
    except (TypeError, ValueError):
        raise VibrInputError(f"scale must be a number, got {scale!r}") from None
    if not (scale > 0 and scale <= MAX_SCALE):
        raise VibrInputError(f"scale must be in (0, {MAX_SCALE:g}], got {scale:g} (enlarging the photographs adds "
                             "no detail; a render is supersampled by itself)")
    fmt = get_format(detect_format(path))
    p = Path(path)
    unknown = sorted(set(options) - set(fmt.options))
    if unknown:
        raise VibrInputError(f"options {unknown} do not apply to {fmt.name} scenes", p)
    if "allow_outside" in fmt.options:
        options["allow_outside"] = ALLOW_OUTSIDE_PATHS if allow_outside is None else allow_outside
    return fmt.load(p, scale=scale, views=views, **options)
