"""vibr: variational image-based rendering with gradient constraints.

Implements Nieto, Devernay & Crowley (2016), "Variational image-based rendering with
gradient constraints": a novel view is the image that best explains the warped source
photographs (colour term), their edges (gradient term) and natural-image smoothness
(total variation).
"""

from .camera import Camera
from .errors import VibrInputError
from .scene import Scene, View

__version__ = "0.1.0"


def __getattr__(name):
    # the vibr.render subpackage (its function: ``from vibr.render import render``),
    # imported on first use so that ``import vibr`` stays light
    if name == "render":
        import importlib

        return importlib.import_module(".render", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["Camera", "Scene", "View", "VibrInputError", "render", "__version__"]
