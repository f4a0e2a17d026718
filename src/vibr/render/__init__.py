"""Rendering stage (paper §4): operators with adjoints, TV prox, FISTA, push–pull, the
method registry (:mod:`vibr.render.methods`), the render's parameters
(:class:`RenderParams`, :mod:`vibr.render.params`) and :func:`render`.

``from vibr.render import render`` is the function; ``vibr.render`` is this subpackage.
"""

from ..errors import RenderStopped
from .api import RenderResult, SharedGeometry, fine_grid, grid_params, render, render_samples, shared_geometry
from .methods import METHODS
from .params import AUTO, DEFAULTS, RenderParams

__all__ = ["render", "render_samples", "fine_grid", "grid_params", "shared_geometry", "SharedGeometry",
           "RenderResult", "RenderParams", "RenderStopped", "METHODS", "DEFAULTS", "AUTO"]
