"""The paper's evaluation protocol: hold a view out, render it with several methods, measure.

:mod:`.protocol` evaluates one target (:func:`run_evaluation`); :mod:`.leave_one_out` every
view in turn, on processes or a cluster; :mod:`.figures` and :mod:`.sigma_figures` draw the
comparisons and the uncertainty maps.
"""

from .protocol import EvalOptions, Evaluation, Setting, evaluate, run_evaluation, settings_grid, write_report

__all__ = ["EvalOptions", "Evaluation", "Setting", "evaluate", "run_evaluation", "settings_grid", "write_report"]
