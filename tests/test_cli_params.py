"""The method options come from RenderParams and are the same for every command that renders."""

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from vibr.cli import build_parser
from vibr.cli._options import PARAM_FLAGS, method_option_fields, render_params
from vibr.errors import VibrInputError
from vibr.render.params import AUTO, DEFAULTS, RenderParams, param_fields

ROOT = Path(__file__).resolve().parents[1]

#: The subcommands that render with a method, and the method options each must accept.
RENDERING = ("render", "eval", "view")


def _subparsers() -> dict:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _flags(p) -> set:
    return {o for a in p._actions for o in a.option_strings}


def test_every_rendering_command_takes_every_method_option():
    """A method option (a RenderParams field with a flag, --preset, --method) missing from one
    of the commands that render fails here, naming it."""
    subs = _subparsers()
    shared = set(PARAM_FLAGS.values()) | {"--preset", "--method", "--no-precond"}
    assert "--gamma" in shared and "--intensity-scale" in shared
    missing = {name: sorted(shared - _flags(subs[name])) for name in RENDERING}
    assert not any(missing.values()), f"method options missing: {missing}"
    # and every command that has one method option has them all (a new command included)
    partial = {name: sorted(shared - _flags(p)) for name, p in subs.items()
               if _flags(p) & (shared - {"--method"}) and shared - _flags(p)}
    assert not partial, f"commands with some method options but not all: {partial}"


def test_the_flags_are_built_from_the_fields():
    """Each flag's help gives the field's units, range and default."""
    opts = {o: a for a in _subparsers()["render"]._actions for o in a.option_strings}
    for f in method_option_fields():
        h = opts[f.metadata["flag"]].help
        assert f.metadata["description"].replace("%", "%%") in h, f.name
        if f.metadata["units"]:
            assert f.metadata["units"] in h, f.name
    assert "default 0.6" in opts["--lam"].help and "bvs: 0.3" in opts["--lam"].help


def test_eval_parses_a_preset_and_the_same_options():
    args = _subparsers()["eval"].parse_args(["scene", "--target", "3", "--json", "r.json", "--preset", "paper",
                                             "--gamma", "1,2", "--sigma-s", "2", "--no-precond", "--outer", "1"])
    assert args.preset == "paper" and args.gamma == [1.0, 2.0] and args.sigma_s == 2.0 and args.precond is False
    kw = render_params(args, skip=("alpha", "gamma", "lam"))
    assert kw["preset"] == "paper" and kw["n_outer"] == 1 and "gamma" not in kw


def test_render_path_and_view_parse_the_options(tmp_path):
    subs = _subparsers()
    a = subs["render"].parse_args(["scene", "-o", "out.mp4", "--path", "p.json", "--preset", "paper", "--lam", "0.002"])
    assert a.preset == "paper" and a.lam == 0.002
    v = subs["view"].parse_args(["scene", "--psf", "footprint", "--gamma", "0.5"])
    assert v.psf == "footprint" and v.gamma == 0.5


def test_view_settings_carry_the_options():
    from vibr.cli.view import _settings
    from vibr.viewer import ViewSettings

    v = _subparsers()["view"].parse_args(["scene", "--preset", "paper", "--iterations", "7"])
    s = _settings(v, ViewSettings)
    p = s.render_params()
    assert p.max_iter == 7 and p.tv_weighting == "samples" and s.gamma == 1.0  # the preset's own gamma
    with pytest.raises(VibrInputError, match="auto"):
        _settings(_subparsers()["view"].parse_args(["scene", "--gamma", "auto"]), ViewSettings)


def test_render_params_fields_defaults_and_overrides():
    assert list(DEFAULTS) == [f.name for f in param_fields()] and len(DEFAULTS) == 34
    g = RenderParams()
    assert g.as_dict() == DEFAULTS and g.method == "gradient"
    b = RenderParams.from_kwargs("bvs", gamma=0.5, lam=None)
    assert b.gamma == 0.0 and b.lam == 0.3 and b.view_k == 0  # bvs has no gradient term; its own lam
    assert b.replace(lam=2.0).lam == 2.0 and b.replace(lam=2.0).method == "bvs"
    assert RenderParams.from_kwargs("gradient", lam=AUTO).auto == ("lam",)
    with pytest.raises(VibrInputError, match="sigma_s must be > 0"):
        RenderParams(sigma_s=0.0)
    with pytest.raises(VibrInputError, match="psf must be one of"):
        g.replace(psf="gauss")
    with pytest.raises(TypeError, match="unknown render parameter"):
        RenderParams.from_kwargs("gradient", lamda=1.0)
    with pytest.raises(VibrInputError, match="for method 'bvs'"):
        RenderParams.coerce("gradient", b)


def test_parameters_page_is_current():
    """docs/reference/parameters.md is generated (docs/tools/parameters.py): stale, this fails."""
    r = subprocess.run([sys.executable, str(ROOT / "docs" / "tools" / "parameters.py"), "--check"],
                       capture_output=True, text=True, env={"PYTHONPATH": str(ROOT / "src"), "PATH": ""})
    assert r.returncode == 0, r.stderr
