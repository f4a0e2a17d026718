"""vibr against the peer a competent user would build from the same depth maps: a TSDF mesh,
ray-cast at the target and textured projectively from the source photographs.

The peer (Open3D, the ``bench`` extra: ``pip install -e '.[bench]'``; vibr never imports it):

* the sources' depth maps (vibr's own, estimated without the target, through the depth cache;
  NaN where stereo left none) fused into an Open3D ``VoxelBlockGrid`` TSDF, voxel = one
  pixel's footprint at the sources' median depth, truncation 4 voxels;
* the mesh (marching cubes, every voxel observed at least once) ray-cast at the target and at
  every source, rays through vibr's pixel centres (``(col, row)``, docs/reference/conventions.md);
* each target pixel's surface point textured from the sources that see it (its depth within 4
  voxels of the mesh's depth at the source pixel), blended by angle as Buehler et al.'s ULR
  with vibr's ``ulr_k`` (4) views (``peer``), or taken from the one source of the smallest angle
  (``peer 1 view``); pixels with no surface, or no source that sees it, black.

Open3D's integration reads the depth pixel ``floor(x)`` of a projection x, so its pixel
centres are at ``+½``: the peer gives it ``K`` with the principal point shifted by +½.
``--self-check`` verifies that in closed form: a slanted textured plane (vibr.synthetic),
exact depth, the peer's ray-cast depth at a held-out camera against the plane's. It also
counts the triangles of Open3D's legacy ``ScalableTSDFVolume`` fed the same maps (none, in
the open3d-cpu 0.20 wheel, without a warning: the reason the peer uses ``VoxelBlockGrid``).

``--tune`` chooses the peer's voxel (0.5, 1 or 2 pixel footprints), truncation (2, 4 or 8
voxels) and blend (ULR with 4 views or the best view) as vibr's defaults are chosen: on
procedural scenes only (vibr.synthetic's arc, free and handheld layouts at 160×120, seed 0, the
middle view from the others, the sources photographed as the sweep's, ``_common.CAPTURE``,
depth estimated from them as in the cases; about a minute
with the depth cached), by the best mean PSNR over all pixels (a hole counts black, so that no
setting wins by covering less), then renders the cases with the settings chosen; the page gives
the whole grid. Without it the peer keeps the recipe above.

Cases (those of the quality table): fountain-P11 views 0002, 0005, 0008 at scale 0.25 from the
10 others, cotton's centre from its 8 neighbours (stride 1) with the given and with estimated
depth, backgammon's centre from its 8 neighbours (estimated depth: its ground truth covers the
centre view only), temple view 4 from its 4 best views. Methods: vibr's default (``gradient``), ``ulr``,
``bvs`` (vibr's sources: its depth with the fallback proxy) and the peer. Metrics (2-pixel
border): PSNR over the pixels every method covers, PSNR over all pixels (what a method leaves
black counts), coverage, and :func:`vibr.metrics.sharpness` on the common pixels (the render's
Laplacian energy over the photograph's: 1 as sharp, below 1 blurred).

    PYTHONPATH=$PWD/src python3 benchmarks/quality/mesh_peer.py --self-check
    PYTHONPATH=$PWD/src python3 benchmarks/quality/mesh_peer.py [--tune] [--cases fountain,cotton,backgammon,temple] \\
        [--figures DIR] [--write-docs]

``--decompose`` asks where the peer's lead comes from, per case, on the pixels every row covers:
the peer's blend (the texturing above) over the mesh's depth at the target or over vibr's own
target z-buffer (:func:`vibr.geometry.target_depth`, the nearest warped source surface per
pixel), with the sources' visibility tested against the mesh, against vibr's source depth maps
(the same 4-voxel margin), or not at all, beside vibr's ``ulr`` (each source's samples
forward-warped by its own depth and splatted) and ``gradient``, and those two again with the
sources' measured depth replaced by the mesh's (the peer's fused geometry under vibr's
renderer; the fallback proxy kept where stereo left no depth). Each row's squared error on those
pixels is also split by spatial frequency (:func:`error_bands`: the parts add up to the MSE), which
says at which scale a lead lies: the views' exposures and the blend at the coarse end, registration
and sharpness at the fine end. It prints the tables and writes ``out/mesh_peer/decompose.json``;
the page is not written.

    PYTHONPATH=$PWD/src python3 benchmarks/quality/mesh_peer.py --tune --decompose [--cases ...]

JSON in ``out/mesh_peer/results.json``; ``--write-docs`` writes ``docs/results/peer.md``. Exits 1
when the self-check fails or a case fails to run (then the page is left as it was), not when
vibr loses.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
from _common import (  # noqa: E402
    RESULTS,
    ROOT,
    SceneCache,
    data_dir,
    git_commit,
    machine_description,
    md_table,
    sweep_sources,
)

PAGE = RESULTS / "peer.md"
OUT = ROOT / "out" / "mesh_peer"
VIBR_METHODS = ("gradient", "ulr", "bvs")
METHODS = (*VIBR_METHODS, "peer", "peer 1 view")
BORDER = 2


@dataclass(frozen=True)
class PeerOptions:
    """The peer's settings: the recipe's defaults; ``--tune`` chooses ``voxel_scale``,
    ``trunc_voxels`` and ``k`` on procedural scenes (:data:`TUNE_GRID`), none on the cases reported."""

    voxel_scale: float = 1.0  # voxel, in pixel footprints at the sources' median depth
    trunc_voxels: float = 4.0  # TSDF truncation, in voxels
    weight_threshold: float = 1.0  # marching cubes keeps voxels observed at least this often
    k: int = 4  # views blended per pixel (vibr's ulr_k)
    ztol_voxels: float = 4.0  # a source sees a point when its depth is within this of the mesh's
    half_pixel: bool = True  # shift K by +½ for Open3D's integration (its pixel centres at +½)
    block_resolution: int = 8
    block_count: int = 200_000


# -- the peer --------------------------------------------------------------------------------
def voxel_size(sources) -> float:
    """One pixel's footprint at the sources' median depth: median depth / mean focal length."""
    z = np.concatenate([v.depth[np.isfinite(v.depth)].ravel() for v in sources.views])
    f = np.mean([(v.camera.K[0, 0] + v.camera.K[1, 1]) / 2 for v in sources.views])
    return float(np.median(z) / f)


def _o3d_camera(camera, half_pixel: bool):
    """(intrinsic, extrinsic) tensors of a vibr camera for Open3D's integration."""
    import open3d.core as o3c

    K = camera.K.astype(np.float64).copy()
    if half_pixel:  # Open3D reads depth pixel floor(x): its pixel (i, j) spans [j, j + 1)
        K[0, 2] += 0.5
        K[1, 2] += 0.5
    E = np.eye(4)
    E[:3, :3], E[:3, 3] = camera.R, camera.t
    return o3c.Tensor(K), o3c.Tensor(E)


def fuse(sources, voxel: float, opts: PeerOptions):
    """The sources' depth maps fused into a VoxelBlockGrid TSDF; returns the grid."""
    import open3d as o3d
    import open3d.core as o3c

    dev = o3c.Device("CPU:0")
    vbg = o3d.t.geometry.VoxelBlockGrid(attr_names=("tsdf", "weight"), attr_dtypes=(o3c.float32, o3c.float32),
                                        attr_channels=((1), (1)), voxel_size=voxel,
                                        block_resolution=opts.block_resolution, block_count=opts.block_count,
                                        device=dev)
    zmax = 1.05 * max(float(np.nanmax(v.depth)) for v in sources.views)
    for v in sources.views:
        d = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(np.nan_to_num(v.depth, nan=0.0), np.float32)))
        K, E = _o3d_camera(v.camera, opts.half_pixel)
        blocks = vbg.compute_unique_block_coordinates(d, K, E, 1.0, zmax, opts.trunc_voxels)
        vbg.integrate(blocks, d, K, E, 1.0, zmax, opts.trunc_voxels)
    return vbg


def mesh_scene(vbg, opts: PeerOptions):
    """(RaycastingScene of the TSDF's mesh, number of triangles)."""
    import open3d as o3d

    mesh = vbg.extract_triangle_mesh(weight_threshold=opts.weight_threshold)
    scene = o3d.t.geometry.RaycastingScene()
    n = int(mesh.triangle.indices.shape[0]) if "indices" in mesh.triangle else 0
    if n:
        scene.add_triangles(mesh)
    return scene, n


def raycast_depth(scene, camera) -> np.ndarray:
    """Orthogonal depth (H×W float32, NaN where no surface) of the mesh at ``camera``: the ray
    of pixel (x, y) = (col, row) is C + t Rᵀ K⁻¹ (x, y, 1), whose t is the orthogonal depth."""
    import open3d.core as o3c

    pix = camera.pixel_grid().reshape(-1, 2)
    dirs = camera.pixel_rays(pix) @ camera.R  # world directions, unit camera-frame z
    rays = np.hstack([np.broadcast_to(camera.centre, dirs.shape), dirs]).astype(np.float32)
    t = scene.cast_rays(o3c.Tensor(rays))["t_hit"].numpy().reshape(camera.height, camera.width)
    return np.where(np.isfinite(t), t, np.nan).astype(np.float32)


def _bilinear(img, xy):
    """``img`` (H×W×3) at pixel coordinates ``xy`` (N, 2), pixel centres at integers."""
    from scipy.ndimage import map_coordinates

    c = [xy[:, 1], xy[:, 0]]
    return np.stack([map_coordinates(img[..., ch], c, order=1, mode="nearest") for ch in range(img.shape[2])], -1)


def texture(sources, source_depth, camera, depth, voxel: float, opts: PeerOptions):
    """Colour (H×W×3) and coverage of the target pixels of known ``depth``: each source that
    sees the point (inside its image, its depth within ``ztol_voxels`` of the mesh's there)
    weighted as ULR by the angle between its ray and the target's, ``k`` views per pixel."""
    H, W = depth.shape
    ok = np.isfinite(depth)
    X = camera.backproject(camera.pixel_grid()[ok], depth[ok])
    n, S = len(X), len(sources)
    theta = np.full((n, S), np.inf)
    cols = np.zeros((n, S, 3), np.float32)
    to_t = camera.centre - X
    to_t /= np.linalg.norm(to_t, axis=1, keepdims=True)
    for s, v in enumerate(sources.views):
        xy, z, inside = v.camera.sees(X)
        iu = np.clip(np.round(xy[:, 0]), 0, v.camera.width - 1).astype(int)
        iv = np.clip(np.round(xy[:, 1]), 0, v.camera.height - 1).astype(int)
        zs = source_depth[s][iv, iu]
        with np.errstate(invalid="ignore"):
            vis = inside & (np.abs(z - zs) <= opts.ztol_voxels * voxel)
        to_s = v.camera.centre - X
        to_s /= np.linalg.norm(to_s, axis=1, keepdims=True)
        ang = np.arccos(np.clip(np.sum(to_t * to_s, axis=1), -1, 1))
        theta[vis, s] = ang[vis]
        cols[vis, s] = _bilinear(v.image, xy[vis])
    if opts.k == 1:  # the best view alone (ULR's weights would give two tied views, as a grid's, none)
        w = np.zeros((n, S))
        seen = np.isfinite(theta).any(axis=1)
        w[np.flatnonzero(seen), np.argmin(theta[seen], axis=1)] = 1.0
    else:
        srt = np.sort(theta, axis=1)
        thr = srt[:, opts.k] if S > opts.k else np.full(n, np.inf)  # the (k+1)-th best angle
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(np.isfinite(theta), np.maximum(0.0, 1.0 - theta / thr[:, None]) / np.maximum(theta, 1e-4), 0.0)
    wsum = w.sum(axis=1)
    img = np.zeros((H, W, 3), np.float32)
    cov = np.zeros((H, W), bool)
    got = wsum > 0
    vals = np.zeros((n, 3), np.float32)
    vals[got] = (w[got, :, None] * cols[got]).sum(axis=1) / wsum[got, None]
    img[ok] = vals
    cov[ok] = got
    return img, cov


def peer_render(sources, camera, opts: PeerOptions = PeerOptions()) -> dict:
    """The peer's render at ``camera`` from ``sources`` (their depth: NaN where unknown):
    ``image``, ``coverage``, ``depth`` (the mesh's), ``voxel``, ``triangles``, ``seconds``, and
    ``one_view``: the same pixels textured from the one source of the smallest angle (the nearest
    photograph, reprojected: no blend to blur it)."""
    t0 = time.perf_counter()
    voxel = opts.voxel_scale * voxel_size(sources)
    vbg = fuse(sources, voxel, opts)
    scene, ntri = mesh_scene(vbg, opts)
    if not ntri:
        raise RuntimeError("the TSDF fused no surface")
    depth = raycast_depth(scene, camera)
    src_depth = [raycast_depth(scene, v.camera) for v in sources.views]
    img, cov = texture(sources, src_depth, camera, depth, voxel, opts)
    one, one_cov = (img, cov) if opts.k == 1 else texture(sources, src_depth, camera, depth, voxel, replace(opts, k=1))
    assert np.array_equal(one_cov, cov)  # the same pixels, whatever the blend
    return dict(image=img, coverage=cov, depth=depth, voxel=voxel, triangles=ntri, one_view=one,
                blocks=int(vbg.hashmap().size()), seconds=time.perf_counter() - t0)


# -- the closed-form check -------------------------------------------------------------------
def legacy_triangles(sources, voxel: float, opts: PeerOptions) -> int:
    """Triangles of the mesh of Open3D's legacy ``ScalableTSDFVolume`` fed the same depth (16-bit,
    millimetres) and colour: the trap the peer avoids (the open3d-cpu 0.20 wheel's fuses nothing,
    silently)."""
    import open3d as o3d

    integ = o3d.pipelines.integration
    vol = integ.ScalableTSDFVolume(voxel_length=voxel, sdf_trunc=opts.trunc_voxels * voxel,
                                   color_type=integ.TSDFVolumeColorType.RGB8)
    for v in sources.views:
        K, E = (np.asarray(t.numpy()) for t in _o3d_camera(v.camera, opts.half_pixel))
        rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
            o3d.geometry.Image(np.ascontiguousarray((v.image * 255 + 0.5).astype(np.uint8))),
            o3d.geometry.Image(np.ascontiguousarray((np.nan_to_num(v.depth) * 1000).astype(np.uint16))),
            depth_scale=1000.0, depth_trunc=1e4, convert_rgb_to_intensity=False)
        vol.integrate(rgbd, o3d.camera.PinholeCameraIntrinsic(v.camera.width, v.camera.height, K[0, 0], K[1, 1],
                                                              K[0, 2], K[1, 2]), E)
    return len(vol.extract_triangle_mesh().triangles)


#: the check's plane, from the middle view's axis: steep enough that half a pixel moves the
#: depth (its gradient), not so steep that the outer rays graze it (a projective TSDF's holes)
SLANT_DEG = 35.0


def plane_scene(size: int = 160):
    """Five views of a plane of random texture slanted :data:`SLANT_DEG` from the middle view's axis (vibr.synthetic's
    arc layout), exact depth; returns (scene, the plane's normal n, its offset: n · X = d)."""
    from vibr.synthetic import SCENE_CENTRE, World, make_scene

    c = np.asarray(SCENE_CENTRE, float)
    a = np.radians(SLANT_DEG)
    u = np.array([np.cos(a), 0.0, np.sin(a)])  # in the plane, slanted away from the cameras
    v = np.array([0.0, 1.0, 0.0])
    w = World()
    tex = np.random.default_rng(0).random((64, 64, 3)).astype(np.float32)  # texels of ~3 pixels
    w.add_rect(c - 8 * u - 8 * v, 16 * u, 16 * v, texture=tex, tile=4.0)
    n = np.cross(u, v)
    return make_scene("arc", n_views=5, width=size, height=size * 3 // 4, world=w), n, float(n @ c)


def self_check(opts: PeerOptions = PeerOptions()) -> dict:
    """The peer on :func:`plane_scene` (view 2 from the 4 others, exact depth), with and
    without the half-pixel shift: median |depth error| in voxels against the plane's closed-form
    depth (:func:`vibr.synthetic.planar_depth`), coverage (against ``seen``: the target pixels
    whose plane point some source's image holds) and PSNR against the rendered view. Passes when
    the shifted error is under 0.15 voxel and under a third of the unshifted one, the coverage
    above 90 % of ``seen`` (the TSDF loses a voxel or so at the frustums' edges and holes where
    rays are sparse) and the PSNR above 35 dB."""
    from vibr.metrics import psnr
    from vibr.synthetic import planar_depth

    sc, n, d = plane_scene()
    src, tv = sc.split(2)
    truth = planar_depth(tv.camera, d, n)
    ok = np.isfinite(truth)
    X = tv.camera.backproject(tv.camera.pixel_grid()[ok], truth[ok])
    seen = np.logical_or.reduce([v.camera.sees(X)[2] for v in src.views])  # inside some source
    out = {"seen": float(seen.sum()) / truth.size}
    for half in (True, False):
        r = peer_render(src, tv.camera, replace(opts, half_pixel=half))
        both = np.isfinite(r["depth"]) & np.isfinite(truth)
        err = np.abs(r["depth"] - truth)[both] / r["voxel"]
        out["shifted" if half else "unshifted"] = dict(
            median_error_voxels=float(np.median(err)), p90_error_voxels=float(np.percentile(err, 90)),
            coverage=float(r["coverage"].mean()), psnr=psnr(r["image"], tv.image, r["coverage"], border=BORDER))
    out["legacy_triangles"] = legacy_triangles(src, voxel_size(src), opts)
    s, u = out["shifted"], out["unshifted"]
    out["passed"] = bool(s["median_error_voxels"] < 0.15 and u["median_error_voxels"] > 3 * s["median_error_voxels"]
                         and s["coverage"] > 0.9 * out["seen"] and s["psnr"] > 35.0)
    return out


# -- the tuning, on procedural scenes only -------------------------------------------------
#: the settings ``--tune`` tries: voxel (pixel footprints), truncation (voxels), views blended
#: (4: ULR's blend, 1: the best-angle view alone)
TUNE_GRID = dict(voxel_scale=(0.5, 1.0, 2.0), trunc_voxels=(2.0, 4.0, 8.0), k=(4, 1))
#: the tuning scenes (vibr.synthetic, procedural: the *choose* half of ``scene_split``), each
#: its middle view from the others, depth estimated from the sources as in the real cases
TUNE_LAYOUTS = ("arc", "free", "handheld")
TUNE_SIZE = (160, 120)


def tune_scenes():
    """(name, sources with estimated depth (NaN where stereo left none), target view) of each
    :data:`TUNE_LAYOUTS` scene, seed 0, at :data:`TUNE_SIZE`, its sources photographed as the
    sweep's (``_common.CAPTURE``); the depth through the depth cache."""
    from _common import CAPTURE, scene_split
    from vibr.stereo.cache import estimated_depth
    from vibr.synthetic import make_scene, photograph

    assert scene_split("synthetic") == "choose"  # the peer is tuned on no scene it is reported on
    out = []
    for lo in TUNE_LAYOUTS:
        sc = make_scene(lo, width=TUNE_SIZE[0], height=TUNE_SIZE[1], seed=0)
        src, tv = sc.split(len(sc) // 2)
        out.append((f"synthetic {lo}", estimated_depth(photograph(src, **CAPTURE)), tv))
    return out


def tune(base: PeerOptions = PeerOptions()) -> dict:
    """Every :data:`TUNE_GRID` setting on :func:`tune_scenes`: the peer's PSNR on all pixels
    (black where it leaves a hole: a setting cannot win by covering less) and on its covered
    pixels, per scene; ``chosen``: the setting of the best mean all-pixel PSNR."""
    from vibr.metrics import psnr

    scenes = tune_scenes()
    rows = []
    for vs in TUNE_GRID["voxel_scale"]:
        for tr in TUNE_GRID["trunc_voxels"]:
            o = replace(base, voxel_scale=vs, trunc_voxels=tr, k=max(TUNE_GRID["k"]))
            res = {k: dict(psnr_all=[], psnr_covered=[], coverage=[]) for k in TUNE_GRID["k"]}
            for _name, src, tv in scenes:
                r = peer_render(src, tv.camera, o)  # one fusion gives both blends
                for k, img in ((o.k, r["image"]), (1, r["one_view"])):
                    res[k]["psnr_all"].append(psnr(img, tv.image, border=BORDER))
                    res[k]["psnr_covered"].append(psnr(img, tv.image, r["coverage"], border=BORDER))
                    res[k]["coverage"].append(float(r["coverage"].mean()))
            for k in TUNE_GRID["k"]:
                rows.append(dict(voxel_scale=vs, trunc_voxels=tr, k=k, **res[k],
                                 mean_psnr_all=float(np.mean(res[k]["psnr_all"])),
                                 mean_psnr_covered=float(np.mean(res[k]["psnr_covered"]))))
            print("tune " + "  ".join(f"vox {vs:g} trunc {tr:g} k {k}: {rows[-i]['mean_psnr_all']:.2f}/"
                                      f"{rows[-i]['mean_psnr_covered']:.2f} dB" for i, k in ((2, 4), (1, 1))),
                  flush=True)
    best = max(rows, key=lambda r: r["mean_psnr_all"])
    return dict(scenes=[n for n, _, _ in scenes], size=list(TUNE_SIZE), rows=rows,
                chosen=dict(voxel_scale=best["voxel_scale"], trunc_voxels=best["trunc_voxels"], k=best["k"]))


# -- the cases -------------------------------------------------------------------------------
def cases(which):
    """The cases of the scenes ``which`` ("fountain", "cotton", "backgammon", "temple"), in that order."""
    every = {"fountain": [dict(kind="fountain", target=t, name=f"fountain {t}") for t in ("0002", "0005", "0008")],
             "cotton": [dict(kind="cotton", depth=dp, stride=1, name=f"cotton centre, {dp} depth")
                        for dp in ("gt", "estimated")],
             "backgammon": [dict(kind="backgammon", stride=1, name="backgammon centre, estimated depth")],
             "temple": [dict(kind="temple", name="temple 0004 from 4")]}
    unknown = set(which) - set(every)
    if unknown:
        sys.exit(f"unknown scene(s) {', '.join(sorted(unknown))} (choose from {', '.join(every)})")
    return [c for w in which for c in every[w]]


def case_sources(cache, case):
    """(vibr's sources, the peer's sources, target view): the same depth maps, the peer's
    without vibr's fallback proxy (NaN where stereo left no depth; the same depth cache)."""
    from vibr.stereo.cache import estimated_depth

    src, tv = sweep_sources(cache, case)
    if case.get("depth", "estimated") != "estimated":
        return src, src, tv
    full = {"fountain": ("strecha_fountain-P11", 0.25), "temple": ("middlebury_templeSparseRing", 1.0),
            "cotton": ("hci2016_cotton", 1.0), "backgammon": ("hci2016_backgammon", 1.0)}[case["kind"]]
    raw = estimated_depth(cache.get(*full).subset(src.names))
    assert raw.names == src.names
    return src, raw, tv


def measure(renders: dict, ref) -> dict:
    """Per method: PSNR on the common pixels and on all, coverage %, sharpness on the common pixels."""
    from vibr.metrics import psnr, sharpness

    common = np.logical_and.reduce([r["coverage"] for r in renders.values()])
    out = {"common_pct": 100 * float(common.mean())}
    for m, r in renders.items():
        out[m] = dict(psnr_common=psnr(r["image"], ref, common, BORDER), psnr_all=psnr(r["image"], ref, border=BORDER),
                      coverage_pct=100 * float(r["coverage"].mean()),
                      sharpness=sharpness(r["image"], ref, common, BORDER), seconds=r["seconds"])
    return out


def run_case(cache, case, opts: PeerOptions, figures: Path | None) -> dict:
    from vibr.render import render

    src, raw, tv = case_sources(cache, case)
    renders = {}
    for m in VIBR_METHODS:
        t0 = time.perf_counter()
        res = render(src, tv, m)
        renders[m] = dict(image=np.clip(res.image, 0, 1), coverage=np.asarray(res.coverage, bool),
                          seconds=time.perf_counter() - t0)
    p = peer_render(raw, tv.camera, opts)
    renders["peer"] = p
    renders["peer 1 view"] = dict(image=p["one_view"], coverage=p["coverage"], seconds=p["seconds"])
    rep = dict(name=case["name"], sources=src.names, target=tv.name, size=list(tv.image.shape[:2]),
               voxel=p["voxel"], triangles=p["triangles"], blocks=p["blocks"], **measure(renders, tv.image))
    if figures is not None:
        save_strip(figures / (case["name"].replace(" ", "_").replace(",", "") + ".png"), tv.image, renders)
    return rep


#: the rows of ``--decompose``: (label, target depth, sources' depth for the visibility test)
DECOMPOSE_ROWS = (("peer: mesh at the target, visibility by the mesh", "mesh", "mesh"),
                  ("mesh at the target, visibility by vibr's source depth", "mesh", "vibr"),
                  ("mesh at the target, no visibility test", "mesh", None),
                  ("vibr's z-buffer, visibility by vibr's source depth", "zbuffer", "vibr"),
                  ("vibr's z-buffer, no visibility test", "zbuffer", None))


def mesh_at_measured(src, mesh_depth):
    """``src`` with each view's measured depth (not its fallback proxy) replaced by the mesh's
    where the mesh has a surface: vibr over the peer's fused geometry."""
    views = []
    for v, m in zip(src.views, mesh_depth):
        keep = ~np.isfinite(m) if v.fallback is None else ~np.isfinite(m) | v.fallback
        # replace() forgets the proxy mask of a new depth map unless it is passed on
        views.append(v.replace(depth=np.where(keep, v.depth, m).astype(np.float32), fallback=v.fallback))
    return src.replace(views=views)


def decompose(cache, case, opts: PeerOptions) -> dict:
    """PSNR on the pixels every row of :data:`DECOMPOSE_ROWS` and vibr's ``ulr`` and
    ``gradient`` cover (module docstring, ``--decompose``)."""
    from vibr.geometry import compute_samples, target_depth
    from vibr.metrics import psnr
    from vibr.render import render

    src, raw, tv = case_sources(cache, case)
    voxel = opts.voxel_scale * voxel_size(raw)
    scene, ntri = mesh_scene(fuse(raw, voxel, opts), opts)
    if not ntri:
        raise RuntimeError("the TSDF fused no surface")
    depth = {"mesh": raycast_depth(scene, tv.camera),
             "zbuffer": target_depth(compute_samples(src, tv.camera, return_zbuffer=True))}
    at_sources = {"mesh": [raycast_depth(scene, v.camera) for v in raw.views], "vibr": [v.depth for v in src.views],
                  None: [np.zeros(v.camera.shape, np.float32) for v in src.views]}
    rows = {}
    for label, target, vis in DECOMPOSE_ROWS:
        o = opts if vis is not None else replace(opts, ztol_voxels=np.inf)
        img, cov = texture(src, at_sources[vis], tv.camera, depth[target], voxel, o)
        rows[label] = (np.clip(img, 0, 1), cov)
    fused = mesh_at_measured(src, at_sources["mesh"])
    for m in ("ulr", "gradient"):
        for label, s in ((f"vibr {m}", src), (f"vibr {m}, the mesh's depth at its measured pixels", fused)):
            r = render(s, tv, m)
            rows[label] = (np.clip(r.image, 0, 1), np.asarray(r.coverage, bool))
    common = np.logical_and.reduce([c for _, c in rows.values()])
    inner = np.zeros_like(common)
    inner[BORDER:-BORDER, BORDER:-BORDER] = True
    return dict(name=case["name"], common_pct=100 * float(common.mean()),
                psnr_common={k: float(psnr(im, tv.image, common, BORDER)) for k, (im, _) in rows.items()},
                bands={k: error_bands(im, tv.image, common & inner) for k, (im, _) in rows.items()})


#: the spatial-frequency bands of ``--decompose``'s error split, cycles per pixel (0.5: Nyquist
#: along an axis; the diagonal reaches 0.71)
BANDS = (0.0, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 0.75)


def error_bands(img, ref, mask) -> list[float]:
    """The mean squared error of ``img`` against ``ref`` over ``mask`` (per channel, averaged), split
    by the radial spatial frequency of the masked error (:data:`BANDS`): by Parseval the parts
    add up to the MSE, so a lead is located in scale (a wavelength of 1 / f pixels)."""
    H, W = mask.shape
    E = (np.asarray(img, np.float64) - ref) * mask[..., None]
    power = sum(np.abs(np.fft.fft2(E[..., c])) ** 2 for c in range(E.shape[2])) / (E.shape[2] * H * W * mask.sum())
    f = np.hypot(np.fft.fftfreq(H)[:, None], np.fft.fftfreq(W)[None, :])
    return [float(power[(f >= a) & (f < b)].sum()) for a, b in zip(BANDS[:-1], BANDS[1:])]


def save_strip(path: Path, photo, renders):
    """Photo | each method (in :data:`METHODS` order) side by side, then the same at 2× on a
    quarter of the image (left of centre, above it)."""
    import imageio.v3 as iio

    ims = [photo] + [r["image"] for r in renders.values()]
    H, W = photo.shape[:2]
    row = np.concatenate([np.pad(i, ((0, 0), (0, 4), (0, 0)), constant_values=1) for i in ims], axis=1)
    crops = [i[H // 4 + H // 8:H // 4 + H // 8 + H // 4, W // 4 + W // 8:W // 4 + W // 8 + W // 4] for i in ims]
    crops = [np.pad(c.repeat(2, 0).repeat(2, 1), ((0, 0), (0, 4), (0, 0)), constant_values=1) for c in crops]
    zoom = np.concatenate(crops, axis=1)
    zoom = np.pad(zoom, ((4, 0), (0, row.shape[1] - zoom.shape[1]), (0, 0)), constant_values=1)
    path.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(path, (np.clip(np.concatenate([row, zoom], 0), 0, 1) * 255 + 0.5).astype(np.uint8))


# -- the page --------------------------------------------------------------------------------
def tuning_section(tuning) -> list[str]:
    """The page's lines on how the peer's settings were chosen (``--tune``), or on their being the recipe's."""
    if tuning is None:
        return ["## The peer's settings", "",
                "The recipe's (not tuned: the run had no `--tune`).", ""]
    c = tuning["chosen"]
    w, h = tuning["size"]
    rows = [[f"{r['voxel_scale']:g}", f"{r['trunc_voxels']:g}", "ULR, 4 views" if r["k"] > 1 else "best view",
             f"{r['mean_psnr_all']:.2f}", f"{r['mean_psnr_covered']:.2f}", f"{100 * np.mean(r['coverage']):.1f}"]
            for r in tuning["rows"]]
    return ["## The peer's settings, chosen on procedural scenes", "",
            f"`--tune` tries every voxel size (in pixel footprints at the sources' median depth), truncation (in "
            f"voxels) and blend below on procedural scenes only ({', '.join(tuning['scenes'])}: vibr.synthetic, "
            f"{w}×{h}, seed 0, the middle view from the others, the sources photographed as the defaults' sweep's, "
            "depth estimated from them as in the cases below), as vibr's defaults are chosen, and keeps the best mean PSNR over all pixels (a hole counts "
            f"black, so that no setting wins by covering less): voxel {c['voxel_scale']:g}, truncation "
            f"{c['trunc_voxels']:g} voxels, {'ULR with 4 views' if c['k'] > 1 else 'the best view'}. None of the "
            "cases below takes part.", "",
            md_table(["voxel (pixels)", "truncation (voxels)", "blend", "mean PSNR all", "mean PSNR covered",
                      "mean coverage %"], rows), ""]


def page(report: dict) -> str:
    check, opt = report["self_check"], report["options"]
    lines = [
        "# vibr against a TSDF-mesh peer",
        "",
        "Generated by `benchmarks/quality/mesh_peer.py`; every number on this page comes from the run "
        "described here.",
        "",
        "The peer is what a competent user builds from vibr's own depth maps (estimated without the "
        f"target): the maps fused into an Open3D TSDF (`VoxelBlockGrid`, voxel = {opt['voxel_scale']:g} × one "
        f"pixel's footprint at the sources' median depth, truncation {opt['trunc_voxels']:g} voxels), the mesh "
        "ray-cast at the target, each pixel textured from the sources that see its surface point (a z-test "
        f"against the mesh's depth at the source, {opt['ztol_voxels']:g} voxels), "
        + (f"blended by angle as ULR with {opt['k']} views (`peer`) or from the source of the smallest angle "
           "alone (`peer 1 view`)" if opt["k"] > 1 else
           "from the source of the smallest angle alone (`peer` and `peer 1 view`, the same)")
        + "; pixels with no surface are black. vibr's "
        "methods render from the same depth with their fallback proxy where stereo left none. The script's "
        "docstring gives the details; Open3D is the `bench` extra (`pip install -e '.[bench]'`), which "
        "vibr never imports.",
        "",
        "## The run",
        "",
        f"* Command (from the repository root): `{report['command']}`",
        f"* Wall time {report['seconds'] / 60:.1f} min; Open3D {report['open3d']}.",
        "* Machine (shared; timings are indicative):",
        "",
        "```",
        *report["machine"],
        "```",
        "",
        "## The peer's geometry, in closed form",
        "",
        f"A textured plane slanted {SLANT_DEG:g}° (vibr.synthetic, five views of 160×120, exact depth), its middle "
        "view rendered by the peer from the four others: the median error of the ray-cast depth against "
        "the plane's, in voxels, with the intrinsics Open3D's integration is given shifted by half a pixel "
        "(its pixel centres are at +½, vibr's at integers) and unshifted.",
        "",
        md_table(["K given to Open3D", "median |depth error| (voxels)", "90th percentile", "coverage %", "PSNR dB"],
                 [[k, f"{check[k]['median_error_voxels']:.3f}", f"{check[k]['p90_error_voxels']:.3f}",
                   f"{100 * check[k]['coverage']:.1f}", f"{check[k]['psnr']:.2f}"] for k in ("shifted", "unshifted")]),
        "",
        f"Open3D's legacy `ScalableTSDFVolume`, fed the same depth and colour, gives a mesh of "
        f"{check['legacy_triangles']} triangles, without a warning: the peer uses `VoxelBlockGrid`.",
        "",
        *tuning_section(report.get("tuning")),
        "## The cases",
        "",
        "PSNR (dB) on the pixels every method covers and on all pixels (what a method leaves black counts), "
        "coverage, and sharpness: the render's high-frequency energy (squared Laplacian) over the held-out "
        "photograph's on the common pixels (`vibr.metrics.sharpness`; 1 as sharp as the photograph, below "
        "1 blurred, above 1 noisier). 2-pixel border.",
        "",
    ]
    rows = []
    for r in report["cases"]:
        if "error" in r:
            rows.append([r["name"], "failed", r["error"], "", "", "", ""])
            continue
        for m in METHODS:
            x = r[m]
            rows.append([r["name"] if m == METHODS[0] else "", m, f"{r['common_pct']:.1f}" if m == METHODS[0] else "",
                         f"{x['psnr_common']:.2f}", f"{x['psnr_all']:.2f}", f"{x['coverage_pct']:.1f}",
                         f"{x['sharpness']:.2f}"])
    lines += [md_table(["case", "method", "common %", "PSNR common", "PSNR all", "coverage %", "sharpness"], rows), ""]
    if report.get("figures"):
        lines += [f"Figures, written by the run and not committed (they show the dataset photographs): "
                  f"`{report['figures']}/*.png`, the photograph, then {', '.join(METHODS)}, and below a "
                  f"quarter of each at 2×.", ""]
    lines += ["## What the table says", ""]
    for r in report["cases"]:
        if "error" in r:
            continue
        best = max(METHODS, key=lambda m: r[m]["psnr_common"])
        lines.append(f"* {r['name']}: best on the common pixels `{best}`; vibr's default − peer "
                     f"{r['gradient']['psnr_common'] - r['peer']['psnr_common']:+.2f} dB there, "
                     f"{r['gradient']['psnr_all'] - r['peer']['psnr_all']:+.2f} dB on all pixels; sharpness "
                     f"{r['gradient']['sharpness']:.2f} (vibr) against {r['peer']['sharpness']:.2f} (peer).")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", help="data folder (default $VIBR_DATA or ../shared/data)")
    ap.add_argument("--cases", default="fountain,cotton,backgammon,temple",
                    help="comma-separated: fountain, cotton, backgammon, temple")
    ap.add_argument("--self-check", action="store_true", help="run only the closed-form check of the peer")
    ap.add_argument("--tune", action="store_true",
                    help="choose the peer's voxel, truncation and blend on procedural scenes first, then use them")
    ap.add_argument("--figures", type=Path, help="save photo | renders strips (PNG) in this folder")
    ap.add_argument("--write-docs", action="store_true", help=f"write {PAGE.relative_to(ROOT)}")
    ap.add_argument("--decompose", action="store_true",
                    help="where the peer's lead comes from: its blend over either depth at the target, "
                         "with each visibility test, beside vibr's ulr and gradient (prints; the page is not written)")
    a = ap.parse_args(argv)
    if a.decompose and a.write_docs:
        ap.error("--decompose writes no page: run it without --write-docs")
    try:
        import open3d
    except ImportError:
        sys.exit("mesh_peer.py needs Open3D: pip install -e '.[bench]'")
    t0 = time.perf_counter()
    opts = PeerOptions()
    check = self_check(opts)
    print(json.dumps(check, indent=1), flush=True)
    if a.self_check or not check["passed"]:
        if not check["passed"]:
            print("self-check failed: the peer's ray-cast depth does not match the plane's", file=sys.stderr)
        return 0 if check["passed"] else 1
    tuning = None
    if a.tune:
        tuning = tune(opts)
        opts = replace(opts, **tuning["chosen"])
        print(f"tuned: {json.dumps(tuning['chosen'])}", flush=True)
    cache = SceneCache(data_dir(a.data))
    if a.decompose:
        return run_decompose(cache, a.cases.split(","), opts)
    reps = []
    for case in cases(a.cases.split(",")):
        try:
            reps.append(run_case(cache, case, opts, a.figures))
            r = reps[-1]
            print(f"{case['name']}: common {r['common_pct']:.1f} %  " + "  ".join(
                f"{m} {r[m]['psnr_common']:.2f}/{r[m]['psnr_all']:.2f} dB cov {r[m]['coverage_pct']:.1f} "
                f"sharp {r[m]['sharpness']:.2f}" for m in METHODS), flush=True)
        except Exception as e:  # noqa: BLE001  (reported, and the run exits 1)
            reps.append(dict(name=case["name"], error=f"{type(e).__name__}: {e}"))
            print(f"{case['name']}: FAILED {reps[-1]['error']}", file=sys.stderr, flush=True)
    report = dict(command="python3 benchmarks/quality/mesh_peer.py " + " ".join(argv if argv is not None else sys.argv[1:]),
                  seconds=time.perf_counter() - t0, commit=git_commit(), open3d=open3d.__version__,
                  machine=machine_description(), options=asdict(opts), tuning=tuning, self_check=check, cases=reps,
                  figures=None if a.figures is None else str(a.figures))
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "results.json").write_text(json.dumps(report, indent=1))
    failed = [r["name"] for r in reps if "error" in r]
    if failed:
        print(f"failed to run: {', '.join(failed)}" + (f"; {PAGE.name} not written" if a.write_docs else ""),
              file=sys.stderr)
        return 1
    if a.write_docs:
        PAGE.write_text(page(report))
    return 0


def run_decompose(cache, which, opts: PeerOptions) -> int:
    reps = []
    for case in cases([w for w in which if w != "temple"]):  # temple's common pixels are its object's rim only
        reps.append(decompose(cache, case, opts))
        print(f"{case['name']} (common {reps[-1]['common_pct']:.1f} %)", flush=True)
        for k, v in reps[-1]["psnr_common"].items():
            print(f"  {k:<55} {v:6.2f} dB", flush=True)
        print("  MSE (×1e-5) by spatial frequency, cycles per pixel: "
              + "  ".join(f"{a:g}–{b:g}" for a, b in zip(BANDS[:-1], BANDS[1:])), flush=True)
        for k, v in reps[-1]["bands"].items():
            print(f"  {k:<55} " + " ".join(f"{1e5 * x:6.2f}" for x in v), flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "decompose.json").write_text(json.dumps(dict(options=asdict(opts), cases=reps, commit=git_commit()), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
