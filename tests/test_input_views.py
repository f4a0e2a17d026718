"""A render at a source's own camera gives that photograph back, even where the sources'
depth has holes (docs/explanation/renderer.md, "A source's own camera"): the unknown pixels
are completed from their view's depth, and a pixel the target sees
along its own ray is never hidden by another view's surface."""

from __future__ import annotations

import numpy as np
import pytest

from vibr.geometry import apply_fallback, compute_samples
from vibr.geometry.proxy import complete_depth
from vibr.metrics import psnr
from vibr.render import render
from vibr.synthetic import degrade_depth, make_scene


@pytest.fixture(scope="module")
def holed():
    """7 free-layout views of 96×80 whose exact depth has a fifth of its pixels unknown."""
    sc = make_scene("free", n_views=7, width=96, height=80, seed=0)
    return sc.replace(views=[v.replace(depth=degrade_depth(v.depth, holes=0.2, hole_size=6, seed=i))
                             for i, v in enumerate(sc.views)])


def test_a_render_at_a_sources_camera_gives_its_photograph_back(holed):
    src = apply_fallback(holed, "auto")
    for t in (0, 3):
        ref = holed.views[t]
        assert np.isnan(ref.depth).mean() > 0.15
        samples = compute_samples(src, ref.camera)
        assert samples.meta["counts"][ref.name]["occluded"] == 0  # nothing hides its own pixels
        res = render(src, ref.camera)
        assert res.coverage[2:-2, 2:-2].mean() > 0.99  # the image edge lands on the edge of its cells
        p = psnr(res.image, ref.image, border=2)  # all pixels
        # before: the holes' pixels dropped, and the view's own pixels hidden by others' surfaces
        old = render(src, ref.camera, geometry_kw={"same_ray_px": 0.0})
        assert p > 42.5 and p > psnr(old.image, ref.image, border=2) + 2.0


def test_completed_depth_is_a_mean_of_its_neighbourhood_with_the_maps_sigma():
    z = np.full((16, 16), 2.0)
    z[:, 8:] = 4.0
    z[6:10, 6:10] = np.nan  # a hole across the depth edge
    z[12:14, 1:3] = np.nan  # a hole in the flat near part
    zc, s = complete_depth(z, 0.01)
    known = np.isfinite(z)
    assert np.array_equal(zc[known], z[known].astype(np.float32)) and np.all(s[known] == np.float32(0.01))
    assert np.all((zc[~known] >= 2.0 - 1e-5) & (zc[~known] <= 4.0 + 1e-5))
    assert np.allclose(zc[12:14, 1:3], 2.0)
    assert np.all(s[~known] == np.float32(0.01))  # the map's own, beside the edge as well
    z2, s2 = complete_depth(z, 0.01, spread=True)  # the former rule
    assert np.array_equal(z2, zc) and np.allclose(s2[12:14, 1:3], 0.01, atol=1e-6)
    assert s2[7:9, 7:9].min() > 0.3  # both sides of the edge: the neighbourhood's spread
