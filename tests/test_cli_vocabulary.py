"""One meaning per flag across subcommands: --scale, --overwrite, --bit-depth, the metric
rule, ``vibr info`` from image headers; global options before or after the subcommand; SCENE
in every usage; a count and a list of views never under one option name."""

import argparse
import json

import pytest

from vibr.cli import build_parser, main
from vibr.cli._options import names, view_count
from vibr.cli.reference import subcommands


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
                 "--targets", "view_004"]) == 0  # a light-field grid: no consistency check to skip
    sc = load_scene(out)
    assert sc["view_004"].camera.shape == (24, 24) and sc["view_004"].depth.shape == (24, 24)


def _outside_scene(root):
    """A transforms.json scene whose one image lies out of its folder (refused by default)."""
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    scene = save_scene(make_scene("grid", n_views=4, width=16, height=16, seed=1), root / "s")
    (scene / "images" / "view_000.png").rename(root / "view_000.png")
    doc = json.loads((scene / "transforms.json").read_text())
    doc["frames"][0]["file_path"] = "../view_000.png"
    (scene / "transforms.json").write_text(json.dumps(doc))
    return scene


def test_global_options_after_the_subcommand(tmp_path, capsys):
    scene = _outside_scene(tmp_path)
    assert main(["-q", "info", str(scene)]) == 2
    assert main(["info", str(scene), "-q", "--allow-outside-paths"]) == 0  # after it
    assert main(["--allow-outside-paths", "info", str(scene), "-q"]) == 0  # before it
    parser = build_parser()
    top = [a for a in parser._actions if a.option_strings and a.dest != "help"]
    assert {"-q", "-v", "--allow-outside-paths", "--version"} <= {s for a in top for s in a.option_strings}
    for name, sub in subcommands(parser).items():
        for action in top:
            assert set(action.option_strings) <= set(sub._option_string_actions), (name, action.option_strings)
    # given on either side, or not at all: the value reaches the command
    assert parser.parse_args(["-v", "path", "orbit", "S", "-o", "p.json"]).verbose is True
    assert parser.parse_args(["path", "orbit", "S", "-o", "p.json", "-v"]).verbose is True
    assert parser.parse_args(["path", "orbit", "S", "-o", "p.json"]).verbose is False


def _all_subcommands(parser):
    """Every subcommand's parser, nested ones (``vibr path KIND``) included."""
    out = {}
    for name, sub in subcommands(parser).items():
        out[name] = sub
        out.update({f"{name} {k}": s for k, s in _all_subcommands(sub).items()})
    return out


def test_scene_is_spelt_scene_in_every_usage():
    seen = 0
    for name, sub in _all_subcommands(build_parser()).items():
        scenes = [a for a in sub._actions if not a.option_strings and a.dest == "scene"]
        words = sub.format_usage().split()
        assert "scene" not in words, name
        if scenes:
            seen += 1
            assert scenes[0].metavar == "SCENE" and "SCENE" in words, name
    assert seen >= 7  # every command but demo and calibrate reads a scene


def _kind(action) -> str | None:
    """"list" for a comma-separated list, "count" for a number of things, else None."""
    if action.type is names:
        return "list"
    if action.type in (int, view_count):
        return "count"
    return None


def test_no_option_is_a_count_in_one_subcommand_and_a_list_in_another():
    kinds: dict[str, dict[str, str]] = {}
    for name, sub in _all_subcommands(build_parser()).items():
        for action in sub._actions:
            if action.help is argparse.SUPPRESS or _kind(action) is None:  # a deprecated alias is hidden
                continue
            for flag in action.option_strings:
                kinds.setdefault(flag, {})[name] = _kind(action)
    mixed = {flag: by for flag, by in kinds.items() if len(set(by.values())) > 1}
    assert not mixed, mixed
    assert set(kinds["--views"].values()) == {"count"} and len(kinds["--views"]) == 3  # render, eval, view
    assert {kinds[f][c] for f, c in (("--sources", "render"), ("--through", "path interpolate"), ("--targets", "depth"),
                                     ("--only", "info"), ("--only", "convert"), ("--exclude", "depth"))} == {"list"}


@pytest.mark.parametrize("argv,new", [
    (["info", "{scene}", "--views", "0,view_004"], "--only"),
    (["convert", "{scene}", "{tmp}/c", "--views", "0,view_004"], "--only"),
    (["path", "interpolate", "{scene}", "-o", "{tmp}/p.json", "--frames", "4", "--views", "view_000,view_004"],
     "--through"),
])
def test_old_list_spelling_still_works_with_a_warning(grid48_dir, tmp_path, capsys, argv, new):
    args = [a.format(scene=grid48_dir, tmp=tmp_path) for a in argv]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert f"--views is deprecated and will be removed: use {new}" in err
    assert main([*args[:-2], new, args[-1], "--overwrite"] if argv[0] == "convert"
                else [*args[:-2], new, args[-1]]) == 0
    assert "deprecated" not in capsys.readouterr().err
    sub = subcommands(build_parser())[argv[0]]
    assert "--views" not in sub.format_help() and new in sub.format_help()  # hidden from --help


def test_old_list_spelling_sets_the_new_option():
    parser = build_parser()
    assert parser.parse_args(["depth", "S", "--views", "a,b"]).targets == ["a", "b"]
    assert parser.parse_args(["info", "S", "--views", "a"]).only == ["a"]
    assert parser.parse_args(["path", "interpolate", "S", "-o", "p.json", "--views", "a,b"]).views == ["a", "b"]  # --through fills the path function's views
    assert parser.parse_args(["render", "S", "-o", "o.png", "--views", "3"]).views == 3
