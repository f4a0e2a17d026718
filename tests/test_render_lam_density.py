"""``lam_density``: lam scaled by rho_ref over the density counted in views (the TV weight of a
MAP estimate, constant against the data's sum), or at 0 (the default) lam against
density-normalised data terms."""

from __future__ import annotations

import numpy as np
import pytest

from vibr.errors import VibrInputError
from vibr.render import render
from vibr.render.methods import method_params
from vibr.render.variational import view_density
from vibr.synthetic import make_scene


@pytest.fixture(scope="module")
def arc():
    return make_scene("arc", n_views=5, width=64, height=48).split(2)


def test_lam_density_scales_lam_by_the_reference_over_the_density(arc):
    """rho_ref = twice the density in views gives the render of lam × 2, bit for bit; 0 leaves
    lam alone; the default is 3 for gradient, 0 for the baselines."""
    src, tv = arc
    base = render(src, tv.camera, lam=0.6, lam_density=0.0)
    rho_c = base.params["colour_density"]
    assert 1.0 < rho_c < 5.0
    views = view_density(rho_c, src_samples(src, tv))
    assert 0.5 * rho_c < views < 2.0 * rho_c  # sources and target of one resolution
    doubled = render(src, tv.camera, lam=0.6, lam_density=2.0 * views)
    assert np.array_equal(doubled.image, render(src, tv.camera, lam=1.2, lam_density=0.0).image)
    assert not np.array_equal(doubled.image, base.image)
    at_views = render(src, tv.camera, lam=0.6, lam_density=views)  # the reference density itself
    assert np.allclose(at_views.image, base.image, atol=1e-6)
    assert method_params("gradient")["lam_density"] == 3.0
    assert method_params("bvs")["lam_density"] == method_params("savsr")["lam_density"] == 0.0


def src_samples(src, tv):
    """The samples ``render`` computes for ``tv`` from ``src``."""
    from vibr.geometry import compute_samples

    return compute_samples(src, tv.camera)


def test_the_density_in_views_counts_finer_sources_once():
    """Each source pixel's target area |det ∂tau/∂x| (1 / inv_det): four samples a pixel from
    a source twice as fine count as one view."""
    s = type("S", (), {"inv_det": np.array([4.0, 4.0, 4.0, 4.0, 0.0], np.float32)})()
    assert view_density(8.0, s) == pytest.approx(2.0)


@pytest.mark.parametrize("bad", [-1.0, float("nan")])
def test_lam_density_must_be_non_negative(bad):
    with pytest.raises(VibrInputError, match="lam_density"):
        method_params("gradient", lam_density=bad)


def test_fewer_views_are_smoothed_more(arc):
    """With the default the TV weight grows as the views that weigh a pixel fall: the same
    target from 2 of its views gets lam × 3 / (their density), more than from 4."""
    from vibr.render.variational import view_density as vd

    src, tv = arc
    two = src.subset([0, 1])
    dens = []
    for s in (src, two):
        r = render(s, tv.camera, lam=0.6, lam_density=0.0)
        dens.append(vd(r.params["colour_density"], src_samples(s, tv)))
        scaled = render(s, tv.camera, lam=0.6)
        assert np.array_equal(scaled.image, render(s, tv.camera, lam=0.6 * 3.0 / dens[-1], lam_density=0.0).image)
    assert dens[1] < dens[0]
