"""``vibr depth`` end to end on a tiny synthetic scene."""

from __future__ import annotations

import json

import numpy as np

from vibr.cli import main


def test_vibr_depth_in_place_and_out(tmp_path, capsys):
    from vibr.io import load_scene, save_scene
    from vibr.synthetic import make_scene

    s = make_scene("free", n_views=4, width=64, height=48, seed=2)
    for v in s.views:
        v.depth = None
        v.sigma_z = None
    src = save_scene(s, tmp_path / "scene")
    out = tmp_path / "out"
    assert main(["-q", "depth", str(src), "-o", str(out), "--targets", "view_000",
                 "--exclude", "view_003"]) == 0
    e = load_scene(out)
    # a 64×48 scene with 2 usable partners keeps ~20 % (an end-to-end smoke test: the
    # accuracy tests are in test_stereo_planesweep.py)
    assert e[0].depth is not None and np.isfinite(e[0].depth).mean() > 0.15
    assert np.ndim(e[0].sigma_z) == 2
    assert e[3].depth is None
    # in place
    assert main(["-q", "depth", str(src), "--targets", "view_001", "--no-consistency"]) == 0
    e2 = load_scene(src)
    assert e2[1].depth is not None
    assert "depth" in json.dumps(json.load(open(src / "transforms.json")))
    # --fill-segments reaches estimate_depth: no fewer known pixels, and the report says so
    capsys.readouterr()
    out2 = tmp_path / "out_fill"
    assert main(["depth", str(src), "-o", str(out2), "--targets", "view_000", "--exclude", "view_003",
                 "--fill-segments"]) == 0
    assert np.isfinite(load_scene(out2)[0].depth).sum() > np.isfinite(e[0].depth).sum()
    assert "filled from segment planes" in capsys.readouterr().out


def test_vibr_depth_bad_input(tmp_path, capsys):
    assert main(["-q", "depth", str(tmp_path / "missing"), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "vibr depth: error" in err and len(err.strip().splitlines()) == 1
    # in place on a folder that is not a transforms.json scene
    (tmp_path / "x").mkdir()
    assert main(["-q", "depth", str(tmp_path / "x")]) == 2


def test_vibr_depth_coarse_level_options(tmp_path, capsys):
    """--sweep-scale/--coarse-iter reach estimate_depth: a bad value is a one-line error
    with exit 2 and no output folder; the full-size sweep (no coarse level) runs."""
    from vibr.io import load_scene, save_scene
    from vibr.synthetic import make_scene

    s = make_scene("free", n_views=3, width=64, height=48, seed=2)
    src = save_scene(s, tmp_path / "scene")
    out = tmp_path / "bad"
    assert main(["-q", "depth", str(src), "-o", str(out), "--targets", "view_000",
                 "--coarse-iter", "-1"]) == 2
    err = capsys.readouterr().err
    assert "coarse_iter" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
    out = tmp_path / "full"
    assert main(["-q", "depth", str(src), "-o", str(out), "--targets", "view_000",
                 "--sweep-scale", "1", "--coarse-iter", "0", "--no-consistency"]) == 0
    assert np.isfinite(load_scene(out)[0].depth).mean() > 0.15


def test_estimate_depth_refuses_an_empty_or_repeated_request():
    import pytest

    from vibr.errors import VibrInputError
    from vibr.stereo import estimate_depth
    from vibr.synthetic import make_scene

    s = make_scene("free", n_views=3, width=32, height=24, seed=2)
    with pytest.raises(VibrInputError, match="list of views is empty"):
        estimate_depth(s, views=[])
    with pytest.raises(VibrInputError, match="every view is excluded"):
        estimate_depth(s, exclude=[0, 1, 2])
    with pytest.raises(VibrInputError, match="listed twice"):
        estimate_depth(s, views=[1, "view_001"])


def test_an_estimate_that_keeps_little_warns():
    """A depth range that misses the scene kept 0 % of pixels without a word."""
    import io
    import logging

    from vibr.progress import configure_logging
    from vibr.stereo import estimate_depth
    from vibr.synthetic import make_scene

    lg = logging.getLogger("vibr")
    saved = (list(lg.handlers), lg.level, lg.propagate)  # whatever earlier CLI tests left
    buf = io.StringIO()
    try:
        configure_logging(0, stream=buf)
        s = make_scene("arc", n_views=4, width=48, height=32, seed=2)  # plane sweep
        estimate_depth(s, views=[0], depth_range=(100.0, 200.0))
    finally:
        lg.handlers[:], lg.level, lg.propagate = saved
    assert "% of pixels kept" in buf.getvalue() and "--depth-range" in buf.getvalue(), buf.getvalue()
