"""Camera paths and fly-throughs.

:mod:`.camera_path` reads and writes nerfstudio's ``camera_path.json`` and generates paths
(``interpolate``, ``orbit``, ``spiral``), the kinds ``vibr path`` offers registered in
:mod:`.kinds` (:func:`register_path_kind`); :mod:`.flythrough` renders every camera of a path
and encodes the video (:func:`render_path`).
"""

from .camera_path import CameraPath, interpolate, orbit, read_camera_path, scene_centre, spiral, write_camera_path
from .flythrough import FlyOptions, FlyResult, render_path
from .kinds import PATH_KINDS, PathKind, PathOption, register_path_kind, unregister_path_kind

__all__ = ["CameraPath", "FlyOptions", "FlyResult", "interpolate", "orbit", "read_camera_path", "render_path",
           "scene_centre", "spiral", "write_camera_path", "PATH_KINDS", "PathKind", "PathOption", "register_path_kind",
           "unregister_path_kind"]
