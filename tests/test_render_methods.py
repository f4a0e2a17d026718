"""The method registry, the one prepare step, Scene.replace and the CLI built from them."""

import argparse

import numpy as np
import pytest

from vibr.errors import VibrInputError
from vibr.render.methods import DEFAULTS, METHODS, PSFS, REGISTRY, Method, get_method, method_params


def test_registry_declares_each_method():
    assert METHODS == tuple(REGISTRY) == ("ulr", "savsr", "bvs", "gradient")
    ulr, savsr, bvs, grad = (REGISTRY[m] for m in METHODS)
    assert not ulr.solve and savsr.solve and bvs.solve and grad.solve
    assert grad.gradient and not (ulr.gradient or savsr.gradient or bvs.gradient)
    assert bvs.reweight and grad.reweight and not savsr.reweight
    assert not savsr.geometric and bvs.geometric
    assert get_method("bvs") is bvs and get_method(bvs) is bvs
    from vibr.render.operators import PSFS as splat_psfs

    assert PSFS is splat_psfs


def test_method_params_fills_and_checks():
    p = method_params("gradient", gamma=2.0, lam=None)
    assert p["gamma"] == 2.0 and p["lam"] == DEFAULTS["lam"]
    assert method_params("bvs", gamma=3.0)["gamma"] == 0.0  # no gradient term
    assert method_params("savsr")["n_outer"] == 1 and method_params("ulr")["n_outer"] == 0
    with pytest.raises(TypeError, match="lamda"):
        method_params("gradient", lamda=0.1)
    with pytest.raises(VibrInputError, match="unknown method"):
        method_params("nope")
    with pytest.raises(VibrInputError, match="psf"):
        method_params("gradient", psf="gauss")


def _subparser(name):
    from vibr.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[name]


@pytest.mark.parametrize("cmd", ["render", "demo"])
def test_cli_method_choices_from_registry(cmd):
    opt = {o: a for a in _subparser(cmd)._actions for o in a.option_strings}
    assert tuple(opt["--method"].choices) == METHODS
    assert opt["--method"].default == "gradient"


def test_cli_help_defaults_from_defaults():
    opt = {o: a for a in _subparser("render")._actions for o in a.option_strings}
    assert f"default {DEFAULTS['lam']:g}" in opt["--lam"].help
    assert f"default {DEFAULTS['n_outer']}" in opt["--outer"].help
    assert tuple(opt["--psf"].choices) == PSFS
    ev = {o: a for a in _subparser("eval")._actions for o in a.option_strings}
    assert ev["--method"].default == list(METHODS)
    assert ev["--depth"].default == opt["--depth"].default == "auto"


@pytest.mark.parametrize("flags, expected", [([], None), (["--precond"], True), (["--no-precond"], False)])
def test_cli_precond_both_ways(flags, expected):
    """The preconditioner is on by default: the CLI can turn it off as well as on."""
    from vibr.cli._options import render_params

    args = _subparser("render").parse_args(["scene", "-o", "x.png", *flags])
    assert render_params(args)["precond"] is expected
    assert method_params("gradient", **{k: v for k, v in render_params(args).items() if v is not None})[
        "precond"] is (DEFAULTS["precond"] if expected is None else expected)


def test_scene_replace_copies_meta():
    from vibr.synthetic import make_scene

    sc = make_scene("grid", n_views=4, width=24, height=24, seed=0)
    sc2 = sc.replace(views=sc.views[:2])
    assert len(sc2) == 2 and sc2.name == sc.name and sc2.grid == sc.grid
    sc2.meta["x"] = 1
    assert "x" not in sc.meta


def test_prepare_is_the_one_depth_vocabulary():
    from vibr.pipeline import DEPTH_MODES, DepthUnavailable, prepare
    from vibr.synthetic import make_scene

    assert DEPTH_MODES == ("auto", "gt", "estimated", "planar", "files")
    sc = make_scene("grid", n_views=4, width=24, height=24, seed=0)
    src, tgt = prepare(sc, 1)  # default auto: the scene's depth
    assert tgt.name == sc.views[1].name and tgt.name not in src.names and src.has_depth
    with pytest.raises(VibrInputError, match="unknown depth mode"):
        prepare(sc, 1, depth="given")
    bare = sc.replace(views=[v.replace(depth=None) for v in sc.views])
    with pytest.raises(DepthUnavailable) as e:
        prepare(bare, 1, depth="gt")
    assert "--" not in str(e.value)  # library messages name no CLI flag


def test_n_views_picks_the_best_of_the_listed_sources():
    """``n_views`` with ``sources``: the K best of that list (a list used to turn it off)."""
    from vibr.geometry.selection import select_views
    from vibr.pipeline import prepare
    from vibr.synthetic import make_scene

    sc = make_scene("grid", n_views=9, width=24, height=24, seed=0)
    listed = [0, 1, 2, 3, 5]
    src, tgt = prepare(sc, 4, sources=listed, n_views=2)
    pool = sc.subset(listed)
    assert src.names == [pool.names[i] for i in select_views(pool, tgt.camera, 2)]
    assert len(src) == 2 and set(src.names) <= set(pool.names)


def test_render_holds_out_a_target_among_its_sources():
    """render() prepares sources that are not ready (target among them): the result equals
    rendering from the prepared sources."""
    from vibr.pipeline import prepare
    from vibr.render import render
    from vibr.synthetic import make_scene

    sc = make_scene("grid", n_views=9, width=48, height=48, seed=1)
    a = render(sc, sc.views[4], "bvs", n_outer=1, max_iter=5)
    src, tgt = prepare(sc, 4)
    b = render(src, tgt, "bvs", n_outer=1, max_iter=5)
    np.testing.assert_array_equal(a.image, b.image)
    assert a.metrics["psnr"] == b.metrics["psnr"]


def test_a_registered_method_renders():
    """Adding a method is one registration: a bvs variant without re-weighting."""
    from vibr.render import methods, render
    from vibr.synthetic import make_scene

    m = Method("bvs1", "bvs without re-weighting", reweight=False, overrides=dict(gamma=0.0, n_outer=1))
    methods.register_method(m)
    try:
        sc = make_scene("grid", n_views=9, width=48, height=48, seed=1)
        r = render(sc, sc.views[4], "bvs1", max_iter=5)
        assert r.method == "bvs1" and r.metrics["psnr"] > 30
    finally:
        del methods.REGISTRY["bvs1"]
        methods.METHODS = tuple(methods.REGISTRY)


#: a value other than the default for each render parameter
_OTHER = {"alpha": 2.0, "gamma": 0.7, "lam": 2.5, "sigma_s": 3.0, "sigma_z": 0.05, "n_outer": 3,
          "max_iter": 4, "precond": True, "psf": "footprint", "grad_consistency": 4.0,
          "grad_coverage": 20.0,  # above the 8 views' coverage: every gradient sample weighs less
          "z_corr": 0.5}


@pytest.mark.parametrize("name", METHODS)
def test_ignored_params_are_really_ignored(name):
    """What ``Method.ignored_params`` lists changes nothing in the image (the CLI refuses
    them on that ground), and every parameter it does not list changes the image."""
    from vibr.geometry import compute_samples
    from vibr.render import render
    from vibr.synthetic import make_scene

    sc = make_scene("grid", n_views=9, width=40, height=40, seed=3)
    src = sc.subset([0, 1, 2, 3, 5, 6, 7, 8])
    smp = compute_samples(src, sc.views[4].camera, keep=("jac",))  # the footprint PSF's too
    base = render(src, sc.views[4], name, samples=smp).image
    ignored = get_method(name).ignored_params()
    assert set(ignored) <= set(_OTHER)
    for k, v in _OTHER.items():
        if k == "precond":  # its default differs between the methods
            v = not method_params(name)["precond"]
        img = render(src, sc.views[4], name, samples=smp, **{k: v}).image
        same = np.array_equal(img, base)
        assert same == (k in ignored), f"{name}: {k}={v} {'changed' if not same else 'did not change'} the image"


@pytest.mark.parametrize("cmd,extra,msg", [
    ("render", ["--method", "ulr", "--gamma", "0.5"], "--gamma does not apply to --method ulr"),
    ("render", ["--method", "ulr", "--lam", "2", "--precond"], "--lam, --precond do not apply to --method ulr"),
    ("render", ["--method", "bvs", "--gamma", "1"], "--gamma does not apply to --method bvs"),
    ("render", ["--method", "bvs", "--grad-consistency", "4"], "--grad-consistency does not apply to --method bvs"),
    ("render", ["--method", "savsr", "--sigma-z", "0.01"], "--sigma-z does not apply to --method savsr"),
    ("render", ["--method", "savsr", "--z-corr", "0.5"], "--z-corr does not apply to --method savsr"),
    ("eval", ["--method", "ulr,bvs", "--gamma", "0.5"], "--gamma does not apply to --method ulr,bvs (only to gradient)"),
    ("eval", ["--method", "ulr", "--lam", "1"], "--lam does not apply to --method ulr (only to savsr, bvs, gradient)"),
    ("eval", ["--method", "ulr", "--psf", "footprint"], "--psf does not apply to --method ulr (only to savsr, bvs, gradient)"),
])
def test_cli_refuses_a_parameter_the_methods_ignore(tmp_path, capsys, cmd, extra, msg):
    """``vibr render`` (one method) and ``vibr eval`` (a grid: no method of the list reads it)."""
    from vibr.cli import main
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    save_scene(make_scene("grid", n_views=4, width=24, height=24, seed=1), tmp_path / "s")
    out = tmp_path / ("v.png" if cmd == "render" else "e.json")
    capsys.readouterr()
    argv = [cmd, str(tmp_path / "s"), "--target", "view_000", "-o" if cmd == "render" else "--json", str(out)]
    assert main([*argv, "-q", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err
    assert not out.exists()


@pytest.mark.parametrize("method", ["gradient", "ulr"])
def test_render_stops_between_its_stages(method):
    """``stop`` is polled between the geometry's stages (z-buffer, visibility, fields) and,
    for a solved method, between the solve's stages before its first FISTA iteration and
    after each iteration; True raises RenderStopped at once (a stale viewer render stops in
    a fraction of a render)."""
    from vibr.render import RenderStopped, render
    from vibr.synthetic import make_scene

    scene = make_scene("grid", n_views=5, width=48, height=40, seed=1)
    src, cam = scene.subset([0, 1, 3, 4]), scene.views[2].camera
    its, polls = [], []
    res = render(src, cam, method, callback=lambda *a: its.append(1), stop=lambda: polls.append(len(its)) or False)
    assert res.image.shape == (40, 48, 3)
    if method == "ulr":
        assert polls == [0, 0, 0]  # z-buffer, visibility, fields; the blend is one stage
    else:  # and the view prior, the coverage, the first weights
        assert polls.count(0) >= 6 and len(its) > 0
        assert polls[polls.count(0):] == sorted(polls[polls.count(0):]) and len(polls) >= polls.count(0) + len(its)
    for n in range(1, polls.count(0) + 1):  # told to stop at the n-th poll: no iteration ran
        its.clear()
        calls = []
        with pytest.raises(RenderStopped):
            render(src, cam, method, callback=lambda *a: its.append(1),
                   stop=lambda: calls.append(1) or len(calls) >= n)
        assert its == [] and len(calls) == n
