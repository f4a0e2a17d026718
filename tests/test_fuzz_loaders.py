"""Property-based fuzzing of every loader (fast profile; the long profile is
benchmarks/tools/fuzz_long.py). See tests/_fuzz.py for the mutations and the property."""

from __future__ import annotations

import os

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from _fuzz import SEEDS, add_camera_path_seed, build_seed, fresh_copy, mutate, run_case

add_camera_path_seed()
#: examples per loader in the fast profile (derandomised: the same cases on every run)
N_FAST = int(os.environ.get("VIBR_FUZZ_EXAMPLES", "20"))


@pytest.mark.parametrize("name", sorted(SEEDS))
def test_loader_survives_mutations(name, tmp_path_factory):
    seed = SEEDS[name]
    base = tmp_path_factory.mktemp(f"fuzz_{name}")
    seed_dir = build_seed(seed, base / "seed")

    @settings(max_examples=N_FAST, deadline=None, database=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(st.data())
    def prop(data):
        work = fresh_copy(seed_dir, base / "work")
        label = mutate(data, seed, work)
        out = run_case(seed.load, work, time_budget=10.0, mem_budget=1 << 30)
        assert out.passed, f"{name}, {label}: {out.status}: {out.message}"

    prop()
