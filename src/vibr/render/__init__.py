"""Rendering stage (paper §4): operators with adjoints, TV prox, FISTA, push–pull, methods,
and :func:`render`."""

from .api import RenderResult, render, render_samples
from .methods import DEFAULTS, METHODS

__all__ = ["render", "render_samples", "RenderResult", "METHODS", "DEFAULTS"]
