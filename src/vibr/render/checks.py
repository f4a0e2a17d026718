"""Checks of the render's memory, at the API boundary, before any work.

:func:`check_render_memory` refuses a render whose estimated peak (:func:`render_memory`)
exceeds the memory available. The render's parameters are checked by
:meth:`vibr.render.params.RenderParams.validate`, on every RenderParams made.
"""

from __future__ import annotations

import numpy as np

from .._runtime.memory import check_memory
from ..geometry.samples import Samples
from ..geometry.sampling import OPTIONAL_FIELDS

# ----------------------------------------------------------------------------- memory
#: Estimated bytes per target pixel of a variational render besides its samples: the
#: stencils (9 + 9 planes), right-hand sides (3 + 6), the image and the solver's buffers
#: (≈ 18 planes), the TV duals (3 × 6 planes), float64 accumulations; float32 unless noted.
RENDER_BYTES_PER_TARGET_PIXEL = 400
#: Geometry buffers per target pixel and source view (z-buffer and visibility, float64).
GEOMETRY_BYTES_PER_TARGET_PIXEL_VIEW = 16
#: A render on a coarser grid enlarged to the target (RenderResult.enlarged): per target
#: pixel, the image and its start twice in float64 (3 channels) and once in float32, σ, coverage.
ENLARGE_BYTES_PER_TARGET_PIXEL = 2 * (3 * 8 * 2 + 3 * 4) + 4 + 1


def sample_bytes(keep=()) -> int:
    """Bytes of one :class:`vibr.geometry.Samples` entry, from its arrays' dtypes: the
    optional fields (:data:`vibr.geometry.sampling.OPTIONAL_FIELDS`) only when in ``keep``."""

    e = Samples.concatenate([], (1, 1))
    return sum(int(a.dtype.itemsize * np.prod(a.shape[1:], dtype=np.int64))
               for name, a in vars(e).items()
               if isinstance(a, np.ndarray) and (name not in OPTIONAL_FIELDS or name in keep))


def render_memory(source_shapes, target_shape, keep=()) -> int:
    """Estimated peak bytes of a render of ``target_shape`` (H, W) from sources of the
    given shapes: samples (at most one per source pixel landing in the target, ×1.5 for
    the geometry's temporaries; with the optional fields ``keep``, :func:`sample_bytes`)
    plus the per-pixel buffers of the solve and the geometry (docs/reference/errors-and-limits.md)."""
    th, tw = target_shape
    tpx = float(th) * float(tw)
    n_samples = sum(min(float(h) * float(w), 4.0 * tpx) for h, w in source_shapes)
    return int(1.5 * n_samples * sample_bytes(keep) + tpx * RENDER_BYTES_PER_TARGET_PIXEL
               + tpx * len(source_shapes) * GEOMETRY_BYTES_PER_TARGET_PIXEL_VIEW)


def check_render_memory(source_shapes, target_shape, source=None, keep=(), way_out=None,
                        output_shape=None) -> None:
    """Refuse a render whose :func:`render_memory` exceeds the available memory; with
    ``output_shape`` (a render on a coarser grid enlarged to it) that enlargement counted too,
    and named."""
    need = render_memory(source_shapes, target_shape, keep)
    if output_shape is not None and tuple(output_shape) != tuple(target_shape):
        need += int(float(output_shape[0]) * float(output_shape[1]) * ENLARGE_BYTES_PER_TARGET_PIXEL)
        target_shape = output_shape
    th, tw = target_shape
    check_memory(need,
                 f"rendering {tw}x{th} from {len(source_shapes)} views",
                 way_out or "render at a lower resolution (--scale 0.5, or a smaller camera) or from "
                 "fewer views (--views K)", source)
