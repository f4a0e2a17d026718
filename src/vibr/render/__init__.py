"""Rendering stage (paper §4): operators with adjoints, TV prox, FISTA, push–pull, the
method registry (:mod:`vibr.render.methods`) and :func:`render`.

``from vibr.render import render`` is the function; ``vibr.render`` is this subpackage.
"""

from ..errors import RenderStopped
from .api import RenderResult, SharedGeometry, fine_grid, grid_params, render, render_samples, shared_geometry
from .methods import DEFAULTS, METHODS

__all__ = ["render", "render_samples", "fine_grid", "grid_params", "shared_geometry", "SharedGeometry",
           "RenderResult", "RenderStopped", "METHODS", "DEFAULTS"]
