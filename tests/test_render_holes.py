"""``hole_fill``: the holes of a variational render (pixels no sample covers) take the push–pull
fill of the solved image's covered pixels (the default), or the energy's minimiser there
("solve": TV and the integrated gradient samples at the hole's edge)."""

from __future__ import annotations

import numpy as np
import pytest

from vibr.errors import VibrInputError
from vibr.pipeline import prepare
from vibr.render import render
from vibr.render.methods import method_params
from vibr.render.pushpull import push_pull
from vibr.render.variational import fill_holes
from vibr.synthetic import make_scene


@pytest.fixture(scope="module")
def two_views():
    """The middle of 7 free-layout views from its 2 best: disocclusions beside the objects."""
    return prepare(make_scene("free", n_views=7, width=128, height=96), 3, n_views=2)


def test_holes_take_the_push_pull_of_the_covered_pixels(two_views):
    src, tv = two_views
    solved = render(src, tv.camera, hole_fill="solve")
    filled = render(src, tv.camera)
    cov = filled.coverage
    assert 0.005 < (~cov).mean() < 0.2
    assert np.array_equal(filled.image[cov], solved.image[cov])  # the solve is untouched
    m = cov.astype(np.float32)
    expect = push_pull(solved.image * m[..., None], m)
    assert np.allclose(filled.image[~cov], expect[~cov], atol=1e-6)
    # the gradient samples at a hole's edge streak the solve's fill; push-pull does not
    err = lambda im: float(np.mean((im[~cov] - tv.image[~cov]) ** 2))  # noqa: E731
    assert err(filled.image) < 0.8 * err(solved.image)


def test_fill_holes_leaves_full_or_empty_coverage_alone():
    img = np.random.default_rng(0).random((8, 9, 3)).astype(np.float32)
    assert fill_holes(img, np.ones((8, 9), bool)) is img
    assert fill_holes(img, np.zeros((8, 9), bool)) is img
    cov = np.ones((8, 9), bool)
    cov[3:5, 4] = False
    out = fill_holes(img, cov)
    assert out.dtype == np.float32 and np.array_equal(out[cov], img[cov])
    lo, hi = img[cov].min(axis=0), img[cov].max(axis=0)
    assert np.all((out[~cov] >= lo - 1e-6) & (out[~cov] <= hi + 1e-6))  # a blend of covered colours


def test_hole_fill_default_and_validation():
    assert method_params("gradient")["hole_fill"] == "push-pull"
    with pytest.raises(VibrInputError, match="hole_fill"):
        method_params("gradient", hole_fill="inpaint")
