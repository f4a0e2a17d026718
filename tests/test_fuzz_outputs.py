"""The fuzz of the CLI over its outputs (benchmarks/tools/fuzz_outputs.py), a short profile:
vibr never overwrites or deletes a file it did not write, fails in one line, and leaves no
partial output. The long profile is the script itself (500 cases)."""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

import pytest

#: processes, fly-throughs and real encodes: seconds each (the fast subset leaves them out)
pytestmark = pytest.mark.slow

_SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "tools" / "fuzz_outputs.py"


@pytest.fixture(scope="module")
def fuzz():
    spec = importlib.util.spec_from_file_location("fuzz_outputs", _SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_outputs"] = mod  # its dataclasses look their module up
    spec.loader.exec_module(mod)
    yield mod
    sys.modules.pop("fuzz_outputs", None)


def test_twenty_cases_pass(fuzz):
    results, skipped = fuzz.fuzz(20, seed=7)
    assert len(results) == 20
    bad = [(r.spec.line(), r.problems) for r in results if r.problems]
    assert not bad, fuzz.summary(results, skipped)
    codes = {r.rc for r in results}
    assert {0, 2} <= codes, codes  # some commands wrote, some were refused: both sides are checked
    if os.geteuid() == 0 and skipped is None:
        assert any(r.spec.family == "full-disk" for r in results)


def test_the_fuzz_sees_a_lost_file(fuzz, monkeypatch):
    """With vibr taking every file for its own, the fuzz reports the user's files it writes
    over: its checks can fail."""
    import vibr.io.outputs as outputs

    monkeypatch.setattr(outputs, "written_by_vibr", lambda path: True)
    results, _ = fuzz.fuzz(20, seed=7, families=["render", "path", "eval"])
    problems = [p for r in results for p in r.problems]
    assert any(p.startswith("user's") and ("changed" in p or "became" in p) for p in problems), problems
