"""Memory of a render against vibr.validate.render_memory's estimate (docs/ERRORS.md).

    python3 benchmarks/render_memory.py [SIZE]      # synthetic grid, SIZE² from 8 views

Renders once to warm up, then measures how far the peak resident memory of a second render
rises above the resident memory before it (Linux ru_maxrss), and prints the estimate.
"""

from __future__ import annotations

import gc
import resource
import sys

from vibr.render import render
from vibr.synthetic import make_scene
from vibr.validate import render_memory


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 512
    s = make_scene("grid", n_views=9, width=n, height=n, seed=1)
    src, tv = s.split(4)
    render(src, tv, "gradient")  # compile and warm up: the peak below includes this run's
    gc.collect()
    with open("/proc/self/statm") as f:
        rss0 = int(f.read().split()[1]) * resource.getpagesize()
    est = render_memory([v.camera.shape for v in src.views], tv.camera.shape)
    render(src, tv, "gradient")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(f"{n}x{n} from {len(src)} views: estimate {est / 2**20:.0f} MiB, resident before the render "
          f"{rss0 / 2**20:.0f} MiB, peak {peak / 2**20:.0f} MiB, growth {max(0, peak - rss0) / 2**20:.0f} MiB")


if __name__ == "__main__":
    main()
