"""vibr's glibc malloc settings (vibr._runtime.malloc): large blocks come from the heap, and the
opt-outs leave glibc's defaults. Each case runs in a fresh interpreter (process-global)."""

import os
import platform
import subprocess
import sys

import pytest

pytestmark = [pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
                                 reason="glibc's allocator only"), pytest.mark.optional]

# mallinfo2 (glibc ≥ 2.33): hblkhd = bytes in mmapped blocks, arena = bytes of the heap
_MALLINFO = r"""
import ctypes, json, threading
import numpy as np
from vibr._runtime.malloc import tune_malloc

class MI(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd",
                "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]

libc = ctypes.CDLL("libc.so.6")
libc.mallinfo2.restype = MI
tuned = tune_malloc()
"""

_PROBE = _MALLINFO + r"""
a = np.ones(64 * 2 ** 20, np.uint8)
m = libc.mallinfo2()
print(json.dumps({"tuned": tuned, "mmapped": m.hblkhd, "heap": m.arena}))
"""

# as the viewer's render thread: an array larger than a thread arena's heap (64 MiB)
_THREAD_PROBE = _MALLINFO + r"""
out = {}

def work():
    a = np.ones(96 * 2 ** 20, np.uint8)
    out["mmapped"] = libc.mallinfo2().hblkhd

t = threading.Thread(target=work)
t.start()
t.join()
print(json.dumps({"tuned": tuned, **out}))
"""


def _probe(script=_PROBE, **env):
    e = {k: v for k, v in os.environ.items()
         if k not in ("VIBR_MALLOC", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES",
                      "MALLOC_ARENA_MAX")}
    e.update(env)
    out = subprocess.run([sys.executable, "-c", script], env=e, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    import json

    return json.loads(out.stdout.strip().splitlines()[-1])


# a render's working set freed at the top of the heap (arrays below the mmap threshold)
_TOP_PROBE = _MALLINFO + r"""
blocks = [np.ones(200 * 2 ** 20, np.uint8) for _ in range(4)]
before = libc.mallinfo2().arena
del blocks
print(json.dumps({"tuned": tuned, "heap_before": before, "heap_after": libc.mallinfo2().arena}))
"""


def test_tuned_process_keeps_a_freed_working_set():
    """800 MiB freed at the top of the heap stay mapped for the next render (they were given
    back above the former 512 MiB threshold, and faulted in again by the viewer's next
    render); with glibc's defaults (mmapped blocks) the heap never held them."""
    r = _probe(_TOP_PROBE)
    assert r["tuned"] is True
    assert r["heap_before"] >= 800 * 2 ** 20
    assert r["heap_after"] >= 800 * 2 ** 20


def test_tuned_process_keeps_large_arrays_in_the_heap():
    r = _probe()
    assert r["tuned"] is True
    assert r["mmapped"] < 2 ** 20 and r["heap"] >= 64 * 2 ** 20


@pytest.mark.parametrize("env", [{"VIBR_MALLOC": "default"}, {"MALLOC_TRIM_THRESHOLD_": "65536"}])
def test_opt_outs_leave_glibc_defaults(env):
    """VIBR_MALLOC=default, or glibc's own variables set by the user (Dask's nanny sets the
    trim threshold): a 64 MiB array is then mmapped, as glibc does by default."""
    r = _probe(**env)
    assert r["tuned"] is False
    assert r["mmapped"] >= 64 * 2 ** 20


def test_the_vibr_command_tunes_its_process():
    """The CLI sets the allocator before it does anything else (here: fails to load)."""
    out = subprocess.run([sys.executable, "-m", "vibr", "-v", "info", "/nonexistent/scene"], capture_output=True,
                         text=True, timeout=120, env={k: v for k, v in os.environ.items()
                                                   if k not in ("VIBR_MALLOC", "MALLOC_ARENA_MAX")})
    assert out.returncode == 2
    assert "malloc: mmap threshold 256 MiB, trim threshold 2048 MiB, arenas 1: set" in out.stderr


@pytest.mark.parametrize("arena_max", [None, "8"])
def test_a_thread_allocates_from_the_tuned_heap(arena_max):
    """With one arena (vibr's setting) a thread's 96 MiB array comes from the main heap;
    with the user's MALLOC_ARENA_MAX (kept) glibc gives the thread an arena of its own,
    whose heaps cannot hold it: mapped (and unmapped at free, every time)."""
    r = _probe(_THREAD_PROBE, **({} if arena_max is None else {"MALLOC_ARENA_MAX": arena_max}))
    assert r["tuned"] is True
    if arena_max is None:
        assert r["mmapped"] < 2 ** 20
    else:
        assert r["mmapped"] >= 96 * 2 ** 20
