"""One meaning per flag across subcommands: --scale, --overwrite, --bit-depth, the metric
rule, ``vibr info`` from image headers."""

import pytest

from vibr.cli import main


@pytest.fixture(scope="module")
def grid48_dir(tmp_path_factory):
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    return save_scene(make_scene("grid", n_views=9, width=48, height=48, seed=2), tmp_path_factory.mktemp("v") / "s")


def test_render_bit_depth_and_metric_rule(grid48_dir, tmp_path, capsys):
    from vibr.io.images import png_bit_depth

    out8, out16 = tmp_path / "a.png", tmp_path / "b.png"
    args = ["render", str(grid48_dir), "--target", "view_004", "--method", "ulr", "-q"]
    assert main(args + ["-o", str(out8)]) == 0
    txt = capsys.readouterr().out
    assert "2-px border excluded" in txt
    assert main(args + ["-o", str(out16), "--bit-depth", "16"]) == 0
    assert png_bit_depth(out8) == 8 and png_bit_depth(out16) == 16


def test_info_reads_headers_only(grid48_dir, capsys, monkeypatch):
    import vibr.io.images as images

    def no_decode(path):
        raise AssertionError(f"decoded {path}")

    monkeypatch.setattr(images, "read_image", no_decode)
    assert main(["info", str(grid48_dir), "--scale", "0.5"]) == 0
    out = capsys.readouterr().out
    assert "views    9" in out and "24x24" in out
    with images.headers_only():
        from vibr.io import load_scene

        sc = load_scene(grid48_dir)
    assert all(v.image is None for v in sc.views) and sc.views[0].camera.shape == (48, 48)


def test_overwrite_is_the_name_and_scale_loads(grid48_dir, tmp_path, capsys):
    from vibr.io import load_scene

    out = tmp_path / "c"
    assert main(["-q", "convert", str(grid48_dir), str(out), "--scale", "0.5"]) == 0
    assert main(["-q", "convert", str(grid48_dir), str(out)]) == 2
    err = capsys.readouterr().err
    assert "already exists" in err and "--overwrite" in err and len(err.strip().splitlines()) == 1
    assert main(["-q", "convert", str(grid48_dir), str(out), "--overwrite"]) == 0
    assert main(["-q", "convert", str(grid48_dir), str(out), "--force"]) == 0  # hidden alias
    assert load_scene(out).views[0].camera.shape == (48, 48)


def test_depth_scale_is_the_estimation_scale(grid48_dir, tmp_path):
    """``vibr depth --scale`` loads the scene at that scale (the output has that size);
    ``--depth-scale`` estimates at a fraction of it."""
    from vibr.io import load_scene

    out = tmp_path / "d"
    assert main(["-q", "depth", str(grid48_dir), "-o", str(out), "--scale", "0.5", "--depth-scale", "0.5",
                 "--views", "view_004"]) == 0  # a light-field grid: no consistency check to skip
    sc = load_scene(out)
    assert sc["view_004"].camera.shape == (24, 24) and sc["view_004"].depth.shape == (24, 24)
