"""Shared fixtures. Real scenes are found at ``$VIBR_DATA`` or ``../shared/data`` beside
the repository; tests that need them skip only when that folder is absent."""

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


def find_data_dir() -> Path | None:
    env = os.environ.get("VIBR_DATA")
    for cand in ([Path(env)] if env else []) + [_REPO.parent / "shared" / "data"]:
        if cand.is_dir():
            return cand
    return None


@pytest.fixture(scope="session")
def data_dir() -> Path:
    d = find_data_dir()
    if d is None:
        pytest.skip("real data folder not found (set VIBR_DATA or place ../shared/data)")
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
