"""One render worker per browser client, holding only the newest request.

A camera update replaces whatever request was waiting (stale requests are dropped, never
queued). The worker renders the newest request once as a *preview* (small image, fast) and,
when no newer request has come for ``settle_s`` seconds, once more at *full* size. Renders
run on the worker's own thread, never on viser's event loop or its callback pool.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

logger = logging.getLogger(__name__)

__all__ = ["Request", "LatestRequestWorker"]


@dataclass(frozen=True)
class Request:
    """A render request: ``seq`` (increasing per worker), ``t_update`` (time.perf_counter()
    of the camera update that made it) and ``payload`` (what the render function needs)."""

    seq: int
    t_update: float
    payload: Any


class LatestRequestWorker:
    """Render the newest request, preview first, full size once the camera settled.

    Parameters
    ----------
    render_fn : callable
        ``render_fn(request, kind)`` with ``kind`` in ``{"preview", "full"}``; runs on the
        worker thread. Exceptions are logged and the worker carries on.
    settle_s : float
        Seconds without a newer request before the full-size render (default 0.3).
    name : str
        Thread name.
    """

    def __init__(self, render_fn: Callable[[Request, str], None], settle_s: float = 0.3,
                 name: str = "vibr-view-render"):
        self._fn = render_fn
        self.settle_s = float(settle_s)
        self._cv = threading.Condition()
        self._req: Request | None = None
        self._seq = 0
        self._started = 0  # seq of the newest request whose preview has started
        self._done_full = 0  # seq of the newest request whose full render has started
        self._stop = False
        self.submitted = 0
        self.dropped = 0  # requests replaced before any render of them started
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def submit(self, payload: Any, t_update: float | None = None) -> int:
        """Replace the waiting request by this one; returns its sequence number."""
        t = time.perf_counter() if t_update is None else t_update
        with self._cv:
            if self._req is not None and self._req.seq != self._started:
                self.dropped += 1
            self._seq += 1
            self.submitted += 1
            self._req = Request(self._seq, t, payload)
            self._cv.notify_all()
            return self._seq

    def _next(self) -> tuple[Request, str] | None:
        """Wait for work: the newest request's preview, else its full render once settled."""
        with self._cv:
            while not self._stop:
                r = self._req
                if r is not None and r.seq != self._started:
                    self._started = r.seq
                    return r, "preview"
                if r is not None and r.seq != self._done_full:
                    wait = r.t_update + self.settle_s - time.perf_counter()
                    if wait <= 0:
                        self._done_full = r.seq
                        return r, "full"
                    self._cv.wait(wait)
                    continue
                self._cv.wait()
            return None

    def _loop(self) -> None:
        while True:
            job = self._next()
            if job is None:
                return
            req, kind = job
            try:
                self._fn(req, kind)
            except Exception:  # a bad camera or parameter must not kill the viewer
                logger.exception("render of request %d (%s) failed", req.seq, kind)

    @property
    def latest_seq(self) -> int:
        with self._cv:
            return self._seq

    def is_stale(self, req: Request) -> bool:
        """True when a newer request has arrived or the worker is stopping (the render
        function may stop early)."""
        with self._cv:
            return self._stop or self._seq != req.seq

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the thread (after the render in progress, if any)."""
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        self._thread.join(timeout)
