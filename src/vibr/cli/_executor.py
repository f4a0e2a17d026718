"""The scale-out flags shared by subcommands: ``--workers N`` and ``--dask ADDRESS|local``."""

from __future__ import annotations

import argparse


def add_executor_args(p: argparse.ArgumentParser, default: str = "one after the other here") -> None:
    """Add ``--workers`` and ``--dask`` (mutually exclusive) to a subcommand's parser;
    ``default`` says what happens without either."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, metavar="N", default=None,
                   help="run the independent tasks on N local processes, each with "
                        f"NUMBA_NUM_THREADS = cores // N; 1: here (default: {default})")
    g.add_argument("--dask", metavar="ADDRESS|local", default=None,
                   help="run the tasks on the Dask scheduler at ADDRESS (e.g. tcp://host:8786), or "
                        "'local' for a LocalCluster of 2 workers x 1 thread started for this command; "
                        "needs the dask extra: pip install 'vibr[dask]'")


def executor_from_args(args, default=None):
    """The ``executor`` argument of :func:`vibr.executor.run_tasks` for parsed flags
    (``default`` when neither flag is given)."""
    from ..errors import VibrInputError
    from ..executor import check_scheduler, parse_executor, require_distributed

    workers, dask = getattr(args, "workers", None), getattr(args, "dask", None)
    if dask is not None:
        if not dask.strip():
            raise VibrInputError("--dask needs a scheduler address or 'local'")
        require_distributed()
        kind, address = parse_executor(dask)
        if kind == "dask":
            check_scheduler(address)
        return dask
    if workers is not None:
        if workers < 1:
            raise VibrInputError(f"--workers must be >= 1, got {workers}")
        return workers
    return default
