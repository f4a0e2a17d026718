"""Every subcommand with invalid numeric options, unwritable outputs and missing
inputs exits with status 2, one line on stderr, no traceback, and writes nothing."""

from __future__ import annotations

import pytest

from vibr.cli import main


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    d = tmp_path_factory.mktemp("sweep")
    return save_scene(make_scene("grid", n_views=4, width=24, height=24, seed=0), d / "s")


def _cases(s, o):
    """(argv, output path that must not appear) per case; ``o`` is a fresh folder."""
    r = ["render", s, "--target", "0", "-o", o / "r.png"]
    e = ["eval", s, "--target", "0", "--method", "ulr,gradient", "--json", o / "r.json"]
    d = ["depth", s, "-o", o / "d"]
    cases = [(r + [flag, v], o / "r.png") for flag, v in [
        ("--lam", "nan"), ("--alpha", "inf"), ("--iterations", "0"), ("--sigma-s", "0"), ("--gamma", "-1"),
        ("--intensity-scale", "0"), ("--outer", "-1"), ("--views", "0"), ("--scale", "inf"), ("--scale", "abc"),
        ("--target", "-1"), ("--sigma-z", "-2"), ("--scale", "0")]]
    cases += [(e + [flag, v], o / "r.json") for flag, v in [
        ("--lam", "nan"), ("--alpha", "inf"), ("--gamma", "-1"), ("--intensity-scale", "0"), ("--border", "-1"),
        ("--views", "0"), ("--step-px", "0"), ("--max-planes", "0"), ("--scale", "-1"), ("--target", "-1"),
        ("--lam", "1,x")]]
    cases += [(d + [flag, *v.split()], o / "d") for flag, v in [
        ("--step-px", "0"), ("--max-planes", "0"), ("--median-radius", "-1"), ("--depth-scale", "2"), ("--scale", "0"),
        ("--neighbours", "0"), ("--refine-iter", "-1"), ("--depth-range", "5 1"), ("--depth-range", "nan 1"),
        ("--sweep-scale", "0"), ("--targets", "-1")]]
    cases += [(["convert", s, o / "c", "--scale", v], o / "c") for v in ("0", "nan", "-1", "1e9")]
    cases += [(["info", s, "--scale", v], None) for v in ("0", "nan")]
    cases += [(["demo", "--size", v, "-o", o / "x.png"], o / "x.png") for v in ("0", "-3", "100000")]
    # options that do not apply: refused, not ignored
    cases += [(["demo", "--no-video", "--video", o / "x.mp4"], o / "x.mp4"),
              (["demo", "--no-video", "--bit-depth", "16"], None),
              (r + ["--depth-files", o], o / "r.png"),
              (e + ["--depth", "gt", "--depth-files", o], o / "r.json")]
    # missing inputs
    miss = o / "missing"
    cases += [(["render", miss, "--target", "0", "-o", o / "r.png"], o / "r.png"),
              (["eval", miss, "--target", "0", "--json", o / "r.json"], o / "r.json"),
              (["depth", miss, "-o", o / "d"], o / "d"), (["convert", miss, o / "c"], o / "c"),
              (["info", miss], None), (["calibrate", miss, o / "cal"], o / "cal"),
              (["render", s, "--target", miss / "cam.json", "-o", o / "r.png"], o / "r.png"),
              (["render", s, "--target", "0", "--depth", "files", "--depth-files", miss, "-o", o / "r.png"],
               o / "r.png")]
    # unwritable outputs (a read-only file system, a folder where a file goes)
    ro = "/proc/vibr_sweep"
    cases += [(["render", s, "--target", "0", "-o", f"{ro}/r.png"], None),
              (["eval", s, "--target", "0", "--json", f"{ro}/r.json"], None),
              (["eval", s, "--target", "0", "--json", o / "r.json", "--figures", f"{ro}/f"], o / "r.json"),
              (["depth", s, "-o", f"{ro}/d"], None), (["convert", s, f"{ro}/c"], None),
              (["calibrate", s, f"{ro}/cal"], None), (["demo", "-o", f"{ro}/x.png"], None),
              (["render", s, "--target", "0", "-o", o], None),
              (["path", "orbit", s, "-o", miss / "p.json"], miss),  # a folder that is not there
              (["render", s, "--target", "0", "-o", o / "r.png", "--cache-dir", s + "/transforms.json"],
               o / "r.png")]
    return cases


def test_cli_sweep(scene, tmp_path, capsys):
    import itertools

    failures = []
    for k, (argv, out) in enumerate(_cases(str(scene), tmp_path)):
        argv = [str(a) for a in argv]
        try:
            code = main(["-q"] + argv)
        except SystemExit as exc:  # argparse
            code = exc.code
        err = capsys.readouterr().err.strip()
        ok = (code == 2 and err.count("\n") == 0 and "Traceback" not in err and err.startswith("vibr")
              and (out is None or not out.exists()))
        if not ok:
            failures.append(f"{' '.join(argv)} -> {code}: {err[:300]}")
        leftovers = [p for p in tmp_path.iterdir() if p.name != "missing"]
        if leftovers:
            failures.append(f"{' '.join(argv)} left {leftovers}")
            for p in leftovers:
                p.unlink() if p.is_file() else __import__("shutil").rmtree(p)
    assert not failures, "\n".join(failures)
    del itertools


@pytest.mark.parametrize("extra,msg", [
    (["--neighbours", "2"], "--neighbours applies to the MVS estimate only"),
    (["--method", "lightfield", "--no-consistency", "--fill-segments"],
     "--no-consistency, --fill-segments apply to the MVS estimate only"),
])
def test_depth_refuses_the_plane_sweeps_options_for_a_light_field(cotton_dir, tmp_path, capsys, extra, msg):
    """The light-field estimate reads none of them: refused, not ignored (before, they were
    accepted and did nothing)."""
    out = tmp_path / "d"
    capsys.readouterr()
    assert main(["-q", "depth", str(cotton_dir), "--targets", "input_Cam040", "-o", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err and str(cotton_dir) in err
    assert not out.exists()


@pytest.mark.parametrize("extra,msg", [
    (["--step-px", "2"], "--step-px applies to estimated depth only, and this evaluation's depth is 'gt'"),
    (["--depth", "planar", "--depth-range", "1", "2"], "--depth-range applies to estimated depth only"),
    (["--depth", "estimated", "--max-planes", "50"], "--max-planes applies to the MVS estimate only"),
])
def test_eval_refuses_depth_estimation_options_that_do_not_apply(scene, tmp_path, capsys, extra, msg):
    """The synthetic grid has depth and a light-field grid: the estimate's options are
    refused where no depth is estimated, and the plane sweep's where a light field is."""
    out = tmp_path / "e.json"
    capsys.readouterr()
    assert main(["-q", "eval", str(scene), "--target", "0", "--json", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err
    assert not out.exists()
