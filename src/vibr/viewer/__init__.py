"""``vibr view``: look at a scene and vibr's render of any viewpoint in a web browser.

Built on viser (https://viser.studio). :class:`Viewer` serves a scene: its input cameras as
frustums with thumbnails (a click moves the view there), a point cloud from the depth maps,
and the view rendered by :func:`vibr.render.render` for the browser's camera — a small
preview while the camera moves, full size once it is still. Keyframes compose a
``camera_path.json`` (nerfstudio's schema) that ``vibr render --path`` renders.
"""

from .app import POINT_MODES, CameraState, SentImage, Viewer, ViewerOptions, check_port_free
from .convert import camera_from_viser, image_size, viser_pose_from_camera
from .renderer import ViewImage, ViewRenderer, ViewSettings, scene_with_depth
from .worker import LatestRequestWorker

__all__ = ["Viewer", "ViewerOptions", "ViewSettings", "ViewRenderer", "ViewImage", "SentImage",
           "CameraState", "LatestRequestWorker", "camera_from_viser", "viser_pose_from_camera",
           "image_size", "scene_with_depth", "check_port_free", "POINT_MODES"]
