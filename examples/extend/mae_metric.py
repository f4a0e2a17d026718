"""An image metric for vibr: the mean absolute error (docs/how-to/extend/add-a-metric.md)."""

import numpy as np

from vibr.metrics import Metric, register_metric


def mae(img, ref, mask=None, border=0):
    """Mean absolute difference over the channels of the pixels of ``mask`` (None: all),
    ``border`` pixels left out at each edge."""
    a, b = np.asarray(img, np.float64), np.asarray(ref, np.float64)
    keep = np.ones(a.shape[:2], bool) if mask is None else np.asarray(mask, bool).copy()
    if border:
        keep[:border] = keep[-border:] = False
        keep[:, :border] = keep[:, -border:] = False
    return float(np.abs(a - b)[keep].mean())


register_metric(Metric("mae", mae, higher_is_better=False, summary="mean absolute error",
                       heading="MAE", width=7, fmt=".4f"))
