"""Cameras from photographs or a video, with COLMAP (pycolmap, CPU).

:func:`calibrate_scene` registers the photos (:mod:`.colmap`); photographs turned on the spot
are fitted to a one-centre model (:mod:`.pan`); a video gives its sharpest frame of each
stretch as photos (:mod:`.video_frames`).
"""

from .colmap import CalibrateOptions, CalibrationReport, calibrate, calibrate_scene, list_photos, pose_errors

__all__ = ["CalibrateOptions", "CalibrationReport", "calibrate", "calibrate_scene", "list_photos", "pose_errors"]
