"""Leave-one-out over many views: :func:`vibr.eval.protocol.evaluate` once per target, through
:func:`vibr.executor.run_tasks`.

Each held-out view is one task: the worker loads the scene once (:func:`load_context`),
evaluates its target (:func:`evaluate_target`, the target never takes part in the depth
estimation of its sources) and writes that target's report atomically to
``VIEWS_DIR/TARGET.json``. A rerun with the same settings and the same code finds those
files and skips their targets. The driver gathers the per-target reports into one report,
in the spirit of 3D Gaussian Splatting's ``per_view.json`` / ``results.json``: ``per_view``
(target → report) and ``summary`` (per setting: mean and median PSNR, SSIM and DSSIM over
the targets).

Independent processes (a job array) can share the targets: with ``shard=(I, N)``
:func:`evaluate_all` evaluates only the targets ``k`` (in the order given) with ``k % N == I - 1``
(:func:`vibr.executor.shard_of`) and writes their reports; :func:`assemble_all` then builds the
report from the per-target files, refusing while any is missing. A target's report does not
depend on the other targets, so the assembled report holds the numbers one process gives.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from .._runtime.checkpoint import code_fingerprint
from ..errors import VibrInputError
from ..executor import parse_shard, run_tasks, shard_of
from ..io import load_scene
from ..metrics import METRICS
from .figures import write_evaluation_figures
from .protocol import Setting, run_evaluation, write_report

logger = logging.getLogger(__name__)

#: Fields of a per-target report that vary from run to run (times, machine), not results.
VOLATILE = ("seconds", "depth_seconds", "samples_seconds", "geometry_seconds", "wall_seconds",
            "machine", "time_s", "skipped")


def resolve_targets(scene, spec: str | Sequence[str]) -> list[str]:
    """View names for ``spec``: ``"all"`` (every view, in scene order), a comma list or a
    sequence of names / indices."""
    if isinstance(spec, str):
        if spec.strip().lower() == "all":
            return list(scene.names)
        spec = [s.strip() for s in spec.split(",") if s.strip()]
    names = [scene.views[scene.index(int(s) if isinstance(s, str) and s.isdigit() and s not in scene.names
                                     else s)].name for s in spec]
    if not names:
        raise VibrInputError("no target view given")
    if len(set(names)) != len(names):
        raise VibrInputError(f"a target is given twice: {', '.join(names)}")
    return names


def load_context(scene_path, scale: float):
    """Per-worker setup: the scene, loaded once (``scene.meta['scale']`` recorded)."""

    scene = load_scene(scene_path, scale=scale)
    scene.meta.setdefault("scale", scale)
    return scene


def _config_key(task: dict) -> str:
    """A hash of everything that decides a target's numbers (not where files go), vibr's
    code included: a report written by other code is recomputed, not mixed in."""

    cfg = {k: v for k, v in task.items() if k not in ("report", "eval_kw")}
    cfg["code"] = code_fingerprint()
    cfg["eval_kw"] = {k: v for k, v in task["eval_kw"].items() if k not in ("figures", "cache_dir")}
    cfg["settings"] = [(s.method, s.params) for s in task["settings"]]
    blob = json.dumps(cfg, sort_keys=True, default=str)
    return hashlib.sha1(blob.encode()).hexdigest()[:16]


def _report_done(task: dict) -> dict | None:
    """The report ``task`` already has on disk, made with its ``config`` (``"skipped":
    true`` added), else None."""
    path = Path(task["report"])
    if not path.is_file():
        return None
    try:
        old = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return {**old, "skipped": True} if isinstance(old, dict) and old.get("config") == task["config"] else None


def evaluate_target(scene, task: dict) -> dict:
    """One leave-one-out evaluation (a task of :func:`vibr.executor.run_tasks`).

    ``task``: ``target``, ``settings``, ``eval_kw`` (keyword arguments of
    :func:`vibr.eval.protocol.evaluate`), ``report`` (the JSON file to write), ``config`` (hash
    of the settings). Returns the target's report; when ``report`` already holds a report
    with the same ``config``, returns it without recomputing (``"skipped": true``).
    """

    old = _report_done(task)
    if old is not None:
        return old
    path = Path(task["report"])
    t0 = time.perf_counter()
    kw = dict(task["eval_kw"])
    if kw.get("sources"):  # leave-one-out over a listed pool: each target is held out of it
        kw["sources"] = [v for v in kw["sources"] if scene[v].name != task["target"]]
    figures = kw.pop("figures", None)
    ev = run_evaluation(scene, task["target"], task["settings"], **kw)
    rep = ev.report
    if figures:
        rep["figures"] = write_evaluation_figures(ev, figures)
    rep["wall_seconds"] = round(time.perf_counter() - t0, 3)
    rep["config"] = task["config"]
    rep["worker_pid"] = os.getpid()
    write_report(rep, path)
    return rep


def _tasks(scene_path: str, targets, settings, views_dir: Path, scale: float, eval_kw: dict) -> list[dict]:
    """One task per target (:func:`evaluate_target`), with its report file and config key."""
    tasks = []
    for t in targets:
        task = {"scene": scene_path, "scale": float(scale), "target": t, "settings": settings,
                "eval_kw": dict(eval_kw), "report": str(views_dir / f"{t}.json")}
        task["config"] = _config_key(task)
        tasks.append(task)
    return tasks


def evaluate_all(scene_path, targets: Sequence[str], settings: Sequence[Setting], *, views_dir,
                 scale: float = 1.0, executor=None, retries: int = 2, shard=None, **eval_kw) -> dict:
    """Leave-one-out evaluation of every view in ``targets`` (module docstring).

    Parameters
    ----------
    scene_path : path
        The scene (each worker loads it once, at ``scale``).
    targets : sequence of str
        View names (:func:`resolve_targets`).
    settings : sequence of Setting
    views_dir : path
        Folder of the per-target reports ``TARGET.json`` (kept: a rerun skips them).
    executor
        :func:`vibr.executor.run_tasks`'s engine: None, N processes, "local", an address.
    shard : (I, N) or "I/N", optional
        Evaluate only shard ``I`` of ``N`` of ``targets`` (module docstring); the report then
        covers those targets (``"shard": [I, N]``): :func:`assemble_all` makes the whole one.
    **eval_kw
        Keyword arguments of :func:`vibr.eval.protocol.evaluate` (depth, n_views, mask, ...).

    Returns
    -------
    dict
        ``scene``, ``targets``, ``settings`` (labels), ``per_view`` (target → report),
        ``summary`` (:func:`summarise`), ``wall_seconds``.
    """

    settings = list(settings)
    views_dir = Path(views_dir)
    scene_path = str(Path(scene_path).resolve())
    shard = None if shard is None else parse_shard(shard)
    targets = [list(targets)[k] for k in shard_of(len(targets), shard)]
    tasks = _tasks(scene_path, targets, settings, views_dir, scale, eval_kw)
    t0 = time.perf_counter()
    # the targets already evaluated are read here, so that the tasks and the progress line
    # (its time left) are the targets still to do
    reports = [_report_done(t) for t in tasks]
    todo = [i for i, r in enumerate(reports) if r is None]
    if todo:
        done = run_tasks(evaluate_target, [tasks[i] for i in todo], setup=load_context,
                         setup_args=(scene_path, float(scale)), executor=executor, desc="leave-one-out",
                         retries=retries)
        for i, r in zip(todo, done):
            reports[i] = r
    skipped = sum(bool(r.get("skipped")) for r in reports)
    if skipped:
        logger.info("%d of %d targets were already evaluated (%s)", skipped, len(targets), views_dir)
    return _report(reports, scene_path, scale, targets, settings, views_dir, t0) | (
        {"shard": list(shard)} if shard else {})


def assemble_all(scene_path, targets: Sequence[str], settings: Sequence[Setting], *, views_dir,
                 scale: float = 1.0, **eval_kw) -> dict:
    """The report of :func:`evaluate_all` over ``targets``, from the per-target reports its
    shards wrote in ``views_dir`` (same arguments as theirs, ``executor`` and ``shard`` aside).

    Raises
    ------
    VibrInputError
        One line naming every target without a report made with these settings and this code.
    """
    settings = list(settings)
    views_dir = Path(views_dir)
    scene_path = str(Path(scene_path).resolve())
    t0 = time.perf_counter()
    tasks = _tasks(scene_path, list(targets), settings, views_dir, scale, eval_kw)
    reports = [_report_done(t) for t in tasks]
    missing = [t["target"] for t, r in zip(tasks, reports) if r is None]
    if missing:
        raise VibrInputError(f"{len(missing)} of {len(tasks)} targets have no report with these settings in "
                             f"{views_dir}: {', '.join(missing)}; evaluate them (their shards again) before "
                             "assembling")
    # read from the shards' files: none was skipped by the shard that wrote it
    reports = [{k: v for k, v in r.items() if k != "skipped"} for r in reports]
    return _report(reports, scene_path, scale, list(targets), settings, views_dir, t0)


def _report(reports, scene_path, scale, targets, settings, views_dir, t0) -> dict:
    """The leave-one-out report (:func:`evaluate_all`'s Returns) of the per-target reports."""
    return {
        "scene": reports[0]["scene"] if reports else Path(scene_path).name,
        "scene_path": scene_path,
        "scale": float(scale),
        "targets": targets,
        "settings": [s.label for s in settings],
        "views_dir": str(views_dir),
        "wall_seconds": round(time.perf_counter() - t0, 3),
        "summary": summarise(reports),
        "per_view": {t: r for t, r in zip(targets, reports)},
    }


def summarise(reports: Sequence[dict]) -> dict:
    """Per setting label: ``n`` targets and mean / median of each registered metric
    (:data:`vibr.metrics.METRICS`: PSNR, SSIM, DSSIM, ...), and of the
    uncertainty's AUSE and Spearman correlation when the reports hold them (``uncertainty``)."""
    by: dict[str, dict[str, list]] = {}
    for rep in reports:
        for r in rep["results"]:
            d = by.setdefault(r["label"], {"method": r["method"], **{k: [] for k in METRICS},
                                           "ause": [], "spearman": []})
            for k in METRICS:
                if k in r:  # a report written before a metric was registered
                    d[k].append(r[k])
            for k in ("ause", "spearman"):
                if "uncertainty" in r:
                    d[k].append(r["uncertainty"][k])
    out = {}
    for label, d in by.items():
        out[label] = {"method": d["method"], "n": len(d["psnr"])}
        for k in (*METRICS, "ause", "spearman"):
            a = np.asarray(d[k], float)
            a = a[np.isfinite(a)] if k in ("ause", "spearman") else a  # a flat sigma has no rank
            if len(a):
                out[label][k] = {"mean": float(a.mean()), "median": float(np.median(a))}
    return out


def results_only(report: dict) -> dict:
    """``report`` without the fields that change from run to run (times, machine, pids):
    what two runs of the same evaluation must agree on exactly."""
    if isinstance(report, dict):
        return {k: results_only(v) for k, v in report.items()
                if k not in VOLATILE and k not in ("worker_pid", "views_dir", "figures")}
    if isinstance(report, list):
        return [results_only(v) for v in report]
    return report


def format_all_table(report: dict) -> str:
    """Per-view table (PSNR / DSSIM of each setting, depth and wall time) and the summary."""
    labels = report["settings"]
    w = max(12, *(len(lb) for lb in labels))
    head = f"{'target':<10}" + "".join(f" {lb[:w]:>{w}}" for lb in labels) + f" {'depth s':>8} {'wall s':>7}"
    lines = [f"{report['scene']}: leave-one-out over {len(report['targets'])} views "
             f"(PSNR dB / DSSIM; image scale {report['scale']:g})", head]
    for t in report["targets"]:
        rep = report["per_view"][t]
        cells = {r["label"]: f"{r['psnr']:.2f} / {r['dssim']:.0f}" for r in rep["results"]}
        lines.append(f"{t:<10}" + "".join(f" {cells.get(lb, '-'):>{w}}" for lb in labels)
                     + f" {rep.get('depth_seconds', 0):>8.1f} {rep.get('wall_seconds', 0):>7.1f}"
                     + (" (done before)" if rep.get("skipped") else ""))
    s = report["summary"]
    for stat in ("mean", "median"):
        lines.append(f"{stat:<10}" + "".join(
            f" {s[lb]['psnr'][stat]:>{w - 8}.2f} / {s[lb]['dssim'][stat]:>5.0f}" for lb in labels))
    lines.append("SSIM mean: " + ", ".join(f"{lb} {s[lb]['ssim']['mean']:.4f}" for lb in labels))
    if any("ause" in s[lb] for lb in labels):  # --uncertainty
        lines.append("uncertainty AUSE mean (lower is better): "
                     + ", ".join(f"{lb} {s[lb]['ause']['mean']:.4f}" for lb in labels if "ause" in s[lb]))
    return "\n".join(lines)
