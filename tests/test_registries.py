"""The registries users extend vibr through: a method, a scene format, a camera-path kind and a
metric, each one file of examples/extend/ that registers it on import. Each test imports one,
checks that it works end to end (the library and the CLI), then unregisters it. The how-tos of
docs/how-to/extend/ show each example file and its test exactly as they are here."""

from __future__ import annotations

import inspect
import re
import sys
from pathlib import Path

import pytest

_REPO = Path(__file__).resolve().parents[1]
EXAMPLES = _REPO / "examples" / "extend"
HOW_TOS = _REPO / "docs" / "how-to" / "extend"


@pytest.fixture(autouse=True)
def examples_importable(monkeypatch):
    """examples/extend/ on the path; an example imported by a test is forgotten after it, so
    that importing it again registers it again."""
    monkeypatch.syspath_prepend(str(EXAMPLES))
    before = set(sys.modules)
    yield
    for name in set(sys.modules) - before:
        if name in {p.stem for p in EXAMPLES.glob("*.py")}:
            del sys.modules[name]


def test_ulr2_method(tmp_path, capsys):
    import numpy as np
    import ulr2_method  # noqa: F401  (registers "ulr2")

    from vibr.cli import main
    from vibr.io import load_scene, save_scene
    from vibr.render import render
    from vibr.render.methods import REGISTRY, unregister_method
    from vibr.synthetic import make_scene

    try:
        scene = load_scene(save_scene(make_scene("grid", n_views=9, width=48, height=48, seed=2), tmp_path / "s"))
        target = scene.views[4]
        sources = scene.replace(views=[v for v in scene.views if v is not target])
        two = render(sources, target, "ulr2")
        assert two.method == "ulr2"
        assert np.array_equal(two.image, render(sources, target, "ulr", ulr_k=2).image)
        assert not np.array_equal(two.image, render(sources, target, "ulr").image)
        with pytest.raises(SystemExit):
            main(["render", "--help"])
        assert "ulr2: ULR blending the 2 best views per pixel" in " ".join(capsys.readouterr().out.split())
    finally:
        unregister_method("ulr2")
    assert "ulr2" not in REGISTRY


def test_marker_format(tmp_path, capsys):
    import marker_format  # noqa: F401  (registers "marker")
    import numpy as np

    from vibr.cli import main
    from vibr.errors import VibrInputError
    from vibr.io import FORMATS, detect_format, load_scene, save_scene, unregister_format
    from vibr.synthetic import make_scene

    folder = tmp_path / "marked"
    save_scene(make_scene("grid", n_views=9, width=48, height=48, seed=2), folder / "inner")
    (folder / "scene.marker").write_text("inner\n")
    try:
        assert detect_format(folder) == "marker"
        scene = load_scene(folder, views=["view_000", "view_004"])
        assert scene.meta["format"] == "marker" and scene.names == ["view_000", "view_004"]
        assert np.array_equal(scene.views[1].image, load_scene(folder / "inner").views[4].image)
        assert main(["info", str(folder)]) == 0
        assert "format   marker" in capsys.readouterr().out
        with pytest.raises(SystemExit):
            main(["info", "--help"])
        assert "folder with scene.marker" in " ".join(capsys.readouterr().out.split())
        (tmp_path / "empty").mkdir()
        with pytest.raises(VibrInputError, match="or a scene.marker file"):
            detect_format(tmp_path / "empty")
        (folder / "scene.marker").write_text("../elsewhere\n")
        with pytest.raises(VibrInputError, match="must name a folder inside the scene"):
            load_scene(folder)
    finally:
        unregister_format("marker")
    assert "marker" not in FORMATS
    with pytest.raises(VibrInputError, match="no supported scene found"):
        detect_format(folder)


def test_dolly_path(tmp_path, capsys):
    import dolly_path  # noqa: F401  (registers "dolly")
    import numpy as np

    from vibr.cli import main
    from vibr.io import load_scene, save_scene
    from vibr.paths import read_camera_path
    from vibr.paths.kinds import PATH_KINDS, unregister_path_kind
    from vibr.synthetic import make_scene

    scene_dir = save_scene(make_scene("grid", n_views=9, width=48, height=48, seed=2), tmp_path / "s")
    out = tmp_path / "dolly.json"
    try:
        with pytest.raises(SystemExit):
            main(["path", "--help"])
        assert "dolly a straight line from one view's camera to another's" in " ".join(capsys.readouterr().out.split())
        assert main(["path", "dolly", str(scene_dir), "-o", str(out), "--frames", "5",
                     "--start", "view_000", "--end", "view_008"]) == 0
        scene, path = load_scene(scene_dir), read_camera_path(out)
        C = np.array([c.centre for c in path.cameras])
        assert len(path) == 5 and path.meta["kind"] == "dolly"
        assert np.allclose(C[0], scene.views[0].camera.centre) and np.allclose(C[-1], scene.views[8].camera.centre)
        assert np.allclose(np.diff(C, axis=0), (C[-1] - C[0]) / 4)  # evenly spaced on the line
        assert np.allclose(path.cameras[2].R, scene.views[0].camera.R)  # looking as the first view
        assert main(["path", "orbit", str(scene_dir), "-o", str(out), "--start", "view_000"]) == 2
        assert "--start applies to 'vibr path dolly' only" in capsys.readouterr().err
    finally:
        unregister_path_kind("dolly")
    assert "dolly" not in PATH_KINDS
    with pytest.raises(SystemExit):
        main(["path", "dolly", str(scene_dir), "-o", str(out)])


def test_mae_metric(tmp_path, capsys):
    import json

    import mae_metric  # noqa: F401  (registers "mae")
    import numpy as np

    from vibr.cli import main
    from vibr.eval.leave_one_out import summarise
    from vibr.io import save_scene
    from vibr.metrics import METRICS, unregister_metric, view_metrics
    from vibr.synthetic import make_scene

    rng = np.random.default_rng(0)
    img, ref, mask = rng.random((32, 32, 3)), rng.random((32, 32, 3)), rng.random((32, 32)) > 0.3
    scene_dir = save_scene(make_scene("grid", n_views=9, width=48, height=48, seed=2), tmp_path / "s")
    try:
        values = view_metrics(img, ref, mask, border=2)
        assert list(values) == ["psnr", "psnr_all", "ssim", "dssim", "sharpness", "mae"]
        assert values["mae"] == pytest.approx(np.abs(img - ref)[2:-2, 2:-2][mask[2:-2, 2:-2]].mean())
        report = tmp_path / "eval.json"
        assert main(["-q", "eval", str(scene_dir), "--target", "view_004", "--method", "ulr",
                     "--json", str(report)]) == 0
        table = capsys.readouterr().out.splitlines()
        (result,) = json.loads(report.read_text())["results"]
        assert "MAE" in table[1] and f"{result['mae']:.4f}" in table[2]
        assert 0 < result["mae"] < 0.1
        assert summarise([json.loads(report.read_text())])["ulr"]["mae"]["mean"] == result["mae"]
    finally:
        unregister_metric("mae")
    assert "mae" not in METRICS and "mae" not in view_metrics(img, ref)


@pytest.mark.parametrize("how_to,example,test", [
    ("add-a-method.md", "ulr2_method.py", test_ulr2_method),
    ("add-a-format.md", "marker_format.py", test_marker_format),
    ("add-a-path-kind.md", "dolly_path.py", test_dolly_path),
    ("add-a-metric.md", "mae_metric.py", test_mae_metric),
])
def test_each_how_to_shows_its_example_and_its_test(how_to, example, test):
    blocks = re.findall(r"```python\n(.*?)```", (HOW_TOS / how_to).read_text(encoding="utf-8"), re.S)
    assert len(blocks) == 2, f"{how_to}: the example file and its test"
    assert blocks[0] == (EXAMPLES / example).read_text(encoding="utf-8"), f"{how_to} does not show {example} as it is"
    assert blocks[1] == inspect.getsource(test), f"{how_to} does not show {test.__name__} as it is"


def test_the_built_in_entries_are_registered_in_order():
    from vibr.io import FORMATS
    from vibr.metrics import METRICS
    from vibr.paths.kinds import PATH_KINDS
    from vibr.render.methods import REGISTRY

    assert list(REGISTRY) == ["ulr", "savsr", "bvs", "gradient"]
    assert list(FORMATS) == ["transforms", "hci", "colmap", "middlebury", "strecha"]  # the detection order
    assert list(PATH_KINDS) == ["interpolate", "orbit", "spiral"]
    assert list(METRICS) == ["psnr", "psnr_all", "ssim", "dssim", "sharpness"]
