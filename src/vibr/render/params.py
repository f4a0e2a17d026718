"""The render's parameters as one typed object: :class:`RenderParams`.

Each parameter is a field with paper names (eq. energy_final, docs/explanation/method.md) and,
in its metadata, a one-line description, its units, its allowed range and its default
(:data:`DEFAULTS`); the reasons for the defaults are in :mod:`vibr.render.methods`. The
command line's method options (:mod:`vibr.cli._options`) and docs/reference/parameters.md
(``python3 docs/tools/parameters.py``) are built from these fields.

A :class:`RenderParams` is filled for one method: a field given as None takes the method's
default (:data:`DEFAULTS` updated with the method's ``overrides``); ``gamma`` keeps the
method's default for the methods without the gradient term. Construction validates every
field (:meth:`RenderParams.validate`): an invalid RenderParams does not exist.
``gamma`` and ``lam`` may be :data:`AUTO`, chosen per scene by :mod:`vibr.render.autotune`
when :func:`vibr.render.render` runs.

    >>> p = RenderParams.from_kwargs("gradient", gamma=0.5)
    >>> p.replace(lam=1.0).as_dict()["lam"]
    1.0
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from typing import Literal, Union

from ..errors import VibrInputError, check_int, check_real
from .operators import PSFS
from .variational import TV_WEIGHTINGS
from .weights import ROBUST_LOSSES

__all__ = ["AUTO", "Auto", "RenderParams", "DEFAULTS", "PSFS", "GRAD_WEIGHTINGS", "HOLE_FILLS", "METHOD_REGISTRY",
           "PRESETS", "PRESET_DEFAULTS", "PAPER_DEFAULTS", "PAPER_GAMMA_FACTOR", "PAPER_LAM_FACTOR", "paper_params",
           "param_fields", "range_text", "default_text", "options_table", "params_table"]

#: The value that asks for self-tuning (``gamma="auto"``, ``lam="auto"``, CLI ``--gamma auto``).
AUTO: Literal["auto"] = "auto"
#: The type of :data:`AUTO`.
Auto = Literal["auto"]

#: How the variational methods fill the holes (pixels no sample covers, ``Bᵀ1 < hole_threshold``).
HOLE_FILLS = ("push-pull", "solve")
#: Weights of the gradient term's samples.
GRAD_WEIGHTINGS = ("visibility", "none", "W")

#: The registered methods by name (:class:`vibr.render.methods.Method`), filled by
#: :func:`vibr.render.methods.register_method` (``vibr.render.methods.REGISTRY`` is this dict):
#: parameters are filled for a method by its name without importing the renderers.
METHOD_REGISTRY: dict = {}


def _param(description: str, units: str, default, kind: str = "real", *, lo=None, hi=None, lo_open=False,
           none: str | None = None, auto: bool = False, choices=(), flag: str | None = None,
           metavar: str | None = None, check_name: str | None = None):
    """A :class:`RenderParams` field: None by default (the method's default, ``default``
    unless the method overrides it), its description, units, range and command-line flag in
    the metadata. ``none``: what a filled value of None means (no None allowed otherwise)."""
    meta = dict(description=description, units=units, default=default, kind=kind, lo=lo, hi=hi,
                lo_open=lo_open, none=none, auto=auto, choices=tuple(choices), flag=flag, metavar=metavar,
                check_name=check_name)
    return field(default=None, metadata=meta)


@dataclass(frozen=True)
class RenderParams:
    """Every parameter of a render of ``method`` (paper names; a field given as None takes
    the method's default). See the module docstring, and each field's metadata
    (:func:`param_fields`) or docs/reference/parameters.md for its meaning, units and range.
    """

    method: str = "gradient"
    alpha: float = _param("colour-term weight (eq. energy_final)", "", 1.0, lo=0.0, flag="--alpha")
    gamma: Union[float, Auto] = _param(
        "gradient-term weight, vibr's units (forward differences; the paper's through preset paper)", "", 0.3,
        lo=0.0, auto=True, flag="--gamma", metavar="G|auto")
    lam: Union[float, Auto] = _param(
        "TV weight, where the colour term's density is lam_density views", "intensity scale", 0.6, lo=0.0,
        auto=True, flag="--lam", metavar="L|auto")
    sigma_s: float = _param("sensor noise (std. dev.)", "intensity scale", 1.0, lo=0.0, lo_open=True,
                            flag="--sigma-s")
    sigma_z: float | None = _param("depth std. dev. of the sources", "scene units", None, lo=0.0, lo_open=True,
                                   none="the geometry's (the scene's, else 1 % of the median depth)",
                                   flag="--sigma-z")
    scale: float = _param("intensity scale the other parameters refer to: 255 grey levels of 8-bit images, "
                          "1 intensities in [0, 1]", "", 255.0, lo=0.0, lo_open=True, flag="--intensity-scale",
                          metavar="S", check_name="intensity_scale (scale)")
    n_outer: int = _param("outer passes: the weights re-estimated from the image before each", "passes", 2,
                          "int", lo=0, flag="--outer")
    max_iter: int = _param("FISTA iterations per pass at most", "iterations", 60, "int", lo=1,
                           flag="--iterations", check_name="iterations (max_iter)")
    tol: float = _param("FISTA stops when an accepted step lowers the energy by less than this fraction",
                        "relative energy", 1e-4, lo=0.0)
    tol_outer: float | None = _param("tol of the passes before the last", "relative energy", None, lo=0.0,
                                     none="tol")
    min_iter: int = _param("FISTA iterations per pass at least", "iterations", 3, "int", lo=0)
    tv_iter: int = _param("iterations of the TV proximal step", "iterations", 2, "int", lo=1)
    coupled_tv: bool = _param("TV coupled across the colour channels", "", True, "bool")
    grad_weighting: str = _param("weights of the gradient term's samples", "", "visibility", "choice",
                                 choices=GRAD_WEIGHTINGS)
    grad_max: float = _param("clamp of the luminance gradient in the geometric weights (at strong edges)",
                             "intensity scale / px", 64.0, lo=0.0,
                             lo_open=True)
    grad_consistency: float = _param(
        "a gradient-term sample the other views do not confirm weighs 1 / (1 + (residual / C)^2); 0: every "
        "sample at full weight, the paper's term", "intensity scale / px", 24.0, lo=0.0,
        flag="--grad-consistency", metavar="C")
    grad_coverage: float = _param(
        "with grad_consistency, a gradient-term sample landing where fewer than N samples land weighs "
        "(samples there) / N; 0: full weight", "samples", 1.5, lo=0.0, flag="--grad-coverage", metavar="N")
    z_corr: float | None = _param(
        "correlation of the views' depth errors at a target pixel; 0: independent, the paper's model",
        "", None, lo=0.0, hi=1.0, none="the geometry's (0.9 for a proxy such as depth planar, else 0)",
        flag="--z-corr", metavar="RHO")
    precond: bool = _param("diagonally preconditioned FISTA (the authors' variable metric); false: plain FISTA",
                           "", True, "bool", flag="--precond")
    d_floor: float = _param("floor of the preconditioner's diagonal", "", 0.05, lo=0.0)
    hole_threshold: float = _param("a pixel whose splat coverage Bᵀ1 is below this is a hole", "", 0.5, lo=0.0,
                                   hi=1.0)
    normalise: bool = _param("data terms divided by their sample density rho, so that alpha, gamma and lam mean "
                                "the same whatever the number of views", "", True, "bool")
    ulr_k: int = _param("views blended per pixel by ulr", "views", 4, "int", lo=1)
    ulr_beta_res: float = _param("weight of ULR's resolution penalty against its angle penalty", "", 0.1, lo=0.0)
    psf: str = _param("image-formation model v_k = B_k u: bilinear, or footprint (the source pixel's "
                      "parallelogram: sources finer than the target, on the target's own grid)", "", "bilinear",
                      "choice", choices=PSFS, flag="--psf")
    robust: str = _param("the data term's loss: none (least squares) or cauchy (IRLS weights against each "
                         "sample's residual)", "", "none", "choice", choices=ROBUST_LOSSES)
    robust_c: float = _param("Cauchy scale in robust median absolute deviations", "", 3.0, lo=0.0,
                             lo_open=True)
    tv_weighting: str = _param("uniform (lam everywhere) or samples (lam raised where few samples land, the "
                               "authors' code)", "", "uniform", "choice", choices=TV_WEIGHTINGS)
    view_k: int = _param("each sample's weight multiplied by ULR's view prior over the view_k best views per "
                         "pixel; 0: every view alike", "views", 4, "int", lo=0)
    view_tie: float = _param("views within this factor of a pixel's best penalty share the view prior's weight",
                             "", 1.1, lo=0.0)
    lam_density: float = _param("the view density at which lam applies as given, scaled by it elsewhere; "
                                       "0: lam against the density-normalised data terms (the paper's)", "views",
                                       3.0, lo=0.0)
    grid_factor: int = _param("the samples lie on a grid this many times finer than the target (set by render)",
                              "", 1, "int", lo=1)
    grid_source_size: float = _param("median size of a source pixel on the grid rendered on (set by render)",
                                     "grid pixels", 1.0, lo=0.0, lo_open=True)
    hole_fill: str = _param("holes filled by push-pull of the solved image, or by the energy's minimiser (solve)",
                            "", "push-pull", "choice", choices=HOLE_FILLS)

    def __post_init__(self):
        m = _lookup(self.method)
        object.__setattr__(self, "method", m.name)
        for f in param_fields():
            own = m.overrides.get(f.name, f.metadata["default"])
            if getattr(self, f.name) is None or (f.name == "gamma" and not m.gradient):
                object.__setattr__(self, f.name, own)
        self.validate()

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_kwargs(cls, method="gradient", preset: str | None = None, **kw) -> "RenderParams":
        """The parameters of ``method`` (a registered name or a Method) with ``kw`` (None:
        the method's default). ``preset`` (a name of :data:`PRESETS`, e.g. ``"paper"``) reads
        ``kw`` in that preset's units first. An unknown keyword raises TypeError."""
        if preset is not None:
            if preset not in PRESETS:
                raise VibrInputError(f"unknown preset {preset!r} (choose from {', '.join(PRESETS)})")
            kw = PRESETS[preset](kw)
        unknown = set(kw) - set(DEFAULTS)
        if unknown:
            raise TypeError(f"unknown render parameter(s): {', '.join(sorted(unknown))}")
        return cls(method=_lookup(method).name, **kw)

    @classmethod
    def coerce(cls, method=None, params=None, **kw) -> "RenderParams":
        """``params`` (a RenderParams, a dict of keyword arguments, or None) with the keyword
        arguments ``kw`` (``preset`` included) applied, for ``method`` (None: ``params.method``,
        else "gradient"): what the functions that take ``params=`` and keyword arguments render
        with. A RenderParams filled for another method, or with a preset, is refused."""
        if params is None or isinstance(params, dict):
            return cls.from_kwargs("gradient" if method is None else method, **{**(params or {}), **kw})
        if not isinstance(params, RenderParams):
            raise VibrInputError(f"params must be a RenderParams, got {type(params).__name__}")
        if method is not None and params.method != _lookup(method).name:
            raise VibrInputError(f"params are for method {params.method!r}, not {_lookup(method).name!r}")
        if kw.get("preset") is not None:  # a RenderParams is in vibr's units already
            raise VibrInputError("a preset applies to keyword arguments (RenderParams.from_kwargs), "
                                 "not to a RenderParams")
        kw.pop("preset", None)
        return params.replace(**kw) if kw else params

    def replace(self, **kw) -> "RenderParams":
        """A copy with the fields ``kw`` changed (None: the method's default); an unknown name
        raises TypeError."""
        unknown = set(kw) - set(DEFAULTS) - {"method"}
        if unknown:
            raise TypeError(f"unknown render parameter(s): {', '.join(sorted(unknown))}")
        return dataclasses.replace(self, **kw)

    def as_dict(self) -> dict:
        """The parameters by name, in :data:`DEFAULTS`' order (the method not included): what
        the solver reads and :attr:`vibr.render.RenderResult.params` records."""
        return {f.name: getattr(self, f.name) for f in param_fields()}

    @property
    def auto(self) -> tuple[str, ...]:
        """The names of the fields given as :data:`AUTO` (tuned when :func:`vibr.render.render` runs)."""
        return tuple(k for k in ("gamma", "lam") if isinstance(getattr(self, k), str) and getattr(self, k) == AUTO)

    # ------------------------------------------------------------------ checks
    def validate(self) -> "RenderParams":
        """Refuse a value out of its field's range with a one-line
        :class:`~vibr.errors.VibrInputError` naming the parameter, its value and the range
        (a NaN weight, an infinite one or zero iterations would otherwise make the solver
        return its initial blend, and ``sigma_s = 0`` divide by zero); returns ``self``."""
        for f in param_fields():
            _check(f, getattr(self, f.name))
        return self


def _lookup(method):
    """The registered method named ``method`` (a Method passes through)."""
    if not isinstance(method, str) and hasattr(method, "overrides"):
        return method
    try:
        return METHOD_REGISTRY[method]
    except (KeyError, TypeError):
        raise VibrInputError(f"unknown method {method!r} (choose from {', '.join(METHOD_REGISTRY)})") from None


def _check(f, v) -> None:
    """Check one filled value against its field's metadata."""
    m = f.metadata
    name = m["check_name"] or f.name
    if m["auto"] and isinstance(v, str) and v == AUTO:
        return
    if m["kind"] == "choice":
        if v not in m["choices"]:
            raise VibrInputError(f"{f.name} must be one of {m['choices']}, got {v!r}")
    elif m["kind"] == "int":
        check_int(name, v, lo=m["lo"], none_ok=m["none"] is not None)
    elif m["kind"] == "real":
        check_real(name, v, lo=m["lo"], lo_open=m["lo_open"], hi=m["hi"], none_ok=m["none"] is not None)


def param_fields() -> tuple:
    """The :class:`RenderParams` fields that are render parameters (all but ``method``)."""
    return tuple(f for f in dataclasses.fields(RenderParams) if f.name != "method")


#: The defaults shared by the methods (a method's ``overrides`` replace some), from the fields' metadata.
DEFAULTS = {f.name: f.metadata["default"] for f in param_fields()}


# ----------------------------------------------------------------------------- presets
#: The paper's (alpha, gamma, lam) when ``preset="paper"`` is given without them: the
#: light-field setting of the authors' experiments (docs/explanation/method.md §10: lambda = 0.001 on [0, 1]).
PAPER_DEFAULTS = dict(alpha=1.0, gamma=1.0, lam=0.001)

#: Paper gamma → vibr gamma: the authors apply ``dt_beta × gradient_step`` (0.1) to the
#: compact Laplacian divided by 4, i.e. ``γ·0.1/4 · Dᵀ D`` with vibr's forward differences.
PAPER_GAMMA_FACTOR = 0.1 / 4
#: Paper lambda → vibr lam: the paper's lambda is on [0, 1] intensities against a data
#: term normalised per pixel to unit weight; vibr's lam is on its ``scale`` (255) with a
#: data term of unit weight per grey level² (sigma_s = 1): lam = 255 · lambda.
PAPER_LAM_FACTOR = 255.0


def paper_params(params: dict) -> dict:
    """The paper's units → vibr's (docs/explanation/renderer.md, "The paper's units"): ``alpha`` kept,
    ``gamma·0.1/4`` (forward differences), ``lam·255`` (scale 255), the gradient term
    weighted by W (``grad_weighting="W"``, the authors' ``gw_type 1``), the spatially
    varying TV (``tv_weighting="samples"``), no view prior, every gradient sample at full
    weight (``grad_consistency=0``), independent depth errors (``z_corr=0``), lam against the
    per-pixel normalised data term (``lam_density=0``), the energy's minimiser in the holes too
    (``hole_fill="solve"``) and plain FISTA unless given.
    ``params`` holds the paper's alpha / gamma / lam (None: :data:`PAPER_DEFAULTS`; :data:`AUTO`
    stays, tuned in vibr's units) and any other vibr parameter."""
    out = dict(params)
    if params.get("scale") not in (None, 255.0):
        raise VibrInputError("preset 'paper' fixes the intensity scale to 255")
    factor = dict(alpha=1.0, gamma=PAPER_GAMMA_FACTOR, lam=PAPER_LAM_FACTOR)
    for k, d in PAPER_DEFAULTS.items():
        v = params.get(k)
        out[k] = v if isinstance(v, str) and v == AUTO else (d if v is None else float(v)) * factor[k]
    for k, v in (("grad_weighting", "W"), ("tv_weighting", "samples"), ("view_k", 0), ("precond", False),
                 ("grad_consistency", 0.0), ("grad_coverage", 0.0), ("z_corr", 0.0), ("lam_density", 0.0),
                 ("hole_fill", "solve")):
        if out.get(k) is None:
            out[k] = v
    return out


#: Parameter presets by name: a function of the given parameters returning vibr's.
PRESETS = {"paper": paper_params}
#: Each preset's alpha, gamma and lam when not given, in its own units.
PRESET_DEFAULTS = {"paper": PAPER_DEFAULTS}


# ----------------------------------------------------------------------------- descriptions
def _g(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v).lower() if isinstance(v, bool) else str(v)


def range_text(f) -> str:
    """The allowed values of a field, e.g. ">= 0, or auto", "[0, 1]", "integer >= 1"."""
    m = f.metadata
    if m["kind"] == "choice":
        out = " | ".join(m["choices"])
    elif m["kind"] == "bool":
        out = "true | false"
    else:
        if m["hi"] is not None:
            out = f"[{_g(m['lo'])}, {_g(m['hi'])}]"
        else:
            out = f"{'>' if m['lo_open'] else '>='} {_g(m['lo'])}"
        if m["kind"] == "int":
            out = "integer " + out
    return out + (f", or {AUTO}" if m["auto"] else "")


def default_text(f, overrides: dict | None = None) -> str:
    """A field's default as text, and the methods that override it (``overrides``: method
    name → its overrides), e.g. "1 (savsr: 0.3, bvs: 0.3)"."""
    d = f.metadata["default"]
    out = f.metadata["none"] if d is None else _g(d)
    over = [f"{name}: {'none' if o[f.name] is None else _g(o[f.name])}"
            for name, o in (overrides or {}).items() if f.name in o]
    return out + (f" ({', '.join(over)})" if over else "")


def _docstring_attributes(cls) -> dict:
    """``name → description`` from the numpydoc "Attributes" section of ``cls``'s docstring
    (a line ``a, b : type`` describes each name listed)."""
    doc = (cls.__doc__ or "").expandtabs()
    lines = doc.splitlines()
    try:
        start = next(i for i, ln in enumerate(lines) if ln.strip() == "Attributes") + 2
    except StopIteration:
        return {}
    out, names, text, indent = {}, [], [], None
    for ln in lines[start:] + ["END"]:
        if not ln.strip():
            continue
        ind = len(ln) - len(ln.lstrip())
        if indent is None:
            indent = ind
        if ind <= indent:
            for n in names:
                out[n] = " ".join(text)
            names, text = [n.strip() for n in ln.strip().split(" : ")[0].split(",")], []
        else:
            text.append(ln.strip())
    return out


def _cell(text: str) -> str:
    """Text for a Markdown table cell (roles and pipes made plain)."""
    text = re.sub(r":(?:func|class|data|mod|meth|attr):`~?([^`]+)`", r"`\1`", text).replace("``", "`")
    return text.replace("|", "\\|").strip()


def options_table(cls) -> str:
    """A Markdown table of the fields of the options dataclass ``cls``: name, default, and the
    description from its docstring's "Attributes" section."""
    desc = _docstring_attributes(cls)
    rows = ["| field | default | description |", "|---|---|---|"]
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            d = repr(f.default)
        elif f.default_factory is not dataclasses.MISSING:
            d = repr(f.default_factory())
        else:
            d = "(required)"
        rows.append(f"| `{f.name}` | `{d}` | {_cell(desc.get(f.name, ''))} |")
    return "\n".join(rows)


def params_table(overrides: dict | None = None) -> str:
    """A Markdown table of :class:`RenderParams`' fields: name, command-line flag, units,
    range, default (and the methods' overrides) and description."""
    rows = ["| parameter | flag | units | range | default | description |", "|---|---|---|---|---|---|"]
    for f in param_fields():
        m = f.metadata
        flag = f"`{m['flag']}`" if m["flag"] else ""
        rows.append(f"| `{f.name}` | {flag} | {m['units']} | {_cell(range_text(f))} | "
                    f"{_cell(default_text(f, overrides))} | {_cell(m['description'])} |")
    return "\n".join(rows)
