"""gamma="auto" / lam="auto" (vibr.render.autotune): leave-one-source-out on the sources,
never the target's image; the right choice where the answer is clear."""

from __future__ import annotations

import numpy as np
import pytest

from vibr.errors import VibrInputError
from vibr.render import autotune, render
from vibr.synthetic import make_scene


@pytest.fixture(scope="module")
def grid_split64():
    sc = make_scene("grid", width=64, height=64)
    return sc.split(4)


def test_probe_is_nearest_source_and_scale_keeps_the_budget(grid_split64):
    src, tv = grid_split64
    (p,) = autotune.probe_views(src, tv.camera, 1)
    d = [np.linalg.norm(v.camera.centre - tv.camera.centre) for v in src.views]
    assert d[p] == min(d)
    s = autotune.probe_scale(src, tv.camera, [p], 6, budget=1.0)
    assert autotune.MIN_SIDE / 64 <= s <= 1.0
    big = make_scene("grid", width=256, height=256)
    bs, bt = big.split(4)
    s = autotune.probe_scale(bs, bt.camera, [0], 6, budget=1.0)
    assert s * s * 6 <= 1.0 + 1e-9  # 6 probe renders hold at most the target's pixels


def test_auto_picks_the_known_best_gamma(grid_split64):
    """Exact depth on the synthetic grid: the gradient term clearly helps (gamma 0.25 beats
    gamma 0 by more than 0.5 dB on the target); the tuner, which sees only the sources,
    picks 0.25, by a clear margin on its probe."""
    src, tv = grid_split64
    on_target = {g: render(src, tv, gamma=g, lam=0.1).metrics["psnr"] for g in (0.0, 0.25)}
    assert on_target[0.25] > on_target[0.0] + 0.5
    t = autotune.tune(src, tv.camera, "gradient", gammas=(0.0, 0.25), lam=0.1)
    assert t.gamma == 0.25 and t.lam == 0.1 and set(t.scores) == {(0.0, 0.1), (0.25, 0.1)}
    assert t.scores[(0.25, 0.1)] < 0.9 * t.scores[(0.0, 0.1)]


def test_never_reads_the_target_image(grid_split64, monkeypatch):
    """render(gamma="auto") with a target whose image is NaN: the tuner gets the camera only,
    and the result is the same as with the real image."""
    src, tv = grid_split64
    seen = []
    real = autotune.tune

    def spy(sources, target, *a, **k):
        seen.append((type(target).__name__, [v.name for v in sources.views]))
        return real(sources, target, *a, **k)

    monkeypatch.setattr(autotune, "tune", spy)
    import vibr.render.api

    nan_target = tv.replace()
    nan_target.image = np.full_like(tv.image, np.nan)  # after the View's checks, which refuse NaN
    monkeypatch.setattr(vibr.render.api, "view_metrics", lambda *a, **k: {})  # no metric of a NaN image
    r1 = render(src, nan_target, gamma="auto", lam="auto")
    r2 = render(src, tv, gamma="auto", lam="auto")
    assert seen[0] == ("Camera", src.names) and tv.name not in seen[0][1]
    np.testing.assert_array_equal(r1.image, r2.image)
    assert r1.params["gamma"] in autotune.GAMMA_GRID and r1.params["lam"] in autotune.LAM_GRID
    with pytest.raises(VibrInputError):
        autotune.tune(src, tv, "gradient")  # a View (with its image) is refused


def test_auto_needs_the_sources():
    from vibr.render.api import render_samples

    with pytest.raises(VibrInputError, match="auto"):
        render_samples(None, "gradient", gamma="auto")


def test_cli_accepts_auto():
    import argparse

    from vibr.cli._options import add_render_params

    p = argparse.ArgumentParser()
    add_render_params(p)
    a = p.parse_args(["--gamma", "auto", "--lam", "0.3"])
    assert a.gamma == "auto" and a.lam == 0.3
    with pytest.raises(SystemExit):
        p.parse_args(["--gamma", "high"])
