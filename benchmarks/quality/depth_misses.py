"""Where MVS depth misses on the hand-held synthetic scenes, and what would recover them.

The target is >= 95 % of textured pixels within 1 % of the exact depth on a free camera
layout. This script takes the reference view (view 0) of ``make_scene("handheld")`` scenes,
runs :func:`vibr.stereo.estimate_depth` on every view (as ``bench_depth.py synthetic``
does), and splits the misses:

* by the object of the synthetic world that each pixel's centre ray hits (back wall,
  floor, box, sphere, card), with the share whose own surface is flat (``_common.surface_textured``), unknown
  (NaN) and estimated nearer than the truth;
* by the number of the reference's stereo partners that see the exact point;
* by the distance to a depth edge of the exact depth map;
* what the consistency check drops, right or wrong before it, by what the partners say
  there (agree, see farther, see nearer, have no depth).

Two oracles bound what choosing among existing hypotheses could give, on the depth before
the consistency check:

* ``views``: a pixel counts as right when any partner's estimated depth map, splatted into
  the reference (nearest pixel, z-buffer), is within 1 % there (the most a
  geometric-consistency pass, COLMAP-style, could select);
* ``planes``: when the plane of a pixel 3 px away in one of the 8 directions, extended to
  it, is within 1 % (the most a re-decision among neighbouring planes could select).

``--redecide shift`` runs that re-decision for real (after the weighted median, before the
consistency check): each pixel keeps the cheapest of those 9 planes, each costed with the
best of 5 windows shifted by 3 px (shiftable windows, Kang, Szeliski & Chai 2001).
``--estimate/--refine/--median 'k=v,...'`` override keyword arguments of
``estimate_depth``, ``refine_planes`` and ``median_planes`` (parameter variants).

Usage::

    python benchmarks/quality/depth_misses.py --seeds 5 6 --size 512
    python benchmarks/quality/depth_misses.py --seeds 5 6 --size 512 --refine single_view_penalty=0.05 --quick
"""

from __future__ import annotations

import argparse
import inspect
import sys
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the shared _common
import vibr.stereo.api as api  # noqa: E402
from _common import seen_count, surface_textured, textured  # noqa: E402

NOMASK = np.zeros((0, 1, 1), np.uint8)  # the kernels' ``valid`` for sources without masks
from vibr.stereo import _kernels as kern  # noqa: E402
from vibr.stereo import planesweep as ps  # noqa: E402
from vibr.synthetic import default_world, make_scene  # noqa: E402

_SHIFT = 3
_DIRS = [(0, 0), (0, _SHIFT), (0, -_SHIFT), (_SHIFT, 0), (-_SHIFT, 0),
         (_SHIFT, _SHIFT), (_SHIFT, -_SHIFT), (-_SHIFT, _SHIFT), (-_SHIFT, -_SHIFT)]


def _kwargs(text: str) -> dict:
    """'a=1,b=0.5' -> {'a': 1, 'b': 0.5} (values are Python literals)."""
    import ast

    out = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        k, v = item.split("=", 1)
        out[k.strip()] = ast.literal_eval(v.strip())
    return out


def _shifted(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """out[p] = a[p − (dy, dx)], edge-clamped."""
    H, W = a.shape
    return a[np.clip(np.arange(H) - dy, 0, H - 1)][:, np.clip(np.arange(W) - dx, 0, W - 1)]


def _neighbour_planes(res):
    """The plane of the pixel at each offset of ``_DIRS``, extended to every pixel:
    list of (w, gx, gy) fields."""
    w = res.inv_depth
    gx, gy = res.meta["plane_gradient"]
    out = []
    for oy, ox in _DIRS:
        wq, xq, yq = (_shifted(a, -oy, -ox) for a in (w, gx, gy))
        out.append((wq - xq * ox - yq * oy, xq, yq))
    return out


def _redecide_shiftable(res, ref_image, ref_camera, src_images, src_cameras, n_best):
    """Each pixel takes the cheapest of the 9 neighbouring planes, each costed by the
    best of 5 windows shifted by ``_SHIFT`` px that contain the pixel."""
    I = ps.to_grey(ref_image).astype(np.float64)
    srcs, sizes = ps._stack_greys(src_images)
    A, b = ps.plane_homographies(ref_camera, list(src_cameras))
    d = {k: p.default for k, p in inspect.signature(ps.refine_planes).parameters.items()}
    offs = ps.window_offsets(d["radius"], d["stride"])
    guide = np.ascontiguousarray(np.asarray(ref_image, np.float32))
    wts, wI, sdI = kern.support_weights(I, offs, d["sigma_c"], float(d["sigma_s"] or d["radius"]), guide)
    best = np.full(res.inv_depth.shape, np.inf)
    bw, bx, by = (a.copy() for a in (res.inv_depth, *res.meta["plane_gradient"]))
    for wp, xq, yq in _neighbour_planes(res):
        C = np.full(best.shape, np.inf)
        for sy, sx in _DIRS[:5]:
            wc = wp + xq * sx + yq * sy
            cc = kern.plane_costs(wts, wI, sdI, offs, srcs, sizes, NOMASK, A, b, n_best, d["eps"] ** 2,
                                  _shifted(wc, sy, sx), _shifted(xq, sy, sx), _shifted(yq, sy, sx),
                                  d["single_view_penalty"])
            C = np.minimum(C, _shifted(cc, -sy, -sx))
        better = C < best
        best = np.where(better, C, best)
        bw, bx, by = np.where(better, wp, bw), np.where(better, xq, bx), np.where(better, yq, by)
    bw = np.clip(bw, res.winv.min(), res.winv.max())
    return ps.SweepResult(depth=(1 / bw).astype(np.float32), inv_depth=bw, cost=res.cost,
                          sigma_z=res.sigma_z, confident=res.confident, winv=res.winv,
                          meta=dict(res.meta, plane_gradient=(bx, by)))


def _splat(depth, cam_from, cam_to) -> np.ndarray:
    """Depth map of ``cam_from`` seen from ``cam_to``: nearest pixel, z-buffer, NaN empty."""
    ok = np.isfinite(depth)
    xy, z = cam_to.project(cam_from.backproject(cam_from.pixel_grid()[ok], depth[ok]))
    u, v = np.round(xy[:, 0]).astype(int), np.round(xy[:, 1]).astype(int)
    ins = (z > 0) & (u >= 0) & (v >= 0) & (u < cam_to.width) & (v < cam_to.height)
    zb = np.full(cam_to.shape, np.inf)
    np.minimum.at(zb, (v[ins], u[ins]), z[ins])
    zb[np.isinf(zb)] = np.nan
    return zb


def _within(d, gt):
    with np.errstate(invalid="ignore"):
        return np.abs(d - gt) / gt < 0.01


def run(seed: int, size: int, args) -> None:
    H = size * 4 // 5
    scene = make_scene("handheld", width=size, height=H, seed=seed)
    rec = {}
    refine_kw, median_kw = _kwargs(args.refine), _kwargs(args.median)
    refine0, median0, check0 = api.refine_planes, api.median_planes, api.check_consistency

    def refine(ref_image, ref_camera, src_images, src_cameras, init, **k):
        k.update(refine_kw)
        rec.setdefault("inputs", {})[id(ref_camera)] = (ref_image, ref_camera, src_images, src_cameras,
                                                        k.get("n_best"))
        return refine0(ref_image, ref_camera, src_images, src_cameras, init, **k)

    def median(ref_image, res, **k):
        k.update(median_kw)
        out = median0(ref_image, res, **k)
        if ref_image is scene[0].image:  # at scale 1 the pipeline passes the view's own image
            rec["planes"] = _neighbour_planes(out)
        if args.redecide == "shift":
            ri, rc, si, scs, nb = next(v for v in rec["inputs"].values() if v[0] is ref_image)
            out = _redecide_shiftable(out, ri, rc, si, scs, nb)
        return out

    def check(d, cam, nb_depths, nb_cams, **k):
        if cam is scene[0].camera:
            rec["before_check"] = (d.copy(), [x.copy() for x in nb_depths], list(nb_cams))
        return check0(d, cam, nb_depths, nb_cams, **k)

    api.refine_planes, api.median_planes, api.check_consistency = refine, median, check
    try:
        t = time.perf_counter()
        est = api.estimate_depth(scene, **_kwargs(args.estimate))
        t = time.perf_counter() - t
    finally:
        api.refine_planes, api.median_planes, api.check_consistency = refine0, median0, check0
    gt, d, img = scene[0].depth, est[0].depth, scene[0].image
    tex = textured(img) & np.isfinite(gt)
    n = tex.sum()
    ok = _within(d, gt)
    miss = tex & ~ok
    print(f"\nhand-held seed {seed}, {size}x{H}: within 1 % {100 * ok[tex].mean():.2f} % of textured pixels "
          f"(unknown {100 * (tex & ~np.isfinite(d)).sum() / n:.2f} %), {t:.0f} s; "
          f"estimate {args.estimate or '-'}, refine {args.refine or '-'}, median {args.median or '-'}, "
          f"re-decision {args.redecide}")
    if args.quick:
        return
    surf = surface_textured(img, gt)
    d0, nb_depths, nb_cams = rec["before_check"]
    ok0 = _within(d0, gt)
    print(f"  before the consistency check {100 * ok0[tex].mean():.2f} %")
    # objects: the world's object hit by each pixel's centre ray
    cam = scene[0].camera
    world = default_world(seed)
    fin = np.isfinite(gt)
    X = cam.backproject(cam.pixel_grid()[fin], gt[fin])
    lab = np.full(gt.shape, "", object)
    lab[fin] = [world.names.get(int(o), "") for o in world.raycast(cam.centre[None], X - cam.centre)[1]]
    print(f"  {'object':<12} {'% of tex.':>9} {'within 1 %':>10} {'misses':>7} {'flat own surf.':>14} "
          f"{'unknown':>8} {'nearer':>7}   (misses and their parts: % of all textured pixels)")
    for name in world.names.values():
        m = tex & (lab == name)
        if m.any():
            mm = miss & m
            print(f"  {name:<12} {100 * m.sum() / n:>9.1f} {100 * ok[m].mean():>10.1f} {100 * mm.sum() / n:>7.2f} "
                  f"{100 * (mm & ~surf).sum() / n:>14.2f} {100 * (mm & ~np.isfinite(d)).sum() / n:>8.2f} "
                  f"{100 * (mm & (d < gt)).sum() / n:>7.2f}")
    partners = [scene.index(k) for k in est.meta["depth_estimation"]["views"]["view_000"]["neighbours"]]
    seen = seen_count(scene, 0, partners)
    print(f"  seen by k of the {len(partners)} partners {[scene.views[j].name for j in partners]}:")
    for k in range(len(partners) + 1):
        m = tex & (seen == k)
        if m.any():
            print(f"    k={k}: {100 * m.sum() / n:5.2f} % of tex., within 1 % {100 * ok[m].mean():5.1f}, "
                  f"misses {100 * (miss & m).sum() / n:.2f} "
                  f"(unknown {100 * (miss & m & ~np.isfinite(d)).sum() / n:.2f})")
    g = np.where(fin, gt, 1e3)
    edge = np.zeros(gt.shape, bool)
    jx = np.abs(np.diff(g, axis=1)) > 0.05 * np.minimum(g[:, 1:], g[:, :-1])
    jy = np.abs(np.diff(g, axis=0)) > 0.05 * np.minimum(g[1:], g[:-1])
    edge[:, 1:] |= jx
    edge[:, :-1] |= jx
    edge[1:] |= jy
    edge[:-1] |= jy
    dist = distance_transform_edt(~edge)
    print("  distance to a depth edge (> 5 % jump between 4-neighbours of the exact depth):")
    for lo, hi in ((0, 1.5), (1.5, 3.5), (3.5, 5.5), (5.5, np.inf)):
        m = tex & (dist >= lo) & (dist < hi)
        print(
            f"    {lo}-{hi} px: {100 * m.sum() / n:5.1f} % of tex., within 1 % {100 * ok[m].mean():5.1f}, "
            f"misses {100 * (miss & m).sum() / n:.2f}"
        )
    views_ok = ok0.copy()
    for Dv, cv in zip(nb_depths, nb_cams):
        views_ok |= _within(_splat(Dv, cv, cam), gt)
    planes_ok = ok0.copy()
    for wp, _, _ in rec["planes"]:
        with np.errstate(divide="ignore"):
            planes_ok |= _within(1.0 / wp, gt)
    print(
        f"  oracles on the depth before the check: any partner's depth map within 1 % "
        f"{100 * views_ok[tex].mean():.2f} %; any plane 3 px away within 1 % {100 * planes_ok[tex].mean():.2f} %"
    )
    _check_breakdown(d0, d, gt, tex, cam, nb_depths, nb_cams)


def _check_breakdown(d0, d, gt, tex, cam, nb_depths, nb_cams, rel_tol: float = 0.01) -> None:
    """What the consistency check drops, by what the consistency partners say at the
    reference point's projection: a partner agrees (its depth within ``rel_tol``), sees
    farther (free-space violation: the point would hide what it sees), sees nearer (the
    point may be occluded there: no evidence), or has no depth there (unknown or outside)."""
    n = tex.sum()
    known = np.isfinite(d0)
    X = cam.backproject(cam.pixel_grid().reshape(-1, 2), np.where(known, d0, 1.0).ravel())
    agree = np.zeros(d0.shape, bool)
    farther = np.zeros(d0.shape, bool)
    nearer = np.zeros(d0.shape, bool)
    for Dv, cv in zip(nb_depths, nb_cams):
        xy, zv = cv.project(X)
        u, v = np.floor(xy[:, 0] + 0.5).astype(int), np.floor(xy[:, 1] + 0.5).astype(int)
        ins = (zv > 0) & (u >= 0) & (v >= 0) & (u < cv.width) & (v < cv.height)
        dv = np.full(zv.shape, np.nan)
        dv[ins] = Dv[v[ins], u[ins]]
        with np.errstate(invalid="ignore"):
            agree |= (np.abs(dv - zv) <= rel_tol * zv).reshape(d0.shape)
            farther |= (dv > zv * (1 + rel_tol)).reshape(d0.shape)
            nearer |= (dv < zv * (1 - rel_tol)).reshape(d0.shape)
    dropped = known & ~np.isfinite(d)
    right = _within(d0, gt)
    print("  dropped by the consistency check (% of textured pixels), by what the partners say:")
    for name, sel in (("right before the check", right), ("wrong before the check", ~right)):
        m = tex & dropped & sel
        print(
            f"    {name}: {100 * m.sum() / n:.2f} = depth agrees but round trip fails "
            f"{100 * (m & agree).sum() / n:.2f}, a partner sees farther {100 * (m & ~agree & farther).sum() / n:.2f}, "
            f"only nearer (occlusion possible) {100 * (m & ~agree & ~farther & nearer).sum() / n:.2f}, "
            f"no depth there {100 * (m & ~agree & ~farther & ~nearer).sum() / n:.2f}"
        )


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, nargs="+", default=[5, 6])
    p.add_argument("--size", type=int, default=512, help="image width (height 4/5 of it)")
    p.add_argument("--estimate", default="", help="estimate_depth overrides, 'k=v,...'")
    p.add_argument("--refine", default="", help="refine_planes overrides, 'k=v,...'")
    p.add_argument("--median", default="", help="median_planes overrides, 'k=v,...'")
    p.add_argument("--redecide", choices=["none", "shift"], default="none")
    p.add_argument("--quick", action="store_true", help="the headline figure only")
    args = p.parse_args(argv)
    for seed in args.seeds:
        run(seed, args.size, args)


if __name__ == "__main__":
    main()
