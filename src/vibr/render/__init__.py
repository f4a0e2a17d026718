"""Rendering stage (paper §4): operators with adjoints, TV prox, FISTA, push–pull, methods,
and :func:`render`.

``vibr.render`` is both this subpackage and the function: ``vibr.render(scene, target,
method=...)`` calls :func:`vibr.render.api.render`, while ``vibr.render.solver`` and the other
modules stay importable under their names.
"""

import sys
import types

from .api import RenderResult, render, render_samples
from .methods import DEFAULTS, METHODS

__all__ = ["render", "render_samples", "RenderResult", "METHODS", "DEFAULTS"]


class _CallableModule(types.ModuleType):
    def __call__(self, *args, **kwargs):
        return render(*args, **kwargs)

    __call__.__doc__ = render.__doc__


sys.modules[__name__].__class__ = _CallableModule
