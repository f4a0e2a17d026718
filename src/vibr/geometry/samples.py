"""The geometry stage's output: warped source samples, what the renderer consumes.

Every visible source pixel (k, m) becomes one sample: where it lands in the target
(``tau_k(x_m)``, docs/explanation/method.md §2 eq. projection), its colour and colour gradient in the source,
the local Jacobian of the warp, the deformation factor ``1/|det ∂tau_k/∂x_m|``, the depth
derivative ``∂tau_k/∂z`` and the depth uncertainty. Samples of all source views are
concatenated; ``view`` tells which view each came from. :func:`vibr.geometry.compute_samples`
returns them sorted by the target pixel they land on (row-major), so that the renderer's
passes, bucketed by target row, stream through the arrays. The renderer knows nothing of
cameras: it sees only these arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

_DTYPES = {"xy": np.float64, "colour": np.float32, "grad": np.float32, "jac": np.float32,
           "inv_det": np.float32, "dtau_dz": np.float32, "sigma_z": np.float32, "view": np.int32,
           "src_xy": np.int32, "X": np.float32}


@dataclass(eq=False)
class Samples:
    """Visible source samples landing in a target of shape ``target_shape``.

    Attributes (N samples)
    ----------------------
    xy : (N, 2) float64
        Target pixel coordinates ``tau_k(x_m)`` (vibr's convention: centre of the
        top-left pixel at (0, 0)); every sample satisfies ``0 <= x <= W-1``,
        ``0 <= y <= H-1``.
    colour : (N, 3) float32
        Source colour ``v_k(m)`` in [0, 1].
    grad : (N, 3, 2) float32
        Source colour gradient ``∇v_k(m)`` (per channel, d/dx then d/dy), in source
        pixels: :func:`vibr.geometry.gradient.grad_image` of the source image with the
        scheme of ``meta["grad_scheme"]``.
    jac : (N, 2, 2) float32 or None
        ``∂tau_k/∂x_m`` (docs/explanation/method.md §2 eq. deformation); rows are target x, y; columns source
        x, y. Only the footprint PSF reads it: None unless asked for
        (:func:`vibr.geometry.compute_samples`'s ``keep``).
    inv_det : (N,) float32
        Deformation weight ``1 / |det ∂tau_k/∂x_m|``.
    dtau_dz : (N, 2) float32
        ``∂tau_k/∂z`` (docs/explanation/method.md §2 eq. geometrie), target pixels per scene unit of depth.
    sigma_z : (N,) float32
        Depth standard deviation of the sample, scene units.
    view : (N,) int32
        Index of the source view (into the list of sources).
    src_xy : (N, 2) int32 or None
        The sample's source pixel (x = column, y = row); no render reads it: None unless
        asked for (``keep``).
    X : (N, 3) float32
        The sample's 3D point in world coordinates (for view-dependent blending, ULR).
    target_shape : (H, W)
    meta : dict
        Diagnostics (counts per view, times).
    """

    xy: np.ndarray
    colour: np.ndarray
    grad: np.ndarray
    jac: np.ndarray
    inv_det: np.ndarray
    dtau_dz: np.ndarray
    sigma_z: np.ndarray
    view: np.ndarray
    src_xy: np.ndarray
    X: np.ndarray
    target_shape: tuple[int, int]
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        # the dtypes above, contiguous: a float64 or strided field would compile every kernel
        # that reads it once more (no copy when the field already conforms)
        for name, dtype in _DTYPES.items():
            a = getattr(self, name)
            if a is not None:
                setattr(self, name, np.ascontiguousarray(a, dtype))

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    def select(self, mask) -> "Samples":
        """The samples where boolean ``mask`` (N,) is true."""
        opt = lambda a: None if a is None else a[mask]  # noqa: E731
        return Samples(
            self.xy[mask], self.colour[mask], self.grad[mask], opt(self.jac),
            self.inv_det[mask], self.dtau_dz[mask], self.sigma_z[mask], self.view[mask],
            opt(self.src_xy), self.X[mask], self.target_shape, dict(self.meta),
        )

    @staticmethod
    def concatenate(parts: list["Samples"], target_shape) -> "Samples":
        if not parts:
            z2 = np.zeros((0, 2))
            f4 = np.float32
            return Samples(z2, np.zeros((0, 3), f4), np.zeros((0, 3, 2), f4), np.zeros((0, 2, 2), f4),
                           np.zeros(0, f4), np.zeros((0, 2), f4), np.zeros(0, f4), np.zeros(0, np.int32),
                           np.zeros((0, 2), np.int32), np.zeros((0, 3), f4), tuple(target_shape))
        def cat(name):
            arrays = [getattr(p, name) for p in parts]
            if any(a is None for a in arrays):  # an optional field (jac, src_xy) some part lacks
                return None
            return np.concatenate(arrays)

        return Samples(cat("xy"), cat("colour"), cat("grad"), cat("jac"), cat("inv_det"),
                       cat("dtau_dz"), cat("sigma_z"), cat("view"), cat("src_xy"),
                       cat("X"), tuple(target_shape), {})


def view_counts(samples) -> np.ndarray:
    """(H, W) int: how many distinct source views have a visible sample whose landing
    point rounds to each target pixel."""
    H, W = samples.target_shape
    if len(samples) == 0:
        return np.zeros((H, W), np.int64)
    x = np.clip(np.rint(samples.xy[:, 0]).astype(np.int64), 0, W - 1)
    y = np.clip(np.rint(samples.xy[:, 1]).astype(np.int64), 0, H - 1)
    key = np.unique(np.asarray(samples.view, np.int64) * (H * W) + y * W + x)
    return np.bincount(key % (H * W), minlength=H * W).reshape(H, W)
