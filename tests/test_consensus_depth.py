"""The views' consensus on their depth (vibr.stereo.consensus_depth)."""

from __future__ import annotations

import numpy as np
import pytest

from vibr.stereo import consensus_depth
from vibr.synthetic import make_scene


@pytest.fixture(scope="module")
def grid():
    return make_scene("grid", n_views=9, width=64, height=64, seed=0)


def _rel(a, b):
    return np.abs(a - b) / b


def test_exact_depth_stays(grid):
    depths = [v.depth for v in grid.views]
    out, agree = consensus_depth(depths, [v.camera for v in grid.views], rel_tol=0.05)
    for o, v in zip(out, grid.views):
        assert np.nanmedian(_rel(o, v.depth)) < 1e-4
    assert min(agree) > 5  # most of the 8 neighbours see each point


def test_independent_noise_is_averaged_out(grid):
    rng = np.random.default_rng(0)
    noisy = [(v.depth * (1 + 0.005 * rng.standard_normal(v.depth.shape))).astype(np.float32) for v in grid.views]
    out, _ = consensus_depth(noisy, [v.camera for v in grid.views], rel_tol=0.03)
    before = np.median([np.nanmedian(_rel(n, v.depth)) for n, v in zip(noisy, grid.views)])
    after = np.median([np.nanmedian(_rel(o, v.depth)) for o, v in zip(out, grid.views)])
    assert after < 0.5 * before  # nine estimates: about a third of the error


def test_a_view_that_disagrees_is_left_out(grid):
    depths = [v.depth.copy() for v in grid.views]
    depths[0] = depths[0] * 1.5  # one view far off: outside the tolerance, it pulls no mean
    out, _ = consensus_depth(depths, [v.camera for v in grid.views], rel_tol=0.05)
    assert np.nanmedian(_rel(out[4], grid.views[4].depth)) < 1e-3  # averaged in, it would be about 5 %
    assert np.nanmedian(_rel(out[0], depths[0])) < 1e-4  # and keeps its own depth where none agrees


def test_order_of_the_views_does_not_matter(grid):
    rng = np.random.default_rng(1)
    depths = [(v.depth * (1 + 0.01 * rng.standard_normal(v.depth.shape))).astype(np.float32) for v in grid.views]
    depths[2][10:20, 10:20] = np.nan
    cams = [v.camera for v in grid.views]
    out, _ = consensus_depth(depths, cams, rel_tol=0.05)
    perm = [3, 8, 0, 5, 1, 7, 2, 6, 4]
    outp, _ = consensus_depth([depths[i] for i in perm], [cams[i] for i in perm], rel_tol=0.05)
    for k, i in enumerate(perm):
        np.testing.assert_array_equal(outp[k], out[i])
    assert np.isnan(out[2][10:20, 10:20]).all()  # unknown stays unknown


def test_zero_tolerance_and_bad_arguments(grid):
    depths = [v.depth for v in grid.views]
    cams = [v.camera for v in grid.views]
    out, agree = consensus_depth(depths, cams, rel_tol=0.0)
    assert all(np.array_equal(o, d, equal_nan=True) for o, d in zip(out, depths)) and agree == [0.0] * 9
    with pytest.raises(ValueError, match="rel_tol"):
        consensus_depth(depths, cams, rel_tol=-0.1)
    with pytest.raises(ValueError, match="depth maps"):
        consensus_depth(depths[:3], cams, rel_tol=0.1)


def test_the_cli_refuses_the_consensus_for_a_plane_sweep(tmp_path, capsys):
    from vibr.cli import main
    from vibr.io import save_scene

    sc = make_scene("arc", n_views=3, width=32, height=32)
    save_scene(sc.replace(views=[v.replace(depth=None, sigma_z=None) for v in sc.views]), tmp_path / "s")
    rc = main(["depth", str(tmp_path / "s"), "-o", str(tmp_path / "out"), "--consensus-tol", "0.1"])
    err = capsys.readouterr().err
    assert rc == 2 and "--consensus-tol applies to a light field" in err and not (tmp_path / "out").exists()


def test_a_light_field_estimate_takes_the_consensus():
    from vibr.stereo import estimate_depth

    sc = make_scene("grid", n_views=9, width=48, height=48)
    bare = sc.replace(views=[v.replace(depth=None, sigma_z=None) for v in sc.views])
    with_c = estimate_depth(bare)
    without = estimate_depth(bare, consensus_tol=0)
    stats = with_c.meta["depth_estimation"]["views"]
    assert all(stats[v.name]["consensus_agree"] > 4 for v in sc.views)
    assert "consensus_agree" not in without.meta["depth_estimation"]["views"]["view_004"]
    err = [np.nanmedian(_rel(e.depth, t.depth)) for e, t in zip(with_c.views, sc.views)]
    err0 = [np.nanmedian(_rel(e.depth, t.depth)) for e, t in zip(without.views, sc.views)]
    assert np.median(err) < np.median(err0)
    alone = estimate_depth(bare, views=["view_004"])  # one view estimated: nothing to agree with
    np.testing.assert_array_equal(alone.views[0].depth, estimate_depth(bare, views=["view_004"], consensus_tol=0).views[0].depth)
