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

__all__ = ["Camera", "Scene", "View", "VibrInputError", "__version__"]

# The renderer lives in ``vibr.render`` (``from vibr.render import render``); it is not
# re-exported here so that the name keeps meaning the subpackage.
