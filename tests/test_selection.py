import logging

import numpy as np
import pytest

from vibr import Camera, Scene, View
from vibr.geometry.selection import rank_views, select_views


def _grid_scene(n=5, z=10.0, size=32):
    """Parallel cameras on an n×n grid (baseline 1), fronto-parallel plane at depth z."""
    K = Camera.intrinsics(40.0, size, size)
    views = []
    for r in range(n):
        for c in range(n):
            C = np.array([c - n // 2, r - n // 2, 0.0])
            cam = Camera.from_centre(K, np.eye(3), C, size, size)
            views.append(View(f"v{r}{c}", np.zeros((size, size, 3), np.float32), cam,
                              depth=np.full((size, size), z, np.float32)))
    return Scene(views, grid=(n, n))


def test_nearest_grid_neighbours_rank_first():
    scene = _grid_scene()
    sources, target = scene.split("v22")
    order, pen, overlap = rank_views(sources, target.camera)
    first4 = {sources.views[i].name for i in order[:4]}
    assert first4 == {"v12", "v21", "v23", "v32"}
    # Diagonal neighbours come next, the far corners last.
    next4 = {sources.views[i].name for i in order[4:8]}
    assert next4 == {"v11", "v13", "v31", "v33"}
    assert {sources.views[i].name for i in order[-4:]} == {"v00", "v04", "v40", "v44"}


def test_view_facing_away_is_last():
    scene = _grid_scene(n=3)
    # Turn one source around: it sees none of the target's points.
    v = scene.views[0]
    Rflip = np.diag([-1.0, 1.0, -1.0])
    scene.views[0] = v.replace(camera=Camera.from_centre(v.camera.K, Rflip, v.camera.centre, 32, 32))
    sources, target = scene.split("v11")
    order, pen, overlap = rank_views(sources, target.camera)
    assert overlap[0] == 0 and order[-1] == 0
    assert 0 not in select_views(sources, target.camera, 7)


def test_select_all_when_k_large():
    scene = _grid_scene(n=3)
    sources, target = scene.split(4)
    assert select_views(sources, target.camera, 100) == list(range(8))
    assert len(select_views(sources, target.camera, 3)) == 3


def test_no_geometry_falls_back_to_plane():
    scene = _grid_scene(n=3)
    scene = Scene([v.replace(depth=None) for v in scene.views], grid=(3, 3))
    sources, target = scene.split("v11")
    order, pen, overlap = rank_views(sources, target.camera)
    assert np.all(overlap > 0)
    assert {sources.views[i].name for i in order[:4]} == {"v01", "v10", "v12", "v21"}


def _ring(n=12, radius=3.0, centre=(0.1, 0.2, -0.1), size=32):
    K = Camera.intrinsics(40.0, size, size)
    views = []
    for k, t in enumerate(np.linspace(0, 2 * np.pi, n, endpoint=False)):
        eye = np.array(centre) + radius * np.array([np.cos(t), 0.0, np.sin(t)])
        cam = Camera.look_at(eye, centre, [0, -1, 0], K, size, size)
        views.append(View(f"r{k:02d}", np.zeros((size, size, 3), np.float32), cam))
    return Scene(views)


def test_axes_meeting_point_closed_form():
    from vibr.camera import axes_meeting_point

    ring = _ring()
    np.testing.assert_allclose(axes_meeting_point([v.camera for v in ring.views]), [0.1, 0.2, -0.1], atol=1e-9)
    # parallel axes (a light-field grid) do not meet
    assert axes_meeting_point([v.camera for v in _grid_scene(n=3).views]) is None


def test_ring_without_geometry_picks_ring_neighbours():
    """No depth, no points: the fallback plane goes through the object the ring looks at,
    so the best views are the target's neighbours on the ring, not the far side."""
    ring = _ring()
    sources, target = ring.split("r00")
    chosen = {sources.views[i].name for i in select_views(sources, target.camera, 4)}
    assert chosen == {"r01", "r02", "r11", "r10"}


def test_prepare_keeps_the_n_best_views():
    """prepare(n_views=K) keeps the K best sources for the target (rank_views order); the
    target stays out; n_views ≥ the number of sources keeps them all."""
    from vibr.pipeline import prepare

    scene = _grid_scene()
    src, tview = prepare(scene, "v22", depth="gt", n_views=4)
    assert tview.name == "v22"
    assert set(src.names) == {"v12", "v21", "v23", "v32"}
    src8, _ = prepare(scene, "v22", depth="gt", n_views=8)
    assert set(src8.names) == {"v12", "v21", "v23", "v32", "v11", "v13", "v31", "v33"}
    assert len(prepare(scene, "v22", depth="gt", n_views=100)[0]) == 24
    assert len(prepare(scene, "v22", depth="gt")[0]) == 24


def test_prepare_estimates_depth_for_the_best_views_only(monkeypatch):
    """With depth to estimate and no sources or n_views given, a target of a large scene is
    rendered from its ESTIMATED_SOURCES best views (one estimate per source: a 9×9 light
    field's 80 took 10 minutes), announced once with the way back ("all"); "all", a count,
    a list of sources or known depth keep what they ask, without the line."""
    import vibr.stereo.cache
    from _checks import messages_logged
    from vibr.errors import VibrInputError
    from vibr.geometry.selection import select_views
    from vibr.pipeline import ALL_VIEWS, ESTIMATED_SOURCES, prepare

    estimated = []
    monkeypatch.setattr(vibr.stereo.cache, "estimate_depth", lambda src, **kw: estimated.append(len(src)) or src)
    scene = _grid_scene()
    assert len(scene) - 1 > ESTIMATED_SOURCES
    rest, tv = scene.split("v22")
    best = [rest.names[i] for i in select_views(rest, tv.camera, ESTIMATED_SOURCES)]
    with messages_logged("vibr.pipeline", logging.INFO) as seen:
        src, _ = prepare(scene, "v22", depth="estimated", fallback="never")
        assert src.names == best and estimated == [ESTIMATED_SOURCES]
        assert len(seen) == 1 and f"the {ESTIMATED_SOURCES} best of the scene's 25 views" in seen[0]
        assert "--views all" in seen[0]
        assert len(prepare(scene, "v22", depth="estimated", n_views=ALL_VIEWS, fallback="never")[0]) == 24
        assert len(prepare(scene, "v22", depth="estimated", n_views=8, fallback="never")[0]) == 8
        listed = [n for n in scene.names if n != "v22"]
        assert len(prepare(scene, "v22", depth="estimated", sources=listed, fallback="never")[0]) == 24
        assert len(prepare(scene, "v22", depth="gt", fallback="never")[0]) == 24
    assert len(seen) == 1 and estimated == [ESTIMATED_SOURCES, 24, 8, 24]
    small = _grid_scene(n=3)  # fewer views than the default: all of them, nothing said
    with messages_logged("vibr.pipeline", logging.INFO) as seen:
        assert len(prepare(small, "v11", depth="estimated", fallback="never")[0]) == 8
    assert seen == []
    for bad in (0, -1, 2.5, "some", True):
        with pytest.raises(VibrInputError, match="n_views must be a positive integer or 'all'"):
            prepare(scene, "v22", depth="gt", n_views=bad)


def test_planar_proxy_renders_from_the_best_views():
    """With the planar proxy and no sources or n_views given, a target is rendered from its
    PLANAR_SOURCES best views (the plane misplaces the farther ones), announced once with the
    way back; "all", a count or a list of sources keep what they ask."""
    from _checks import messages_logged
    from vibr.pipeline import ALL_VIEWS, PLANAR_SOURCES, prepare

    scene = _grid_scene()
    with messages_logged("vibr.pipeline", logging.INFO) as seen:
        src, _ = prepare(scene, "v22", depth="planar")
    assert set(src.names) == {"v12", "v21", "v23", "v32"} and PLANAR_SOURCES == 4
    assert len(seen) == 1 and "the 4 best of the scene's 25 views" in seen[0] and "--views all" in seen[0]
    assert len(prepare(scene, "v22", depth="planar", n_views=ALL_VIEWS)[0]) == 24
    assert len(prepare(scene, "v22", depth="planar", n_views=8)[0]) == 8
    assert len(prepare(scene, "v22", depth="planar", sources=["v00", "v01", "v02", "v03", "v04"])[0]) == 5


def test_cli_views_option_selects_the_sources(tmp_path, monkeypatch, capsys):
    """vibr render --views K renders from the K best views: the sources prepare() hands to
    the renderer are those of prepare(n_views=K)."""
    import vibr.pipeline as pipeline
    from vibr.cli import main
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    sc = make_scene("grid", n_views=9, width=32, height=32, seed=5)
    save_scene(sc, tmp_path / "s")
    seen = []
    real = pipeline.prepare

    def spy(*a, **kw):
        out = real(*a, **kw)
        seen.append((kw.get("n_views"), list(out[0].names)))
        return out

    monkeypatch.setattr(pipeline, "prepare", spy)
    assert main(["render", str(tmp_path / "s"), "--target", "view_004", "-o", str(tmp_path / "o.png"),
                 "--views", "4", "--method", "ulr", "-q"]) == 0
    assert seen and seen[-1][0] == 4
    assert sorted(seen[-1][1]) == ["view_001", "view_003", "view_005", "view_007"]
    assert main(["render", str(tmp_path / "s"), "--target", "view_004", "-o", str(tmp_path / "o.png"),
                 "--views", "all", "--method", "ulr", "-q"]) == 0
    assert seen[-1][0] == "all" and len(seen[-1][1]) == 8
    for bad in ("0", "-2", "some", "2.5"):
        with pytest.raises(SystemExit) as e:
            main(["render", str(tmp_path / "s"), "--target", "view_004", "-o", str(tmp_path / "x.png"),
                  "--views", bad, "-q"])
        err = capsys.readouterr().err.strip()
        assert e.value.code == 2 and "\n" not in err and "expected a positive integer or 'all'" in err, err
    assert not (tmp_path / "x.png").exists()
