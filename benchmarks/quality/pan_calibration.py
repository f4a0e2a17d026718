"""Videos turned on the spot, and videos that are not, through ``vibr calibrate``.

Each case films the synthetic world (`vibr.synthetic`, ray-cast) as 60 frames of 320×240
(``wide``: 180, ``full``: 72), H.264 at crf 18, and calibrates it with ``vibr.calib.colmap.calibrate(VIDEO, OUT,
frames=N)``, N a third of the frames:

* ``tripod``: turning 50° about one point (:func:`vibr.synthetic.pan_cameras`);
* ``wide``: turning 90° in 180 frames, of which 60 are calibrated;
* ``full``: turning a full circle (72 frames) in a room of four textured walls 4 units away;
* ``hand pan ρ``: the same turn with the camera ρ scene units in front of the axis it turns
  about (a phone held out while the body turns; the scene is 2.6–6 units away);
* ``wall walk``: walking 2 units along a flat textured wall 4 units away, looking at it
  (every pair of frames related by a homography, with a baseline);
* ``arc walk``: walking along a 40° arc round the scene (:func:`vibr.synthetic.arc_cameras`).

For each: COLMAP's homography pairs, the median error of the pairs' homographies and of one
centre for every frame, the verdict, the frames registered, the focal length against the
truth (307.3 px), the largest rotation error after the best common rotation, the spread of the
camera centres (relative to the sparse points' median distance from their mean), and the
leave-one-out render of the middle frame (``vibr eval --target 10 --method gradient --gamma
0.2``: the default setting; depth
estimated where the cameras do not share a centre). ``--compare`` also runs COLMAP's mapper
alone (``pan=False``) on each case that was taken as turned on the spot.

    python benchmarks/quality/pan_calibration.py [--cases tripod,hand0.03,...] [--compare]
"""

from __future__ import annotations

import argparse
import json
import logging
import tempfile
import time
from pathlib import Path

import numpy as np

SIZE = (320, 240)
FOV_DEG = 55.0


def _cameras(case: str) -> tuple[list, object]:
    """The case's 60 true cameras and its world."""
    import vibr.synthetic as syn
    from vibr.camera import Camera

    w, h = SIZE
    if case == "tripod":
        return syn.pan_cameras(60, pan_deg=50, width=w, height=h, fov_deg=FOV_DEG), syn.default_world(0)
    if case == "wide":
        return syn.pan_cameras(180, pan_deg=90, width=w, height=h, fov_deg=FOV_DEG), syn.default_world(0)
    if case.startswith("hand"):
        rho = float(case[4:])
        out = []
        for c in syn.pan_cameras(60, pan_deg=50, width=w, height=h, fov_deg=FOV_DEG):
            a = c.R[2] * [1, 0, 1]
            out.append(Camera.from_centre(c.K, c.R, c.centre + rho * a / np.linalg.norm(a), w, h))
        return out, syn.default_world(0)
    if case == "full":
        world = syn.World()
        for k, (p0, u) in enumerate([([-4, -2, 4], [8, 0, 0]), ([4, -2, 4], [0, 0, -8]),
                                     ([4, -2, -4], [-8, 0, 0]), ([-4, -2, -4], [0, 0, 8])]):
            world.add_rect(p0, u, [0, 4, 0], ["astronaut", "coffee", "chelsea", "rocket"][k], tile=4.0)
        world.add_rect([-4, 2, -4], [8, 0, 0], [0, 0, 8], "gravel", tile=2.0, name="floor")
        K = Camera.intrinsics(syn._focal(w, FOV_DEG), w, h)
        out = []
        for a in np.radians(np.arange(72) * 5.0):
            R = np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]])
            out.append(Camera.from_centre(K, R, [0.0, 0.0, 0.0], w, h))
        return out, world
    if case == "wall":
        world = syn.World()
        world.add_rect([-6.0, -3.0, 4.0], [12.0, 0, 0], [0, 6.0, 0], "astronaut", tile=3.0, name="wall")
        K = Camera.intrinsics(syn._focal(w, FOV_DEG), w, h)
        return [Camera.from_centre(K, np.eye(3), [x, 0.0, 0.0], w, h) for x in np.linspace(-1, 1, 60)], world
    if case == "arc":
        return syn.arc_cameras(60, arc_deg=40, width=w, height=h, fov_deg=FOV_DEG), syn.default_world(0)
    raise SystemExit(f"unknown case {case!r}")


def _rotation_error_deg(est: list, ref: list) -> float:
    """Largest angle between estimated and true rotations after the best common rotation."""
    M = sum(r.R.T @ e.R for e, r in zip(est, ref))
    U, _, Vt = np.linalg.svd(M)
    Rs = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt  # est world -> true world
    err = [np.degrees(np.arccos(np.clip((np.trace(r.R @ Rs @ e.R.T) - 1) / 2, -1, 1))) for e, r in zip(est, ref)]
    return float(max(err))


def _px(v) -> str:
    """An error in px as the table gives it ("-" where there is none: no model, no points)."""
    return "-" if v is None else f"{v:.3f}"


def run_case(case: str, work: Path, pan) -> dict:
    from vibr.calib.colmap import calibrate
    from vibr.cli import main
    from vibr.io.video import write_video
    from vibr.render.methods import DEFAULTS
    from vibr.synthetic import render_view

    cams, world = _cameras(case)
    video = work / f"{case}.mp4"
    if not video.exists():
        write_video(video, [render_view(world, c)[0] for c in cams], fps=20, crf=18)
    out = work / f"{case}-{pan}"
    t0 = time.perf_counter()
    frames = len(cams) // 3
    scene = calibrate(video, out, overwrite=True, frames=frames, pan=pan)
    seconds = time.perf_counter() - t0
    c = scene.meta["calibration"]
    kept = c["video"]["frames_kept"]
    by_name = {f"frame_{k:06d}": k for k in kept}
    est = [v.camera for v in scene.views]
    ref = [cams[by_name[v.name]] for v in scene.views]
    C = np.array([e.centre for e in est])
    dist = np.median(np.linalg.norm(scene.points - C.mean(0), axis=1)) if len(scene.points) else np.nan
    report = work / f"{case}-{pan}-eval.json"
    rc = main(["eval", str(out), "--target", scene.names[len(scene) // 2], "--method", "gradient",
               "--gamma", str(DEFAULTS["gamma"]), "--json", str(report), "-q"])
    psnr = json.loads(report.read_text())["results"][0]["psnr"] if rc == 0 else float("nan")
    one = c.get("one_centre", {})
    pts, reg = one.get("points_px", {}), one.get("registered", {})
    return {
        "case": case, "pan": "auto" if pan is None else str(pan), "pairs": one.get("homography_pairs", "-"),
        "h_px": _px(one.get("pair_homographies_px")), "one_px": _px(one.get("matches_px")),
        "pts": f"{_px(pts.get('one_centre'))} / {_px(pts.get('mapper'))}",
        "reg": f"{reg.get('one_centre', '-')} / {reg.get('mapper', '-')}",
        "one_centre": c["turned_on_the_spot"], "registered": f"{len(c['registered'])}/{frames}",
        "focal": float(est[0].K[0, 0]), "rot_deg": _rotation_error_deg(est, ref),
        "spread": float(np.ptp(C, axis=0).max() / dist) if np.isfinite(dist) else np.nan,
        "psnr": psnr, "seconds": seconds,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", default="tripod,wide,full,hand0.03,hand0.1,hand0.3,wall,arc")
    ap.add_argument("--compare", action="store_true", help="also COLMAP's mapper alone where one centre was taken")
    ap.add_argument("--work", default=None, help="keep videos and scenes here (default: a temporary folder)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    work = Path(args.work or tempfile.mkdtemp(prefix="vibr-pan-"))
    work.mkdir(parents=True, exist_ok=True)
    rows = []
    for case in args.cases.split(","):
        rows.append(run_case(case, work, None))
        if args.compare and rows[-1]["one_centre"]:
            rows.append(run_case(case, work, False))
    head = ("| case | pan | homography pairs | pairs' H px | one centre: matches px | points px: one centre / "
            "mapper | registered: one centre / mapper | one centre taken | registered | f px | max rot err ° | "
            "centre spread | eval PSNR dB | s |")
    print(head)
    print("|" + "|".join(["---"] * (head.count("|") - 1)) + "|")
    for r in rows:
        print(f"| {r['case']} | {r['pan']} | {r['pairs']} | {r['h_px']} | {r['one_px']} | {r['pts']} | "
              f"{r['reg']} | "
              f"{'yes' if r['one_centre'] else 'no'} | {r['registered']} | {r['focal']:.1f} | {r['rot_deg']:.2f} | "
              f"{r['spread']:.3f} | {r['psnr']:.2f} | {r['seconds']:.1f} |")
    print(f"(truth: f = {SIZE[0] / 2 / np.tan(np.radians(FOV_DEG / 2)):.1f} px; work folder {work})")


if __name__ == "__main__":
    main()
