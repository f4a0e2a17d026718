"""Each heavy kernel compiles once per run: a kernel called with a float64 array where it is
otherwise given float32, or with a transposed or read-only one, compiles again, and on a
clean machine (CI, a user's first run) each compilation of a parallel kernel costs seconds."""

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow

#: The kernels whose compilation took longest in a profile of the suite on a cold cache.
KERNELS = {
    "vibr.stereo._kernels": ("patchmatch_refine", "consistency", "support_weights", "plane_costs", "sweep_slab"),
    "vibr.render.weights": ("_coverage_kernel", "_weighted_kernel", "_shared_error_kernel", "_prior_splat",
                            "_weight_gradient_kernel"),
    "vibr.render.uncertainty": ("_sigma_splat",),
    "vibr.render.fused": ("_hessian_terms",),
    "vibr.render.tv": ("_dual_step",),
}

PIPELINE = """
import importlib, json, sys
import numpy as np
from vibr import synthetic
from vibr.camera import Camera
from vibr.geometry import apply_fallback
from vibr.render import render
from vibr.stereo import estimate_depth

scene = synthetic.make_scene("arc", n_views=4, width=64, height=48)
# half the cameras with a transposed (Fortran-ordered) rotation, as R = R_cw.T gives one
scene = scene.replace(views=[v.replace(camera=Camera(v.camera.K, np.asfortranarray(v.camera.R) if i % 2 else v.camera.R,
                                                      v.camera.t, v.camera.width, v.camera.height))
                             for i, v in enumerate(scene.views)])
src, target = scene.subset(scene.names[1:]), scene.views[0]
est = apply_fallback(estimate_depth(src))
for method in ("gradient", "ulr"):
    render(est, target, method)
render(est, target, "gradient", uncertainty=True)
render(est, target, "gradient", z_corr=0.5)
kernels = json.loads(sys.argv[1])
print(json.dumps({f"{m}.{k}": len(getattr(importlib.import_module(m), k).signatures)
                  for m, names in kernels.items() for k in names}))
"""


def test_a_pipeline_run_compiles_each_heavy_kernel_once():
    # a process of its own, so that only this run's calls count; a kernel loaded from numba's
    # cache counts as one compiled there
    out = subprocess.run([sys.executable, "-c", PIPELINE, json.dumps(KERNELS)], capture_output=True, text=True,
                         timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    counts = json.loads(out.stdout.strip().splitlines()[-1])
    assert counts["vibr.stereo._kernels.patchmatch_refine"] == 1  # the run did reach the kernels
    assert not {k: n for k, n in counts.items() if n > 1}
