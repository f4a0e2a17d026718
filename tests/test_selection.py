import numpy as np

from vibr import Camera, Scene, View
from vibr.selection import rank_views, select_views


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


def test_prepare_warns_before_estimating_depth_for_many_sources(monkeypatch):
    """Depth estimated for every source of a large scene (the default sources) takes one
    estimate per view: prepare says so, with the way out, and says nothing when n_views or
    the sources are given."""
    from _checks import messages_logged

    import vibr.stereo
    from vibr.pipeline import MANY_SOURCES, prepare

    monkeypatch.setattr(vibr.stereo, "estimate_depth", lambda src, **kw: src)
    scene = _grid_scene()
    assert len(scene) - 1 > MANY_SOURCES
    with messages_logged("vibr.pipeline") as seen:
        prepare(scene, "v22", depth="estimated", fallback="never")
        assert len(seen) == 1 and "all 24 source views" in seen[0] and "--views K" in seen[0]
        prepare(scene, "v22", depth="estimated", n_views=8, fallback="never")
        prepare(scene, "v22", depth="estimated", sources=[n for n in scene.names if n != "v22"], fallback="never")
    assert len(seen) == 1


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
