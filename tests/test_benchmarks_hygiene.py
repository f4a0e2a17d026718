"""Benchmarks never write tracked files unless asked: paper_tables.py writes docs/RESULTS.md
only with --write-docs (refused with --quick) or an explicit --doc PATH."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _paper_tables():
    spec = importlib.util.spec_from_file_location("paper_tables", ROOT / "benchmarks" / "paper_tables.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_quick_run_refuses_to_write_the_docs(capsys):
    pt = _paper_tables()
    with pytest.raises(SystemExit) as e:
        pt.main(["--quick", "--write-docs"])
    assert e.value.code == 2 and "write-docs" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        pt.main(["--report-only"])  # rewriting a markdown file needs a target


def test_no_markdown_by_default(monkeypatch, tmp_path):
    """Without --write-docs / --doc the run writes no markdown (the tables' runs are
    replaced by stubs: this checks the plumbing, not the numbers)."""
    pt = _paper_tables()
    written = []
    monkeypatch.setattr(pt, "write_results", lambda path, *a, **k: written.append(path))
    monkeypatch.setattr(pt, "run_cases", lambda args, data, cases, log: [])
    monkeypatch.setattr(pt, "data_dir", lambda arg: tmp_path)
    pt.main(["--quick", "--out", str(tmp_path / "out")])
    assert written == []
    pt.main(["--quick", "--out", str(tmp_path / "out"), "--doc", str(tmp_path / "R.md")])
    assert written == [str(tmp_path / "R.md")]


def test_write_results_keeps_later_sections_and_generates_the_discussion(tmp_path):
    """The discussion is rewritten from the reports (a hand-written one does not survive) and
    what follows it (other scripts' marker sections) is kept byte for byte."""
    import argparse

    pt = _paper_tables()
    doc = tmp_path / "R.md"
    later = "## Uncertainty\n\n<!-- uncert:begin -->\n| a | b |\n<!-- uncert:end -->\n"
    doc.write_text("# old\n\n<!-- BEGIN DISCUSSION -->\nhand-written 12.34 dB\n<!-- END DISCUSSION -->\n\n" + later)
    args = argparse.Namespace(fountain_scale=0.25, strides=[2], cotton_depths=["gt"], out=tmp_path / "out")
    pt.write_results(str(doc), args, [], [], [], [], 1.0, "2026-01-01 00:00", (1.0, 1.0, 1.0), [],
                     git={"commit": "0" * 40, "dirty": ""})
    text = doc.read_text()
    assert "hand-written 12.34" not in text and "from this run's JSON" in text
    assert text.endswith(later) and text.count("<!-- uncert:begin -->") == 1
