"""A small COLMAP model written by pycolmap itself (there is no real COLMAP data here): two
cameras, three posed images with 2-D points, 3-D points with tracks, rigs and frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from _helpers import rot_about
from vibr.io.images import write_image


def write_colmap_model(root, *, text: bool = False, size=(32, 24)) -> Path:
    """Write ``root/sparse/0`` (binary, or text) and ``root/images``; returns the model folder."""
    import pycolmap

    w, h = size
    root = Path(root)
    rec = pycolmap.Reconstruction()
    cams = [pycolmap.Camera.create_from_model_name(1, "PINHOLE", 40.0, w, h),
            pycolmap.Camera.create_from_model_name(2, "SIMPLE_PINHOLE", 38.0, w, h)]
    cams[0].params = [40.0, 41.0, w / 2, h / 2]
    for c in cams:
        rec.add_camera_with_trivial_rig(c)
    rng = np.random.default_rng(0)
    X = rng.uniform([-0.5, -0.4, 2.0], [0.5, 0.4, 3.0], (5, 3))
    for iid, (cid, R, t) in enumerate([(1, rot_about(1, 0.05), [0.1, 0.0, 0.0]),
                                       (2, rot_about(0, -0.03), [-0.1, 0.05, 0.1]),
                                       (1, rot_about(2, 0.02), [0.0, -0.1, 0.05])], 1):
        im = pycolmap.Image(name=f"im{iid}.png", camera_id=cid, image_id=iid)
        im.points2D = [pycolmap.Point2D(rng.uniform(0, w, 2)) for _ in range(len(X))]
        rec.add_image_with_trivial_frame(im, pycolmap.Rigid3d(pycolmap.Rotation3d(R), np.asarray(t, float)))
    for k, x in enumerate(X):
        tr = pycolmap.Track()
        for iid in (1, 2, 3):
            tr.add_element(iid, k)
        rec.add_point3D(x, tr)
    model = root / "sparse" / "0"
    model.mkdir(parents=True, exist_ok=True)
    (rec.write_text if text else rec.write)(str(model))
    (root / "images").mkdir(exist_ok=True)
    for iid in (1, 2, 3):
        write_image(root / "images" / f"im{iid}.png", rng.uniform(0, 1, (h, w, 3)).astype(np.float32))
    return model
