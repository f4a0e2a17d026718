"""What :func:`vibr.render.render` returns."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["RenderResult"]


@dataclass
class RenderResult:
    """What :func:`render` returns.

    Attributes
    ----------
    image : (H, W, 3) float32 in [0, 1]
    coverage : (H, W) bool
        Pixels reached by the source samples (accumulated bilinear weight ≥
        ``hole_threshold``); the rest was filled (push–pull, then TV).
    energy : list of float
        Total energy after each FISTA iteration, all outer passes concatenated, in
        ``scale²`` units (intensities on the 0..scale range).
    terms : list of (E_color, E_grad, TV)
        The three terms (unweighted) per iteration, same units (TV in ``scale`` units).
    outer : list of int
        Index into ``energy`` where each outer (weight-update) pass starts.
    times : dict
        Seconds per stage: ``geometry``, ``weights``, ``init``, ``assembly``, ``solve``,
        ``total``.
    method : str
    params : dict
        The parameters used (defaults filled in), plus (variational methods) ``density``
        (the normalisation rho of the gradient term), ``colour_density`` (rho_c, the colour
        term's: rho weighted by the view prior), ``psf_shrunk`` (fraction of the samples whose footprint
        was shrunk to fit a 2×2 block; 0 with the bilinear PSF) and ``psf_degenerate``
        (fraction with a non-finite or singular Jacobian, given the unit-square PSF).
    n_samples : int
    metrics : dict
        ``psnr`` / ``ssim`` / ``dssim`` against the held-out view (when the target is a
        View with an image), over the covered pixels with a 2-pixel border excluded.
    init : (H, W, 3) float32 or None
        The initial image (weighted blend + push–pull) the solver started from.
    iterations, power_iterations : int
        FISTA iterations and power iterations (step size) over all outer passes.
    uncertainty : (H, W) float32 or None
        Per-pixel standard deviation, grey levels of ``scale``, when rendered with
        ``uncertainty=True`` (:mod:`vibr.render.uncertainty`; docs/RENDERER.md).
    """

    image: np.ndarray
    coverage: np.ndarray
    energy: list = field(default_factory=list)
    terms: list = field(default_factory=list)
    outer: list = field(default_factory=list)
    times: dict = field(default_factory=dict)
    method: str = "gradient"
    params: dict = field(default_factory=dict)
    n_samples: int = 0
    metrics: dict = field(default_factory=dict)
    init: np.ndarray | None = None
    iterations: int = 0
    power_iterations: int = 0
    uncertainty: np.ndarray | None = None
