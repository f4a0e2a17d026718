"""Pinhole cameras.

Conventions (used everywhere in vibr, written down once here)
------------------------------------------------------------
* **World → camera**: ``X_cam = R @ X_world + t`` with ``R`` a rotation (orthonormal,
  det +1). The camera looks along its +z axis, x to the right, y down (OpenCV / the
  paper §5.2: x̃ = K (R X + t)). Camera centre ``C = -Rᵀ t``.
* **Depth** is *orthogonal* depth: the third coordinate of ``R X + t``, in scene units.
  Radial distances and disparities are converted to it once, at load time.
* **Pixel coordinates** ``(x, y)``: x along image columns, y along rows, the **centre of
  the top-left pixel at (0, 0)**; pixel ``(row i, col j)`` of an H×W array has centre
  ``(x, y) = (j, i)``. ``K`` maps to these coordinates. Loaders of formats that put the
  centre of the top-left pixel at (0.5, 0.5) (COLMAP, nerfstudio) shift the principal
  point by 0.5 on the way in and out.
* Images are H×W×3 float32 arrays in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import VibrInputError

_ORTHO_TOL = 1e-5


def _as_matrix(a, shape, name, source):
    try:
        m = np.asarray(a, dtype=np.float64).reshape(shape)
    except (TypeError, ValueError) as exc:
        raise VibrInputError(f"{name} must have shape {shape}: {exc}", source) from None
    if not np.all(np.isfinite(m)):
        raise VibrInputError(f"{name} has non-finite entries", source)
    return m


def image_side(v, name, source) -> int:
    """An image side: an integer (or an integral float, as JSON writers give); a bool, a
    string or 64.5 is refused rather than truncated."""
    number = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))
    if not (number and np.isfinite(v) and float(v) == int(v)):
        raise VibrInputError(f"{name} must be an integer number of pixels, got {v!r}", source)
    return int(v)


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera with its image size.

    Parameters
    ----------
    K : (3, 3) array
        Intrinsics, upper triangular, positive focal lengths, in vibr's pixel convention
        (centre of the top-left pixel at (0, 0)).
    R : (3, 3) array
        World-to-camera rotation.
    t : (3,) array
        World-to-camera translation; the centre is ``C = -R.T @ t``.
    width, height : int
        Image size in pixels.
    source : str, optional
        Where the camera came from (a file name), used in error messages.

    The projection is ``x̃ = K (R X + t)``, ``(x, y) = (x̃₁/x̃₃, x̃₂/x̃₃)`` (Nieto et al.
    2016, §5.2).

    Examples
    --------
    A 64×48 camera at the origin looking down +z, its principal point at the image centre:

    >>> K = np.array([[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]])
    >>> cam = Camera(K, np.eye(3), np.zeros(3), 64, 48)
    >>> xy, z = cam.project([[0.1, -0.2, 2.0]])
    >>> xy.tolist(), z.tolist()
    ([[36.5, 13.5]], [2.0])
    >>> np.round(cam.backproject(xy, z), 12).tolist()
    [[0.1, -0.2, 2.0]]
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    source: str | None = field(default=None, compare=False)

    def __post_init__(self):
        src = self.source
        K = _as_matrix(self.K, (3, 3), "K", src)
        R = _as_matrix(self.R, (3, 3), "R", src)
        t = _as_matrix(self.t, (3,), "t", src)
        if K[0, 0] <= 0 or K[1, 1] <= 0 or abs(K[2, 2] - 1) > 1e-9 or np.any(K[[1, 2, 2], [0, 0, 1]] != 0):
            raise VibrInputError(
                "K must be upper triangular with positive focal lengths and K[2,2] = 1", src
            )
        err = np.abs(R @ R.T - np.eye(3)).max()
        if err > _ORTHO_TOL or np.linalg.det(R) < 0:
            raise VibrInputError(
                f"R is not a rotation (|R Rᵀ - I| = {err:.2g}, det = {np.linalg.det(R):.3g})", src
            )
        w, h = image_side(self.width, "width", src), image_side(self.height, "height", src)
        if w <= 0 or h <= 0:
            raise VibrInputError(f"image size must be positive, got {w}x{h}", src)
        for name, val in (("K", K), ("R", R), ("t", t)):
            val.setflags(write=False)
            object.__setattr__(self, name, val)
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "height", h)

    # ---------------------------------------------------------------- constructors
    @classmethod
    def from_centre(cls, K, R, C, width, height, source=None) -> "Camera":
        """Camera from intrinsics, world-to-camera rotation and centre ``C`` (world)."""
        R = np.asarray(R, dtype=np.float64)
        return cls(K, R, -R @ np.asarray(C, dtype=np.float64), width, height, source)

    @classmethod
    def look_at(cls, eye, target, up, K, width, height) -> "Camera":
        """Camera at ``eye`` looking at ``target``; ``up`` is the world up direction
        (the image's y axis points opposite to it)."""
        eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
        z = target - eye
        z /= np.linalg.norm(z)
        x = np.cross(-up, z)
        if np.linalg.norm(x) < 1e-12:
            raise ValueError("look_at: up is parallel to the viewing direction")
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        R = np.stack([x, y, z])
        return cls.from_centre(K, R, eye, width, height)

    @staticmethod
    def intrinsics(f, width, height, fy=None, cx=None, cy=None) -> np.ndarray:
        """K with focal ``f`` (pixels) and, by default, the principal point at the image
        centre ``((W-1)/2, (H-1)/2)``."""
        fy = f if fy is None else fy
        cx = (width - 1) / 2 if cx is None else cx
        cy = (height - 1) / 2 if cy is None else cy
        return np.array([[f, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64)

    # ---------------------------------------------------------------- properties
    @property
    def centre(self) -> np.ndarray:
        """Camera centre in world coordinates, ``C = -Rᵀ t``."""
        return -self.R.T @ self.t

    @property
    def K_inv(self) -> np.ndarray:
        return np.linalg.inv(self.K)

    @property
    def P(self) -> np.ndarray:
        """3×4 projection matrix ``K [R | t]``."""
        return self.K @ np.hstack([self.R, self.t[:, None]])

    @property
    def optical_axis(self) -> np.ndarray:
        """Unit viewing direction (camera +z) in world coordinates."""
        return self.R[2].copy()

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)``, the shape of this camera's images."""
        return (self.height, self.width)

    @property
    def c2w(self) -> np.ndarray:
        """4×4 camera-to-world matrix (OpenCV axes: x right, y down, z forward)."""
        M = np.eye(4)
        M[:3, :3] = self.R.T
        M[:3, 3] = self.centre
        return M

    # ---------------------------------------------------------------- maps
    def world_to_camera(self, X) -> np.ndarray:
        """(..., 3) world points → (..., 3) camera coordinates."""
        return np.asarray(X, dtype=np.float64) @ self.R.T + self.t

    def camera_to_world(self, Xc) -> np.ndarray:
        """(..., 3) camera coordinates → (..., 3) world points."""
        return (np.asarray(Xc, dtype=np.float64) - self.t) @ self.R

    def project(self, X) -> tuple[np.ndarray, np.ndarray]:
        """Project (..., 3) world points: returns pixel coordinates (..., 2) and
        orthogonal depth (...). Points behind the camera get depth ≤ 0 (their pixel
        coordinates are meaningless)."""
        Xc = self.world_to_camera(X)
        xh = Xc @ self.K.T
        z = Xc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = xh[..., :2] / xh[..., 2:3]
        return xy, z

    def sees(self, X) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Project (N, 3) world points: ``(xy, z, inside)``, ``inside`` where a point is in
        front of the camera and within the image (pixel centres at integers, so the image
        spans ``[−½, W − ½] × [−½, H − ½]``)."""
        xy, z = self.project(X)
        inside = (z > 0) & (xy[..., 0] >= -0.5) & (xy[..., 0] <= self.width - 0.5) & \
                 (xy[..., 1] >= -0.5) & (xy[..., 1] <= self.height - 0.5)
        return xy, z, inside

    def pixel_rays(self, xy) -> np.ndarray:
        """(..., 2) pixels → (..., 3) camera-frame rays ``K⁻¹ x̄`` with unit third
        coordinate (so ``depth * ray`` is the camera-frame point)."""
        xy = np.asarray(xy, dtype=np.float64)
        xh = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
        return xh @ self.K_inv.T

    def backproject(self, xy, depth) -> np.ndarray:
        """(..., 2) pixels with orthogonal ``depth`` (...) → (..., 3) world points."""
        rays = self.pixel_rays(xy)
        return self.camera_to_world(rays * np.asarray(depth, dtype=np.float64)[..., None])

    def pixel_grid(self) -> np.ndarray:
        """H×W×2 array of pixel-centre coordinates ``(x, y) = (col, row)``."""
        y, x = np.mgrid[0 : self.height, 0 : self.width].astype(np.float64)
        return np.stack([x, y], axis=-1)

    def scaled(self, s: float) -> "Camera":
        """The same camera for images resized by factor ``s`` (new size rounded).

        With pixel centres at integer coordinates, a resize maps ``x' = s (x + ½) − ½``.
        """
        w, h = max(1, int(round(self.width * s))), max(1, int(round(self.height * s)))
        sx, sy = w / self.width, h / self.height
        S = np.array([[sx, 0, 0.5 * sx - 0.5], [0, sy, 0.5 * sy - 0.5], [0, 0, 1.0]])
        return Camera(S @ self.K, self.R, self.t, w, h, self.source)

    def with_size(self, width: int, height: int) -> "Camera":
        return Camera(self.K, self.R, self.t, width, height, self.source)

    def turned(self, k: int) -> "Camera":
        """The same camera rolled by ``k`` quarter turns about its optical axis: the camera
        of the image turned clockwise ``k`` times (``np.rot90(image, -k)``, size W×H for
        odd ``k``).

        One quarter turn maps pixels ``(u, v) -> (H - 1 - v, u)`` (``Q``) and camera axes
        ``(x, y, z) -> (-y, x, z)`` (``R_z``): ``K' = Q K R_zᵀ``, ``R' = R_z R``, so that
        ``K' [R' | t'] = Q K [R | t]``. A skewed ``K`` has no such turn (``K'`` would not be
        upper triangular): refused."""
        k = int(k) % 4
        if k and self.K[0, 1] != 0:
            raise VibrInputError("a camera with a skewed K cannot be turned by quarter turns", self.source)
        cam = self
        Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        for _ in range(k):
            Q = np.array([[0.0, -1.0, cam.height - 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
            cam = Camera.from_centre(Q @ cam.K @ Rz.T, Rz @ cam.R, cam.centre, cam.height, cam.width, self.source)
        return cam

    def allclose(self, other: "Camera", atol: float = 1e-9) -> bool:
        return (
            self.width == other.width
            and self.height == other.height
            and np.allclose(self.K, other.K, atol=atol, rtol=0)
            and np.allclose(self.R, other.R, atol=atol, rtol=0)
            and np.allclose(self.t, other.t, atol=atol, rtol=0)
        )

    def to_dict(self) -> dict:
        return {
            "K": self.K.tolist(),
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "width": self.width,
            "height": self.height,
        }

    @classmethod
    def from_dict(cls, d: dict, source=None) -> "Camera":
        try:
            return cls(d["K"], d["R"], d["t"], d["width"], d["height"], source)
        except KeyError as exc:
            raise VibrInputError(f"camera is missing key {exc}", source) from None

    def __repr__(self) -> str:
        f = self.K[0, 0]
        C = np.array2string(self.centre, precision=3, suppress_small=True)
        return f"Camera({self.width}x{self.height}, f={f:.1f}px, C={C})"


#: Cameras share one centre when every centre lies within ``SHARED_CENTRE_REL`` times the
#: scene's depth scale (the median distance of its sparse points) of their mean: then the
#: parallax is below a millionth of the focal length, no depth can be estimated and none is
#: needed. Without points the scale of the scene is unknown, and the centres must agree to
#: ``SHARED_CENTRE_ABS`` times their distance from the origin (at least 1): one point up to
#: rounding, wherever the coordinates' origin lies (georeferenced scenes sit 10⁵–10⁶ units
#: from it, with baselines of a metre).
SHARED_CENTRE_REL = 1e-6
SHARED_CENTRE_ABS = 1e-9


def shared_centre(cameras, points=None) -> np.ndarray | None:
    """The common centre of cameras that all sit at one point (a rotation-only capture:
    a panorama from a tripod), else None (:data:`SHARED_CENTRE_REL`,
    :data:`SHARED_CENTRE_ABS`)."""
    C = np.array([c.centre for c in cameras], dtype=np.float64)
    if len(C) < 2:
        return None
    mean = C.mean(axis=0)
    spread = float(np.linalg.norm(C - mean, axis=1).max())
    scale = 0.0
    if points is not None and len(points):
        scale = SHARED_CENTRE_REL * float(np.median(np.linalg.norm(np.asarray(points, np.float64) - mean, axis=1)))
    tol = scale if scale > 0 else SHARED_CENTRE_ABS * max(1.0, float(np.linalg.norm(mean)))
    return mean if spread <= tol else None


def axes_meeting_point(cameras, max_cond: float = 1e6) -> np.ndarray | None:
    """The point nearest to every camera's optical axis (least squares), or None.

    Minimises ``Σ_k ‖(I − a_k a_kᵀ)(X − C_k)‖²`` over X (``a_k`` the unit axis, ``C_k`` the
    centre): ``(Σ P_k) X = Σ P_k C_k`` with ``P_k = I − a_k a_kᵀ``. Cameras that look at a
    common object (a ring, an arc, hand-held photos of a thing) meet there; cameras with
    (nearly) parallel axes (a light-field grid) do not, and None is returned, as it is when
    the point lies behind most of the cameras.
    """
    cams = list(cameras)
    if len(cams) < 2:
        return None
    M = np.zeros((3, 3))
    rhs = np.zeros(3)
    for c in cams:
        a = c.optical_axis
        P = np.eye(3) - np.outer(a, a)
        M += P
        rhs += P @ c.centre
    if np.linalg.cond(M) > max_cond:
        return None
    X = np.linalg.solve(M, rhs)
    in_front = [float((X - c.centre) @ c.optical_axis) > 0 for c in cams]
    if np.mean(in_front) < 0.5:
        return None
    # parallel-ish axes give a well-posed but meaningless point very far away: require the
    # point to be nearer the axes than the cameras are to each other's spread
    spread = np.max([np.linalg.norm(c.centre - cams[0].centre) for c in cams])
    miss = np.sqrt(np.mean([np.sum(((np.eye(3) - np.outer(c.optical_axis, c.optical_axis)) @ (X - c.centre)) ** 2)
                            for c in cams]))
    if spread <= 0 or miss > spread:
        return None
    return X
