"""``lam_density``: lam scaled by rho_ref / rho_c (the TV weight of a MAP estimate, constant
against the data's sum), or at 0 (the default) lam against density-normalised data terms."""

from __future__ import annotations

import numpy as np
import pytest

from vibr.errors import VibrInputError
from vibr.render import render
from vibr.render.methods import method_params
from vibr.synthetic import make_scene


@pytest.fixture(scope="module")
def arc():
    return make_scene("arc", n_views=5, width=64, height=48).split(2)


def test_lam_density_scales_lam_by_the_reference_over_the_density(arc):
    """rho_ref = 2 rho_c gives the render of lam × 2, bit for bit; 0, the default, leaves lam
    alone."""
    src, tv = arc
    base = render(src, tv.camera, lam=0.6)
    rho_c = base.params["colour_density"]
    assert 1.0 < rho_c < 5.0
    doubled = render(src, tv.camera, lam=0.6, lam_density=2.0 * rho_c)
    assert np.array_equal(doubled.image, render(src, tv.camera, lam=1.2).image)
    assert not np.array_equal(doubled.image, base.image)
    assert np.array_equal(render(src, tv.camera, lam=0.6, lam_density=0.0).image, base.image)
    assert method_params("gradient")["lam_density"] == 0.0


@pytest.mark.parametrize("bad", [-1.0, float("nan")])
def test_lam_density_must_be_non_negative(bad):
    with pytest.raises(VibrInputError, match="lam_density"):
        method_params("gradient", lam_density=bad)
