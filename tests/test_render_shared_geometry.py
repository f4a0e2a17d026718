"""``vibr.render.shared_geometry``: one geometry stage for several renders of a target gives
what :func:`vibr.render.render` gives for each (``vibr eval`` and the defaults' sweep render
through it)."""

import numpy as np

from vibr.pipeline import prepare
from vibr.render import render, shared_geometry
from vibr.synthetic import make_scene


def _case():
    # a hand-held layout whose 4 best sources are coarser than the target (gamma / s²)
    src, tv = prepare(make_scene("free", n_views=7, width=96, height=72, seed=1), 3, n_views=4)
    return src, tv


def test_each_render_equals_render():
    src, tv = _case()
    geo = shared_geometry(src, tv, [("gradient", {}), ("ulr", {}), ("bvs", {})])
    assert geo.plan.grid_source_size > 1.05
    for m in ("gradient", "ulr", "bvs"):
        assert np.array_equal(geo.render(m).image, render(src, tv, m).image), m
    assert np.array_equal(geo.render("gradient", lam=0.3).image, render(src, tv, "gradient", lam=0.3).image)
    # the same samples without the grid's parameters render another image: the helper's point
    plain = render(src, tv.camera, "gradient", samples=geo.samples).image
    assert not np.array_equal(plain, geo.render("gradient").image)


def test_a_supersampled_grid_comes_back_to_the_target():
    src, tv = _case()
    cam = tv.camera.scaled(0.5)  # sources twice finer: rendered on a finer grid, averaged
    geo = shared_geometry(src, cam)
    assert geo.plan.supersample == 2 and geo.camera.shape != cam.shape
    img = geo.render("gradient").image
    assert img.shape[:2] == cam.shape
    assert np.array_equal(img, render(src, cam, "gradient").image)


def test_sources_not_ready_are_made_ready_as_render_makes_them():
    """The target among the sources is held out (as :func:`render` does it)."""
    src, tv = _case()
    with_target = src.replace(views=[*src.views, tv])
    geo = shared_geometry(with_target, tv)
    assert tv.name not in geo.sources.names
    assert np.array_equal(geo.render("gradient").image, render(with_target, tv, "gradient").image)
