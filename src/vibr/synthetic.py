"""Ray-cast synthetic scenes with exact depth: the demo's scene and the main test fixture.

A :class:`World` holds textured finite rectangles (planes), boxes (six rectangles sharing
one object id) and spheres. :meth:`World.raycast` finds the nearest hit of arbitrary rays
(numba, parallel); :func:`render_view` renders a :class:`~vibr.camera.Camera` with
supersampling and returns the image and the exact orthogonal depth (vibr's conventions,
see :mod:`vibr.camera`); :func:`make_scene` builds a whole :class:`~vibr.scene.Scene`
(light-field grid, arc, free or hand-held camera layout).

World coordinates of :func:`default_world` follow the grid cameras' axes: x to the right,
**y down** (world up is ``-y``), z forward, scene units ~ metres. Everything lies in the
bounding box :data:`DEFAULT_BBOX` = x ∈ [-5, 5], y ∈ [-4, 1.5], z ∈ [-1, 6]:

* back wall ``z = 6`` (x ∈ [-5, 5], y ∈ [-4, 1.5]), a photograph tiled with mirrored repeat;
* floor ``y = 1.5`` (x ∈ [-5, 5], z ∈ [-1, 6]), a tinted natural texture (gravel, grass,
  brick);
* a box standing on the floor, rotated about the vertical axis;
* a sphere resting on the floor;
* a tilted card (a small textured rectangle) floating in front, for a thin occluder;
* with ``far`` (``default_world(seed, far=30)``), the back wall stops short of the right and a
  façade far behind shows past its corner: a far background that stereo mostly misses.

Images are band-limited so that a source pixel is well modelled as a bilinear sample of
another view (the renderer's assumption, docs/explanation/method.md §4): textures are pre-smoothed (Gaussian,
sigma 1 texel) and stored as a mip-map pyramid; each ray picks the pyramid level whose
texel matches the pixel footprint ``z / f`` (divided by ``sqrt|cos θ|`` on slanted
surfaces), trilinearly, so that a texel is never smaller than about one image pixel; and
:func:`render_view` averages ``s × s`` sub-pixel rays (box filter). Shading is Lambertian
with a fixed light, hence view-independent, as IBR assumes.
"""

from __future__ import annotations

import math
import types
from functools import lru_cache

import numpy as np
from numba import njit, prange

from .camera import Camera
from .errors import VibrInputError
from .scene import Scene, View

__all__ = [
    "World",
    "default_world",
    "render_view",
    "grid_cameras",
    "arc_cameras",
    "free_cameras",
    "make_scene",
    "ring_scene",
    "RING_KINDS",
    "handheld_cameras",
    "walk_cameras",
    "degrade_depth",
    "photograph",
    "planar_depth",
    "zoom_photos",
    "TEXTURES",
    "DEFAULT_BBOX",
    "DEFAULT_SIGMA_Z",
    "SCENE_CENTRE",
    "FAR_GAP_X",
]

#: Bounding box of :func:`default_world`: ((xmin, xmax), (ymin, ymax), (zmin, zmax)).
DEFAULT_BBOX = ((-5.0, 5.0), (-4.0, 1.5), (-1.0, 6.0))
#: Right edge of the back wall in :func:`default_world` with a far background (world x): the
#: gap to its right shows the far façade.
FAR_GAP_X = 1.2
#: Point the arc and free layouts look at (world coordinates).
SCENE_CENTRE = (0.0, 0.3, 3.6)
#: Depth uncertainty (scene units) given to the exact depth maps of :func:`make_scene`
#: (about 1/1000 of the scene depth range: exact up to float32 rounding and the
#: pixel-centre sampling of depth).
DEFAULT_SIGMA_Z = 0.005

#: Texture side (texels) of the finest pyramid level.
_TEX_SIZE = 512
_N_LEVELS = 8  # 512 .. 4 texels
#: Light direction (towards the light; world up is -y) for view-independent shading.
_LIGHT = np.array([-0.35, -1.0, -0.55]) / np.linalg.norm([-0.35, -1.0, -0.55])
_AMBIENT = 0.6

#: Textures that ship with scikit-image's wheel (no download): name -> (loader, tint).
#: Greyscale ones are tinted so that every channel carries texture.
TEXTURES = {
    "astronaut": ("astronaut", None),
    "coffee": ("coffee", None),
    "chelsea": ("chelsea", None),
    "rocket": ("rocket", None),
    "brick": ("brick", (0.95, 0.55, 0.40)),
    "grass": ("grass", (0.45, 0.80, 0.35)),
    "gravel": ("gravel", (0.75, 0.70, 0.62)),
}


# ---------------------------------------------------------------------------- textures
def _gauss_blur(img: np.ndarray, sigma: float) -> np.ndarray:
    from scipy.ndimage import gaussian_filter

    # "reflect" (half-sample symmetric) matches the mirrored-repeat tiling
    return gaussian_filter(img, sigma=(sigma, sigma, 0), mode="reflect")


@lru_cache(maxsize=None)
def _texture_pyramid(name: str) -> tuple[np.ndarray, ...]:
    """Mip-map pyramid of a bundled texture: levels of side 512, 256, ... 4 texels,
    H×W×3 float32 in [0, 1], each pre-smoothed with a Gaussian of sigma 1 texel (of its
    own level) so that bilinear lookups are band-limited."""
    if name not in TEXTURES:
        raise VibrInputError(f"unknown texture {name!r} (known: {', '.join(TEXTURES)})")
    import skimage.data

    loader, tint = TEXTURES[name]
    img = np.asarray(getattr(skimage.data, loader)(), dtype=np.float32) / 255.0
    if img.ndim == 2:
        img = img[..., None] * np.asarray(tint, dtype=np.float32)[None, None, :]
        img = 0.1 + 0.85 * img
    return _pyramid_from_image(img[..., :3])


def _pyramid_from_image(img: np.ndarray) -> tuple[np.ndarray, ...]:
    from skimage.transform import resize

    img = np.asarray(img, dtype=np.float32)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    h, w = img.shape[:2]
    s = min(h, w)  # centre square crop, then resize to the pyramid's base size
    img = img[(h - s) // 2 : (h - s) // 2 + s, (w - s) // 2 : (w - s) // 2 + s]
    img = resize(img, (_TEX_SIZE, _TEX_SIZE), order=1, anti_aliasing=True).astype(np.float32)
    levels = [_gauss_blur(img, 1.0)]
    for _ in range(1, _N_LEVELS):
        prev = _gauss_blur(levels[-1], 1.0)
        h2 = prev.shape[0] // 2
        levels.append(prev.reshape(h2, 2, h2, 2, 3).mean(axis=(1, 3)).astype(np.float32))
    return tuple(np.clip(lv, 0.0, 1.0) for lv in levels)


# ---------------------------------------------------------------------------- numba core
@njit(cache=True, inline="always")
def _mirror_coord(u):
    """Mirrored repeat (period 2 tiles) of a texture coordinate, into [0, 1]: seamless
    tiling. Mirroring the coordinate maps texel centres to texel centres, so a bilinear
    lookup at the mirrored coordinate with indices clamped to the edge equals the lookup
    in the infinite mirrored texture."""
    m = u - 2.0 * math.floor(0.5 * u)
    return 2.0 - m if m > 1.0 else m


@njit(cache=True)
def _bilinear(tex_flat, off, n, u, v, out):
    """Bilinear lookup at mirrored texture coordinates (u, v) ∈ [0, 1]² of one pyramid
    level (side n texels, flat offset ``off``) into out[0:3]."""
    x = u * n - 0.5
    y = v * n - 0.5
    x0 = math.floor(x)
    y0 = math.floor(y)
    fx = x - x0
    fy = y - y0
    ix0 = min(max(int(x0), 0), n - 1)
    ix1 = min(max(int(x0) + 1, 0), n - 1)
    iy0 = min(max(int(y0), 0), n - 1)
    iy1 = min(max(int(y0) + 1, 0), n - 1)
    w00 = (1 - fx) * (1 - fy)
    w01 = fx * (1 - fy)
    w10 = (1 - fx) * fy
    w11 = fx * fy
    r0 = off + iy0 * n
    r1 = off + iy1 * n
    for c in range(3):
        out[c] = (
            w00 * tex_flat[r0 + ix0, c]
            + w01 * tex_flat[r0 + ix1, c]
            + w10 * tex_flat[r1 + ix0, c]
            + w11 * tex_flat[r1 + ix1, c]
        )


# packed rectangle columns: P0 0:3, U 3:6, V 6:9, tile 9, group 10, texture 11,
# texture offset (tiles) 12:14, n = U x V 14:17, n . P0 17, 1/|U|^2 18, 1/|V|^2 19
_RECT_COLS = 20


def _intersect_py(ox, oy, oz, dx, dy, dz, rects, groups, spheres, tmin):
    """Nearest hit of the ray o + t d (t > tmin): returns (t, kind, index) with kind 0 =
    rectangle, 1 = sphere, -1 = miss (t = inf).

    ``groups`` (G, 6): rectangles ``start:end`` of a group and its bounding sphere
    (centre, radius; radius 0 = no culling), so a box costs one sphere test for rays
    that miss it."""
    best = np.inf
    kind = -1
    idx = -1
    a = dx * dx + dy * dy + dz * dz
    for g in range(groups.shape[0]):
        rb = groups[g, 5]
        if rb > 0.0:
            ex = ox - groups[g, 2]
            ey = oy - groups[g, 3]
            ez = oz - groups[g, 4]
            b = ex * dx + ey * dy + ez * dz
            c = ex * ex + ey * ey + ez * ez - rb * rb
            disc = b * b - a * c
            if disc < 0.0:
                continue
            if (-b - math.sqrt(disc)) / a >= best:  # bounding sphere entirely behind
                continue
        for k in range(int(groups[g, 0]), int(groups[g, 1])):
            # rectangle P0 + s U + q V, s, q in [0, 1]
            nx, ny, nz = rects[k, 14], rects[k, 15], rects[k, 16]
            den = nx * dx + ny * dy + nz * dz
            if den == 0.0:
                continue
            t = (rects[k, 17] - (nx * ox + ny * oy + nz * oz)) / den
            if t <= tmin or t >= best:
                continue
            qx = ox + t * dx - rects[k, 0]
            qy = oy + t * dy - rects[k, 1]
            qz = oz + t * dz - rects[k, 2]
            s = (qx * rects[k, 3] + qy * rects[k, 4] + qz * rects[k, 5]) * rects[k, 18]
            if s < 0.0 or s > 1.0:
                continue
            q = (qx * rects[k, 6] + qy * rects[k, 7] + qz * rects[k, 8]) * rects[k, 19]
            if q < 0.0 or q > 1.0:
                continue
            best = t
            kind = 0
            idx = k
    for k in range(spheres.shape[0]):
        cx, cy, cz, r = spheres[k, 0], spheres[k, 1], spheres[k, 2], spheres[k, 3]
        ex = ox - cx
        ey = oy - cy
        ez = oz - cz
        b = ex * dx + ey * dy + ez * dz
        c = ex * ex + ey * ey + ez * ez - r * r
        disc = b * b - a * c
        if disc < 0.0:
            continue
        sq = math.sqrt(disc)
        t = (-b - sq) / a
        if t <= tmin:
            t = (-b + sq) / a
        if t <= tmin or t >= best:
            continue
        best = t
        kind = 1
        idx = k
    return best, kind, idx


def _surface_colour_py(ox, oy, oz, dx, dy, dz, t, kind, idx, foot_per_t, rects, spheres,
                    tex_flat, tex_off, tex_side, light, out, tmp):
    """Shaded, mip-mapped texture colour at the hit (kind, idx) of the ray at t.

    ``foot_per_t``: pixel footprint (scene units, perpendicular to the view direction)
    per unit of ray parameter; 0 selects the finest level."""
    hx = ox + t * dx
    hy = oy + t * dy
    hz = oz + t * dz
    if kind == 0:
        px, py, pz = rects[idx, 0], rects[idx, 1], rects[idx, 2]
        ux, uy, uz = rects[idx, 3], rects[idx, 4], rects[idx, 5]
        vx, vy, vz = rects[idx, 6], rects[idx, 7], rects[idx, 8]
        tile = rects[idx, 9]
        tex = int(rects[idx, 11])
        qx, qy, qz = hx - px, hy - py, hz - pz
        # texture coordinates in tiles: distance along the edges / tile size
        tu = (qx * ux + qy * uy + qz * uz) * math.sqrt(rects[idx, 18]) / tile + rects[idx, 12]
        tv = (qx * vx + qy * vy + qz * vz) * math.sqrt(rects[idx, 19]) / tile + rects[idx, 13]
        nx, ny, nz = rects[idx, 14], rects[idx, 15], rects[idx, 16]
        texel = tile / tex_side[0]
    else:
        cx, cy, cz, r = spheres[idx, 0], spheres[idx, 1], spheres[idx, 2], spheres[idx, 3]
        nx, ny, nz = (hx - cx) / r, (hy - cy) / r, (hz - cz) / r
        lon = math.atan2(nx, -nz) + math.pi  # [0, 2 pi]
        lat = math.acos(min(1.0, max(-1.0, ny)))  # [0, pi]
        tiles_u = spheres[idx, 4]
        tu = lon / (2 * math.pi) * tiles_u
        tv = lat / math.pi * (tiles_u / 2)
        tex = int(spheres[idx, 6])
        texel = 2 * math.pi * r / tiles_u / tex_side[0]
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    nx, ny, nz = nx / nn, ny / nn, nz / nn
    dn = math.sqrt(dx * dx + dy * dy + dz * dz)
    cosv = abs(nx * dx + ny * dy + nz * dz) / dn
    # level of detail: log2(footprint / texel), footprint stretched on slanted surfaces
    nlev = tex_side.shape[0]
    lod = 0.0
    if foot_per_t > 0.0:
        foot = t * foot_per_t / math.sqrt(max(cosv, 0.05))
        if foot > texel:
            lod = math.log2(foot / texel)
    if lod > nlev - 1:
        lod = nlev - 1.0
    l0 = int(lod)
    fl = lod - l0
    tu = _mirror_coord(tu)
    tv = _mirror_coord(tv)
    _bilinear(tex_flat, tex_off[tex, l0], tex_side[l0], tu, tv, out)
    if fl > 0.0 and l0 + 1 < nlev:
        _bilinear(tex_flat, tex_off[tex, l0 + 1], tex_side[l0 + 1], tu, tv, tmp)
        for c in range(3):
            out[c] = (1 - fl) * out[c] + fl * tmp[c]
    # two-sided Lambertian shading, view-independent for viewers on one side
    if nx * dx + ny * dy + nz * dz > 0:
        nx, ny, nz = -nx, -ny, -nz
    lam = max(0.0, nx * light[0] + ny * light[1] + nz * light[2])
    shade = _AMBIENT + (1 - _AMBIENT) * lam
    for c in range(3):
        out[c] *= shade


def _renamed(func, name):
    """A copy of the Python function ``func`` called ``name`` (its own numba cache entry)."""
    code = func.__code__.replace(co_name=name, co_qualname=name)
    g = types.FunctionType(code, func.__globals__, name, func.__defaults__, func.__closure__)
    g.__qualname__ = name
    g.__doc__ = func.__doc__
    return g


# The render kernel, the hot path, gets copies inlined at numba-IR level (about 25 % less
# CPU time); the ray-query kernel calls ordinary compiled copies, which compile ~5x faster.
_intersect = njit(cache=True, inline="always")(_renamed(_intersect_py, "_intersect"))
_surface_colour = njit(cache=True, inline="always")(_renamed(_surface_colour_py, "_surface_colour"))
_intersect_ni = njit(cache=True)(_renamed(_intersect_py, "_intersect_ni"))
_surface_colour_ni = njit(cache=True)(_renamed(_surface_colour_py, "_surface_colour_ni"))


@njit(parallel=True, cache=True)
def _raycast_kernel(origins, dirs, foot, rects, groups, spheres, obj_rect, obj_sph,
                    tex_flat, tex_off, tex_side, light, background):
    n = origins.shape[0]
    t_out = np.full(n, np.inf)
    obj_out = np.full(n, -1, dtype=np.int64)
    col = np.empty((n, 3), dtype=np.float32)
    for i in prange(n):
        out = np.empty(3)
        tmp = np.empty(3)
        ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
        dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        t, kind, idx = _intersect_ni(ox, oy, oz, dx, dy, dz, rects, groups, spheres, 1e-9)
        if kind < 0:
            for c in range(3):
                col[i, c] = background[c]
            continue
        t_out[i] = t
        obj_out[i] = obj_rect[idx] if kind == 0 else obj_sph[idx]
        _surface_colour_ni(ox, oy, oz, dx, dy, dz, t, kind, idx, foot[i], rects, spheres,
                        tex_flat, tex_off, tex_side, light, out, tmp)
        for c in range(3):
            col[i, c] = out[c]
    return t_out, obj_out, col


@njit(parallel=True, cache=True)
def _render_kernel(C, M, H, W, ss, foot_per_t, rects, groups, spheres, tex_flat, tex_off,
                   tex_side, light, background):
    """Render an H×W image: ray of pixel (x, y) is C + t M [x, y, 1] with M = Rᵀ K⁻¹, so t
    is the orthogonal depth. ss × ss sub-pixel rays (box filter) for colour, the
    pixel-centre ray for depth (and for colour when ss = 1). One call site of the
    (inlined) intersection and shading keeps the compile time down."""
    img = np.empty((H, W, 3), dtype=np.float32)
    depth = np.empty((H, W), dtype=np.float32)
    nsub = ss * ss if ss > 1 else 0
    inv = 1.0 / max(nsub, 1)
    for i in prange(H):
        out = np.empty(3)
        tmp = np.empty(3)
        acc = np.empty(3)
        for j in range(W):
            acc[:] = 0.0
            for k in range(nsub + 1):
                if k < nsub:  # sub-pixel sample
                    y = i + ((k // ss) + 0.5) / ss - 0.5
                    x = j + ((k % ss) + 0.5) / ss - 0.5
                else:  # pixel centre
                    y = float(i)
                    x = float(j)
                dx = M[0, 0] * x + M[0, 1] * y + M[0, 2]
                dy = M[1, 0] * x + M[1, 1] * y + M[1, 2]
                dz = M[2, 0] * x + M[2, 1] * y + M[2, 2]
                t, kind, idx = _intersect(C[0], C[1], C[2], dx, dy, dz, rects, groups, spheres, 1e-9)
                if k == nsub:
                    depth[i, j] = t if kind >= 0 else np.nan
                    if nsub > 0:
                        break
                if kind >= 0:
                    _surface_colour(C[0], C[1], C[2], dx, dy, dz, t, kind, idx, foot_per_t,
                                    rects, spheres, tex_flat, tex_off, tex_side, light, out, tmp)
                    for c in range(3):
                        acc[c] += out[c]
                else:
                    for c in range(3):
                        acc[c] += background[c]
            for c in range(3):
                img[i, j, c] = acc[c] * inv
    return img, depth


# ---------------------------------------------------------------------------- world
class World:
    """A scene of textured rectangles, boxes and spheres.

    Build it with :meth:`add_rect`, :meth:`add_box` and :meth:`add_sphere`; each returns
    the new object's id (boxes: one id for the six faces). Textures are names from
    :data:`TEXTURES` or H×W×3 float arrays in [0, 1].

    Attributes
    ----------
    bbox : ((xmin, xmax), (ymin, ymax), (zmin, zmax)) or None
        Documented bounding box of the content (set by :func:`default_world`).
    background : (3,) float
        Colour of rays that hit nothing.
    """

    def __init__(self, background=(0.0, 0.0, 0.0)):
        self._rects: list[list[float]] = []  # P0(3) U(3) V(3) tile group tex offset(2)
        self._groups: list[list[float]] = []  # start end centre(3) bounding radius
        self._rect_obj: list[int] = []
        self._spheres: list[list[float]] = []  # c(3) r tiles_u unused tex
        self._sph_obj: list[int] = []
        self._tex_names: list = []
        self._tex_pyr: list[tuple[np.ndarray, ...]] = []
        self._n_obj = 0
        self._packed = None
        self.bbox = None
        self.background = np.asarray(background, dtype=np.float64).reshape(3)
        self.names: dict[int, str] = {}

    # ------------------------------------------------------------------ building
    def _texture_index(self, texture) -> int:
        if isinstance(texture, str):
            for i, n in enumerate(self._tex_names):
                if isinstance(n, str) and n == texture:
                    return i
            pyr = _texture_pyramid(texture)
            self._tex_names.append(texture)
        else:
            for i, n in enumerate(self._tex_names):
                if n is texture:  # the same array again (a box's six faces): its pyramid once
                    return i
            pyr = _pyramid_from_image(np.asarray(texture, dtype=np.float32))
            self._tex_names.append(texture)
        self._tex_pyr.append(pyr)
        return len(self._tex_pyr) - 1

    def _new_obj(self, name):
        oid = self._n_obj
        self._n_obj += 1
        self.names[oid] = name
        self._packed = None
        return oid

    def add_rect(self, p0, u, v, texture="gravel", tile=1.0, name="rect", offset=(0.0, 0.0),
                 _obj=None) -> int:
        """Finite rectangle ``p0 + s u + q v``, ``s, q ∈ [0, 1]`` (``u ⟂ v``), textured with
        one texture tile per ``tile`` scene units (mirrored repeat), the texture
        coordinate at ``p0`` being ``offset`` (in tiles). Returns its object id."""
        p0, u, v = (np.asarray(a, dtype=np.float64).reshape(3) for a in (p0, u, v))
        nu, nv = np.linalg.norm(u), np.linalg.norm(v)
        if nu == 0 or nv == 0 or abs(u @ v) > 1e-9 * nu * nv:
            raise ValueError("add_rect: edges u and v must be non-zero and orthogonal")
        if tile <= 0:
            raise ValueError("add_rect: tile must be positive")
        tex = self._texture_index(texture)
        oid = self._new_obj(name) if _obj is None else _obj
        if _obj is None:  # a group of its own, no culling sphere
            self._groups.append([len(self._rects), len(self._rects) + 1, 0.0, 0.0, 0.0, 0.0])
        self._rects.append([*p0, *u, *v, float(tile), float(len(self._groups) - 1), float(tex),
                            float(offset[0]), float(offset[1])])
        self._rect_obj.append(oid)
        self._packed = None
        return oid

    def add_box(self, centre, half, texture="brick", tile=1.0, yaw_deg=0.0, name="box") -> int:
        """Box of half-extents ``half`` (3,) centred at ``centre``, rotated by ``yaw_deg``
        about the vertical (y) axis; six rectangles sharing one object id."""
        c = np.asarray(centre, dtype=np.float64).reshape(3)
        h = np.asarray(half, dtype=np.float64).reshape(3)
        a = math.radians(yaw_deg)
        # columns: box axes in world coordinates
        B = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
        oid = self._new_obj(name)
        # the six faces form one group culled by the box's bounding sphere
        self._groups.append([len(self._rects), len(self._rects) + 6, *c, 1.0001 * float(np.linalg.norm(h))])
        for ax in range(3):
            b, cc = (ax + 1) % 3, (ax + 2) % 3
            for sgn in (-1.0, 1.0):
                fc = c + sgn * h[ax] * B[:, ax]
                p0 = fc - h[b] * B[:, b] - h[cc] * B[:, cc]
                self.add_rect(p0, 2 * h[b] * B[:, b], 2 * h[cc] * B[:, cc], texture, tile, _obj=oid)
        return oid

    def add_sphere(self, centre, radius, texture="chelsea", tiles=2, name="sphere") -> int:
        """Sphere, textured in longitude/latitude with ``tiles`` (even, for a seamless
        mirrored repeat) texture tiles around the equator."""
        if radius <= 0:
            raise ValueError("add_sphere: radius must be positive")
        tiles = max(2, 2 * int(round(tiles / 2)))
        tex = self._texture_index(texture)
        oid = self._new_obj(name)
        self._spheres.append([*np.asarray(centre, dtype=np.float64).reshape(3), float(radius),
                              float(tiles), 0.0, float(tex)])
        self._sph_obj.append(oid)
        return oid

    @property
    def n_objects(self) -> int:
        return self._n_obj

    # ------------------------------------------------------------------ packing
    def _pack(self):
        if self._packed is None:
            if not self._tex_pyr:
                self._texture_index("gravel")
            sides = np.array([lv.shape[0] for lv in self._tex_pyr[0]], dtype=np.int64)
            flat, offs, o = [], np.zeros((len(self._tex_pyr), len(sides)), np.int64), 0
            for ti, pyr in enumerate(self._tex_pyr):
                for li, lv in enumerate(pyr):
                    offs[ti, li] = o
                    flat.append(lv.reshape(-1, 3))
                    o += lv.shape[0] * lv.shape[1]
            r = np.asarray(self._rects, np.float64).reshape(-1, 14)
            U, V = r[:, 3:6], r[:, 6:9]
            n = np.cross(U, V)
            rects = np.concatenate([r, n, np.einsum("ij,ij->i", n, r[:, 0:3])[:, None],
                                    1 / np.einsum("ij,ij->i", U, U)[:, None],
                                    1 / np.einsum("ij,ij->i", V, V)[:, None]], axis=1)
            self._packed = dict(
                rects=np.ascontiguousarray(rects.reshape(-1, _RECT_COLS)),
                groups=np.asarray(self._groups, np.float64).reshape(-1, 6),
                spheres=np.asarray(self._spheres, np.float64).reshape(-1, 7),
                obj_rect=np.asarray(self._rect_obj, np.int64),
                obj_sph=np.asarray(self._sph_obj, np.int64),
                tex_flat=np.ascontiguousarray(np.concatenate(flat), dtype=np.float32),
                tex_off=offs,
                tex_side=sides,
                light=_LIGHT.copy(),
                background=self.background.astype(np.float64),
            )
        return self._packed

    # ------------------------------------------------------------------ queries
    def raycast(self, origins, dirs, footprint=None):
        """Nearest hit of each ray ``o + t d``, ``t > 0``.

        Parameters
        ----------
        origins, dirs : (N, 3) float
            Ray origins and directions (world); directions need not be unit.
        footprint : (N,) float or float, optional
            Pixel footprint per unit of ``t`` (scene units), for the mip-map level of
            detail; None or 0 uses the finest texture level.

        Returns
        -------
        t : (N,) float64
            Ray parameter of the hit (``o + t d``), ``inf`` on a miss.
        obj : (N,) int64
            Object id, -1 on a miss.
        colour : (N, 3) float32
            Shaded texture colour in [0, 1] (bilinear / trilinear lookup); the
            background colour on a miss.
        """
        o = np.ascontiguousarray(np.asarray(origins, dtype=np.float64).reshape(-1, 3))
        d = np.ascontiguousarray(np.asarray(dirs, dtype=np.float64).reshape(-1, 3))
        if o.shape != d.shape:
            if o.shape[0] == 1:
                o = np.ascontiguousarray(np.broadcast_to(o, d.shape))
            else:
                raise ValueError(f"raycast: origins {o.shape} and dirs {d.shape} differ")
        if footprint is None:
            foot = np.zeros(d.shape[0])
        else:
            foot = np.ascontiguousarray(np.broadcast_to(np.asarray(footprint, np.float64), d.shape[:1]))
        p = self._pack()
        return _raycast_kernel(o, d, foot, p["rects"], p["groups"], p["spheres"], p["obj_rect"], p["obj_sph"],
                               p["tex_flat"], p["tex_off"], p["tex_side"], p["light"], p["background"])

    def __repr__(self) -> str:
        return (f"World({self._n_obj} objects: {len(self._rects)} rectangles, "
                f"{len(self._spheres)} spheres, {len(self._tex_pyr)} textures)")


def default_world(seed: int = 0, far: float | None = None) -> World:
    """The standard synthetic world (see the module docstring and :data:`DEFAULT_BBOX`).

    ``seed`` jitters the box and sphere positions (a few centimetres to decimetres) and
    permutes the textures; seed 0 is the reference scene. Object ids: 0 back wall, 1 floor,
    2 box, 3 sphere, 4 card.

    ``far``: a far background, as a street seen past a wall's corner. The back wall then
    stops at x = :data:`FAR_GAP_X`, and through the gap right of it the views see a
    textured façade at z = ``far`` (object 5, wide and tall enough to fill the gap from
    every layout's cameras). From one view to the next the façade slides behind the wall's
    corner by more than the strip each view shows of it, and its parallax is small: what
    stereo leaves without depth on a real scene's far buildings. The bounding box
    (``bbox``) then reaches z = ``far``.

    Examples
    --------
    >>> w = default_world(far=30.0)
    >>> w.names[5], w.bbox[2]
    ('far façade', (-1.0, 30.0))
    """
    rng = np.random.default_rng(seed)
    photos = ["astronaut", "coffee", "chelsea", "rocket"]
    grounds = ["gravel", "grass", "brick"]
    if seed != 0:
        rng.shuffle(photos)
        rng.shuffle(grounds)
    jit = (lambda s: rng.uniform(-s, s)) if seed != 0 else (lambda s: 0.0)
    (x0, x1), (y0, y1), (z0, z1) = DEFAULT_BBOX
    w = World()
    floor_y = y1
    # back wall z = 6, one 4.5-unit tile (a 512-texel tile: texel ~ 9 mm), offset so that
    # the middle of the photograph (not a mirror fold) faces the cameras
    if far is not None and not far > z1:
        raise VibrInputError(f"far must lie behind the back wall (z > {z1:g}), got {far!r}")
    right = x1 if far is None else FAR_GAP_X
    w.add_rect([x0, y0, z1], [right - x0, 0, 0], [0, floor_y - y0, 0], photos[0], tile=4.5,
               offset=(-0.8, -0.4), name="back wall")
    # floor y = 1.5 (below the cameras: world up is -y)
    w.add_rect([x0, floor_y, z0], [x1 - x0, 0, 0], [0, 0, z1 - z0], grounds[0], tile=2.5, name="floor")
    # box standing on the floor
    bh = np.array([0.6, 0.7, 0.6])
    w.add_box([-1.0 + jit(0.2), floor_y - bh[1], 4.0 + jit(0.2)], bh, grounds[2], tile=1.2,
              yaw_deg=30.0 + jit(10.0), name="box")
    # sphere resting on the floor
    r = 0.7
    w.add_sphere([1.0 + jit(0.2), floor_y - r, 3.3 + jit(0.2)], r, photos[1], tiles=2, name="sphere")
    # a tilted card floating in front (a thin occluder with strong depth discontinuities)
    a = math.radians(25.0 + jit(10.0))
    u = np.array([1.2 * math.cos(a), 0.0, -1.2 * math.sin(a)])
    v = np.array([0.0, 0.9, 0.0])
    w.add_rect(np.array([-0.3 + jit(0.2), -1.3, 2.6]) - 0.5 * u, u, v, photos[2], tile=1.2, name="card")
    w.bbox = DEFAULT_BBOX
    if far is not None:
        # the photograph no other object shows, a tile about 120 px wide at 256 px: structure a
        # matcher could use, as a far building's windows
        w.add_rect([-far, -far, far], [2.5 * far, 0, 0], [0, 1.5 * far, 0], photos[3], tile=far / 2.0,
                   name="far façade")
        w.bbox = (DEFAULT_BBOX[0], DEFAULT_BBOX[1], (DEFAULT_BBOX[2][0], float(far)))
    return w


# ---------------------------------------------------------------------------- rendering
def render_view(world: World, camera: Camera, supersample: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Ray-cast ``camera``'s view of ``world``.

    Parameters
    ----------
    supersample : int
        ``s``: each pixel's colour is the mean of ``s × s`` rays on a regular sub-pixel
        grid (a box filter over the pixel); 1 casts the pixel-centre ray only.

    Returns
    -------
    image : (H, W, 3) float32 in [0, 1]
    depth : (H, W) float32
        Orthogonal depth (scene units) of the pixel-centre ray ``C + z Rᵀ K⁻¹ [x, y, 1]``,
        NaN where it hits nothing.
    """
    ss = int(supersample)
    if ss < 1:
        raise ValueError("supersample must be >= 1")
    p = world._pack()
    M = np.ascontiguousarray(camera.R.T @ camera.K_inv)  # z-component of K⁻¹[x,y,1] is 1
    C = np.ascontiguousarray(camera.centre)
    foot = 1.0 / math.sqrt(camera.K[0, 0] * camera.K[1, 1])  # pixel size at unit depth
    img, depth = _render_kernel(C, M, camera.height, camera.width, ss, foot, p["rects"],
                                p["groups"], p["spheres"], p["tex_flat"], p["tex_off"], p["tex_side"],
                                p["light"], p["background"])
    np.clip(img, 0.0, 1.0, out=img)
    return img, depth


# ---------------------------------------------------------------------------- cameras
def _look_at(eye, target, K, width, height, up=(0.0, -1.0, 0.0)) -> Camera:
    """Camera at ``eye`` looking at ``target``; synthetic worlds have ``-y`` up."""
    return Camera.look_at(eye, target, up, K, width, height)


def _focal(width: int, fov_deg: float) -> float:
    """Focal length (pixels) for a horizontal field of view ``fov_deg``."""
    return 0.5 * width / math.tan(math.radians(fov_deg) / 2)


def grid_cameras(rows: int = 3, cols: int = 3, baseline: float = 0.1, *, width: int = 128,
                 height: int = 128, fov_deg: float = 55.0, centre=(0.0, 0.0, 0.0)) -> list[Camera]:
    """Light-field grid (HCI-like): parallel cameras looking along +z (R = I), centres on a
    ``rows × cols`` grid of step ``baseline`` in the z = centre[2] plane; view ``i`` is at
    row ``i // cols`` (y, downwards), column ``i % cols`` (x, rightwards). Disparity
    between neighbours is ``f · baseline / z`` pixels."""
    if rows < 1 or cols < 1:
        raise ValueError("grid_cameras: rows and cols must be >= 1")
    K = Camera.intrinsics(_focal(width, fov_deg), width, height)
    c0 = np.asarray(centre, dtype=np.float64)
    cams = []
    for r in range(rows):
        for c in range(cols):
            C = c0 + np.array([(c - (cols - 1) / 2) * baseline, (r - (rows - 1) / 2) * baseline, 0.0])
            cams.append(Camera.from_centre(K, np.eye(3), C, width, height))
    return cams


def arc_cameras(n: int = 5, *, arc_deg: float = 30.0, radius: float = 3.6, width: int = 128,
                height: int = 128, fov_deg: float = 55.0, target=SCENE_CENTRE,
                height_offset: float = -0.3) -> list[Camera]:
    """``n`` cameras on a horizontal circle arc of ``arc_deg`` degrees (total) and
    ``radius`` around ``target``, all looking at ``target``; the middle of the arc is
    straight in front (-z side) of it. ``height_offset`` raises (negative y) the cameras
    above the target."""
    if n < 1:
        raise ValueError("arc_cameras: n must be >= 1")
    tgt = np.asarray(target, dtype=np.float64)
    K = Camera.intrinsics(_focal(width, fov_deg), width, height)
    angles = np.radians(np.linspace(-arc_deg / 2, arc_deg / 2, n)) if n > 1 else np.zeros(1)
    cams = []
    for a in angles:
        eye = tgt + np.array([radius * math.sin(a), height_offset, -radius * math.cos(a)])
        cams.append(_look_at(eye, tgt, K, width, height))
    return cams


def pan_cameras(n: int = 5, *, pan_deg: float = 24.0, width: int = 128, height: int = 128,
                fov_deg: float = 55.0, eye=(0.0, -0.3, 0.0), target=SCENE_CENTRE) -> list[Camera]:
    """``n`` cameras at one centre ``eye`` turned about the vertical by ``pan_deg`` degrees in
    all, the middle one looking at ``target``: a rotation-only capture (a panorama from a
    tripod), whose views are related by homographies whatever the depth."""
    if n < 1:
        raise ValueError("pan_cameras: n must be >= 1")
    e = np.asarray(eye, dtype=np.float64)
    d = np.asarray(target, dtype=np.float64) - e
    K = Camera.intrinsics(_focal(width, fov_deg), width, height)
    angles = np.radians(np.linspace(-pan_deg / 2, pan_deg / 2, n)) if n > 1 else np.zeros(1)
    cams = []
    for a in angles:
        c, s_ = math.cos(a), math.sin(a)
        cams.append(_look_at(e, e + np.array([c * d[0] + s_ * d[2], d[1], -s_ * d[0] + c * d[2]]), K, width, height))
    return cams


def _aimed_rolled(eye, target, rng, aim_jitter, roll_deg, K, width, height) -> Camera:
    """Camera at ``eye`` looking at ``target`` ± ``aim_jitter`` per axis, rolled about its
    optical axis by ± ``roll_deg`` (uniform draws from ``rng``, in that order)."""
    cam = _look_at(eye, target + rng.uniform(-aim_jitter, aim_jitter, 3), K, width, height)
    g = math.radians(rng.uniform(-roll_deg, roll_deg))
    Rz = np.array([[math.cos(g), -math.sin(g), 0], [math.sin(g), math.cos(g), 0], [0, 0, 1]])
    return Camera.from_centre(K, Rz @ cam.R, eye, width, height)


def _random_layout(name: str, n: int, seed: int, width: int, height: int, fov_deg: float, eye, target):
    """The shared start of the random layouts: the seeded generator, the intrinsics, the
    nominal eye and target as arrays (``n`` checked)."""
    if n < 1:
        raise ValueError(f"{name}: n must be >= 1")
    rng = np.random.default_rng(seed)
    K = Camera.intrinsics(_focal(width, fov_deg), width, height)
    return rng, K, np.asarray(eye, np.float64), np.asarray(target, np.float64)


def free_cameras(n: int = 5, seed: int = 0, *, width: int = 128, height: int = 128,
                 fov_deg: float = 55.0, eye=(0.0, -0.3, 0.0), target=SCENE_CENTRE,
                 pos_jitter: float = 0.25, aim_jitter: float = 0.2,
                 roll_deg: float = 4.0) -> list[Camera]:
    """``n`` random poses around a nominal one (``eye`` looking at ``target``): centres
    jittered uniformly by ± ``pos_jitter`` per axis, aim point by ± ``aim_jitter``,
    roll about the optical axis by ± ``roll_deg``. Deterministic for a seed."""
    rng, K, e0, t0 = _random_layout("free_cameras", n, seed, width, height, fov_deg, eye, target)
    cams = []
    for _ in range(n):
        e = e0 + rng.uniform(-pos_jitter, pos_jitter, 3)
        cams.append(_aimed_rolled(e, t0, rng, aim_jitter, roll_deg, K, width, height))
    return cams


def handheld_cameras(n: int = 7, seed: int = 0, *, width: int = 128, height: int = 128,
                     fov_deg: float = 55.0, eye=(0.0, -0.3, 0.0), target=SCENE_CENTRE,
                     baseline=(0.3, 0.6), z_jitter: float = 0.15, aim_jitter: float = 0.2,
                     roll_deg: float = 4.0) -> list[Camera]:
    """A hand-held capture around a reference viewpoint: view 0 at ``eye``, the others
    displaced from it in random directions spread around it (view k near the angle
    ``2π(k−1)/(n−1)``, ± 20°) by a random distance in ``baseline`` (scene units) across the
    line of sight and ± ``z_jitter`` along it; every view looks at ``target`` ± ``aim_jitter``
    per axis, rolled by ± ``roll_deg``. Unlike :func:`free_cameras`, every view sees most of
    what the reference sees and the baselines are bounded below (depth precision grows with
    the baseline), so the layout is free (no grid, general rotations) yet triangulable.
    Deterministic for a seed."""
    rng, K, e0, t0 = _random_layout("handheld_cameras", n, seed, width, height, fov_deg, eye, target)
    cams = []
    for k in range(n):
        off = np.zeros(3)
        if k > 0:
            a = 2 * math.pi * (k - 1) / max(n - 1, 1) + rng.uniform(-0.35, 0.35)
            r = rng.uniform(*baseline)
            off = np.array([r * math.cos(a), r * math.sin(a), rng.uniform(-z_jitter, z_jitter)])
        cams.append(_aimed_rolled(e0 + off, t0, rng, aim_jitter, roll_deg, K, width, height))
    return cams


def walk_cameras(n: int = 40, seed: int = 0, *, step: float = 0.1, turn_deg: float = 1.0,
                 jitter: float = 0.0, jitter_deg: float = 0.0, width: int = 160, height: int = 120,
                 fov_deg: float = 55.0) -> list[Camera]:
    """A steady walk, as one frame a second of a walking video: key ``i`` at ``(i · step, 0,
    0)``, turned by ``i · turn_deg`` about the y axis; shaken by a hand when ``jitter`` /
    ``jitter_deg`` are given: each centre moved by N(0, ``jitter``) per axis and each
    orientation turned by N(0, ``jitter_deg``°) about each axis (rotation vector).
    Deterministic for a seed; the same ``n`` and ``seed`` without jitter give the walk the
    shaken one was shaken from."""
    from scipy.spatial.transform import Rotation

    rng, K, _, _ = _random_layout("walk_cameras", n, seed, width, height, fov_deg, (0, 0, 0), (0, 0, 1))
    cams = []
    for i in range(n):
        C = np.array([step * i, 0.0, 0.0]) + rng.normal(0.0, 1.0, 3) * jitter
        rv = np.radians([0.0, turn_deg * i, 0.0]) + rng.normal(0.0, 1.0, 3) * np.radians(jitter_deg)
        cams.append(Camera.from_centre(K, Rotation.from_rotvec(rv).as_matrix().T, C, width, height))
    return cams


def make_scene(layout: str = "grid", n_views: int | None = None, width: int = 128,
               height: int = 128, seed: int = 0, world: World | None = None, *,
               grid: tuple[int, int] | None = None, baseline: float = 0.1,
               fov_deg: float = 55.0, supersample: int = 2,
               sigma_z: float = DEFAULT_SIGMA_Z) -> Scene:
    """A synthetic :class:`~vibr.scene.Scene` with exact depth on every view.

    Parameters
    ----------
    layout : "grid" | "arc" | "free" | "handheld" | "pan"
        Camera layout (:func:`grid_cameras`, :func:`arc_cameras`, :func:`free_cameras`,
        :func:`handheld_cameras`, :func:`pan_cameras`).
    n_views : int, optional
        Number of views. Grid: a perfect square gives a square grid, otherwise one row
        (overridden by ``grid``); default 3×3. Arc, free and pan: default 5; handheld: 7.
    width, height : int
        Image size; the default 128×128 renders in a fraction of a second, 768×768 is a
        large scene.
    seed : int
        Seed of the world (:func:`default_world`) and of the free and hand-held layouts' poses.
    world : World, optional
        Defaults to ``default_world(seed)``.
    grid : (rows, cols), optional
        Grid shape of the grid layout.
    baseline : float
        Grid step (scene units) of the grid layout.
    sigma_z : float
        Depth uncertainty stored on every view (scene units, :data:`DEFAULT_SIGMA_Z`).

    Views are named ``view_000``, ``view_001``, ...; ``meta`` holds ``format="synthetic"``,
    the layout, seed and baseline; the grid layout sets ``scene.grid`` and
    ``meta["grid_pos"]`` (name → (row, col)).

    Examples
    --------
    >>> sc = make_scene("grid", n_views=9, width=48, height=48)
    >>> len(sc), sc.views[0].name, sc.views[0].image.shape, sc.views[0].depth.shape
    (9, 'view_000', (48, 48, 3), (48, 48))
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise VibrInputError(f"seed must be an integer >= 0 (numpy's rule), got {seed!r}")
    world = default_world(seed) if world is None else world
    kw = dict(width=width, height=height, fov_deg=fov_deg)
    gshape = None
    if layout == "grid":
        if grid is not None:
            gshape = (int(grid[0]), int(grid[1]))
        elif n_views is None:
            gshape = (3, 3)
        else:
            r = int(round(math.sqrt(n_views)))
            gshape = (r, r) if r * r == n_views else (1, int(n_views))
        cams = grid_cameras(gshape[0], gshape[1], baseline, **kw)
    elif layout == "arc":
        cams = arc_cameras(5 if n_views is None else int(n_views), **kw)
    elif layout == "free":
        cams = free_cameras(5 if n_views is None else int(n_views), seed, **kw)
    elif layout == "handheld":
        cams = handheld_cameras(7 if n_views is None else int(n_views), seed, **kw)
    elif layout == "pan":
        cams = pan_cameras(5 if n_views is None else int(n_views), **kw)
    else:
        raise VibrInputError(f"unknown synthetic layout {layout!r} (grid, arc, free, handheld or pan)")
    views = []
    for i, cam in enumerate(cams):
        img, depth = render_view(world, cam, supersample)
        views.append(View(f"view_{i:03d}", img, cam, depth=depth, sigma_z=float(sigma_z)))
    meta = {"format": "synthetic", "layout": layout, "seed": seed, "supersample": supersample,
            "bbox": world.bbox, "depth_kind": "orthogonal, exact"}
    if layout == "grid":
        meta["baseline"] = baseline
        meta["grid_pos"] = {v.name: (i // gshape[1], i % gshape[1]) for i, v in enumerate(views)}
    return Scene(views, name=f"synthetic-{layout}", grid=gshape, meta=meta)


#: :func:`ring_scene` kinds: a textureless grey-white object on black (the Middlebury rings'
#: backdrop, an object stereo leaves mostly unknown) and a textured object on a uniform grey backdrop.
RING_KINDS = ("textureless", "textured")


def ring_scene(kind: str = "textureless", n_views: int = 16, width: int = 160, height: int = 120,
               supersample: int = 2) -> Scene:
    """A ring of ``n_views`` cameras around an object on a uniform backdrop, as the
    Middlebury temple and dino rings are taken: rays that miss the object see the backdrop.

    The object: a box on a wider slab and a sphere beside it, about the origin; the cameras on
    a circle of radius 4 in the plane 1.2 above it (world up is −y), all looking at it.
    ``kind`` (:data:`RING_KINDS`): ``"textureless"``, every surface one grey-white (faces
    differ by shading only) on a black backdrop; ``"textured"``, brick, gravel and a photograph
    on a uniform grey backdrop.

    Every view's depth is the ray-cast truth where a stereo matcher could find it: NaN where
    the ray hits nothing (the backdrop) and where the photograph is flat
    (:func:`vibr.geometry.proxy.flat_pixels`, the windows no matcher can match); the truth
    (image and full depth) stays in ``meta["truth_depth"]`` (name → depth map).
    """
    from .geometry.proxy import flat_pixels

    if kind not in RING_KINDS:
        raise VibrInputError(f"ring_scene: kind must be one of {', '.join(RING_KINDS)}, got {kind!r}")
    if n_views < 3:
        raise VibrInputError(f"ring_scene: at least 3 views, got {n_views}")
    plain = np.full((8, 8, 3), 0.85, np.float32)
    w = World(background=(0.0, 0.0, 0.0) if kind == "textureless" else (0.45, 0.45, 0.5))
    tex = (plain, plain, plain) if kind == "textureless" else ("brick", "gravel", "coffee")
    w.add_box([0.0, 0.45, 0.0], [0.9, 0.15, 0.6], tex[1], tile=0.8, name="slab")
    w.add_box([-0.3, -0.2, 0.0], [0.35, 0.5, 0.35], tex[0], tile=0.6, yaw_deg=20.0, name="box")
    w.add_sphere([0.5, 0.0, 0.1], 0.3, tex[2], tiles=2, name="sphere")
    K = Camera.intrinsics(_focal(width, 40.0), width, height)
    cams = []
    for a in np.linspace(0.0, 2 * math.pi, int(n_views), endpoint=False):
        eye = np.array([4.0 * math.sin(a), -1.2, -4.0 * math.cos(a)])
        cams.append(_look_at(eye, (0.0, 0.1, 0.0), K, width, height))
    views, truth = [], {}
    for i, cam in enumerate(cams):
        img, depth = render_view(w, cam, supersample)
        name = f"ring_{i:03d}"
        truth[name] = depth
        views.append(View(name, img, cam, depth=np.where(flat_pixels(img), np.nan, depth).astype(np.float32),
                          sigma_z=float(DEFAULT_SIGMA_Z)))
    meta = {"format": "synthetic", "layout": "ring", "kind": kind, "supersample": supersample,
            "depth_kind": "orthogonal, exact where textured", "truth_depth": truth}
    return Scene(views, name=f"synthetic-ring-{kind}", meta=meta)


# ---------------------------------------------------------------------------- depth helpers
def degrade_depth(depth, *, noise: float = 0.0, quantise: float = 0.0, holes: float = 0.0,
                  seed: int = 0, hole_size: float = 3.0) -> np.ndarray:
    """A degraded copy of an orthogonal depth map (H×W, NaN = unknown), in this order:

    * ``noise``: relative Gaussian noise, ``z' = z (1 + noise · n)``, ``n ~ N(0, 1)``;
    * ``quantise``: step in inverse depth (scene units⁻¹, like a disparity step),
      ``z' = 1 / (q · round(1 / (z q)))``; 0 disables;
    * ``holes``: fraction of the known pixels set to NaN, in blobs of about
      ``hole_size`` pixels (a Gaussian-smoothed random field thresholded at its
      ``holes`` quantile over the known pixels).

    Returns H×W float32; values stay positive (clipped at 1e-6 of the smallest depth).
    Deterministic for a seed.
    """
    from scipy.ndimage import gaussian_filter

    d = np.array(depth, dtype=np.float64)
    if d.ndim != 2:
        raise VibrInputError(f"depth must be H×W, got shape {d.shape}")
    if not 0.0 <= holes <= 1.0:
        raise ValueError("holes must be a fraction in [0, 1]")
    if noise < 0 or quantise < 0:
        raise ValueError("noise and quantise must be >= 0")
    rng = np.random.default_rng(seed)
    known = np.isfinite(d)
    floor = 1e-6 * (np.nanmin(d) if known.any() else 1.0)
    if noise > 0:
        d = d * (1.0 + noise * rng.standard_normal(d.shape))
        d = np.where(known, np.maximum(d, floor), np.nan)
    if quantise > 0:
        k = np.maximum(np.round(1.0 / (d * quantise)), 1.0)
        d = np.where(known, 1.0 / (k * quantise), np.nan)
    if holes > 0 and known.any():
        field = gaussian_filter(rng.standard_normal(d.shape), hole_size, mode="reflect")
        n_holes = int(round(holes * known.sum()))
        if n_holes > 0:
            vals = field[known]
            thr = np.partition(vals, n_holes - 1)[n_holes - 1]
            d[known & (field <= thr)] = np.nan
    return d.astype(np.float32)


def photograph(scene, *, noise: float = 2.0, blur: float = 0.5, exposure: float = 0.05, seed: int = 0):
    """``scene`` as a camera records it: a ray-cast image is exact, a photograph is not.

    Each view's image is, in this order, blurred by a Gaussian of ``blur`` px (the lens and
    the demosaicing), multiplied by its own exposure gain drawn uniformly in
    ``[1 − exposure, 1 + exposure]``, given Gaussian sensor noise of ``noise`` grey levels
    (standard deviation, of 255), and rounded to 8 bits. Cameras, depth and masks are kept.
    Deterministic for a seed (view ``i`` draws from ``seed + i``).

    Examples
    --------
    >>> sc = photograph(make_scene("grid", n_views=4, width=32, height=32))
    >>> bool(np.all(np.round(sc.views[0].image * 255) == sc.views[0].image * 255))
    True
    """
    from scipy.ndimage import gaussian_filter

    if noise < 0 or blur < 0 or not 0 <= exposure < 1:
        raise ValueError("noise and blur must be >= 0 and exposure in [0, 1)")
    views = []
    for i, v in enumerate(scene.views):
        rng = np.random.default_rng(seed + i)
        img = np.asarray(v.image, np.float64)
        if blur > 0:
            img = gaussian_filter(img, (blur, blur) + (0,) * (img.ndim - 2), mode="nearest")
        img = img * rng.uniform(1 - exposure, 1 + exposure) + rng.normal(0.0, noise / 255.0, img.shape)
        views.append(v.replace(image=(np.round(np.clip(img, 0, 1) * 255) / 255).astype(np.float32)))
    return scene.replace(views=views)


def planar_depth(camera: Camera, z: float, normal=None) -> np.ndarray:
    """Orthogonal depth map of a plane seen by ``camera`` (H×W float32, NaN where the
    plane is behind the camera or seen edge-on).

    With ``normal=None``: the fronto-parallel plane at depth ``z`` (constant map). With a
    world ``normal`` n: the plane ``{X : n · X = z}``; the pixel ray ``X = C + s Rᵀ K⁻¹ x̄``
    (s = orthogonal depth) gives ``s = (z − n · C) / (n · Rᵀ K⁻¹ x̄)``.
    """
    if normal is None:
        if not z > 0:
            raise ValueError("planar_depth: a fronto-parallel plane needs z > 0")
        return np.full(camera.shape, z, dtype=np.float32)
    n = np.asarray(normal, dtype=np.float64).reshape(3)
    rays = camera.pixel_rays(camera.pixel_grid()) @ camera.R  # world directions, (H, W, 3)
    den = rays @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (z - n @ camera.centre) / den
    s[~(s > 0) | ~np.isfinite(s)] = np.nan
    return s.astype(np.float32)


def zoom_photos(folder, n: int = 10, zoom: float = 1.5) -> dict[str, float]:
    """Write ``n`` synthetic 480×360 JPEG photos on a 40° arc, every other one zoomed by
    ``zoom``, with EXIF make "Acme", model "Zoomer" and focal lengths 24 mm and 24·zoom mm:
    the input of a calibration with a zoom lens.

    Parameters
    ----------
    folder : path-like
        An existing folder; the photos are ``v00.jpg``, ``v01.jpg``, ...

    Returns
    -------
    dict
        Photo stem -> true focal length in pixels at 480 px width.
    """
    from pathlib import Path

    from PIL import Image

    folder = Path(folder)
    world = default_world(0)
    truth = {}
    for i, c in enumerate(arc_cameras(n, arc_deg=40, width=480, height=360)):
        z = 1.0 if i % 2 == 0 else zoom
        K = c.K.copy()
        K[:2, :2] *= z
        img, _ = render_view(world, Camera(K, c.R, c.t, c.width, c.height))
        im = Image.fromarray((img * 255 + 0.5).astype(np.uint8))
        ex = im.getexif()
        ex[0x010F], ex[0x0110] = "Acme", "Zoomer"
        ex.get_ifd(0x8769)[0x920A] = 24.0 * z
        im.save(folder / f"v{i:02d}.jpg", exif=ex.tobytes(), quality=95)
        truth[f"v{i:02d}"] = float(K[0, 0])
    return truth
