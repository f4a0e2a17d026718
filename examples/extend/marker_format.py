"""A scene format for vibr: a folder marked by a ``scene.marker`` file, which names the scene
inside the folder that it wraps (docs/how-to/extend/add-a-format.md)."""

from pathlib import Path

from vibr.errors import VibrInputError
from vibr.io import Format, load_scene, register_format

MARKER = "scene.marker"


def is_marked(path: Path) -> bool:
    """A folder holding a scene.marker file."""
    return path.is_dir() and (path / MARKER).is_file()


def load_marked(path: Path, *, scale: float = 1.0, views=None):
    """The scene scene.marker names (a folder relative to ``path``), its format noted."""
    inner = (path / (path / MARKER).read_text().strip()).resolve()
    if not inner.is_relative_to(path.resolve()):  # a scene never makes vibr read outside it
        raise VibrInputError(f"{MARKER} must name a folder inside the scene", path / MARKER)
    scene = load_scene(inner, scale=scale, views=views)
    scene.meta["format"] = "marker"
    return scene


register_format(Format("marker", "folder with scene.marker", is_marked, load_marked,
                       looks_for="a scene.marker file"))
