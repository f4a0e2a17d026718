"""The benchmarks as a reader meets them: each script answers ``--help``, no script imports
another (only ``benchmarks/_common.py``), every path the docs and the code cite exists, a
generator writes no tracked file unless asked, and one below its floor exits 1.

Nothing here imports from benchmarks/: the scripts run as subprocesses."""

import ast
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"
SCRIPTS = sorted(p for p in BENCH.glob("*/*.py"))
PAPER_TABLES = BENCH / "quality" / "paper_tables.py"


def _run(script, *args, timeout=120):
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, str(script), *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=ROOT)


def test_the_layout_is_by_purpose():
    assert {p.parent.name for p in SCRIPTS} == {"perf", "quality", "assets", "tools"}
    assert [p.name for p in BENCH.glob("*.py")] == ["_common.py"]


@pytest.fixture(scope="module")
def help_runs(request):
    """The ``--help`` run of every script the session's tests check, one per core at a time (each is
    mostly an interpreter's imports, on one core), started at the first test that asks."""
    from concurrent.futures import ThreadPoolExecutor

    scripts = [item.callspec.params["script"] for item in request.session.items
               if item.originalname == "test_every_script_answers_help"]
    with ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 2)) as pool:
        yield {s: pool.submit(_run, s, "--help") for s in scripts}


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_script_answers_help(script, help_runs):
    r = help_runs[script].result()
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.lstrip().startswith("usage:"), r.stdout[:200]


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_no_script_imports_another(script):
    """A script imports vibr, third-party modules and ``_common``, never another script
    (tools/fuzz_long.py shares tests/_fuzz.py with the fast profile)."""
    names = {p.stem for p in SCRIPTS}
    tree = ast.parse(script.read_text())
    imported = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            imported.add(node.module.split(".")[0])
    assert not imported & names, f"{script.name} imports {sorted(imported & names)}"


def test_every_cited_benchmark_exists():
    """Every ``benchmarks/...`` path in docs/, src/ and tests/ names a file or folder that exists."""
    cited = {}
    for folder in ("docs", "src", "tests"):
        for f in (ROOT / folder).rglob("*"):
            if f.suffix in (".md", ".py") and f.is_file():
                for m in re.finditer(r"benchmarks/[A-Za-z0-9_/]+(?:\.py)?", f.read_text(errors="replace")):
                    cited.setdefault(m.group(0).rstrip("/"), f.relative_to(ROOT))
    assert cited, "no citation found: the pattern is wrong"
    missing = {p: str(f) for p, f in cited.items() if not (ROOT / p).exists()}
    assert not missing, missing


def test_quick_run_refuses_to_write_the_docs():
    r = _run(PAPER_TABLES, "--quick", "--write-docs")
    assert r.returncode == 2 and "write-docs" in r.stderr
    r = _run(PAPER_TABLES, "--report-only")  # rewriting a markdown file needs a target
    assert r.returncode == 2 and "--doc" in r.stderr


def _fountain_report(target, psnr, scale=0.25):
    """A report as paper_tables.py writes it, reduced to what the floor check reads."""
    return {"target": target, "scale": scale,
            "results": [{"method": "gradient", "params": {"alpha": 0.1, "gamma": 1.0, "lam": 0.002},
                         "intensity_scale": 255.0, "psnr": psnr}]}


def test_a_result_below_the_floor_exits_1_with_one_line(tmp_path):
    f = tmp_path / "reports.json"
    f.write_text(json.dumps([_fountain_report("0002", 30.0), _fountain_report("0005", 29.5)]))
    r = _run(PAPER_TABLES, "--check-only", f)
    assert r.returncode == 1
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "BELOW floor" in lines[0] and "0005" in lines[0] and "0002" not in lines[0]


def test_a_result_at_the_floor_passes(tmp_path):
    f = tmp_path / "report.json"
    f.write_text(json.dumps(_fountain_report("0005", 31.0)))
    assert _run(PAPER_TABLES, "--check-only", f).returncode == 0
    # another scale has no floor
    f.write_text(json.dumps(_fountain_report("0005", 20.0, scale=0.5)))
    assert _run(PAPER_TABLES, "--check-only", f).returncode == 0
