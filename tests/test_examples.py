"""examples/slurm_eval.py runs (its cluster replaced by a LocalCluster stand-in) and its
SLURM job script says what docs/explanation/scale-out.md says it does."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import distributed  # noqa: F401  (a plain import: the test extra installs it)
import pytest

pytestmark = pytest.mark.slow

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "slurm_eval.py"


def _load():
    spec = importlib.util.spec_from_file_location("slurm_eval", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_slurm_example_runs_on_a_local_stand_in(tmp_path):
    from vibr.executor import start_local_cluster
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    ex = _load()
    scene = tmp_path / "grid"
    save_scene(make_scene("grid", n_views=4, width=32, height=24, seed=1), scene)
    out = tmp_path / "all.json"
    made = []

    def stand_in(args):
        assert args.jobs == 2 and args.cores == 3
        made.append(start_local_cluster(1))
        return made[0]

    rc = ex.main([str(scene), "--targets", "view_000,view_003", "--method", "ulr", "--depth", "gt",
                  "--json", str(out), "--jobs", "2", "--cores", "3"], cluster_factory=stand_in)
    assert rc == 0 and made and made[0].status.name == "closed"
    rep = json.loads(out.read_text())
    assert rep["targets"] == ["view_000", "view_003"] and rep["summary"]["ulr"]["n"] == 2
    assert (tmp_path / "all_views" / "view_003.json").is_file()


def test_slurm_job_script():
    import dask_jobqueue  # noqa: F401  (the test extra installs it)

    ex = _load()
    args = ex.parse_args(["scene", "--json", "x.json", "--cores", "8", "--memory", "16GB",
                          "--walltime", "02:00:00", "--queue", "normal"])
    cluster = ex.slurm_cluster(args)  # nothing is submitted until scale()
    try:
        script = cluster.job_script()
    finally:
        cluster.close()
    assert "#SBATCH -p normal" in script and "#SBATCH -t 02:00:00" in script
    assert "export NUMBA_NUM_THREADS=8" in script and "--nthreads 1" in script
