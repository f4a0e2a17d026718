"""Depth estimation: per-view depth maps and sigma_z from calibrated photographs.

* :func:`estimate_depth` — the entry point (light-field or plane-sweep MVS), its options
  :class:`DepthOptions`.
* :func:`plane_sweep` — plane-sweep stereo for one reference view.
* :func:`refine_planes` (:class:`RefineOptions`) — slanted-plane PatchMatch refinement of a sweep.
* :func:`check_consistency` — forward-backward geometric consistency across views;
  :func:`consensus_depth` — the views' mean depth where they agree.
* :func:`segment_image`, :func:`fill_segment_planes` — colour-segment plane completion
  (the dense output, ``estimate_depth(fill_segments=True)``).
* :func:`epi_disparity`, :func:`lightfield_depth` (:class:`LightFieldOptions`) — light-field estimators.
"""

from .api import DepthOptions, depth_options, estimate_depth
from .consistency import ConsistencyResult, check_consistency, consensus_depth
from .lightfield import LightFieldOptions, disparity_model, epi_disparity, lightfield_depth
from .partners import complete_coverage, default_depth_range, frustum_coverage, select_neighbours, upsample_depth
from .planesweep import RefineOptions, SweepResult, median_planes, plane_homographies, plane_sweep, refine_planes
from .segments import SegmentFill, fill_segment_planes, segment_image

__all__ = ["estimate_depth", "DepthOptions", "depth_options", "default_depth_range", "select_neighbours", "complete_coverage",
           "frustum_coverage", "upsample_depth",
           "plane_sweep", "plane_homographies", "refine_planes", "RefineOptions", "median_planes", "SweepResult", "check_consistency", "consensus_depth",
           "ConsistencyResult", "epi_disparity", "disparity_model", "lightfield_depth", "LightFieldOptions",
           "segment_image", "fill_segment_planes", "SegmentFill"]
