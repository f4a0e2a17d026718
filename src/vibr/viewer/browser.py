"""Headless Chromium for the viewer's test, benchmark and screenshot (not used by
``vibr view`` itself, which serves whatever browser the user opens).

Uses Debian's ``chromium`` package through the ``playwright`` Python package
(``executable_path``); playwright's own browser download is never relied on.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket

__all__ = ["CHROMIUM_ARGS", "chromium_path", "free_port", "launch_chromium", "open_page"]

#: Flags for a headless, sandbox-free Chromium that talks to nothing but the page's server.
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def chromium_path() -> str | None:
    """The Chromium executable: ``$VIBR_CHROMIUM``, else /usr/bin/chromium, else
    ``chromium`` on the PATH; None when there is none."""
    for cand in (os.environ.get("VIBR_CHROMIUM"), "/usr/bin/chromium"):
        if cand and os.path.isfile(cand) and os.access(cand, os.X_OK):
            return cand
    return shutil.which("chromium")


def launch_chromium(playwright, timeout_s: float = 30.0):
    """A headless Chromium browser from a started ``sync_playwright()`` context."""
    exe = chromium_path()
    if exe is None:
        raise FileNotFoundError("chromium not found (Debian: apt-get install -y chromium)")
    return playwright.chromium.launch(executable_path=exe, args=CHROMIUM_ARGS, timeout=timeout_s * 1000)


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` now (the OS's choice), for a test or benchmark server."""
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def open_page(url: str, width: int = 800, height: int = 800, timeout_s: float = 60.0):
    """A headless Chromium page of ``width`` × ``height`` opened at ``url`` (the viewer's
    benchmarks and screenshots); the browser is closed on leaving."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = launch_chromium(pw)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(url, timeout=timeout_s * 1000)
            yield page
        finally:
            browser.close()
