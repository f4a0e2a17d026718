"""Fingerprints of renders, depth maps and camera paths over a fixed set of cases.

Run it on two commits and compare the outputs: a refactoring that changes no behaviour
prints the same digests, case by case (renders, σ maps, depth maps, path cameras).

    python3 benchmarks/tools/identical_outputs.py > before.json      # on the first commit
    python3 benchmarks/tools/identical_outputs.py > after.json       # on the second
    python3 benchmarks/tools/identical_outputs.py --compare before.json after.json

The cases use small synthetic scenes (no data needed) and run in a few minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import sys

import numpy as np


def _import(*names):
    """The first module of ``names`` that imports (the layout changed across versions)."""
    for n in names:
        try:
            return importlib.import_module(n)
        except ModuleNotFoundError:
            continue
    raise ModuleNotFoundError(names[0])


def _digest(*arrays) -> str:
    h = hashlib.md5()
    for a in arrays:
        if a is None:
            h.update(b"none")
            continue
        a = np.ascontiguousarray(np.asarray(a))
        h.update(str((a.dtype, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _scenes():
    from vibr.synthetic import degrade_depth, make_scene

    grid = make_scene("grid", width=96, height=96)
    free = make_scene("free", n_views=5, width=96, height=96)
    arc = make_scene("arc", n_views=5, width=96, height=96)
    pan = make_scene("pan", n_views=5, width=96, height=96)
    holes = make_scene("grid", width=96, height=96)
    for i, v in enumerate(holes.views):
        v.depth = degrade_depth(v.depth, holes=0.3, seed=i)
    return dict(grid=grid, free=free, arc=arc, pan=pan, holes=holes)


def _render_cases(scenes):
    from vibr.pipeline import prepare
    from vibr.render import render

    def case(scene, target="view_004", method="gradient", depth="gt", n_views=None, target_scale=None,
             uncertainty=False, supersample="auto", **params):
        sc = scenes[scene]
        src, tgt = prepare(sc, target, depth=depth, n_views=n_views)
        if target_scale is not None:
            tgt = tgt.camera.scaled(target_scale) if hasattr(tgt, "camera") else tgt.scaled(target_scale)
        res = render(src, tgt, method, uncertainty=uncertainty, supersample=supersample, **params)
        sigma = getattr(res, "sigma", None)
        return _digest(res.image, res.coverage, sigma)

    cases = {
        "grid/gradient": dict(scene="grid"),
        "grid/bvs": dict(scene="grid", method="bvs"),
        "grid/savsr": dict(scene="grid", method="savsr"),
        "grid/ulr": dict(scene="grid", method="ulr"),
        "grid/gradient/footprint": dict(scene="grid", psf="footprint"),
        "grid/gradient/uncertainty": dict(scene="grid", uncertainty=True),
        "grid/gradient/preset-paper": dict(scene="grid", preset="paper"),
        "grid/gradient/robust": dict(scene="grid", robust="cauchy"),
        "grid/gradient/n_outer3": dict(scene="grid", n_outer=3),
        "grid/gradient/view_k0": dict(scene="grid", view_k=0),
        "grid/gradient/gamma1-lam0.2": dict(scene="grid", gamma=1.0, lam=0.2),
        "grid/gradient/tv-samples": dict(scene="grid", tv_weighting="samples"),
        "grid/gradient/half-target": dict(scene="grid", target_scale=0.5),
        "grid/gradient/half-target-ss1": dict(scene="grid", target_scale=0.5, supersample=1),
        "grid/gradient/double-target": dict(scene="grid", target_scale=2.0),
        "grid/gradient/planar": dict(scene="grid", depth="planar"),
        "grid/ulr/planar": dict(scene="grid", method="ulr", depth="planar"),
        "grid/gradient/4-views": dict(scene="grid", n_views=4),
        "free/gradient": dict(scene="free", target="view_002"),
        "free/bvs": dict(scene="free", target="view_002", method="bvs"),
        "free/ulr": dict(scene="free", target="view_002", method="ulr"),
        "arc/gradient": dict(scene="arc", target="view_002"),
        "arc/gradient/estimated": dict(scene="arc", target="view_002", depth="estimated"),
        "pan/gradient": dict(scene="pan", target="view_002"),
        "holes/gradient": dict(scene="holes"),
        "holes/bvs": dict(scene="holes", method="bvs"),
    }
    out = {}
    for name, kw in cases.items():
        try:
            out[name] = case(**kw)
        except Exception as e:  # a case that fails must fail the same way on both commits
            out[name] = f"error: {type(e).__name__}: {e}"
        print(f"{name}: {out[name]}", file=sys.stderr)
    return out


def _depth_cases(scenes):
    from vibr.stereo import estimate_depth

    out = {}
    for name, sc, kw in [("depth/free-mvs", scenes["free"], {}),
                         ("depth/grid-lightfield", scenes["grid"], {}),
                         ("depth/arc-mvs-exclude", scenes["arc"], dict(exclude=("view_002",)))]:
        try:
            est = estimate_depth(sc, **kw)
            out[name] = _digest(*[v.depth for v in est.views], *[v.sigma_z for v in est.views])
        except Exception as e:
            out[name] = f"error: {type(e).__name__}: {e}"
        print(f"{name}: {out[name]}", file=sys.stderr)
    return out


def _path_cases(scenes):
    paths = _import("vibr.paths", "vibr.paths.camera_path")

    def cams(p):
        return _digest(*[np.concatenate([c.K.ravel(), c.R.ravel(), c.t.ravel(), [c.width, c.height]])
                         for c in p.cameras])

    cases = {
        "path/grid-interpolate": lambda: paths.interpolate(scenes["grid"], n_frames=12),
        "path/free-interpolate-smooth": lambda: paths.interpolate(scenes["free"], n_frames=12, smooth=1.0),
        "path/free-orbit": lambda: paths.orbit(scenes["free"], n_frames=12),
        "path/grid-spiral": lambda: paths.spiral(scenes["grid"], n_frames=12),
        "path/arc-orbit-full": lambda: paths.orbit(scenes["arc"], n_frames=8, full=True),
    }
    out = {}
    for name, make in cases.items():
        try:
            out[name] = cams(make())
        except Exception as e:
            out[name] = f"error: {type(e).__name__}: {e}"
        print(f"{name}: {out[name]}", file=sys.stderr)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"),
                    help="compare two outputs of this script; exit 1 when a case differs")
    args = ap.parse_args(argv)
    if args.compare:
        a, b = (json.load(open(p)) for p in args.compare)
        differ = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
        for k in differ:
            print(f"DIFFERS {k}: {a.get(k)} != {b.get(k)}")
        print(f"{len(set(a) | set(b)) - len(differ)} of {len(set(a) | set(b))} cases identical")
        return 1 if differ else 0
    scenes = _scenes()
    out = {**_render_cases(scenes), **_depth_cases(scenes), **_path_cases(scenes)}
    json.dump(out, sys.stdout, indent=1, sort_keys=True)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
