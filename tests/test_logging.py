"""The library logs (children of the "vibr" logger); the CLI sets the handler and level;
progress bars only on a terminal, one line per stage otherwise."""

import io
import logging
import subprocess
import sys

import pytest

from vibr.progress import configure_logging, progress


@pytest.fixture
def restore_vibr_logger():
    lg = logging.getLogger("vibr")
    saved = (list(lg.handlers), lg.level, lg.propagate)
    yield
    lg.handlers[:], lg.level, lg.propagate = saved


def test_progress_off_a_terminal_logs_one_line(restore_vibr_logger):
    buf = io.StringIO()  # not a terminal
    configure_logging(0, stream=buf)
    assert list(progress(range(5), desc="stage A")) == list(range(5))
    bar = progress(total=3, desc="stage B")
    for _ in range(3):
        bar.update(1)
    bar.close()
    out = buf.getvalue()
    assert "\r" not in out
    lines = out.splitlines()
    assert len(lines) == 2 and lines[0].startswith("stage A: 5/5") and lines[1].startswith("stage B: 3/3")


def test_a_long_stage_off_a_terminal_says_how_far_it_is(restore_vibr_logger, monkeypatch):
    """A stage past LONG_S logs its count and the time left, at most once per EVERY_S; a
    short one stays one line (the test above). The time left is at the pace after the
    first item: a first item slowed by compilation says nothing of the others."""
    import vibr.progress as P

    clock = [100.0]
    monkeypatch.setattr(P.time, "perf_counter", lambda: clock[0])
    buf = io.StringIO()
    configure_logging(0, stream=buf)
    bar = progress(total=81, desc="leave-one-out")
    for dt in (400.0, 30.0, 400.0):  # 1 done at 400 s, 2 at 430 s (too soon), 3 at 830 s
        clock[0] += dt
        bar.update(1)
    bar.close()
    lines = buf.getvalue().splitlines()
    # no time left from the first item alone (it pays the start-up); then at the pace since
    assert lines[0] == "leave-one-out: 1/81 in 7 min"
    assert lines[1] == "leave-one-out: 3/81 in 14 min, about 4.7 h left"  # 215 s an item after the first
    assert lines[2].startswith("leave-one-out: 3/81 in 830.0 s") and len(lines) == 3
    assert P.duration_text(42) == "42 s" and P.duration_text(420) == "7 min"
    # two items finishing together (side by side) are the first batch: the pace after them
    buf.truncate(0), buf.seek(0)
    bar = progress(total=6, desc="depth views")
    for dt in (40.0, 0.1, 30.0, 30.0):  # 2 done at 40 s (start-up paid), then one every 30 s
        clock[0] += dt
        bar.update(1)
    bar.close()
    assert buf.getvalue().splitlines()[:2] == ["depth views: 1/6 in 40 s", "depth views: 4/6 in 2 min, about 60 s left"]


def test_a_stage_inside_another_logs_at_debug(restore_vibr_logger):
    """Each view's stage inside "depth views" is a DEBUG line: by default only the outer
    stage's line, with -v both; a stage after the outer one closed is INFO again."""
    for v, expect in ((0, ["depth views: 2/2", "after: 1/1"]),
                      (1, ["view a: 3/3", "view b: 3/3", "depth views: 2/2", "after: 1/1"])):
        buf = io.StringIO()
        configure_logging(v, stream=buf)
        for name in progress(["a", "b"], desc="depth views"):
            list(progress(range(3), desc=f"view {name}"))
        list(progress(range(1), desc="after"))
        lines = buf.getvalue().splitlines()
        assert [ln.split(" in ")[0] for ln in lines] == expect


def test_a_long_stage_inside_another_still_says_how_far_it_is(restore_vibr_logger, monkeypatch):
    import vibr.progress as P

    clock = [0.0]
    monkeypatch.setattr(P.time, "perf_counter", lambda: clock[0])
    buf = io.StringIO()
    configure_logging(0, stream=buf)
    with progress(total=2, desc="depth views") as outer:
        with progress(total=4, desc="plane sweep") as inner:
            for _ in range(4):
                clock[0] += 30.0
                inner.update(1)
        outer.update(1)
    # the inner stage's count and time left (at most once a minute), not its end; the outer's both
    assert buf.getvalue().splitlines() == ["plane sweep: 1/4 in 30 s",
                                           "plane sweep: 3/4 in 2 min, about 30 s left",
                                           "depth views: 1/2 in 2 min",
                                           "depth views: 1/2 in 120.0 s"]


def test_verbosity_levels(restore_vibr_logger):
    lg = logging.getLogger("vibr.somewhere")
    for v, shown in ((-1, ["w"]), (0, ["i", "w"]), (1, ["d", "i", "w"])):
        buf = io.StringIO()
        configure_logging(v, stream=buf)
        lg.debug("d")
        lg.info("i")
        lg.warning("w")
        assert buf.getvalue().split() == shown
    assert len([h for h in logging.getLogger("vibr").handlers if getattr(h, "_vibr_cli", False)]) == 1


@pytest.mark.slow
def test_cli_stderr_redirected_has_no_carriage_returns(tmp_path):
    """``vibr demo ... 2>log``: status lines, one per stage, no progress-bar frames."""
    log = tmp_path / "log"
    with open(log, "w") as err:
        r = subprocess.run([sys.executable, "-m", "vibr", "demo", "--size", "48", "--method", "bvs",
                            "--no-video"],
                           stdout=subprocess.PIPE, stderr=err, text=True, timeout=300)
    assert r.returncode == 0, log.read_text()
    text = log.read_text()
    assert "\r" not in text and "render bvs: 2/2" in text and "scene: 9 views" in text


def test_cli_quiet_leaves_stderr_empty(capsys, restore_vibr_logger):
    from vibr.cli import main

    assert main(["-q", "demo", "--size", "48", "--method", "ulr", "--no-video"]) == 0
    out, err = capsys.readouterr()
    assert err == "" and "PSNR" in out
