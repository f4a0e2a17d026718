"""One seam for running many independent tasks: serially, on local processes, or on Dask.

vibr's heavy jobs (the frames of a fly-through, the held-out views of a leave-one-out
evaluation, the cases of a benchmark) are independent tasks. :func:`run_tasks` runs a
top-level function over a list of tasks with one of three engines and gives the results back
in task order; it does not schedule anything itself:

``executor=None`` (or ``"serial"``, ``1``)
    one after the other in this process (the default).
``executor=N`` (int ≥ 2) or ``"processes:N"``
    N local processes (:class:`concurrent.futures.ProcessPoolExecutor`, *spawn* start
    method). Each process gets ``NUMBA_NUM_THREADS = cores // N`` (and the same for the
    BLAS / OpenMP pools) in its environment before it starts (numba reads it once, when it
    is first imported), so that N processes do not run N × cores threads on the cores.
``executor="local"`` or ``"local:N"``
    a Dask ``LocalCluster`` started for this call (N worker processes, default 2, one
    thread each, numba threads = cores // N) and closed at the end.
``executor="tcp://HOST:PORT"`` (or any other string), or a ``distributed.Client``
    the Dask scheduler at that address (:mod:`dask.distributed`, the ``vibr[dask]`` extra).

The task contract (what makes the engines interchangeable):

* ``fn(context, task)`` and ``setup(*setup_args)`` are top-level (picklable) functions;
  ``setup`` runs once per worker (once in this process for the serial engine) and its
  result, the *context* (typically the loaded scene), is ``fn``'s first argument. On Dask
  the setup arguments are scattered to every worker once and the context is cached in the
  worker process, so a task ships only its own small description.
* A task writes its own result files, atomically (:func:`vibr._runtime.atomic.atomic_path`), and
  returns a small summary (a dict of numbers, a file name): a lost worker then loses no
  finished result, and the driver never holds the images.
* A task whose output already exists (and was made with the same settings) returns at once:
  a rerun of an interrupted job redoes only what is missing. Checking that is the task
  function's job (it knows its files).
* A task that raises, or whose worker process dies, is run again, up to ``retries`` more
  times (Dask: ``Client.submit(retries=...)``, and Dask's scheduler moves the tasks of a
  lost worker elsewhere; processes: a pool broken by a dead process is replaced and the
  unfinished tasks resubmitted, each charged one attempt). The serial engine runs each task
  once and lets its exception through. :class:`vibr.VibrInputError` (bad input) is never
  retried by the process engine.

Results are identical whatever the engine when ``fn`` is deterministic and does not depend
on the number of numba threads (docs/explanation/scale-out.md reports what was checked).

Across machines without a scheduler (a job array), :func:`parse_shard` and :func:`shard_of`
split a job's tasks into ``N`` shards, one per independent process: shard ``I`` takes every
task ``k`` with ``k % N == I - 1`` (interleaved, so that a path's expensive stretch or a
scene's large views are spread over the shards rather than given to one).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import pickle
import signal
import socket
import sys
import tempfile
import threading
import time
import uuid
from concurrent.futures import CancelledError
from typing import Any, Callable, Sequence

from ._runtime.atomic import remove_partial
from ._runtime.malloc import tune_malloc
from ._runtime.memory import available_memory
from .errors import VibrInputError
from .progress import progress

logger = logging.getLogger(__name__)

DASK_HINT = "pip install 'vibr[dask]'"

_THREADS_VAR = "NUMBA_NUM_THREADS"


def parse_shard(text) -> tuple[int, int]:
    """``"I/N"`` (``--shard``) as ``(I, N)``, 1 ≤ I ≤ N; a one-line :class:`VibrInputError`
    otherwise. A tuple ``(I, N)`` is checked and returned."""
    if isinstance(text, tuple):
        i, n = text
    else:
        a, sep, b = str(text).partition("/")
        try:
            i, n = int(a), int(b)
        except ValueError:
            i = n = 0
        if not sep:
            i = n = 0
    if not (isinstance(i, int) and isinstance(n, int) and 1 <= i <= n):
        raise VibrInputError(f"a shard is I/N with 1 <= I <= N (e.g. 2/8, I = $SLURM_ARRAY_TASK_ID), got {text!r}")
    return i, n


def shard_of(n_tasks: int, shard) -> list[int]:
    """The task indices of ``shard`` = ``(I, N)`` among ``n_tasks``: every ``k`` with
    ``k % N == I - 1`` (module docstring); every index when ``shard`` is None."""
    if shard is None:
        return list(range(n_tasks))
    i, n = parse_shard(shard)
    return list(range(i - 1, n_tasks, n))


def available_cores() -> int:
    """CPU cores this process may run on (its affinity mask when the OS has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def threads_per_worker(n_workers: int, cores: int | None = None) -> int:
    """numba threads for each of ``n_workers`` processes sharing ``cores``: ``cores // n``, ≥ 1."""
    return max(1, (cores or available_cores()) // max(1, int(n_workers)))


#: ``auto`` starts a process only for at least this many tasks: a process costs its start
#: (imports, the context unpickled, numba's kernels loaded), about 2–4 s on the 2-core machine.
AUTO_MIN_TASKS_PER_WORKER = 8
#: ``auto`` splits only tasks of at least this many target pixels: smaller renders take a
#: fraction of a second each, which the processes' start would not repay.
AUTO_MIN_TASK_PIXELS = 1 << 18


def auto_workers(n_tasks: int, task_pixels: int, worker_bytes: int, *, cores: int | None = None,
                 memory: int | None = None) -> int:
    """How many local processes ``n_tasks`` independent renders should run on (1: here).

    On the 2-core machine two processes of one numba thread rendered the fountain path's
    frames in 0.86–0.94 of the wall time of one process of two threads, with less CPU time
    in all (docs/explanation/scale-out.md, "Fly-through frames"). So ``n = min(cores, n_tasks // AUTO_MIN_TASKS_PER_WORKER,
    memory // worker_bytes)`` processes, each with ``cores // n`` threads, when the tasks
    are big enough (``task_pixels ≥ AUTO_MIN_TASK_PIXELS``); else 1. Always 1 inside a
    daemonic process (a Dask worker, a ``multiprocessing.Pool`` worker), which may not start
    processes of its own.

    Parameters
    ----------
    n_tasks : int
        Tasks left to run.
    task_pixels : int
        Target pixels of one task (a frame's width × height).
    worker_bytes : int
        Peak memory of one worker: its context plus one render
        (:func:`vibr.render.checks.render_memory`).
    cores, memory : int, optional
        Default :func:`available_cores` and :func:`vibr._runtime.memory.available_memory`.
    """

    cores = available_cores() if cores is None else int(cores)
    if cores < 2 or task_pixels < AUTO_MIN_TASK_PIXELS or multiprocessing.current_process().daemon:
        return 1
    n = min(cores, int(n_tasks) // AUTO_MIN_TASKS_PER_WORKER)
    avail = available_memory() if memory is None else memory
    if avail is not None and worker_bytes > 0:
        n = min(n, int(avail // worker_bytes))
    return max(1, n)


def parse_executor(executor) -> tuple[str, Any]:
    """``(kind, arg)`` for an ``executor`` argument of :func:`run_tasks`.

    kind is ``"serial"`` (arg None), ``"processes"`` (arg N), ``"dask-local"`` (arg N
    workers), ``"dask"`` (arg: a scheduler address) or ``"dask-client"`` (arg: a Client).
    """
    if executor is None:
        return "serial", None
    if isinstance(executor, bool):
        raise VibrInputError(f"executor must be None, a number of processes or a Dask address, not {executor!r}")
    if isinstance(executor, int):
        if executor < 1:
            raise VibrInputError(f"--workers must be >= 1, got {executor}")
        return ("serial", None) if executor == 1 else ("processes", executor)
    if isinstance(executor, str):
        s = executor.strip()
        if s in ("", "serial"):
            return "serial", None
        low = s.lower()
        if low.startswith("processes:") or low.startswith("local:") or low == "local":
            head, _, num = low.partition(":")
            if head == "local" and not num:
                return "dask-local", 2
            try:
                n = int(num)
            except ValueError:
                raise VibrInputError(f"bad executor {executor!r}: expected {head}:N with N a whole number") from None
            if n < 1:
                raise VibrInputError(f"bad executor {executor!r}: N must be >= 1")
            if head == "processes":
                return ("serial", None) if n == 1 else ("processes", n)
            return "dask-local", n
        return "dask", s
    if hasattr(executor, "submit") and hasattr(executor, "scheduler_info"):
        return "dask-client", executor
    raise VibrInputError(f"executor must be None, a number of processes, 'local' or a Dask address, "
                         f"not {executor!r}")


def require_distributed():
    """Import :mod:`distributed` or raise a one-line :class:`VibrInputError` saying how to install it."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise VibrInputError(f"--dask needs dask.distributed, which is not installed: {DASK_HINT}") from None
    return distributed


def check_scheduler(address: str, timeout_s: float = 5.0) -> None:
    """Raise a one-line :class:`VibrInputError` unless a Dask scheduler answers at
    ``address`` within ``timeout_s``: a command checks this before it loads a scene or
    estimates depth, so that a wrong address fails in seconds instead of after minutes of
    work. Two steps: a TCP connection (a refused port or an unknown host fails at once), then
    Dask's handshake, bounded in time (another server on that port, e.g. the dashboard's,
    would otherwise make the client hang or fail with a traceback). tls:// addresses get the
    first step only (the handshake needs the user's certificates)."""
    from distributed.comm import parse_address
    from distributed.comm.addressing import parse_host_port

    try:
        scheme, loc = parse_address(address)
        if scheme not in ("tcp", "tls"):
            return  # inproc://, ucx://, ws://: left to the client
        host, port = parse_host_port(loc, default_port=8786)
    except ValueError as exc:
        raise VibrInputError(f"bad Dask scheduler address {address!r}: {exc}") from None
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            pass
    except OSError as exc:
        why = "timed out" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc))
        raise VibrInputError(f"cannot reach the Dask scheduler at {address}: {why}") from None
    if scheme == "tcp" and not _dask_handshake(address, timeout_s):
        raise VibrInputError(f"no Dask scheduler answered at {address} (a scheduler listens on "
                             f"port 8786 unless told otherwise; 8787 is its dashboard)")


def _dask_handshake(address: str, timeout_s: float) -> bool:
    """Whether a Dask comm at ``address`` completes distributed's handshake in time."""
    import asyncio

    from distributed.comm import connect

    async def _probe():
        comm = await connect(address, timeout=timeout_s)
        await comm.close()

    def _run(ok):
        try:
            asyncio.run(asyncio.wait_for(_probe(), timeout_s))
            ok.append(True)
        except Exception:  # noqa: BLE001 - any failure means: not a scheduler we can use
            pass

    # on a thread of its own: the caller may already run an event loop (a notebook)
    ok: list = []
    t = threading.Thread(target=_run, args=(ok,), daemon=True, name="vibr-dask-probe")
    t.start()
    t.join(timeout_s + 1.0)
    return bool(ok)


def run_tasks(fn: Callable, tasks: Sequence, *, setup: Callable | None = None, setup_args: Sequence = (),
              executor=None, desc: str = "tasks", retries: int = 2) -> list:
    """Run ``fn(context, task)`` for every task; return the results in task order.

    Parameters
    ----------
    fn : callable
        A top-level function ``fn(context, task) -> summary`` (module docstring: it writes
        its own outputs atomically, skips them when present, returns something small).
    tasks : sequence
        Picklable task descriptions (e.g. a view name and an output path).
    setup : callable, optional
        Top-level ``setup(*setup_args) -> context``, run once per worker; without it
        ``context`` is None.
    setup_args : sequence
        Arguments of ``setup`` (picklable; sent once to each worker).
    executor : None, int, str or distributed.Client
        The engine (module docstring): None serial, N processes, "local" a Dask
        LocalCluster, an address a running Dask scheduler.
    desc : str
        Label of the progress bar (one bar over the tasks, advanced as tasks complete).
    retries : int
        Extra attempts for a failed task (parallel engines only).

    Returns
    -------
    list
        ``fn``'s return values, in the order of ``tasks``.
    """
    tasks = list(tasks)
    retries = int(retries)
    if retries < 0:
        raise VibrInputError(f"retries must be >= 0, got {retries}")
    kind, arg = parse_executor(executor)
    if not tasks:
        return []
    if kind == "serial":
        return _run_serial(fn, tasks, setup, tuple(setup_args), desc)
    if kind == "processes":
        return _run_processes(fn, tasks, setup, tuple(setup_args), arg, desc, retries)
    require_distributed()
    return _run_dask(fn, tasks, setup, tuple(setup_args), kind, arg, desc, retries)


# -- serial ------------------------------------------------------------------------------------
def _run_serial(fn, tasks, setup, setup_args, desc):
    context = setup(*setup_args) if setup is not None else None
    out = []
    with progress(total=len(tasks), desc=desc) as bar:
        for t in tasks:
            out.append(fn(context, t))
            bar.update(1)
    return out


# -- local processes ---------------------------------------------------------------------------
_PROCESS_CONTEXT: Any = None


def _on_sigterm(signum, frame) -> None:
    """A pool whose worker died terminates the others (SIGTERM): their half-written outputs
    (:func:`vibr._runtime.atomic.atomic_path`) are removed before the process ends. Through
    ``os._exit``: an exception raised here would be caught as the running task's error and
    leave the process alive, for the pool to wait on."""

    remove_partial()
    os._exit(128 + signum)


def _orphaned() -> None:
    """The end of a worker whose parent is gone: its half-written outputs removed, then out."""
    remove_partial()
    os._exit(128 + signal.SIGTERM)


def _watch_parent(parent: int, interval_s: float) -> None:
    """Watchdog thread: end this process once its parent ``parent`` is gone (the process is
    then re-parented, so ``os.getppid()`` changes). From a thread, through ``os._exit``: it
    works while the main thread is inside a compiled kernel."""
    while True:
        time.sleep(interval_s)
        if os.getppid() != parent:
            _orphaned()


#: How often a worker checks that its parent is alive (:func:`_watch_parent`).
PARENT_CHECK_S = 0.5


def die_with_parent(parent: int) -> None:
    """Make this worker process end when ``parent`` (the process that started it) dies,
    even by ``kill -9``, which gives the parent no chance to stop its pool.

    On Linux the kernel sends SIGTERM at the parent's death (``prctl(PR_SET_PDEATHSIG)``,
    handled by :func:`_on_sigterm`); everywhere a daemon thread checks ``os.getppid()``
    every :data:`PARENT_CHECK_S` seconds (:func:`_watch_parent`)."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError, TypeError):
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGTERM), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    if os.getppid() != parent:  # died before the line above
        _orphaned()
    threading.Thread(target=_watch_parent, args=(parent, PARENT_CHECK_S), daemon=True,
                     name="vibr-parent-watchdog").start()


def _init_process(threads: int, setup, args_file: str, parent: int | None = None) -> None:
    """Pool initializer: end with the parent (:func:`die_with_parent`), check the numba thread
    count, then build this process's context once."""
    global _PROCESS_CONTEXT
    os.environ[_THREADS_VAR] = str(threads)  # already inherited; kept for what imports numba later
    signal.signal(signal.SIGTERM, _on_sigterm)
    if parent is not None:
        die_with_parent(parent)
    _prepare_worker()
    with open(args_file, "rb") as f:
        setup_args = pickle.load(f)
    _PROCESS_CONTEXT = setup(*setup_args) if setup is not None else None


@contextlib.contextmanager
def _pickled(obj):
    """``obj`` pickled to a temporary file, removed on exit; yields its path.

    The pool sends its initializer's arguments down a pipe while the child starts; a child
    that dies before reading them (a script without an ``if __name__ == "__main__":`` guard,
    a failed import) would leave this process blocked for ever on a pipe full of a scene.
    A path is a few bytes: the pool sees the dead child and reports a broken pool instead.
    """
    fd, path = tempfile.mkstemp(prefix="vibr-setup-", suffix=".pkl")
    try:
        with os.fdopen(fd, "wb") as f:
            pickle.dump(obj, f, protocol=pickle.HIGHEST_PROTOCOL)
        yield path
    finally:
        with contextlib.suppress(OSError):
            os.remove(path)


def _prepare_worker() -> None:
    """No progress bars or status lines from workers (warnings only): the driver's bar counts
    their tasks. The allocator as in the ``vibr`` command (:mod:`vibr._runtime.malloc`)."""
    logging.getLogger("vibr").setLevel(logging.WARNING)
    tune_malloc()


def _call_in_process(fn, task):
    return fn(_PROCESS_CONTEXT, task)


@contextlib.contextmanager
def _environ(**values):
    """Set environment variables for processes spawned inside the block, then restore them.

    A spawned child copies the parent's environment when it starts, so this is how a value
    reaches the child before anything in it imports numba. (This process's numba read its own
    value when it was imported; it does not compile while it only waits for results.)
    """
    old = {k: os.environ.get(k) for k in values}
    os.environ.update({k: str(v) for k, v in values.items()})
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _run_processes(fn, tasks, setup, setup_args, n, desc, retries):
    from concurrent.futures import ProcessPoolExecutor, as_completed

    n, threads = _process_plan(n, len(tasks), desc)
    results: list = [None] * len(tasks)
    attempts = [0] * len(tasks)
    pending = list(range(len(tasks)))
    ctx = multiprocessing.get_context("spawn")
    pool = None
    # BLAS / OpenMP pools sized like numba's, as Dask's nanny does for its workers
    blas = {k: threads for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    with _environ(**{_THREADS_VAR: threads}, **blas), _pickled(setup_args) as args_file, \
            progress(total=len(tasks), desc=desc) as bar:
        try:
            while pending:
                if pool is None:
                    pool = ProcessPoolExecutor(max_workers=min(n, len(pending)), mp_context=ctx,
                                               initializer=_init_process,
                                               initargs=(threads, setup, args_file, os.getpid()))
                futs = {pool.submit(_call_in_process, fn, tasks[i]): i for i in pending}
                pending = []
                for f in as_completed(futs):
                    i = futs[f]
                    try:
                        results[i] = f.result()
                        bar.update(1)
                    except VibrInputError:
                        raise
                    except Exception as exc:  # noqa: BLE001 - any task failure is retried
                        _count_failure(exc, i, attempts, retries, desc)
                        pending.append(i)
                if pending and getattr(pool, "_broken", False):
                    pool.shutdown(wait=True, cancel_futures=True)
                    pool = None
                pending.sort()
        except BaseException:
            if pool is not None:
                _stop_pool(pool)
                pool = None
            raise
        finally:
            if pool is not None:
                pool.shutdown(wait=True, cancel_futures=True)
    return results


def _process_plan(n: int, n_tasks: int, desc: str):
    """``(processes, numba threads each)`` for ``n`` processes asked and ``n_tasks`` tasks; a
    warning when the processes outnumber the cores."""
    n = min(int(n), n_tasks)  # a process more than the tasks would only start and wait
    threads = threads_per_worker(n)
    cores = available_cores()
    if n > cores:
        logger.warning("%s: %d processes on %d cores: they take turns on the cores, and each holds "
                       "its own copy of the scene in memory (one process per core is the most that pays)",
                       desc, n, cores)
    logger.info("%s: %d tasks on %d processes (%d numba threads each)", desc, n_tasks, n, threads)
    return n, threads


def _count_failure(exc: Exception, i: int, attempts: list, retries: int, desc: str) -> None:
    """Count a failure of task ``i``; raise ``RuntimeError`` (from ``exc``) once it has
    failed ``retries + 1`` times, else log that it is retried."""
    from concurrent.futures.process import BrokenProcessPool

    if isinstance(exc, BrokenProcessPool):
        why = ("its worker process died; in a script, code that starts workers "
               "must be under `if __name__ == '__main__':`")
    else:
        why = f"{type(exc).__name__}: {exc}"
    attempts[i] += 1
    if attempts[i] > retries:
        raise RuntimeError(f"{desc}: task {i} failed {attempts[i]} times ({why})") from exc
    logger.warning("%s: task %d failed (%s); retrying (attempt %d of %d)",
                   desc, i, why, attempts[i] + 1, retries + 1)


def _stop_pool(pool, grace_s: float = 5.0) -> None:
    """Stop a pool now, its running tasks included (an interrupt, a failed task): a graceful
    shutdown would wait for every task already handed to a worker (minutes for a view's
    depth or a large frame), and an interrupt that lands inside the pool's own locks can
    leave that shutdown waiting for ever. SIGTERM lets each worker remove its half-written
    outputs (:func:`_on_sigterm`); SIGKILL after ``grace_s``."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    for proc in procs:
        with contextlib.suppress(OSError, ValueError):
            proc.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
    deadline = time.monotonic() + grace_s
    for proc in procs:
        proc.join(max(0.0, deadline - time.monotonic()))
        if proc.is_alive():
            proc.kill()
            proc.join(1.0)


# -- Dask --------------------------------------------------------------------------------------
_WORKER_CONTEXTS: dict = {}
_WORKER_LOCK = threading.Lock()


def _dask_call(fn, setup, setup_args, token, task):
    """Run on a Dask worker: build the context once per worker process (cached by run), then fn."""
    with _WORKER_LOCK:
        if token not in _WORKER_CONTEXTS:
            _WORKER_CONTEXTS.clear()  # keep only the current run's context in a long-lived worker
            _prepare_worker()
            _WORKER_CONTEXTS[token] = setup(*setup_args) if setup is not None else None
        context = _WORKER_CONTEXTS[token]
    return fn(context, task)


def _dask_forget(token) -> None:
    with _WORKER_LOCK:
        _WORKER_CONTEXTS.pop(token, None)


_PRE_SPAWN = "distributed.nanny.pre-spawn-environ"


def start_local_cluster(n_workers: int = 2):
    """A Dask ``LocalCluster`` of ``n_workers`` processes × 1 thread, each with
    ``NUMBA_NUM_THREADS = cores // n_workers`` set in its environment before it starts."""
    import logging as _logging

    import dask
    from distributed import LocalCluster

    threads = threads_per_worker(n_workers)
    # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which turns off glibc's
    # adaptive mmap threshold: every large numpy temporary is then a fresh mmap, page-faulted
    # in and unmapped again, and a fly-through frame took ~25 % longer than in a plain process
    # (docs/explanation/scale-out.md, "Dask's malloc setting"). None removes the key (distributed's rule).
    # the scheduler always serves HTTP (its dashboard, or health and metrics): on a free port of
    # the loopback, not on the fixed :8787 (None means that default), which a second cluster
    # or a user's own Dask dashboard would already hold
    with dask.config.set({f"{_PRE_SPAWN}.MALLOC_TRIM_THRESHOLD_": None}):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0",
                            env={_THREADS_VAR: str(threads)}, silence_logs=_logging.ERROR)


def _workers_lost(desc: str, exc: BaseException, done: int, n: int) -> VibrInputError:
    """The one line for a cluster whose workers died under the tasks (every task's output is
    written by the task itself, atomically: a rerun finds the finished ones and resumes)."""
    why = ("its tasks were cancelled (workers lost)" if isinstance(exc, CancelledError)
           else "its workers were killed")
    # a task's result lives on its worker until the client fetches it: tasks that finished on a
    # worker that then died are on disk but never reported, so the count is of reports
    return VibrInputError(f"the Dask cluster stopped the {desc} with {done} of {n} tasks reported back: {why}; run "
                          "the same command again to resume (the tasks that finished are kept and skipped)")


def _run_dask(fn, tasks, setup, setup_args, kind, arg, desc, retries):
    # dask is an optional dependency (the vibr[dask] extra): imported only when asked for
    from distributed import Client, as_completed
    from distributed.scheduler import KilledWorker

    cluster = client = None
    own_client = kind != "dask-client"
    try:
        if kind == "dask-local":
            cluster = start_local_cluster(arg)
            client = Client(cluster)
        elif kind == "dask":
            check_scheduler(arg)
            try:
                client = Client(arg, timeout="20s")
            except (OSError, TimeoutError, ValueError) as exc:
                raise VibrInputError(f"cannot reach the Dask scheduler at {arg}: {exc}") from None
        else:
            client = arg
        n = len(client.scheduler_info(n_workers=-1).get("workers", {})) if kind != "dask-local" else arg
        logger.info("%s: %d tasks on Dask (%s, %d workers)", desc, len(tasks), client.scheduler.address, n)
        token = uuid.uuid4().hex
        args_f = client.scatter([setup_args], broadcast=True, hash=False)[0]
        futs = [client.submit(_dask_call, fn, setup, args_f, token, t, key=f"vibr-{desc}-{i}-{token[:8]}",
                              retries=retries, pure=False) for i, t in enumerate(tasks)]
        index = {f.key: i for i, f in enumerate(futs)}
        results: list = [None] * len(tasks)
        with progress(total=len(tasks), desc=desc) as bar:
            try:
                for f in as_completed(futs):
                    results[index[f.key]] = f.result()
                    bar.update(1)
            except (CancelledError, KilledWorker) as exc:
                client.cancel(futs)
                raise _workers_lost(desc, exc, sum(r is not None for r in results), len(tasks)) from None
            except BaseException:
                client.cancel(futs)
                raise
        with contextlib.suppress(Exception):
            client.run(_dask_forget, token)
        return results
    finally:
        if own_client and client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
