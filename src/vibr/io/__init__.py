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
from .colmap import find_colmap_model, load_colmap
from .depthfiles import read_depth, read_pfm, write_depth, write_pfm
from .entries import select_entries
from .hci import is_hci_folder, load_hci
from .images import is_image_file, read_image, write_image
from .middlebury import find_par_file, load_middlebury
from .strecha import is_strecha_folder, load_strecha
from .transforms import find_transforms, load_transforms, save_scene

__all__ = ["load_scene", "select_entries", "save_scene", "detect_format", "read_image", "write_image", "read_depth",
           "write_depth", "read_pfm", "write_pfm", "read_camera_json", "write_camera_json", "FORMATS"]

FORMATS = ("hci", "strecha", "middlebury", "transforms", "colmap")

#: The largest ``scale`` a scene loads at: enlarging photographs adds no detail, and the
#: memory grows with its square.
MAX_SCALE = 4.0

#: Default of ``load_scene(allow_outside=None)``; the CLI's ``--allow-outside-paths`` sets it.
ALLOW_OUTSIDE_PATHS = False


def detect_format(path) -> str:
    """Name of the scene format at ``path`` (one of :data:`FORMATS`).

    Raises :class:`VibrInputError` when the path is missing or nothing is recognised.
    """

    p = Path(path)
    if not p.exists():
        raise VibrInputError("file or folder not found", p)
    if p.is_file():
        if p.name.endswith("_par.txt"):
            return "middlebury"
        if p.suffix.lower() == ".json":
            return "transforms"
        if p.name == "parameters.cfg":
            return "hci"
        raise VibrInputError("not a scene: give a folder, a transforms.json or a *_par.txt file", p)
    if find_transforms(p) is not None:
        return "transforms"
    if is_hci_folder(p):
        return "hci"
    if find_colmap_model(p) is not None:
        return "colmap"
    if find_par_file(p) is not None:
        return "middlebury"
    if is_strecha_folder(p):
        return "strecha"
    photos = any(is_image_file(f) for f in p.iterdir())
    # a Blender / NeRF-synthetic folder: transforms_train.json, transforms_test.json, ...
    splits = sorted(f.name for f in p.glob("transforms_*.json") if f.is_file())
    hint = ""
    if splits:
        hint = f"; found {', '.join(splits)}: give one of these files as SCENE, e.g. {p / splits[0]}"
    elif photos:
        hint = "; photos without cameras are calibrated first: vibr calibrate (COLMAP)"
    raise VibrInputError(
        "no supported scene found (looked for transforms.json, input_CamNNN.png light-field views, "
        "a COLMAP sparse model, a *_par.txt file, or images with .camera files)" + hint, p)


def load_scene(path, *, scale: float = 1.0, views=None, allow_outside: bool | None = None, **options):
    """Load a scene in any supported format (detected by :func:`detect_format`).

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
        Format-specific options, e.g. ``grid=(rows, cols)`` for an HCI folder without
        ``parameters.cfg``.

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
    fmt = detect_format(path)
    p = Path(path)
    if fmt == "hci":

        return load_hci(p.parent if p.is_file() else p, scale=scale, views=views, **options)
    if options:
        raise VibrInputError(f"options {sorted(options)} do not apply to {fmt} scenes", p)
    if fmt == "transforms":

        return load_transforms(p, scale=scale, views=views,
                               allow_outside=ALLOW_OUTSIDE_PATHS if allow_outside is None else allow_outside)
    if fmt == "colmap":

        return load_colmap(p, scale=scale, views=views)
    if fmt == "middlebury":

        return load_middlebury(p, scale=scale, views=views)

    return load_strecha(p, scale=scale, views=views)


