"""What :func:`vibr.render.render` returns."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..geometry.resample import resize_depth, resize_image, resize_mask

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
        ``uncertainty=True`` (:mod:`vibr.render.uncertainty`; docs/explanation/renderer.md).
    depth : (H, W) float32 or None
        The target's depth in scene units (orthogonal, as vibr's depth maps): the geometry
        stage's z-buffer (:func:`vibr.geometry.sampling.target_depth`), NaN where no source
        surface lands; None when the render was given its samples. From a finer grid, each
        pixel's block's nearest depth; from a coarser one, the nearest grid pixel's
        (:func:`vibr.geometry.resample.resize_depth`): a depth edge never makes an
        in-between depth.
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
    depth: np.ndarray | None = None

    def box_reduced(self, k: int) -> "RenderResult":
        """The result of a render on a grid ``k`` times finer, brought back to the target's
        pixels: the image (and ``init``) averaged over ``k × k`` blocks, a pixel covered where
        its whole block is, the uncertainty the root mean square of its block's (a bound: the
        block's errors are not independent). Energies, times and counts stay the fine grid's."""
        k = int(k)
        if k == 1:
            return self
        H, W = self.coverage.shape[0] // k, self.coverage.shape[1] // k

        def blocks(a):
            a = np.asarray(a)[: H * k, : W * k]
            return a.reshape((H, k, W, k) + a.shape[2:])

        mean = lambda a: None if a is None else blocks(a).astype(np.float64).mean(axis=(1, 3)).astype(np.float32)  # noqa: E731
        unc = None if self.uncertainty is None else np.sqrt(mean(np.square(self.uncertainty, dtype=np.float64)))
        # the nearest surface of each block (fmin skips NaN; NaN where the block saw none)
        depth = None if self.depth is None else np.fmin.reduce(np.fmin.reduce(blocks(self.depth), axis=3), axis=1)
        return replace(self, image=mean(self.image), init=mean(self.init), coverage=blocks(self.coverage).all(axis=(1, 3)),
                       uncertainty=None if unc is None else unc.astype(np.float32), params=dict(self.params),
                       depth=depth)

    def enlarged(self, shape) -> "RenderResult":
        """The result of a render on a coarser grid brought to ``shape = (h, w)`` (the grid of
        :meth:`vibr.camera.Camera.scaled`, whose pixel centres the resize maps back): the
        image (and ``init``) by bicubic interpolation clipped to [0, 1], the uncertainty
        bilinear, a pixel covered where every grid pixel under its bilinear footprint is
        (:func:`vibr.geometry.resample.resize_mask`). Energies, times and counts stay the grid's."""

        shape = tuple(int(v) for v in shape)
        if self.coverage.shape == shape:
            return self

        def cubic(a):
            return None if a is None else np.clip(resize_image(a, shape, order=3, quantise=False), 0.0, 1.0)

        unc = None if self.uncertainty is None else resize_image(self.uncertainty, shape, quantise=False)
        depth = None if self.depth is None else resize_depth(self.depth, shape)
        return replace(self, image=cubic(self.image), init=cubic(self.init), coverage=resize_mask(self.coverage, shape),
                       uncertainty=unc, params=dict(self.params), depth=depth)

    def on_target(self, plan, shape) -> "RenderResult":
        """The result of a render on ``plan``'s grid (:func:`vibr.render.fine_grid`; None: the
        target's own) at the target's ``shape = (h, w)``: :meth:`box_reduced` from a finer
        grid, :meth:`enlarged` from a coarser one; ``params`` records the grid
        (``supersample``, ``coarsen``, ``reduced_sources``)."""
        res = self
        if plan is not None and plan.supersample > 1:
            res = self.box_reduced(plan.supersample)
        elif plan is not None and plan.coarsen > 1:
            res = self.enlarged(shape)
        res.params.update(supersample=plan.supersample if plan else 1, coarsen=plan.coarsen if plan else 1.0,
                          reduced_sources=dict(plan.scales) if plan else {})
        return res
