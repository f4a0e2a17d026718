"""A camera-path kind for ``vibr path``: a dolly, the camera moving on a straight line from one
view's camera to another's, looking as the first one does (docs/how-to/extend/add-a-path-kind.md)."""

import numpy as np

from vibr.camera import Camera
from vibr.paths.camera_path import CameraPath, frame_count
from vibr.paths.kinds import PathKind, PathOption, register_path_kind


def dolly(scene, *, n_frames=None, seconds=None, fps=24.0, width=None, height=None, start=None, end=None):
    """Cameras from view ``start``'s centre to view ``end``'s (default: the first view and the
    last), evenly spaced, with ``start``'s orientation and vertical field of view."""
    first = scene.views[scene.index(0 if start is None else start)].camera
    last = scene.views[scene.index(len(scene.views) - 1 if end is None else end)].camera
    w, h = width or first.width, height or first.height
    K = Camera.intrinsics(first.K[1, 1] * h / first.height, w, h)
    steps = np.linspace(0.0, 1.0, frame_count(n_frames, seconds, fps))
    cameras = [Camera.from_centre(K, first.R, (1 - s) * first.centre + s * last.centre, w, h) for s in steps]
    return CameraPath(cameras, fps, None, w, h, {"kind": "dolly"})


register_path_kind(PathKind(
    "dolly", "a straight line from one view's camera to another's", dolly,
    options=(PathOption("--start", "the view the path starts at, name or index (default: the first)"),
             PathOption("--end", "the view the path ends at, name or index (default: the last)"))))
