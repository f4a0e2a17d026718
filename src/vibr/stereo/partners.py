"""The geometry between a reference view and its stereo partners: which partners
(nearest first, completed where they leave the reference's frustum unseen), the depth range
the sweep covers, and maps moved between the sweep's resolution and the images'.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates

from ..camera import Camera, axes_meeting_point
from ..geometry.resample import resize_image
from ..scene import Scene
from .planesweep import SweepResult, plane_sweep


def _resized(img: np.ndarray, camera: Camera) -> np.ndarray:
    """``img`` at ``camera``'s size (:func:`vibr.geometry.resample.resize_image`: Gaussian
    anti-aliasing only, reflected border, float32 not quantised)."""
    return resize_image(img, camera.shape, box=False, mode="reflect", quantise=False)


def _lo_coords(camera_lo: Camera, camera_hi: Camera) -> list[np.ndarray]:
    """``[y_lo, x_lo]`` of every pixel of ``camera_hi``'s grid on ``camera_lo``'s, by the
    resize mapping of :meth:`Camera.scaled`, ``x_lo = s (x + ½) − ½`` (for map_coordinates)."""
    Hh, Wh = camera_hi.shape
    yy, xx = np.mgrid[0:Hh, 0:Wh].astype(np.float64)
    return [camera_lo.height / camera_hi.height * (yy + 0.5) - 0.5,
            camera_lo.width / camera_hi.width * (xx + 0.5) - 0.5]


def upsample_depth(depth: np.ndarray, camera_lo: Camera, camera_hi: Camera) -> np.ndarray:
    """Bring a depth map (NaN unknown) from ``camera_lo``'s grid to ``camera_hi``'s.

    Pixel x of the high-resolution grid sits at ``x_lo = s (x + ½) − ½`` (the mapping of
    :meth:`Camera.scaled`). Inverse depth is interpolated bilinearly where the four
    low-resolution neighbours are known, nearest-neighbour elsewhere (NaN stays NaN).
    """
    if depth.shape == camera_hi.shape:
        return depth
    yl, xl = _lo_coords(camera_lo, camera_hi)
    known = np.isfinite(depth)
    w = np.where(known, 1.0 / np.where(known, depth, 1.0), 0.0)
    wi = map_coordinates(w, [yl, xl], order=1, mode="nearest")
    ki = map_coordinates(known.astype(np.float64), [yl, xl], order=1, mode="nearest")
    dn = map_coordinates(np.where(known, depth, np.nan), [yl, xl], order=0, mode="nearest")
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(ki > 1 - 1e-9, 1.0 / wi, dn)
    return out.astype(np.float32)


def upsample_sweep(res: SweepResult, camera_lo: Camera, camera_hi: Camera) -> SweepResult:
    """A plane-sweep (or coarse refinement) result computed on ``camera_lo``'s grid,
    brought to ``camera_hi``'s as an initialisation of
    :func:`~vibr.stereo.planesweep.refine_planes`: inverse depth bilinear (every pixel of a
    sweep has one), its inverse-depth width (sigma_z / z²) and ``confident``
    nearest-neighbour; the planes ``winv`` are the same. A coarse refinement's per-pixel
    slopes (``meta["plane_gradient"]``, on the coarse grid) are dropped: the full-size
    refinement starts from the finite differences of the upsampled inverse depth."""
    yl, xl = _lo_coords(camera_lo, camera_hi)
    w = map_coordinates(np.asarray(res.inv_depth, np.float64), [yl, xl], order=1, mode="nearest")
    sigma_w = res.sigma_z.astype(np.float64) * np.asarray(res.inv_depth, np.float64) ** 2
    sigma_w = map_coordinates(sigma_w, [yl, xl], order=0, mode="nearest")
    z = 1.0 / w
    meta = {k: v for k, v in res.meta.items() if k != "plane_gradient"}
    return SweepResult(depth=z.astype(np.float32), inv_depth=w,
                       cost=map_coordinates(res.cost, [yl, xl], order=0, mode="nearest"),
                       sigma_z=(z * z * sigma_w).astype(np.float32),
                       confident=map_coordinates(res.confident.astype(np.uint8), [yl, xl], order=0,
                                                 mode="nearest").astype(bool),
                       winv=res.winv, meta=meta)


def upsample_map(m: np.ndarray, camera_lo: Camera, camera_hi: Camera) -> np.ndarray:
    """Nearest-neighbour resampling of a per-pixel map (e.g. sigma_z) to ``camera_hi``."""
    if m.shape == camera_hi.shape:
        return m
    yl, xl = _lo_coords(camera_lo, camera_hi)
    return map_coordinates(m, [yl, xl], order=0, mode="nearest").astype(np.float32)


def select_neighbours(cameras: list[Camera], ref: int, candidates: list[int], k: int,
                      max_angle_deg: float = 60.0) -> list[int]:
    """The ``k`` candidate views best suited as stereo partners of view ``ref``.

    Candidates whose optical axis turns by more than ``max_angle_deg`` from the
    reference's, or whose centre coincides with it, are dropped; the rest are ranked by the
    distance between centres (the nearest first: small baselines match best, and the
    plane sweep's robust aggregation copes with the loss of depth precision).
    """
    cr = cameras[ref]
    scored = sorted((float(np.linalg.norm(cameras[j].centre - cr.centre)), j) for j in candidates
                    if j != ref and _admissible(cr, cameras[j], max_angle_deg))
    return [j for _, j in scored[:k]]


def _admissible(ref: Camera, cam: Camera, max_angle_deg: float) -> bool:
    """A stereo partner for ``ref``: its optical axis within ``max_angle_deg`` of the
    reference's and its centre elsewhere (a zero baseline has no parallax)."""
    cosang = float(np.clip(ref.optical_axis @ cam.optical_axis, -1, 1))
    return np.degrees(np.arccos(cosang)) <= max_angle_deg and np.linalg.norm(cam.centre - ref.centre) >= 1e-12


def frustum_coverage(ref: Camera, srcs: list[Camera], depth_range, *, n_xy: int = 24,
                     n_depth: int = 8) -> np.ndarray:
    """Which source views see samples of the reference's viewing frustum.

    The reference image is sampled on an ``n_xy``-wide grid (rows in proportion) at
    ``n_depth`` depths uniform in inverse depth over ``depth_range`` (near, far); a sample
    is seen by a source when it lies in front of it and projects inside its image.
    Occlusions are ignored (the geometry is not known yet). Returns (n_src, n_samples) bool.
    """
    near, far = float(depth_range[0]), float(depth_range[1])
    ny = max(2, int(round(n_xy * ref.height / ref.width)))
    xs = (np.arange(n_xy) + 0.5) * ref.width / n_xy - 0.5
    ys = (np.arange(ny) + 0.5) * ref.height / ny - 0.5
    xy = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    z = 1.0 / np.linspace(1.0 / far, 1.0 / near, n_depth)
    X = ref.camera_to_world(ref.pixel_rays(xy)[None] * z[:, None, None]).reshape(-1, 3)
    seen = np.zeros((len(srcs), len(X)), bool)
    for v, c in enumerate(srcs):
        p, zc = c.project(X)
        seen[v] = (zc > 0) & (p[:, 0] > -0.5) & (p[:, 1] > -0.5) & (p[:, 0] < c.width - 0.5) & (p[:, 1] < c.height - 0.5)
    return seen


def complete_coverage(cameras: list[Camera], ref: int, chosen: list[int], candidates: list[int],
                      depth_range, n_need: int, *, min_gain: float = 0.02, max_extra: int = 4,
                      max_angle_deg: float = 60.0) -> list[int]:
    """Add partners to ``chosen`` until the reference's frustum is seen by ``n_need`` views.

    Nearest-first partners (:func:`select_neighbours`) can all sit on one side of a free
    (hand-held) layout and leave part of the reference image, e.g. the near ground at its
    bottom, outside every partner, where no depth can be matched. Here the frustum
    samples of :func:`frustum_coverage` seen by fewer than ``n_need`` chosen views are the
    deficit, and the candidate that removes the most of it is added, as long as it
    removes at least ``min_gain`` of the samples (a partner costs as much time as any
    other; a sliver of coverage is not worth it), at most ``max_extra`` times. This is
    the coverage side of Goesele et al. (2007, §4.1)'s view selection; candidates turned
    by more than ``max_angle_deg`` from the reference are not considered.
    """
    cr = cameras[ref]
    pool = [j for j in candidates
            if j != ref and j not in chosen and _admissible(cr, cameras[j], max_angle_deg)]
    out = list(chosen)
    if not pool or n_need < 1:
        return out
    seen = frustum_coverage(cr, [cameras[j] for j in out + pool], depth_range)
    count = seen[: len(out)].sum(0)
    pool_seen = dict(zip(pool, seen[len(out):]))
    for _ in range(max_extra):
        short = count < n_need
        if not short.any() or not pool_seen:
            break
        best = max(pool_seen, key=lambda j: (pool_seen[j] & short).mean())
        if (pool_seen[best] & short).mean() < min_gain:
            break
        out.append(best)
        count = count + pool_seen.pop(best)
    return out


def _ray_parallax(ref: Camera, src: Camera):
    """``f(w)``: the largest distance, in ``src``'s pixels, between the points at inverse
    depth ``w`` and at infinity of nine rays of the reference (a 3×3 grid at 10, 50 and 90 %
    of its width and height); inf where such a point is not in front of ``src``. Exact (the
    plane homography is projective in ``w``) and the same in any unit of length; several
    rays, because a partner ahead or behind puts its epipole, where parallax vanishes, near
    the image centre. Returns ``(f, baseline)``."""
    g = np.array([0.1, 0.5, 0.9])
    xy = np.stack(np.meshgrid(g * (ref.width - 1), g * (ref.height - 1)), -1).reshape(-1, 2)
    rays = ref.pixel_rays(xy)
    b = max(float(np.linalg.norm(src.centre - ref.centre)), 1e-300)
    xy_inf = src.project(ref.camera_to_world(rays * (1e12 * b)))[0]

    def f(w: float) -> float:
        if w <= 0:
            return 0.0
        xy_w, z = src.project(ref.camera_to_world(rays / w))
        return float(np.linalg.norm(xy_w - xy_inf, axis=-1).max()) if np.all(z > 0) else np.inf

    return f, b


def _near_inverse_depth(ref: Camera, src: Camera, parallax_px: float) -> float:
    """The inverse depth of the reference's plane at which ``src`` sees ``parallax_px``
    pixels of parallax (bisection on :func:`_ray_parallax`; parallax grows with ``w`` until
    a point leaves ``src``'s front)."""
    f, b = _ray_parallax(ref, src)
    lo, hi = 0.0, 1e-6 / b
    while f(hi) < parallax_px and hi < 1e12 / b:
        lo, hi = hi, 2.0 * hi
    if f(hi) < parallax_px:  # never that much parallax (a degenerate pair): the baseline's depth
        return 1.0 / b
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) < parallax_px else (lo, mid)
    return hi


def default_depth_range(scene: Scene, ref: int, cameras: list[Camera], images: dict,
                        neighbours: list[int], *, coarse_width: int = 192,
                        max_parallax: float = 0.5, margin: float = 0.15,
                        use_points: bool = True, cache: dict | None = None) -> tuple[float, float]:
    """A depth range for the reference view when none is given.

    1. Sparse points (``scene.points``), when present: the 2nd–98th percentile of the
       depths of the points that project into the reference, widened by ``margin``.
    2. Otherwise a coarse plane sweep at ``coarse_width`` pixels over a wide range, from
       the plane whose parallax with the nearest neighbour is ``max_parallax`` × image width
       (near) to 100× that depth (far), extended to cover ``[z_c / 4, 4 z_c]`` when the
       cameras' optical axes meet at a depth ``z_c`` (:func:`vibr.camera.axes_meeting_point`)
       and ``[z_c / 2, 2 z_c]`` is not already inside,
       uniform in inverse depth; the 2nd–98th percentile of the confident coarse inverse
       depths, widened by ``margin`` of their span.

    ``cache``: a dict kept across calls (views) for the resized images of step 2, keyed
    by view and size, so that each image is resized once per scene rather than once per
    reference that uses it.
    """
    cam = cameras[ref]
    if use_points and scene.points is not None and len(scene.points) >= 20:
        xy, z = cam.project(np.asarray(scene.points, np.float64))
        inside = (z > 0) & (xy[:, 0] >= 0) & (xy[:, 0] <= cam.width - 1) & (xy[:, 1] >= 0) & (xy[:, 1] <= cam.height - 1)
        if inside.sum() >= 20:
            lo, hi = np.percentile(z[inside], [2, 98])
            span = hi - lo
            return float(max(lo - margin * span, lo * 0.5)), float(hi + margin * span)
    w_max = _near_inverse_depth(cam, cameras[neighbours[0]], max_parallax * cam.width)
    w_min = w_max / 100.0
    # Cameras that converge on an object (a ring, an arc) put it near the point their axes
    # meet. A wide baseline can put that point nearer than the half-image parallax limit
    # above: when a factor 2 around its depth is not inside the sweep, widen the sweep to a
    # factor 4 around it.
    X = axes_meeting_point([cameras[ref]] + [cameras[j] for j in neighbours])
    if X is not None:
        z_c = float((X - cam.centre) @ cam.optical_axis)
        if z_c > 0 and not (w_min <= 0.5 / z_c and 2.0 / z_c <= w_max):
            w_max = max(w_max, 4.0 / z_c)
            w_min = min(w_min, 0.25 / z_c)
    s = min(1.0, coarse_width / cam.width)
    cref = cam.scaled(s)
    csrc = [cameras[j].scaled(s) for j in neighbours]
    n_planes = int(np.clip(np.ceil(max_parallax * cref.width / 0.75), 32, 256))
    cache = {} if cache is None else cache

    def small(j, c):
        key = (j, c.shape)
        if key not in cache:
            cache[key] = _resized(images[j], c)
        return cache[key]

    res = plane_sweep(small(ref, cref), cref, [small(j, c) for j, c in zip(neighbours, csrc)], csrc,
                      (1.0 / w_max, 1.0 / w_min), n_planes=n_planes, radius=2,
                      desc="coarse depth range")
    good = res.confident & (res.cost < 0.5 * res.meta.get("max_cost", 0.6))
    w = res.inv_depth[good]
    if w.size < 50:
        return 1.0 / w_max, 1.0 / w_min
    lo, hi = np.percentile(w, [3, 97])
    span = max(hi - lo, 1e-9 * hi)
    lo = max(lo - margin * span, w_min)
    hi = min(hi + margin * span, w_max)
    return float(1.0 / hi), float(1.0 / lo)

