"""Top-level task functions for tests/test_executor.py (workers import them by name)."""

from __future__ import annotations

import os
from pathlib import Path


def setup_probe(folder):
    """Per-worker setup: record this process once (O_EXCL: a second setup in the same
    process fails), and what numba sees here."""
    import numba

    fd = os.open(os.path.join(folder, f"setup_{os.getpid()}"), os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    os.close(fd)
    return {"pid": os.getpid(), "env": os.environ.get("NUMBA_NUM_THREADS"),
            "numba_threads": int(numba.get_num_threads()), "folder": folder,
            "malloc_trim": os.environ.get("MALLOC_TRIM_THRESHOLD_")}


def square_probe(ctx, task):
    """A task: its result with the worker's pid and numba thread count."""
    return {"value": task * task, "pid": ctx["pid"], "env": ctx["env"], "numba_threads": ctx["numba_threads"],
            "malloc_trim": ctx["malloc_trim"]}


def write_or_die(ctx, task):
    """Write ``out/TASK.txt`` atomically; the task ``victim`` kills its own worker process the
    first time it runs (marker file), as a crashing worker would."""
    from vibr._runtime.atomic import atomic_path

    folder = Path(ctx)
    out = folder / f"{task}.txt"
    if out.exists():
        return {"task": task, "skipped": True}
    if task == "victim":
        marker = folder / "victim.killed"
        if not marker.exists():
            marker.write_text(str(os.getpid()))
            os._exit(17)
    with atomic_path(out) as tmp:
        Path(tmp).write_text(f"result of {task}\n")
    return {"task": task, "pid": os.getpid()}


def identity(ctx, task):
    return ctx, task


def fail_once(ctx, task):
    """Raise the first time (marker file), succeed after: a transient error."""
    marker = Path(ctx) / f"failed_{task}"
    if not marker.exists():
        marker.write_text("x")
        raise RuntimeError(f"transient failure of {task}")
    return task


def die_always(ctx, task):
    os._exit(17)


def print_render_digest():
    """Evaluate one held-out view of a small synthetic scene with every method, depth estimated
    from the sources (plane sweep), and print one JSON line: numba's thread count and, per
    setting, the PSNR / DSSIM bits, the iterations and a hash of the rendered image
    (tests/test_executor.py runs this with 1 and with 2 numba threads)."""
    import hashlib
    import json

    import numba
    import numpy as np

    from vibr.eval.protocol import run_evaluation, settings_grid
    from vibr.synthetic import make_scene

    scene = make_scene("grid", n_views=9, width=80, height=64, seed=5)
    settings = settings_grid(["ulr", "savsr", "bvs", "gradient"], gammas=(1.0,))
    ev = run_evaluation(scene, "view_004", settings, depth="estimated", use_lpips=False)
    res = {r["label"]: [float(r["psnr"]).hex(), float(r["dssim"]).hex(), r.get("iterations"),
                        hashlib.sha1(np.ascontiguousarray(ev.images[r["label"]]).tobytes()).hexdigest()]
           for r in ev.report["results"]}
    # the reductions themselves, on random data (an end-to-end render can round a last-bit
    # difference away; these cannot): inner product, TV, the fused pass's energy terms
    from vibr.render.fused import hessian_terms
    from vibr.render.operators import dot
    from vibr.render.tv import tv_value

    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((2, 3, 301, 257)).astype(np.float32)
    A = rng.random((9, 301, 257)).astype(np.float32)
    _, terms = hessian_terms(A, None, a, b, None, 1.0, 0.0)
    res["kernels"] = [float(v).hex() for v in (dot(a, b), tv_value(a), tv_value(a, False), *terms)]
    print(json.dumps({"threads": numba.get_num_threads(), "results": res}), flush=True)


def write_and_hang(ctx, task):
    """Write ``TASK.txt`` atomically; the first time, announce the temporary path (and this
    process) in ``TASK.tmp`` and hang inside the write: for a test that terminates the worker
    mid-write (the run then reruns the task, which completes)."""
    import time

    from vibr._runtime.atomic import atomic_path

    folder = Path(ctx)
    marker = folder / f"{task}.tmp"
    first = not marker.exists()
    with atomic_path(folder / f"{task}.txt") as tmp:
        Path(tmp).write_text("partial" if first else f"result of {task}\n")
        if first:
            marker.write_text(f"{tmp}\n{os.getpid()}")
            time.sleep(120)
    return task


def write_or_always_die(ctx, task):
    """Write ``out/TASK.txt`` atomically; the task ``victim`` kills its worker every time it
    runs, as a cluster whose workers all die under a task (the scheduler gives up on it)."""
    from vibr._runtime.atomic import atomic_path

    folder = Path(ctx)
    out = folder / f"{task}.txt"
    if out.exists():
        return {"task": task, "skipped": True}
    if task == "victim" and not (folder / "victim.spared").exists():
        os._exit(17)
    with atomic_path(out) as tmp:
        Path(tmp).write_text(task)
    return {"task": task, "skipped": False}


def lost_workers_scenario(folder):
    """Run the victim's tasks on a one-worker LocalCluster whose worker it kills, then again
    with the victim spared; print the error line and the second run's results as JSON (run
    in a process of its own: a LocalCluster wants a fresh event loop)."""
    import json

    import dask
    import distributed  # noqa: F401  (its config defaults, before one of them is set)

    from vibr.errors import VibrInputError
    from vibr.executor import run_tasks

    tasks = ["a", "b", "victim"]
    try:
        # the scheduler gives up at the first death (its default waits for four, each a worker
        # restart: seconds apiece on a loaded machine) and vibr's line is the same either way
        with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
            run_tasks(write_or_always_die, tasks, setup=str, setup_args=(folder,), executor="local:1", retries=0)
        msg = None
    except VibrInputError as exc:
        msg = str(exc)
    done = sorted(p.stem for p in Path(folder).glob("*.txt"))
    (Path(folder) / "victim.spared").write_text("")
    res = run_tasks(write_or_always_die, tasks, setup=str, setup_args=(folder,), executor="local:1")
    print(json.dumps({"message": msg, "done": done, "rerun": res}))
