"""``vibr render`` end to end on a small synthetic scene."""

import pytest


@pytest.fixture(scope="module")
def grid64_dir(tmp_path_factory):
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    d = tmp_path_factory.mktemp("scene")
    save_scene(make_scene("grid", n_views=9, width=64, height=64, seed=1), d / "s")
    return d / "s"


def test_render_held_out_view(grid64_dir, tmp_path, capsys):
    from vibr.cli import main
    from vibr.io import read_image

    out = tmp_path / "v4.png"
    assert main(["render", str(grid64_dir), "--target", "view_004", "-o", str(out), "--method", "bvs", "-q"]) == 0
    txt = capsys.readouterr().out
    assert "PSNR" in txt and "DSSIM" in txt
    psnr = float(txt.split("PSNR")[1].split()[0])
    dssim = float(txt.split("DSSIM")[1].split()[0])
    assert psnr > 36.0 and dssim < 150, txt  # measured 37.43 dB, DSSIM 109.0
    img = read_image(out)
    assert img.shape == (64, 64, 3)


def test_render_camera_file_and_errors(grid64_dir, tmp_path, capsys):
    from vibr.cli import main
    from vibr.io import load_scene, read_image, write_camera_json

    sc = load_scene(grid64_dir)
    cam = tmp_path / "cam.json"
    write_camera_json(cam, sc["view_004"].camera)
    out = tmp_path / "novel.png"
    assert main(["render", str(grid64_dir), "--target", str(cam), "-o", str(out), "--method", "ulr",
                 "--sources", "view_000,view_002,view_006,view_008", "-q"]) == 0
    assert read_image(out).shape == (64, 64, 3)
    assert "PSNR" not in capsys.readouterr().out
    # bad input: one line on stderr, exit status 2, no output written
    bad = tmp_path / "bad.png"
    assert main(["render", str(grid64_dir), "--target", "nope", "-o", str(bad), "-q"]) == 2
    err = capsys.readouterr().err
    assert "nope" in err and len(err.strip().splitlines()) == 1
    assert not bad.exists()


@pytest.mark.slow
def test_scene_without_any_geometry_renders_by_default(tmp_path, capsys):
    """No depth maps, no sparse points: the default --depth auto estimates depth from the
    sources (the target held out) and renders; --depth gt says what is missing."""
    from vibr.cli import main
    from vibr.io import save_scene
    from vibr.scene import Scene
    from vibr.synthetic import make_scene

    sc = make_scene("grid", n_views=9, width=96, height=96, seed=2)
    bare = Scene([v.replace(depth=None, sigma_z=None) for v in sc.views], name="bare")
    save_scene(bare, tmp_path / "bare")
    out = tmp_path / "v4.png"
    assert main(["render", str(tmp_path / "bare"), "--target", "view_004", "-o", str(out), "-q"]) == 0
    psnr = float(capsys.readouterr().out.split("PSNR")[1].split("dB")[0])
    assert psnr > 35.5 and out.is_file()  # measured 37.16 dB (DSSIM 205) with estimated depth
    assert main(["render", str(tmp_path / "bare"), "--target", "view_004", "-o", str(tmp_path / "x.png"),
                 "--depth", "gt", "-q"]) == 2
    assert "no depth" in capsys.readouterr().err and not (tmp_path / "x.png").exists()
