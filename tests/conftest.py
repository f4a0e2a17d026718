"""Shared fixtures and the suite's rules.

Real scenes are found at ``$VIBR_DATA`` (when set, only there) or ``../shared/data`` beside
the repository; tests that need them skip when that folder is absent, except under ``CI=true``.

Under ``CI=true`` (``.ci/run``) nothing may be left out: the session stops at once, with one
line saying why, when the data folder or Chromium (the viewer's browser test) is missing, and
a test that skips fails instead, unless it is marked ``@pytest.mark.optional`` (a check that
does not apply on this platform or hardware).
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest

_REPO = Path(__file__).resolve().parents[1]

# The suite's own depth and scene cache (vibr.stereo.cache), inherited by the processes it
# starts: a run never reads the user's cache (maps another run left there) nor fills it.
os.environ["VIBR_CACHE_DIR"] = tempfile.mkdtemp(prefix="vibr-test-cache-")
atexit.register(shutil.rmtree, os.environ["VIBR_CACHE_DIR"], True)


def in_ci() -> bool:
    """True when ``$CI`` says so (``true``, ``1`` or ``yes``, as CI services set it)."""
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def find_data_dir() -> Path | None:
    """``$VIBR_DATA`` when set (and a folder), else ``../shared/data`` beside the repository."""
    env = os.environ.get("VIBR_DATA")
    cand = Path(env) if env else _REPO.parent / "shared" / "data"
    return cand if cand.is_dir() else None


def _missing_data() -> str | None:
    if find_data_dir() is not None:
        return None
    env = os.environ.get("VIBR_DATA")
    if env:
        return f"VIBR_DATA={env} is not a folder"
    return f"data folder {_REPO.parent / 'shared' / 'data'} not found (place ../shared/data or set VIBR_DATA)"


def _missing_browser() -> str | None:
    from vibr.viewer.browser import chromium_path

    env = os.environ.get("VIBR_CHROMIUM")
    if env and not (os.path.isfile(env) and os.access(env, os.X_OK)):
        return f"VIBR_CHROMIUM={env} is not an executable file"
    if chromium_path() is None:
        return "chromium not found ($VIBR_CHROMIUM, /usr/bin/chromium or PATH; Debian: apt-get install -y chromium)"
    return None


def pytest_configure(config):
    """Under CI=true, stop before any test, with one line, when the data folder or the
    browser is missing (exit status 4, pytest's usage error)."""
    if not in_ci():
        return
    problems = [p for p in (_missing_data(), _missing_browser()) if p]
    if problems:
        raise pytest.UsageError("CI=true: " + "; ".join(problems))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Under CI=true a skipped test fails, unless marked ``optional``."""
    outcome = yield
    rep = outcome.get_result()
    if not (in_ci() and rep.skipped) or hasattr(rep, "wasxfail") or item.get_closest_marker("optional"):
        return
    reason = rep.longrepr[2] if isinstance(rep.longrepr, tuple) else str(rep.longrepr)
    reason = reason.removeprefix("Skipped: ")
    rep.outcome = "failed"
    rep.longrepr = f"skipped under CI=true, where every check must run: {reason}"


@pytest.fixture(scope="session")
def data_dir() -> Path:
    d = find_data_dir()
    if d is None:
        pytest.skip(_missing_data())
    return d


@pytest.fixture(scope="session")
def cotton_dir(data_dir) -> Path:
    return data_dir / "hci2016_cotton"


@pytest.fixture(scope="session")
def fountain_dir(data_dir) -> Path:
    return data_dir / "strecha_fountain-P11"


@pytest.fixture(scope="session")
def temple_dir(data_dir) -> Path:
    return data_dir / "middlebury_templeSparseRing"


@pytest.fixture(scope="session")
def grid_scene_dir(tmp_path_factory) -> Path:
    """A small synthetic light-field grid (9 views of 48 × 40, seed 2) saved as a
    transforms.json folder, a layout vibr eval never saw; shared: tests must not write in it."""
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    d = tmp_path_factory.mktemp("grid_scene") / "grid"
    save_scene(make_scene("grid", n_views=9, width=48, height=40, seed=2), d)
    return d
