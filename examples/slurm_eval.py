"""Leave-one-out evaluation of a scene on a SLURM cluster, through dask-jobqueue.

Each SLURM job runs one Dask worker (``--cores`` cores, one task at a time, numba using all
the job's cores); the scheduler runs here, on the login node or in a small job of its own.
Every held-out view is one task (:func:`vibr.eval.leave_one_out.evaluate_all` through
:func:`vibr.executor.run_tasks`): a worker loads the scene once, evaluates its views and
writes each view's report atomically beside ``--json``; a rerun skips the views already
written, so a job killed by the wall-time limit loses only the views it was working on.

    pip install 'vibr[dask]' dask-jobqueue
    python examples/slurm_eval.py /shared/scenes/fountain --scale 0.25 --views 6 \\
        --json fountain_all.json --jobs 4 --cores 8 --memory 16GB --walltime 01:00:00 \\
        --queue normal --account myproject

The scene folder and the output folder must be on a file system every node sees. The same
run on this machine, without SLURM: ``vibr eval SCENE --target all --dask local``.

tests/test_examples.py runs :func:`main` with a ``cluster_factory`` that returns a Dask
``LocalCluster`` instead (and renders the SLURM job script without submitting it), so this
file is exercised in CI; it has not been run on a real SLURM cluster (docs/explanation/scale-out.md).
"""

from __future__ import annotations

import argparse
import sys


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", help="scene folder (on a shared file system)")
    ap.add_argument("--targets", default="all", help="'all' or a comma list of views (default: all)")
    ap.add_argument("--scale", type=float, default=1.0, help="image scale the scene is loaded at")
    ap.add_argument("--views", type=int, default=None, metavar="K", help="K best source views per target")
    ap.add_argument("--depth", default="auto", help="auto|gt|estimated|planar (vibr eval --depth)")
    ap.add_argument("--method", default="ulr,savsr,bvs,gradient", help="comma-separated methods")
    ap.add_argument("--json", required=True, help="the combined report (per-view reports beside it)")
    ap.add_argument("--jobs", type=int, default=2, help="SLURM jobs, one Dask worker each")
    ap.add_argument("--cores", type=int, default=4, help="cores per job (= numba threads of its worker)")
    ap.add_argument("--memory", default="8GB", help="memory per job")
    ap.add_argument("--walltime", default="01:00:00", help="wall-time limit per job")
    ap.add_argument("--queue", default=None, help="SLURM partition")
    ap.add_argument("--account", default=None, help="SLURM account")
    return ap.parse_args(argv)


def slurm_cluster(args):
    """A dask-jobqueue SLURMCluster: one worker process per job, one task at a time, numba
    threads = the job's cores (set before the worker starts, in the job script)."""
    from dask_jobqueue import SLURMCluster

    return SLURMCluster(queue=args.queue, account=args.account, cores=args.cores, processes=1,
                        memory=args.memory, walltime=args.walltime,
                        worker_extra_args=["--nthreads", "1"],
                        job_script_prologue=[f"export NUMBA_NUM_THREADS={args.cores}",
                                             "export OMP_NUM_THREADS=1"])


def main(argv=None, cluster_factory=slurm_cluster) -> int:
    from distributed import Client

    from vibr.eval.leave_one_out import evaluate_all, format_all_table, resolve_targets
    from vibr.eval.protocol import settings_grid, write_report
    from vibr.io import load_scene

    args = parse_args(argv)
    scene = load_scene(args.scene, scale=args.scale)  # here only to check the scene and name the views
    targets = resolve_targets(scene, args.targets)
    settings = settings_grid([m.strip() for m in args.method.split(",") if m.strip()])
    cluster = cluster_factory(args)
    try:
        if hasattr(cluster, "job_script"):  # dask-jobqueue: submit that many jobs
            cluster.scale(jobs=args.jobs)
        with Client(cluster) as client:
            client.wait_for_workers(1, timeout=600)  # the queue decides when the jobs start
            report = evaluate_all(args.scene, targets, settings, views_dir=args.json.removesuffix(".json") + "_views",
                                  scale=args.scale, executor=client, depth=args.depth, n_views=args.views)
    finally:
        cluster.close()
    write_report(report, args.json)
    print(format_all_table(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
