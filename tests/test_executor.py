"""``vibr.executor.run_tasks``: the serial, process-pool and Dask engines give the same
results in task order; setup runs once per worker; the workers' numba thread count;
a worker killed mid-run; the missing-extra error; ``vibr eval --target all`` bit-identical
across engines and resumable."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
import distributed

import _scaleout_tasks as T  # noqa: E402
from vibr.errors import VibrInputError  # noqa: E402
from vibr.executor import (  # noqa: E402
    AUTO_MIN_TASK_PIXELS,
    AUTO_MIN_TASKS_PER_WORKER,
    auto_workers,
    check_scheduler,
    parse_executor,
    run_tasks,
    threads_per_worker,
)


def test_parse_executor():
    assert parse_executor(None) == ("serial", None)
    assert parse_executor(1) == ("serial", None)
    assert parse_executor(3) == ("processes", 3)
    assert parse_executor("processes:2") == ("processes", 2)
    assert parse_executor("local") == ("dask-local", 2)
    assert parse_executor("local:3") == ("dask-local", 3)
    assert parse_executor("tcp://10.0.0.1:8786") == ("dask", "tcp://10.0.0.1:8786")
    for bad in (0, -2, "processes:x", "local:0", True, 2.5):
        with pytest.raises(VibrInputError):
            parse_executor(bad)
    assert threads_per_worker(2, cores=2) == 1 and threads_per_worker(3, cores=8) == 2
    assert threads_per_worker(4, cores=2) == 1


def test_auto_workers_only_where_processes_pay():
    big, many, gb = 768 * 512, 60, 2**30
    assert auto_workers(many, big, gb, cores=2, memory=16 * gb) == 2
    assert auto_workers(many, big, gb, cores=16, memory=64 * gb) == many // AUTO_MIN_TASKS_PER_WORKER
    assert auto_workers(many, big, gb, cores=16, memory=3.5 * gb) == 3  # what memory holds
    assert auto_workers(many, big, gb, cores=1, memory=16 * gb) == 1  # one core: threads do it
    assert auto_workers(many, AUTO_MIN_TASK_PIXELS - 1, gb, cores=2, memory=16 * gb) == 1  # small frames
    assert auto_workers(2 * AUTO_MIN_TASKS_PER_WORKER - 1, big, gb, cores=2, memory=16 * gb) == 1  # short path
    assert auto_workers(many, big, gb, cores=2, memory=gb // 2) == 1  # not even one worker's memory


def _auto_in_child(q):
    q.put(auto_workers(60, 768 * 512, 2**30, cores=2, memory=16 * 2**30))


def test_auto_workers_is_one_inside_a_daemonic_process():
    """A Dask or Pool worker may not start processes: auto keeps the frames there."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=_auto_in_child, args=(q,), daemon=True)
    p.start()
    got = q.get(timeout=120)
    p.join(30)
    assert got == 1


def test_flythrough_auto_executor(tmp_path, monkeypatch):
    """render_path's "auto": processes for a long path of large frames, here for the rest."""
    import vibr.executor as E
    from vibr.paths.flythrough import FrameContext, auto_executor
    from vibr.synthetic import make_scene

    scene = make_scene("grid", n_views=9, width=48, height=40, seed=1)
    cam = scene.views[0].camera.scaled(16.0)  # 768x640: a large frame
    ctx = FrameContext(scene, [cam] * 40, str(tmp_path))
    monkeypatch.setattr(E, "available_cores", lambda: 2)
    monkeypatch.setattr(E, "available_memory", lambda: 16 * 2**30)
    assert auto_executor(ctx, 40) == 2
    assert auto_executor(ctx, 15) is None
    small = FrameContext(scene, [scene.views[0].camera] * 40, str(tmp_path))
    assert auto_executor(small, 40) is None
    monkeypatch.setattr(E, "available_memory", lambda: 2**20)
    assert auto_executor(ctx, 40) is None


def _check_workers(res, tmp_path, n_workers):
    assert [r["value"] for r in res] == [i * i for i in range(len(res))]  # task order
    want = threads_per_worker(n_workers)
    for r in res:
        # the variable was in the child's environment before numba was imported there
        assert r["env"] == str(want) and r["numba_threads"] == want
        assert r["pid"] != os.getpid()
    pids = {r["pid"] for r in res}
    setups = {int(p.name.split("_")[1]) for p in tmp_path.glob("setup_*")}
    assert pids <= setups and len(setups) <= n_workers  # setup once per worker process


def test_serial_runs_setup_once_here(tmp_path):
    res = run_tasks(T.square_probe, range(5), setup=T.setup_probe, setup_args=(str(tmp_path),))
    assert [r["value"] for r in res] == [0, 1, 4, 9, 16]
    assert {r["pid"] for r in res} == {os.getpid()}
    assert len(list(tmp_path.glob("setup_*"))) == 1


def test_processes_round_trip(tmp_path):
    before = os.environ.get("NUMBA_NUM_THREADS")
    res = run_tasks(T.square_probe, range(8), setup=T.setup_probe, setup_args=(str(tmp_path),), executor=2)
    _check_workers(res, tmp_path, 2)
    assert os.environ.get("NUMBA_NUM_THREADS") == before  # this process's environment restored


@pytest.fixture(scope="module")
def client():
    """One real LocalCluster (2 worker processes x 1 thread, as --dask local) for the Dask tests."""
    from vibr.executor import start_local_cluster

    with start_local_cluster(2) as cluster, distributed.Client(cluster) as c:
        yield c


def test_dask_round_trip_and_transient_errors_retried(tmp_path, client):
    """setup once per worker, numba threads, task order; a Client passed in is used and left
    open; a task that raises once is retried, one that keeps raising fails the run."""
    check_scheduler(client.scheduler.address)  # the CLI's check passes for a real scheduler
    res = run_tasks(T.square_probe, range(8), setup=T.setup_probe, setup_args=(str(tmp_path),), executor=client)
    _check_workers(res, tmp_path, 2)
    # without Dask's default MALLOC_TRIM_THRESHOLD_ (it slowed frames ~25 %, docs/explanation/scale-out.md)
    assert {r["malloc_trim"] for r in res} == {None}
    out = run_tasks(T.fail_once, ["a", "b"], setup=str, setup_args=(str(tmp_path),), executor=client)
    assert out == ["a", "b"] and client.status == "running"
    with pytest.raises(RuntimeError, match="transient"):
        run_tasks(T.fail_once, ["c"], setup=str, setup_args=(str(tmp_path),), executor=client, retries=0)
    assert run_tasks(T.fail_once, ["d", "e"], setup=str, setup_args=(str(tmp_path),), executor=2) == ["d", "e"]


def test_two_local_clusters_at_once_share_no_port():
    """start_local_cluster serves the scheduler's HTTP on a free loopback port: two clusters
    at once (the Dask tests' cluster and a `--dask local` run) start without distributed's
    "port 8787 already in use" warning, and nothing listens beyond 127.0.0.1."""
    import warnings

    from vibr.executor import start_local_cluster

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with start_local_cluster(1) as a, start_local_cluster(1) as b:
            links = [c.scheduler.http_server.port for c in (a, b)]
            addrs = [c.scheduler.address for c in (a, b)]
    assert 8787 not in links and links[0] != links[1]
    assert all(x.startswith("tcp://127.0.0.1:") for x in addrs)


def test_a_terminated_pool_worker_leaves_no_partial_file(tmp_path):
    """A broken pool terminates its other workers (SIGTERM) while they may be writing: the
    worker removes its half-written file (vibr._runtime.atomic) and exits, instead of leaving a
    ``.part`` file behind (a race the killed-worker test below hit now and then); the run
    reruns the task and completes."""
    import signal
    import threading
    import time

    out = {}

    def run():
        out["res"] = run_tasks(T.write_and_hang, ["a"], setup=str, setup_args=(str(tmp_path),), executor=2)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    marker = tmp_path / "a.tmp"
    deadline = time.monotonic() + 120
    while not marker.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.2)  # the marker is written: the worker now sleeps inside the write
    tmp, pid = marker.read_text().split("\n")
    assert Path(tmp).exists()
    os.kill(int(pid), signal.SIGTERM)
    t.join(90)
    assert not t.is_alive(), "the run waits on a terminated worker"
    assert out["res"] == ["a"]
    assert (tmp_path / "a.txt").read_text() == "result of a\n"
    assert not list(tmp_path.glob(".*.part*"))  # the first attempt's file removed


@pytest.mark.parametrize("engine", ["processes", "dask"])
def test_a_killed_worker_loses_nothing(tmp_path, engine, request):
    """A task kills its own worker process the first time: the run still completes with every
    result present and correct (the process pool is replaced; Dask's nanny restarts the
    worker and the scheduler reruns the task)."""
    executor = 2 if engine == "processes" else request.getfixturevalue("client")
    tasks = ["t0", "t1", "victim", "t3", "t4", "t5"]
    res = run_tasks(T.write_or_die, tasks, setup=str, setup_args=(str(tmp_path),), executor=executor)
    assert [r["task"] for r in res] == tasks
    assert (tmp_path / "victim.killed").exists()  # it did die once
    for t in tasks:
        assert (tmp_path / f"{t}.txt").read_text() == f"result of {t}\n"
    assert not list(tmp_path.glob(".*.part*"))  # no partial file left
    # a rerun skips what is there
    again = run_tasks(T.write_or_die, tasks, setup=str, setup_args=(str(tmp_path),))
    assert all(r["skipped"] for r in again)


def test_more_processes_than_cores_or_tasks(monkeypatch):
    """N processes for fewer tasks: only as many as the tasks start; more processes than
    cores: a warning (they take turns, each with its own copy of the context)."""
    import io
    import logging

    import vibr.executor as ex

    buf = io.StringIO()
    h = logging.StreamHandler(buf)
    lg = logging.getLogger("vibr.executor")
    level = lg.level
    lg.addHandler(h)
    lg.setLevel(logging.INFO)  # setLevel, not the attribute: it clears the loggers' caches
    try:
        monkeypatch.setattr(ex, "available_cores", lambda: 1)
        res = run_tasks(T.identity, [1, 2], executor=99)
    finally:
        lg.removeHandler(h)
        lg.setLevel(level)
    out = buf.getvalue()
    assert res == [(None, 1), (None, 2)]
    assert "2 tasks on 2 processes" in out and "2 processes on 1 cores" in out


def test_a_task_that_always_kills_its_worker_fails_cleanly(tmp_path):
    with pytest.raises(RuntimeError, match="failed 2 times"):
        run_tasks(T.die_always, ["x"], executor=2, retries=1)


def test_a_script_without_main_guard_fails_instead_of_hanging(tmp_path):
    """Spawned children re-run an unguarded script and die while starting; with a large setup
    argument (a scene) sent down the start pipe the driver used to block for ever."""
    import subprocess

    script = tmp_path / "unguarded.py"
    script.write_text(
        "import sys\n"
        f"sys.path.insert(0, {str(Path(__file__).parent)!r})\n"
        "import _scaleout_tasks as T\n"
        "from vibr.executor import run_tasks\n"
        "run_tasks(T.identity, [0, 1], setup=len, setup_args=(bytes(4_000_000),), executor=2, retries=0)\n")
    # the children that die while starting leave their own setup file: in tmp_path, not /tmp
    p = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60,
                       env=dict(os.environ, TMPDIR=str(tmp_path)))
    assert p.returncode != 0
    assert "__main__" in p.stderr and "worker process died" in p.stderr


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_an_interrupt_stops_the_running_tasks_at_once(tmp_path, sig):
    """Ctrl-C in the driver (SIGINT to it alone, as ``kill -INT`` sends it), or SIGTERM read as
    one (``vibr.cli.interrupt_on_sigterm``, as the CLI installs it; a job scheduler's stop)
    stops the workers in the middle of their tasks: the driver exits within seconds, not
    after the running tasks (two minutes here) or never (a shutdown stuck in the pool's
    locks), the workers are gone and their half-written files removed."""
    import signal
    import subprocess
    import time

    script = tmp_path / "interrupted.py"
    script.write_text(
        "import sys\n"
        f"sys.path.insert(0, {str(Path(__file__).parent)!r})\n"
        "import _scaleout_tasks as T\n"
        "from vibr.executor import run_tasks\n"
        "from vibr.cli import interrupt_on_sigterm\n"
        "if __name__ == '__main__':\n"
        "    interrupt_on_sigterm()\n"
        "    try:\n"
        "        run_tasks(T.write_and_hang, ['a', 'b', 'c'], setup=str, setup_args=(sys.argv[1],), executor=2)\n"
        "    except KeyboardInterrupt:\n"
        "        sys.exit(130)\n")
    work = tmp_path / "out"
    work.mkdir()
    p = subprocess.Popen([sys.executable, str(script), str(work)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    try:
        deadline = time.monotonic() + 120
        while len(list(work.glob("*.tmp"))) < 2 and time.monotonic() < deadline and p.poll() is None:
            time.sleep(0.05)
        time.sleep(0.2)  # both workers now sleep inside their writes
        pids = [int(m.read_text().split("\n")[1]) for m in work.glob("*.tmp")]
        assert len(pids) == 2
        t0 = time.monotonic()
        p.send_signal(getattr(signal, sig))
        _, err = p.communicate(timeout=30)
        assert p.returncode == 130, err
        assert time.monotonic() - t0 < 15
    finally:
        if p.poll() is None:
            p.kill()
    time.sleep(0.5)
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    assert not list(work.glob(".*.part*")) and not list(work.glob("*.txt"))


def test_missing_extra_gives_one_line(monkeypatch, capsys, tmp_path):
    from vibr.cli import main

    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    with pytest.raises(VibrInputError, match=r"pip install 'vibr\[dask\]'"):
        run_tasks(T.identity, [1], executor="local")
    rc = main(["eval", str(tmp_path), "--target", "all", "--json", str(tmp_path / "r.json"), "--dask", "local"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "pip install 'vibr[dask]'" in err


@pytest.mark.parametrize("server", ["none", "http"])
def test_a_wrong_dask_address_fails_at_once(tmp_path, capsys, server):
    """Nothing listening, or another server on the port (as the dashboard's 8787 would be):
    one line and exit 2 within seconds, before the scene is read (the scene folder is empty
    here, so its own error would come first otherwise). Before, the client hung or died with
    a traceback after the depth had been estimated."""
    import threading
    import time
    from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

    from vibr.cli import main
    from vibr.viewer.browser import free_port

    class Quiet(SimpleHTTPRequestHandler):
        def log_message(self, *args):
            pass

    httpd = ThreadingHTTPServer(("127.0.0.1", 0), Quiet) if server == "http" else None
    if httpd is not None:
        threading.Thread(target=httpd.serve_forever, daemon=True).start()
    port = httpd.server_address[1] if httpd is not None else free_port()
    capsys.readouterr()
    t0 = time.monotonic()
    try:
        rc = main(["eval", str(tmp_path), "--target", "all", "--json", str(tmp_path / "r.json"),
                   "--dask", f"tcp://127.0.0.1:{port}"])
    finally:
        if httpd is not None:
            httpd.shutdown()
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert f"tcp://127.0.0.1:{port}" in err and "Dask scheduler" in err
    assert time.monotonic() - t0 < 15
    assert not (tmp_path / "r.json").exists()


@pytest.mark.slow
def test_a_render_is_bit_identical_on_1_and_2_numba_threads():
    """The same evaluation (plane-sweep depth, samples, every method's render) in a process
    with 1 numba thread and in one with 2 (as a 2-worker pool and a serial run on 2 cores
    have): every number and every image bit for bit. The kernels' reductions are fixed-size
    chunks summed in index order, never numba's thread-split reductions (docs/explanation/scale-out.md)."""
    import subprocess

    procs = []
    for n in (1, 2):  # both at once: each one's start (imports, cached kernels) is serial
        env = dict(os.environ, NUMBA_NUM_THREADS=str(n), OMP_NUM_THREADS=str(n), OPENBLAS_NUM_THREADS=str(n),
                   PYTHONPATH=os.pathsep.join([str(Path(T.__file__).parent), *sys.path]))
        procs.append(subprocess.Popen([sys.executable, "-c", "import _scaleout_tasks as T; T.print_render_digest()"],
                                      env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
    out = []
    try:
        for p in procs:
            stdout, stderr = p.communicate(timeout=900)
            assert p.returncode == 0, stderr[-3000:]
            out.append(json.loads(stdout.strip().splitlines()[-1]))
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    assert [o["threads"] for o in out] == [1, 2]
    assert len(out[0]["results"]) == 5 and len(out[0]["results"]["kernels"]) == 8
    assert out[0]["results"] == out[1]["results"]


# -- vibr eval --target all ------------------------------------------------------------------
def _eval_all(grid_scene_dir, out, *extra):
    from vibr.cli import main

    rc = main(["-q", "eval", str(grid_scene_dir), "--target", "view_000,view_008", "--method",
               "ulr,gradient", "--gamma", "1", "--json", str(out), *extra])
    assert rc == 0
    return json.loads(Path(out).read_text())


def test_eval_of_several_targets_holds_each_out_of_a_listed_pool(grid_scene_dir, tmp_path):
    """``--sources`` with several targets is the pool: each target is rendered from the
    others of the list (it used to fail: 'target view ... is also listed as a source')."""
    pool = ["view_000", "view_001", "view_003", "view_004", "view_008"]
    rep = _eval_all(grid_scene_dir, tmp_path / "p.json", "--sources", ",".join(pool))
    for t in ("view_000", "view_008"):
        assert rep["per_view"][t]["sources"] == [v for v in pool if v != t]


@pytest.mark.slow
def test_eval_all_is_identical_on_every_engine_and_resumes(grid_scene_dir, tmp_path, monkeypatch):
    """Serial (2 numba threads on 2 cores), --workers 2 and --dask local (1 thread each, other
    targets before this one in the same worker): the same JSON numbers bit for bit."""
    from vibr.eval.leave_one_out import results_only

    serial = _eval_all(grid_scene_dir, tmp_path / "serial.json")
    assert list(serial["per_view"]) == ["view_000", "view_008"]
    for label, s in serial["summary"].items():
        ps = [r["psnr"] for v in serial["per_view"].values() for r in v["results"] if r["label"] == label]
        assert s["n"] == 2 and s["psnr"]["mean"] == pytest.approx(sum(ps) / 2)
        assert s["psnr"]["median"] == pytest.approx(sum(ps) / 2)
    procs = _eval_all(grid_scene_dir, tmp_path / "procs.json", "--workers", "2")
    dask = _eval_all(grid_scene_dir, tmp_path / "dask.json", "--dask", "local")
    assert {v["worker_pid"] for v in dask["per_view"].values()} != {os.getpid()}
    for other in (procs, dask):
        a, b = results_only(other), results_only(serial)
        assert a["targets"] == b["targets"] and a["settings"] == b["settings"]
        for t in a["per_view"]:
            ra, rb = a["per_view"][t], b["per_view"][t]
            assert {k: v for k, v in ra.items() if k != "results"} == {k: v for k, v in rb.items() if k != "results"}
            assert ra["results"] == rb["results"]  # every method, to the last bit

    # a rerun finds the per-view reports and recomputes nothing: the same numbers, bit for bit;
    # the reports are read before any task is made (the progress counts what is left)
    import vibr.eval.leave_one_out as loo  # the name the evaluation calls

    real, handed = loo.run_tasks, []
    monkeypatch.setattr(loo, "run_tasks", lambda fn, tasks, **kw: handed.append(len(tasks)) or real(fn, tasks, **kw))
    again = _eval_all(grid_scene_dir, tmp_path / "serial.json")
    assert all(v.get("skipped") for v in again["per_view"].values()) and handed == []
    assert results_only(again) == results_only(serial)
    (tmp_path / "serial_views" / "view_008.json").unlink()
    partial = _eval_all(grid_scene_dir, tmp_path / "serial.json")
    assert handed == [1] and partial["per_view"]["view_000"].get("skipped")
    assert results_only(partial) == results_only(serial)
    # ... but not with other code: the reports are then recomputed
    monkeypatch.setattr(loo, "code_fingerprint", lambda: "other code")
    other = _eval_all(grid_scene_dir, tmp_path / "serial.json")
    assert not any(v.get("skipped") for v in other["per_view"].values())


@pytest.mark.slow
def test_flythrough_frames_identical_on_every_engine(tmp_path, monkeypatch):
    """vibr render --path: serial, --workers 2 and --dask local write byte-identical PNG frames."""
    from vibr.cli import main
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    monkeypatch.setenv("VIBR_CACHE_DIR", str(tmp_path / "cache"))
    scene = tmp_path / "s"
    save_scene(make_scene("grid", n_views=9, width=48, height=40, seed=1), scene)
    pj = tmp_path / "p.json"
    assert main(["path", "orbit", str(scene), "-o", str(pj), "--frames", "4", "--size", "40x32", "-q"]) == 0
    frames = {}
    for name, extra in (("serial", []), ("procs", ["--workers", "2"]), ("dask", ["--dask", "local"])):
        out = tmp_path / name
        assert main(["render", str(scene), "--path", str(pj), "-o", str(out), "--views", "4", "-q", *extra]) == 0
        frames[name] = {p.name: p.read_bytes() for p in sorted(out.glob("*.png"))}
    assert len(frames["serial"]) == 4
    assert frames["procs"] == frames["serial"] and frames["dask"] == frames["serial"]


@pytest.mark.slow
def test_depth_is_identical_on_every_engine_and_resumes(tmp_path, client):
    """estimate_depth's sweeps on 2 processes and on a Dask cluster give the serial depths bit
    for bit; the workers keep each view in the checkpoint, from which a rerun resumes every
    view; vibr depth --workers 2 writes the same maps."""
    import numpy as np

    from vibr.cli import main
    from vibr.io import load_scene, save_scene
    from vibr.stereo import estimate_depth
    from vibr.synthetic import make_scene

    s = make_scene("handheld", n_views=5, width=96, height=72)
    s = s.replace(views=[v.replace(depth=None, sigma_z=None) for v in s.views])
    serial = estimate_depth(s)
    for ex in (2, client):
        ck = tmp_path / f"ck{id(ex)}"
        e = estimate_depth(s, executor=ex, checkpoint=ck)
        for a, b in zip(serial.views, e.views):
            assert np.array_equal(a.depth, b.depth, equal_nan=True) and np.array_equal(a.sigma_z, b.sigma_z)
        again = estimate_depth(s, executor=ex, checkpoint=ck)
        views = again.meta["depth_estimation"]["views"].values()
        assert all(v.get("resumed") for v in views) and len(list(ck.glob("*.npz"))) == len(s)
    save_scene(s, tmp_path / "scene")  # its images on the 8/16-bit grid: estimated again here
    assert main(["depth", str(tmp_path / "scene"), "-o", str(tmp_path / "out"), "--workers", "2", "-q"]) == 0
    here = estimate_depth(load_scene(tmp_path / "scene"))
    for a, b in zip(here.views, load_scene(tmp_path / "out").views):
        np.testing.assert_array_equal(a.depth, b.depth)


@pytest.mark.slow
def test_a_cluster_that_loses_its_workers_ends_in_one_line_and_resumes(tmp_path):
    """Every worker that runs the victim task dies: the scheduler gives up on it (KilledWorker)
    and vibr says so in one line, naming how far it got; the tasks done are on disk, and the
    same call again (the victim spared) runs only what is left. In a process of its own, as
    the CLI would be (the module's cluster holds this one's event loop)."""
    import subprocess

    r = subprocess.run([sys.executable, "-c", f"import _scaleout_tasks as T; T.lost_workers_scenario({str(tmp_path)!r})"],
                       cwd=Path(__file__).parent, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    msg = out["message"]
    assert msg and "\n" not in msg and "run the same command again to resume" in msg and "of 3 tasks" in msg, msg
    assert "victim" not in out["done"]
    assert [x["task"] for x in out["rerun"]] == ["a", "b", "victim"]
    assert all(x["skipped"] for x in out["rerun"] if x["task"] in out["done"]) and not out["rerun"][-1]["skipped"]
