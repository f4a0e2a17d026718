"""Camera paths and fly-throughs.

:mod:`.camera_path` reads and writes nerfstudio's ``camera_path.json`` and generates paths
(``interpolate``, ``orbit``, ``spiral``); :mod:`.flythrough` renders every camera of a path
and encodes the video (:func:`render_path`).
"""

from .camera_path import CameraPath, interpolate, orbit, read_camera_path, scene_centre, spiral, write_camera_path
from .flythrough import FlyOptions, FlyResult, render_path

__all__ = ["CameraPath", "FlyOptions", "FlyResult", "interpolate", "orbit", "read_camera_path", "render_path",
           "scene_centre", "spiral", "write_camera_path"]
