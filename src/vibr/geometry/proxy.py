"""Planar geometric proxy (paper §6, second structured experiment).

The coarsest proxy: a fronto-parallel plane of the *target* camera at depth ``D``
(target-frame orthogonal depth), with a large depth uncertainty sigma_z so that the
geometric weights (docs/explanation/method.md §3) let the variational model, not the proxy, decide.

For a source pixel with ray ``r = R_kᵀ K_k⁻¹ x̄`` (world, scaled so that orthogonal source
depth s gives the point ``C_k + s r``), the plane ``n·X + d_u = D`` with ``n = R_u[2]``,
``d_u = t_u[2]`` is met at ``s = (D − n·C_k − d_u) / (n·r)``; pixels whose ray does not
meet the plane in front of both cameras get NaN.
"""

from __future__ import annotations

import numpy as np

from ..camera import Camera, axes_meeting_point, shared_centre
from ..errors import VibrInputError
from ..scene import Scene, View
from .depth import DEFAULT_SIGMA_Z_REL

__all__ = ["planar_proxy", "plane_depth", "PROXY_SIGMA_Z_REL", "PROXY_SPREAD_REL", "PROXY_Z_CORR", "sphere_proxy", "fallback_depth", "apply_fallback", "flat_pixels", "complete_depth", "FALLBACK_MODES",
           "FALLBACK_FLAT_STD", "FALLBACK_FACTOR", "backdrop_pixels", "backdrop_windows", "carve_silhouettes",
           "FALLBACK_SIGMA_Z_REL", "FALLBACK_PERCENTILE", "BACKDROP_SIGMA_Z_REL"]

#: Default planar-proxy uncertainty: ``sigma_z = max(PROXY_SIGMA_Z_REL · D,
#: PROXY_SPREAD_REL · (p95 − p5))``, the p the percentiles of the available depth seen from
#: the target. Chosen across scenes with a held-out split (``benchmarks/quality/planar_sigma_z.py``,
#: docs/explanation/renderer.md, "The planar proxy's sigma_z"): a fifth of the former rule
#: ``max(0.1 D, ½ (p95 − p5))``, which let TV and the gradient term blur every edge the
#: plane misplaces.
PROXY_SIGMA_Z_REL = 0.02
PROXY_SPREAD_REL = 0.1

#: Correlation of the views' depth errors when one proxy stands in for every view's depth
#: (``meta["proxy"]``: the plane, the sphere): the render's ``z_corr`` for their samples
#: (:func:`vibr.render.weights.shared_error_beta`). Chosen across scenes with a held-out split
#: (``benchmarks/quality/shared_depth_error.py``, docs/explanation/renderer.md, "Depth errors the views share");
#: per-view depth (ground truth, estimated, files) keeps the paper's independent errors, 0.
PROXY_Z_CORR = 0.9


def plane_depth(camera: Camera, target: Camera, D: float) -> np.ndarray:
    """(H, W) float32 source orthogonal depth of the target's fronto-parallel plane at
    target depth ``D``; NaN where the ray misses it or meets it behind a camera."""
    H, W = camera.shape
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    xb = np.stack([x, y, np.ones_like(x)], axis=-1)
    r = xb @ (camera.R.T @ np.linalg.inv(camera.K)).T
    n = target.R[2]
    den = r @ n
    num = D - n @ camera.centre - target.t[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = num / den
    s[~(np.isfinite(s) & (s > 0))] = np.nan
    return s.astype(np.float32)


def sphere_proxy(scene: Scene, centre, radius: float | None = None,
                 sigma_rel: float = 0.25) -> Scene:
    """Every view's depth: the sphere of ``radius`` around ``centre``, the cameras' shared
    centre (:func:`vibr.camera.shared_centre`).

    From one centre the images do not depend on depth (the warp between two views is a
    homography: ``∂τ/∂z = 0``), so any surface renders a view from that centre exactly; a
    sphere around it is one surface that every view agrees on, so the visibility test keeps
    all their samples (a plane per view would put each view's surface at its own depth as
    the target sees it, and the nearest would hide the others). Orthogonal depth of pixel
    ``x̄``: ``z = radius / ‖K⁻¹ x̄‖`` (a camera at the centre).

    Parameters
    ----------
    radius : float, optional
        Scene units; default the median distance of the scene's sparse points to the centre,
        else 1.
    sigma_rel : float
        ``sigma_z = sigma_rel · radius`` (only a target away from the centre sees it).

    Returns
    -------
    Scene with ``meta["proxy"] = {"kind": "sphere", "centre", "radius", "sigma_z"}``.
    """
    centre = np.asarray(centre, np.float64)
    if radius is None:
        pts = scene.points
        radius = float(np.median(np.linalg.norm(pts - centre, axis=1))) if pts is not None and len(pts) else 1.0
    radius = float(radius)
    if not (np.isfinite(radius) and radius > 0):
        raise VibrInputError(f"sphere proxy: radius must be positive, got {radius}", scene.root)
    views = []
    for v in scene.views:
        rays = v.camera.pixel_rays(v.camera.pixel_grid())
        views.append(v.replace(depth=(radius / np.linalg.norm(rays, axis=-1)).astype(np.float32),
                               sigma_z=sigma_rel * radius))
    meta = dict(scene.meta, proxy={"kind": "sphere", "centre": centre.tolist(), "radius": radius,
                                   "sigma_z": sigma_rel * radius})
    return scene.replace(views=views, meta=meta)


def _target_depths(sources: Scene, target: Camera, stride: int = 4) -> np.ndarray:
    out = []
    for v in sources.views:
        if v.depth is None:
            continue
        d = v.depth[::stride, ::stride]
        yy, xx = np.mgrid[0:v.camera.height:stride, 0:v.camera.width:stride]
        ok = np.isfinite(d)
        if not ok.any():
            continue
        X = v.camera.backproject(np.stack([xx[ok], yy[ok]], -1).astype(np.float64), d[ok])
        w = target.project(X)[1]
        out.append(w[w > 0])
    if not out and sources.points is not None and len(sources.points):
        w = target.project(sources.points)[1]
        out.append(w[w > 0])
    return np.concatenate(out) if out else np.zeros(0)


def _axes_depth(sources: Scene, target: Camera) -> tuple[float, str]:
    """(depth in ``target`` of the point the sources' optical axes meet at, how it was
    placed); a one-line error when they do not meet in front of ``target`` (parallel axes: a
    light-field grid). Sources that share one centre (a rotation-only capture) see the same
    image through any surface (``∂τ/∂z = 0``): the plane then sits at depth 1, the radius
    :func:`sphere_proxy` takes without points."""

    cams = [v.camera for v in sources.views]
    if shared_centre(cams) is not None:
        return 1.0, "shared centre (any depth renders the same)"
    X = axes_meeting_point(cams)
    d = float(target.project(X[None])[1][0]) if X is not None else 0.0
    if not d > 0:
        raise VibrInputError("planar proxy: the sources have no depth maps or sparse points seen from the "
                             "target, and their optical axes do not meet in front of it, to place the plane at "
                             "(depth estimated from the photographs needs none: --depth estimated)", sources.root)
    return d, "optical axes"


def planar_proxy(sources: Scene, target_camera, depth: float | None = None,
                 sigma_z: float | None = None) -> Scene:
    """Replace every source depth map by a fronto-parallel plane of the target camera.

    Parameters
    ----------
    sources : Scene
    target_camera : Camera or View
    depth : float, optional
        Plane depth in the target frame (scene units). Default: the median of the
        available depth (source depth maps, else sparse points) seen from the target; with
        neither, the depth of the point the sources' optical axes meet at
        (:func:`vibr.camera.axes_meeting_point`: a ring, an arc or hand-held photos of an
        object), sigma_z then its ``PROXY_SIGMA_Z_REL`` floor.
    sigma_z : float, optional
        Depth uncertainty given to every view; default
        ``max(PROXY_SIGMA_Z_REL·D, PROXY_SPREAD_REL·(p95 − p5))`` = ``max(0.02 D, 0.1 (p95 − p5))``
        of the available depth seen from the target.

    Returns
    -------
    Scene with the same views, their ``depth`` the plane and ``sigma_z`` the scalar above;
    ``meta["proxy"] = {"depth": D, "sigma_z": sigma_z}`` (and ``"from"``: how it was placed,
    when no depth or points placed it).
    """
    cam = target_camera.camera if isinstance(target_camera, View) else target_camera
    wd = None
    if depth is None or sigma_z is None:
        wd = _target_depths(sources, cam)
    placed = {}
    if depth is None and wd.size:
        depth = float(np.median(wd))
    elif depth is None:
        depth, how = _axes_depth(sources, cam)
        placed = {"from": how}
    depth = float(depth)
    if not depth > 0:
        raise VibrInputError(f"planar proxy: plane depth must be positive, got {depth}", sources.root)
    if sigma_z is None:
        spread = float(np.percentile(wd, 95) - np.percentile(wd, 5)) if wd is not None and wd.size else 0.0
        sigma_z = max(PROXY_SIGMA_Z_REL * depth, PROXY_SPREAD_REL * spread)
    views = [v.replace(depth=plane_depth(v.camera, cam, depth), sigma_z=float(sigma_z))
             for v in sources.views]
    meta = dict(sources.meta, proxy={"depth": depth, "sigma_z": float(sigma_z), **placed})
    return sources.replace(views=views, meta=meta)


#: Fallback proxy: unknown source pixels get a fronto-parallel plane of their own
#: view at ``FALLBACK_FACTOR`` times the ``FALLBACK_PERCENTILE``-th percentile of the view's
#: known depth (just behind its farthest known depth, beyond the visibility test's 2 %
#: margin; docs/explanation/renderer.md, "Fallback proxy"), with ``sigma_z = FALLBACK_SIGMA_Z_REL`` times
#: that depth.
FALLBACK_FACTOR = 1.03
FALLBACK_PERCENTILE = 99.0
FALLBACK_SIGMA_Z_REL = 0.25
#: sigma_z of the backdrop's plane (:func:`backdrop_pixels`, ``fallback="auto"``), relative to its
#: depth: 0. Its pixels are flat in their photograph, so wherever a depth error moves one it
#: shows the backdrop's colour: the misregistration weight (``sigma_z · ∂τ/∂z · ∇u``) has no
#: colour error to guard against, and the former 0.25 collapsed the backdrop's weight at every
#: silhouette the target shows, where TV and the gradient term then smeared the object over it
#: (docs/explanation/renderer.md, "Fallback proxy"; chosen on the procedural rings among 0.25,
#: 0.05, 0.01 and 0, ``benchmarks/quality/backdrop_carving.py``).
BACKDROP_SIGMA_Z_REL = 0.0
#: ``fallback="auto"``, in every view: the unknown pixels whose photograph is flat, every
#: channel's standard deviation over the ``(2·FLAT_RADIUS+1)²`` window below
#: ``FALLBACK_FLAT_STD`` (intensities in [0, 1]; the depth benchmarks' limit of a textured
#: window, docs/explanation/depth.md). Stereo cannot match them (a plain wall, the sky), and a plane
#: there costs little colour whatever its depth; an unknown *textured* pixel is a stereo
#: failure on a surface, where the plane would be wrong (docs/explanation/renderer.md, "Fallback proxy").
FALLBACK_FLAT_STD = 0.02
FLAT_RADIUS = 3
#: ``"auto"`` (the plane at each view's backdrop, :func:`backdrop_pixels`; its other unknown
#: pixels completed from the view's known depth, :func:`complete_depth`; then the samples
#: that land on another view's backdrop carved, :func:`carve_silhouettes`), ``"always"``
#: (the plane at every unknown pixel), ``"never"``.
FALLBACK_MODES = ("auto", "always", "never")


def flat_pixels(image, radius: int = FLAT_RADIUS, max_std: float = FALLBACK_FLAT_STD) -> np.ndarray:
    """(H, W) bool: the pixels of ``image`` (H, W, C or H, W; [0, 1]) whose ``(2r+1)²``
    window (the border extended by its nearest pixels) has every channel's standard
    deviation below ``max_std``:
    ``max_c √(E_w[I_c²] − E_w[I_c]²) < max_std``."""
    from scipy.ndimage import uniform_filter

    img = np.asarray(image)
    if img.ndim == 2:
        img = img[..., None]
    size = 2 * int(radius) + 1
    worst = np.zeros(img.shape[:2])
    for c in range(img.shape[2]):  # a channel at a time: a large view's temporaries stay a few planes
        ch = img[..., c].astype(np.float64)
        m = uniform_filter(ch, size, mode="nearest")
        var = uniform_filter(ch * ch, size, mode="nearest") - m * m
        np.maximum(worst, np.sqrt(np.maximum(var, 0.0)), out=worst)
    return worst < float(max_std)


def backdrop_pixels(image, unknown, *, core: bool = False) -> np.ndarray:
    """(H, W) bool: a view's backdrop, the unknown-depth pixels of the flat windows
    (:func:`flat_pixels`) centred in a connected region of such window centres (4-connected,
    unknown depth) that reaches the image border.

    What lies beyond the object (a black cloth, a uniform wall behind it, the sky) fills the
    frame around it: flat, so stereo cannot match it, and continuous up to the image's edge.
    A flat face of the object stereo could not match either is closed in by the object's
    textured outline, or by its silhouette, where the window straddling the edge is not flat.
    The backdrop is the whole of its flat windows, not only their centres: the pixels within
    a window's radius of a silhouette are the backdrop's colour (a window holding them is
    flat) but the centre of none, and left out they took the object's completed depth, a
    halo around it in every target. ``core``: the centres only (what
    :func:`carve_silhouettes` carves against: a window's rim beside a silhouette may hold a
    sliver of the object as another view sees it)."""
    from scipy.ndimage import label

    unknown = np.asarray(unknown, bool)
    cand = unknown & flat_pixels(image)
    lab, n = label(cand)
    if n == 0:
        return cand
    edge = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    centres = np.isin(lab, edge[edge > 0])
    return centres if core else backdrop_windows(centres, unknown)


def backdrop_windows(centres, unknown) -> np.ndarray:
    """The unknown pixels of the flat windows centred at ``centres`` (:func:`backdrop_pixels`
    with ``core=True``): the backdrop up to each silhouette."""
    from scipy.ndimage import binary_dilation

    if not centres.any():
        return centres
    size = 2 * FLAT_RADIUS + 1
    return np.asarray(unknown, bool) & binary_dilation(centres, np.ones((size, size), bool))


#: Depths at which :func:`carve_silhouettes` tests a sample: its depth and ``±sigma_z``
#: between (the segment's ends and midpoints), so only a sample that no depth it may have
#: puts on an object in the other view is carved.
CARVE_STEPS = (-1.0, -0.5, 0.0, 0.5, 1.0)


def carve_silhouettes(sources: Scene, backdrop: dict) -> Scene:
    """Silhouette consistency (space carving with the views' backdrops): drop the depth of
    every source pixel that is not backdrop itself whose 3D point, at every depth within
    its ``±sigma_z``, lands on the backdrop of another view (all four pixels of the
    landing point's bilinear cell backdrop, inside that view's frame, in front of it).

    A view's backdrop pixel saw nothing along its ray up to the backdrop, so no surface
    lies on that ray: a sample put there (a stereo mismatch, a completed depth on the
    wrong side of an edge) is a ghost in any target. Dropped, the pixel is left to the
    other views' samples; fallback pixels of the plane (the backdrop) are kept.

    Parameters
    ----------
    backdrop : dict
        view name → (H, W) bool, :func:`backdrop_pixels` of that view (views not in it
        carve nothing).

    Returns
    -------
    The scene with carved pixels NaN (and out of the ``fallback`` mask), and
    ``meta["carved"] = {name: fraction of the view's pixels carved}``.
    """
    from scipy.ndimage import binary_erosion

    # a landing point is on backdrop when its whole bilinear cell is: the mask eroded towards +x, +y
    cells = {n: binary_erosion(m, np.array([[0, 0, 0], [0, 1, 1], [0, 1, 1]], bool), border_value=0)
             for n, m in backdrop.items() if m is not None and m.any()}
    views, info = [], {}
    for v in sources.views:
        others = [(u.camera, cells[u.name]) for u in sources.views if u.name != v.name and u.name in cells]
        z = None if v.depth is None else np.asarray(v.depth, np.float32)
        own = backdrop.get(v.name)
        test = np.zeros(v.camera.shape, bool) if z is None else np.isfinite(z)
        if own is not None:
            test &= ~own
        if not others or not test.any():
            views.append(v)
            continue
        ys, xs = np.nonzero(test)
        zc = z[ys, xs].astype(np.float64)
        sz = np.zeros_like(zc) if v.sigma_z is None else \
            np.broadcast_to(np.asarray(v.sigma_z, np.float64), z.shape)[ys, xs]
        xy = np.stack([xs, ys], -1).astype(np.float64)
        carved = np.zeros(len(zc), bool)
        for cam, cell in others:
            H, W = cell.shape
            on = np.ones(len(zc), bool)
            for step in CARVE_STEPS:
                d = np.maximum(zc + step * sz, 1e-6 * zc)
                uv, w = cam.project(v.camera.backproject(xy, d))
                x0, y0 = np.floor(uv[:, 0]), np.floor(uv[:, 1])
                inside = (w > 0) & (x0 >= 0) & (y0 >= 0) & (x0 < W - 1) & (y0 < H - 1)
                hit = np.zeros(len(zc), bool)
                hit[inside] = cell[y0[inside].astype(np.int64), x0[inside].astype(np.int64)]
                on &= hit
            carved |= on
        if not carved.any():
            views.append(v)
            continue
        cut = np.zeros(v.camera.shape, bool)
        cut[ys[carved], xs[carved]] = True
        fb = None if v.fallback is None else v.fallback & ~cut
        views.append(v.replace(depth=np.where(cut, np.float32(np.nan), z), fallback=fb))
        info[v.name] = float(cut.mean())
    return sources.replace(views=views, meta=dict(sources.meta, carved=info))


def _push_pull(vals: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Push–pull (Gortler et al. 1996) of ``vals`` (H, W, C) with weights ``weight`` (H, W)
    in [0, 1]: 2×2 weighted means down a pyramid (weights summed, clamped to 1), then each
    level blended with the bilinear enlargement of the coarser one, ``c ← w c + (1 − w)
    up(c')``. Every output is a convex combination of the weighted inputs, the same one for
    every channel; float64."""
    from scipy.ndimage import zoom

    cs, ws = [np.asarray(vals, np.float64)], [np.asarray(weight, np.float64)]
    while max(ws[-1].shape) > 1:
        c, w = cs[-1], ws[-1]
        H, W = w.shape
        h, wd = (H + 1) // 2, (W + 1) // 2
        wp = np.zeros((2 * h, 2 * wd))
        wp[:H, :W] = w
        cp = np.zeros((2 * h, 2 * wd, c.shape[2]))
        cp[:H, :W] = c * w[..., None]
        wsum = wp.reshape(h, 2, wd, 2).sum(axis=(1, 3))
        csum = cp.reshape(h, 2, wd, 2, -1).sum(axis=(1, 3))
        cs.append(csum / np.maximum(wsum, 1e-300)[..., None])
        ws.append(np.minimum(wsum, 1.0))
    for lev in range(len(cs) - 2, -1, -1):
        H, W = ws[lev].shape
        up = zoom(cs[lev + 1], (2, 2, 1), order=1, mode="nearest", grid_mode=True)[:H, :W]
        w = ws[lev][..., None]
        cs[lev] = w * cs[lev] + (1.0 - w) * up
    return cs[0]


def complete_depth(depth: np.ndarray, sigma_z=None, *, spread: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Depth and sigma_z for every pixel of a depth map, its unknown (NaN) pixels completed
    from the known ones around them.

    The inverse depth ``w = 1/z`` is filled by push–pull (:func:`_push_pull`): an unknown
    pixel takes a weighted mean ``E[w]`` of the known depths around it, drawn from a
    neighbourhood as wide as the hole (coarser pyramid levels inside large holes). Its
    sigma_z is the map's own there (what stereo gives an unknown pixel: its view's largest).
    With ``spread``, the former rule, the spread of the neighbourhood's depths
    ``√(E[w²] − E[w]²)``, carried to depth by ``dz = z² dw``, is added in quadrature: beside
    a depth edge it collapsed the completed samples' weights wherever the target has
    texture, where they are the only samples, and TV and the gradient term drew a halo
    there (docs/explanation/renderer.md, "Fallback proxy").

    Parameters
    ----------
    depth : (H, W) array
        Orthogonal depth, NaN unknown; at least one pixel known.
    sigma_z : (H, W) array or float, optional
        The map's own uncertainty (default 0).
    spread : bool
        Add the neighbourhood's spread to the completed pixels' sigma_z.

    Returns
    -------
    z, sigma : (H, W) float32
        Known pixels keep their depth and ``sigma_z``.

    Examples
    --------
    >>> import numpy as np
    >>> z = np.array([[2.0, np.nan, 4.0]])
    >>> zc, s = complete_depth(z, 0.1)
    >>> bool(2.0 < zc[0, 1] < 4.0), float(s[0, 1])
    (True, 0.10000000149011612)
    """
    z = np.asarray(depth, np.float64)
    known = np.isfinite(z) & (z > 0)
    if not known.any():
        raise VibrInputError("complete_depth needs at least one known depth")
    w = np.where(known, 1.0 / np.where(known, z, 1.0), 0.0)
    m = _push_pull(np.stack([w, w * w] if spread else [w], axis=-1), known.astype(np.float64))
    zf = 1.0 / np.maximum(m[..., 0], 1e-300)
    own = np.broadcast_to(np.asarray(0.0 if sigma_z is None else sigma_z, np.float64), z.shape)
    filled = np.nan_to_num(own)
    if spread:
        dev = zf * zf * np.sqrt(np.maximum(m[..., 1] - m[..., 0] ** 2, 0.0))
        filled = np.sqrt(dev ** 2 + filled ** 2)
    return np.where(known, z, zf).astype(np.float32), np.where(known, own, filled).astype(np.float32)


def fallback_depth(sources: Scene, factor: float = FALLBACK_FACTOR,
                   sigma_rel: float = FALLBACK_SIGMA_Z_REL, default_sigma_rel: float | None = None,
                   percentile: float = FALLBACK_PERCENTILE, common: bool = False,
                   min_fraction: float = 0.0, flat_std: float | None = None,
                   complete: bool | str = False, backdrop: bool = False,
                   backdrop_sigma_rel: float = BACKDROP_SIGMA_Z_REL, backdrop_core: bool = False) -> Scene:
    """Give the source pixels of unknown depth (NaN) a fallback proxy: a plane of their view.

    Stereo leaves untextured regions (a black backdrop, the sky, a plain object face)
    without depth; dropped, they leave the renderer nothing but push–pull there, which
    smears the object's colours over what every source shows as background. Here each view
    ``k`` with known depth ``z_k`` gets, at its unknown pixels, the plane of its own camera
    at orthogonal depth

        ``D_k = factor · P_percentile(z_k)``  (default: 1.03 · the 99th percentile)

    with ``sigma_z = sigma_rel · D_k`` (large, so that such a sample's weight collapses
    wherever the image has texture and the samples of known depth, sigma_z ≈ 1 % of the
    depth, win there). Known pixels keep their depth and their sigma_z (the view's own
    map, or ``default_sigma_rel`` · median known depth, the geometry stage's default, made
    explicit because the median would otherwise include the plane). A view with no known
    depth gets the largest ``D_k`` of the others, at its textured pixels too (there is no
    known depth to complete them from); ``common=True`` gives every view that
    largest ``D_k``. In views with less than ``min_fraction`` of their pixels unknown, only
    the unknown pixels :func:`flat_pixels` finds flat at ``flat_std`` get the plane (none
    when ``flat_std`` is None); the others stay unknown, or with ``complete`` take the depth
    :func:`complete_depth` gives them from the view's known depth and its own sigma_z there
    (also marked as fallback; ``complete="spread"``: plus the neighbourhood's spread, the
    former rule). With ``backdrop``, in every view, only the view's backdrop
    (:func:`backdrop_pixels`) gets the plane, with ``sigma_z = backdrop_sigma_rel · D_k``
    (:data:`BACKDROP_SIGMA_Z_REL`), and ``min_fraction`` / ``flat_std`` are not read; its
    other unknown pixels are left, or completed with ``complete``. ``backdrop_core``: the
    backdrop's flat windows' centres only (``backdrop_pixels(..., core=True)``, the former
    rule, measured against by ``benchmarks/quality/backdrop_carving.py``). The geometry
    stage (:func:`vibr.geometry.compute_samples`) hides a fallback sample wherever a known
    surface lands in the target, whatever their depths (known geometry wins: a source facing
    the target has its plane in front of the object); other placements measured in
    docs/explanation/renderer.md.

    Returns the scene with each such view's ``fallback`` mask (:class:`vibr.scene.View`) set
    to the pixels given the plane, and ``meta["fallback"] = {name: {"depth": D_k,
    "fraction": f_k}}`` for the views that have such pixels (``f_k`` their fraction; with
    ``complete``, ``"completed"``: the fraction completed rather than given the plane; with
    ``backdrop``, ``"backdrop"``: the view's backdrop mask, and ``"backdrop_core"``: its flat
    windows' centres, what :func:`carve_silhouettes` tests against).
    """

    dsr = DEFAULT_SIGMA_Z_REL if default_sigma_rel is None else float(default_sigma_rel)
    far = {}
    for v in sources.views:
        if v.depth is not None and np.isfinite(v.depth).any():
            far[v.name] = float(factor) * float(np.percentile(v.depth[np.isfinite(v.depth)], percentile))
    if not far:
        return sources
    views, info = [], {}
    for v in sources.views:
        z = np.full(v.camera.shape, np.nan, np.float32) if v.depth is None else np.asarray(v.depth, np.float32)
        unknown = ~np.isfinite(z)
        if v.mask is not None:  # masked pixels stay out of the render (prepare_depth)
            unknown &= v.mask
        textured = np.zeros_like(unknown)
        bg = None
        if backdrop:
            core = backdrop_pixels(v.image, unknown, core=True)
            bg = core if backdrop_core else backdrop_windows(core, unknown)
            textured = unknown & ~bg if complete else textured
            unknown = bg
        elif unknown.any() and unknown.mean() < min_fraction:
            # a view mostly known: its unknown textured pixels are stereo failures on a surface
            flat = flat_pixels(v.image, max_std=flat_std) if flat_std is not None else np.zeros_like(unknown)
            textured = unknown & ~flat if complete else textured
            unknown = unknown & flat
        if not (unknown.any() or textured.any()):
            views.append(v)
            continue
        D = max(far.values()) if common else far.get(v.name, max(far.values()))
        known = np.isfinite(z)
        if v.sigma_z is not None:
            s = np.broadcast_to(np.asarray(v.sigma_z, np.float32), z.shape).copy()
        else:
            s = np.full(z.shape, dsr * float(np.median(z[known])) if known.any() else 0.0, np.float32)
        z = np.where(unknown, np.float32(D), z)
        s[unknown] = sigma_rel * D
        if bg is not None:  # the backdrop's photograph is flat: a depth error moves it onto the same colour
            s[unknown] = float(backdrop_sigma_rel) * D
        if textured.any() and not known.any():  # nothing to complete from: the plane, as "always" gives it
            z = np.where(textured, np.float32(D), z)
            s[textured] = sigma_rel * D
        elif textured.any():  # a surface stereo missed: its neighbourhood's depth, and how much that varies
            zc, sc = complete_depth(np.where(known, z, np.nan), s, spread=complete == "spread")
            z, s = np.where(textured, zc, z), np.where(textured, sc, s)
        views.append(v.replace(depth=z, sigma_z=s, fallback=unknown | textured))
        info[v.name] = {"depth": D, "fraction": float((unknown | textured).mean())}
        if complete:
            info[v.name]["completed"] = float(textured.mean())
        if bg is not None:
            info[v.name]["backdrop"] = bg
            info[v.name]["backdrop_core"] = core
    return sources.replace(views=views, meta=dict(sources.meta, fallback=info))


def apply_fallback(sources: Scene, mode="auto") -> Scene:
    """The fallback proxy by mode (:data:`FALLBACK_MODES`; True/False read as "always" /
    "never"): the one place :func:`vibr.pipeline.prepare`, :func:`vibr.stereo.cache.scene_with_depth`
    (fly-throughs, the viewer) and the benchmarks decide it. A scene it was applied to
    (``meta["fallback"]`` set) is returned as it is: a second pass would take the first one's
    planes and completed depth for measured depth, and the known layer would no longer hide
    them."""
    mode = {True: "always", False: "never", None: "auto"}.get(mode, mode)
    if mode not in FALLBACK_MODES:
        raise VibrInputError(f"fallback must be one of {', '.join(FALLBACK_MODES)}, got {mode!r}")
    if mode == "never" or "fallback" in sources.meta:
        return sources
    if mode == "always":
        return fallback_depth(sources)
    out = fallback_depth(sources, backdrop=True, complete=True)
    masks = {n: i["backdrop_core"] for n, i in out.meta.get("fallback", {}).items() if "backdrop_core" in i}
    return carve_silhouettes(out, masks)
