"""Every quality figure the README and the hand-written docs state is recomputed and held here.

A quality figure is one of the ``KINDS``: dB, BadPix / MSE×100, grey levels, Spearman's ρ,
AUSE, a ratio ("0.8 times", so also "4 times faster") or a percentage (so also "5 % faster"). ``FIGURES`` is the table: the page, the figure as
the page writes it, and how it is held: either a fixture of this module that recomputes its
numbers (the command the page names beside it, at the page's settings) and must give each
within ``tol`` of the page, both ways (a drop fails, and so does a gain the page does not yet
state), or an existing test, named ``tests/FILE.py::TEST``, whose source asserts a bound
within ``tol`` of the page's figure (``floor``, one per number). ``tol`` is at most the kind's
equivalent of 1 dB. ``NOT_RESULTS`` lists the numbers of those kinds that state no result (a
parameter, a definition, a threshold), each with its context on the page and the reason.
The guard test scans README.md and docs/**/*.md (pages that say they are generated, e.g.
docs/results/*.md with their own floors, excepted) and fails on any such figure neither table
lists: a new figure in the docs needs a row here, and so a test.

Runtime, speed and memory figures are scanned too (the ``speed`` kinds: seconds, "N×", bytes,
frame rates) but never get a row: they belong to docs/results/performance.md, which
``benchmarks/perf/run_all.py --write-docs`` writes from one run and ``--check`` holds (each as
a ratio to a figure measured beside it, peak memory within 15 %). A hand-written page links
that page's figure, or says in words what was decided and names the benchmark that measures
it; only settings, definitions and citations of these kinds stay, in ``NOT_RESULTS``.

The recomputing fixtures are module-scoped and share their work: cotton's samples at stride
2 are computed once for the six renders that read them.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

_REPO = Path(__file__).resolve().parents[1]

_NUMBER = re.compile(r"\d+(?:\.\d+)?")
_SIGNED = re.compile(r"[−+-]?\d+(?:\.\d+)?")
# one number, or several joined by "/", "→", "–", "to", "against"
_NUMBERS = r"[−+-]?\d+(?:\.\d+)?(?:\s*(?:/|→|–|to|against)\s*[−+-]?\d+(?:\.\d+)?)*"
# the names of a measure that carry a number of their own, left out of the figure's values
_LABEL = re.compile(r"BadPix\(0\.07\)|MSE×100")


@dataclass(frozen=True)
class Kind:
    """A kind of quality figure: how the docs write it, and its equivalent of 1 dB."""

    pattern: re.Pattern
    tol: float
    relative: bool = False  # tol is a fraction of the figure, else in its unit
    speed: bool = False  # a runtime or memory figure: no row here, only a NOT_RESULTS entry

    def limit(self, value: float, tol: float) -> float:
        return tol * abs(value) if self.relative else tol


KINDS = {
    "dB": Kind(re.compile(_NUMBERS + r"\s*dB\b"), 1.0),
    # a squared error: 1 dB is a factor 1.26; BadPix is held to the same fraction
    "BadPix/MSE": Kind(re.compile(r"(?:BadPix(?:\(0\.07\))?|MSE×100)(?:\s*/\s*MSE×100)?\s+" + _NUMBERS), 0.2, True),
    # an absolute error: 1 dB is a factor 1.12
    "grey levels": Kind(re.compile(_NUMBERS + r"\s*grey levels?\b"), 0.12, True),
    "ρ": Kind(re.compile(r"ρ\s*(?:=|≤|≥)?\s*" + _NUMBERS), 0.1),
    "AUSE": Kind(re.compile(r"AUSE\s*" + _NUMBERS), 0.2, True),
    "ratio": Kind(re.compile(_NUMBERS + r"\s*times\b"), 0.12, True),
    "%": Kind(re.compile(_NUMBERS + r"\s*%"), 2.0),  # points
    # runtime and memory: "0.3 s", "12 ms", "0.61×" (not "3×3" nor "1280 × 800"), "561 MB",
    # "24 fps"; "N times faster" and "N % faster" are the two kinds above
    "seconds": Kind(re.compile(_NUMBERS + r"\s*(?:s|ms|µs|min|seconds?|minutes?|hours?)\b"), 0.0, speed=True),
    "×": Kind(re.compile(_NUMBERS + r"\s*×(?!\s*\d)"), 0.0, speed=True),
    "bytes": Kind(re.compile(_NUMBERS + r"\s*(?:[kKMGT]i?B|bytes?)\b"), 0.0, speed=True),
    "rate": Kind(re.compile(_NUMBERS + r"\s*(?:fps|Hz)\b"), 0.0, speed=True),
}


@dataclass(frozen=True)
class Figure:
    """One figure of the docs and how it is held."""

    doc: str  # the page, from the repository root
    text: str  # the figure as the page writes it (line breaks as spaces)
    source: str  # a fixture of this module giving its numbers, or "tests/FILE.py::TEST"
    floor: tuple[str, ...] = ()  # for a figure held by another test: what it asserts, per number
    tol: float | None = None  # in the kind's terms, either way; None: the kind's 1 dB
    per: float = 1.0  # the page's unit in the floor's (100: the page says %, the test a fraction)

    @property
    def kind(self) -> str:
        (k,) = [k for k, kind in KINDS.items() if kind.pattern.fullmatch(self.text)]
        return k

    @property
    def values(self) -> tuple[float, ...]:
        return tuple(float(x.replace("−", "-")) for x in _SIGNED.findall(_LABEL.sub("", self.text)))

    def limits(self) -> tuple[float, ...]:
        kind = KINDS[self.kind]
        return tuple(kind.limit(v, kind.tol if self.tol is None else self.tol) for v in self.values)


@dataclass(frozen=True)
class NotAResult:
    """Numbers of a figure's kind that state no result: the phrase holding them, and why."""

    doc: str
    phrase: str  # as the page writes it (line breaks as spaces); covers every match inside it
    reason: str


_R, _D = "docs/explanation/renderer.md", "docs/explanation/depth.md"
_C, _F, _V = "docs/explanation/calibration.md", "docs/explanation/flythrough.md", "docs/explanation/viewer.md"
_M, _P = "docs/explanation/method.md", "docs/explanation/performance.md"
_E = "docs/reference/errors-and-limits.md"
_PARAM = "a parameter or a definition, not a result"
_SETUP = "the set-up of an experiment, not its result"
_DTYPE = "a size from the arrays' dtypes, a definition"
_CITED = "the paper's figure, cited: vibr does not measure it"
_PRINTED = "the command's own settings as it prints them (frames over fps), not a measurement"

FIGURES = [
    Figure(_R, "40 dB",
           "tests/test_render_solver.py::test_synthetic_exact_depth_40db", floor=('r.metrics["psnr"] >= 40.0',)),
    Figure("docs/tutorials/first-render.md", "3 dB",
           "tests/test_cli_demo.py::test_demo_video_spans_the_parallax_and_keeps_the_demos_quality",
           floor=("worst >= demo_psnr - 3.0",)),
    Figure(_R, "51.13 to 35.70 dB", "cotton_intensity_scale"),
    Figure(_R, "49.66 / 49.85 / 49.94 / 49.96 dB", "cotton_paper_gamma_sweep"),
    Figure(_R, "35.98 → 32.69 dB", "grid64_robust_bvs"),
    Figure(_R, "39.25 → 39.43 dB", "grid64_robust_gradient"),
    Figure(_R, "ρ 0.82", "planar_proxy_sigma_rho"),
    Figure(_R, "AUSE 0.117", "planar_proxy_sigma_ause"),
    Figure(_R, "0.01 grey levels", "tests/test_view_prior.py::test_views_the_prior_leaves_out_do_not_change_the_render",
           floor=("assert np.median(d) < 0.01",)),
    Figure(_R, "0.8 times", "tests/test_render_holes.py::test_holes_take_the_push_pull_of_the_covered_pixels",
           floor=("err(filled.image) < 0.8 * err(solved.image)",)),
    Figure(_D, "60 %", "tests/test_stereo_planesweep.py::test_refine_planes_point_seen_by_one_partner",
           floor=("fr[None] < 0.6",), per=100),
    Figure(_D, "90 %", "tests/test_stereo_planesweep.py::test_refine_planes_point_seen_by_one_partner",
           floor=("fr[0.1] >= 0.9",), per=100),
    Figure(_D, "BadPix(0.07) / MSE×100 5.24 / 1.687", "tests/test_stereo_lightfield.py::test_cotton_centre_from_3x3_block",
           floor=("badpix < 5.6", "mse100 < 1.8")),
    Figure(_C, "5 %", "tests/test_calibrate.py::test_a_zoom_gets_one_camera_per_photo",
           floor=("/ 480.0) - 1) < 0.05",), per=100),
    Figure(_F, "4 grey levels", "tests/test_flythrough.py::test_video_colours_are_bt709_tagged",
           floor=("np.array(c)).max() <= 4",)),
    Figure(_V, "1 grey level", "tests/test_viewer_browser.py::test_viewer_in_chromium", floor=("diff.max() <= 1",)),
    Figure(_V, "5–25 %", "tests/test_viewer_browser.py::test_camera_moves_at_the_scale_of_the_scene",
           floor=("0.05 <= moved", "moved <= 0.25"), per=100),
]

NOT_RESULTS = [
    NotAResult(_C, "σ ≤ 0.2 % of the image size and the shift ≤ 3 %", "the refinement's thresholds"),
    NotAResult(_C, "more than 5 times the median error", _PARAM),
    NotAResult(_C, "no better than 1.25 times one centre", _PARAM),
    NotAResult(_C, "outside 0.3–4.8 times the image's longer side", _PARAM),
    NotAResult(_D, "`coverage_gain` (2 %) of the frustum, at most 4 times", _PARAM),
    NotAResult(_D, "widened by 15 %", _PARAM),
    NotAResult(_D, "out to 100 times that depth", _PARAM),
    NotAResult(_D, "within 1 %", "the measure (depth within 1 % of the truth) a figure counts"),
    NotAResult(_D, "within `rel_tol` (1 %)", _PARAM),
    NotAResult(_D, "1 % of depth is a fixed fraction", _PARAM),
    NotAResult(_M, "**sigma_s** = 1 grey level", _PARAM),
    NotAResult(_M, "otherwise 1 % of the median depth", _PARAM),
    NotAResult(_M, "clamped (64 grey levels per pixel)", _PARAM),
    NotAResult(_M, "24 grey levels per pixel", _PARAM),
    NotAResult(_M, "fewer than 1 % of pixels move", _PARAM),
    NotAResult(_R, "(64 grey levels per pixel", _PARAM),
    NotAResult(_R, "TV 255 times stronger", "arithmetic: the intensity scale squared over itself"),
    NotAResult(_R, "effectively 8 times weaker", "arithmetic: the sum over cotton's 8 sources"),
    NotAResult(_R, "(73.6 grey levels", "scale/√12, a definition"),
    NotAResult(_R, "a saturated block over 23 % of it", _SETUP),
    NotAResult(_R, "sigma_z at 1 % of the depth", _PARAM),
    NotAResult(_R, "within 1 %, they weigh", _SETUP),
    NotAResult(_R, "at least 1.1 times the pixel's best penalty", _PARAM),
    NotAResult(_R, "(24 grey levels per pixel)", _PARAM),
    NotAResult(_R, "up to 5 grey levels per pixel", "the Cauchy weight's closed form, a definition"),
    NotAResult(_R, "ρ = 0.9", _PARAM),
    NotAResult(_R, "At a 20 times larger lam", _SETUP),
    NotAResult(_V, "drawn at 6 % of the scene's scale", _PARAM),
    NotAResult(_V, "a drag of 10 % of the canvas", _SETUP),
    NotAResult(_E, "(coverage 0 %)", "a definition"),
    # runtime and memory kinds: settings, definitions and citations only; a measured speed or
    # memory figure goes to docs/results/performance.md (run_all.py --write-docs, held by --check)
    NotAResult("README.md", "a 3 s loop", _PRINTED),
    NotAResult("docs/tutorials/first-render.md", "3.0 s loop round the grid", _PRINTED),
    NotAResult("docs/tutorials/first-render.md", "is a 3 s loop", _PRINTED),
    NotAResult("docs/tutorials/first-render.md", "at 24 fps (2.50 s)", _PRINTED),
    NotAResult("docs/how-to/fly-through.md", "(default 4 s at 24 fps)", _PARAM),
    NotAResult("docs/how-to/scale-out.md", "--memory 16GB", "a command's option in an example"),
    NotAResult(_D, "(40 + 4 × partners) bytes", "the working set's formula, a definition"),
    NotAResult(_D, "(8 GB, `$VIBR_CACHE_MAX_GB`)", _PARAM),
    NotAResult(_F, "more than 2 × `n_views` views", _PARAM),
    NotAResult(_F, "so 24 fps plays at 25", "a frame rate and GIF's rounding of it, a definition"),
    NotAResult(_M, "The paper reports 2–3 s per solve", _CITED),
    NotAResult(_M, "smoothed up to 100× more", "the authors' TV weighting's range, a definition"),
    NotAResult(_P, "A sample takes 84 bytes", _DTYPE),
    NotAResult(_R, "0.1 × relative resolution", "Buehler's penalty, a definition"),
    NotAResult(_R, "`jac` (16 bytes;", _DTYPE),
    NotAResult(_R, "`src_xy` (8 bytes;", _DTYPE),
    NotAResult(_R, "A sample is 84 bytes", _DTYPE),
    NotAResult(_R, "(4 bytes a sample", _DTYPE),
    NotAResult("docs/explanation/scale-out.md", "each bounded by 5 s", _PARAM),
    NotAResult("docs/explanation/scale-out.md", "above 128 KiB", "glibc's default threshold, a definition"),
    NotAResult("docs/explanation/scale-out.md", "(mmap threshold 256 MiB, trim threshold 2 GiB)", _PARAM),
    NotAResult(_V, "update came for 0.3 s", _PARAM),
    NotAResult(_V, "given up after 2 s", _PARAM),
    NotAResult(_V, "`settle_s` = 0.3 s", _PARAM),
    NotAResult(_V, "more than 0.3 s after the one before", "the settle time (`settle_s`), a parameter"),
    NotAResult(_V, "`NUMBA_NUM_THREADS` = 2 × cores", _PARAM),
    NotAResult(_V, "a preview within 0.3 s of a camera update and the full view within 1.5 s",
               "the latency targets, not results"),
    NotAResult(_V, "(up to 1 GiB)", "`PREPARED_BUDGET_BYTES`, a parameter"),
    NotAResult(_V, "opens a 0.25 s window", "viser's behaviour, a definition"),
    NotAResult(_V, "2 GiB − 1 byte", _PARAM),
    NotAResult(_V, "holding its image until 0.3 s", _PARAM),
    NotAResult(_V, "full render after 0.3 s", _PARAM),
    NotAResult(_E, "about 3 bytes a pixel of the photos at `--scale` plus 64 bytes", "the free-space rule, a definition"),
    NotAResult(_E, "not a 2.5 GB allocation", "arithmetic: 13000² pixels at 16 bytes"),
    NotAResult(_E, "84 bytes each from the dtypes", _DTYPE),
    NotAResult(_E, "(16 bytes a pixel,", _DTYPE),
    NotAResult(_E, "11 + 2 × border pixels", "DSSIM's window and border, a definition"),
    NotAResult(_E, "no case over 10 s or 2 GB", "the fuzz test's limits, parameters"),
    NotAResult(_E, "mounts a 2 MB tmpfs", _SETUP),
]


def _collapsed(path: Path) -> str:
    return " ".join(path.read_text(encoding="utf-8").split())


def _hand_written_pages() -> list[Path]:
    """README.md and docs/**/*.md, less the pages that say in their head they are generated."""
    pages = [_REPO / "README.md", *sorted((_REPO / "docs").rglob("*.md"))]
    return [p for p in pages if "generated" not in "".join(p.read_text(encoding="utf-8").splitlines(True)[:5]).lower()]


def _figures_of(text: str) -> list[re.Match]:
    """Every figure of every kind in a page's text; where two overlap, the longer."""
    found = sorted((m for kind in KINDS.values() for m in kind.pattern.finditer(text)),
                   key=lambda m: (m.start(), -len(m.group(0))))
    out: list[re.Match] = []
    for m in found:
        if not out or m.start() >= out[-1].end():
            out.append(m)
    return out


def _allowed_spans(doc: str, text: str) -> list[tuple[int, int]]:
    return [(m.start(), m.end()) for a in NOT_RESULTS if a.doc == doc
            for m in re.finditer(re.escape(a.phrase), text)]


def test_every_figure_in_the_docs_is_in_the_table():
    listed = {(f.doc, f.text) for f in FIGURES}
    pages = _hand_written_pages()
    assert any(p.name == "renderer.md" for p in pages) and not any(p.parent.name == "results" for p in pages)
    missing = []
    for p in pages:
        doc, text = str(p.relative_to(_REPO)), _collapsed(p)
        spans = _allowed_spans(doc, text)
        missing += [(doc, m.group(0), text[max(0, m.start() - 60):m.start()]) for m in _figures_of(text)
                    if (doc, m.group(0)) not in listed and not any(a <= m.start() and m.end() <= b for a, b in spans)]
    assert not missing, ("figures with no row in FIGURES (add one, and so a test) nor in NOT_RESULTS; a speed or "
                         "memory figure (s, ms, N×, MB/GiB, fps) goes to docs/results/performance.md through "
                         f"benchmarks/perf/run_all.py and the page links it: {missing}")


@pytest.mark.parametrize(("text", "found"), [
    ("took 0.61× the time", ["0.61×"]), ("1.5–3.8× the errors", ["1.5–3.8×"]),
    ("18.0 / 17.5 s in-process", ["18.0 / 17.5 s"]), ("12 ms per iteration", ["12 ms"]),
    ("peaks at 10.08 GiB", ["10.08 GiB"]), ("561 MB and 2.5GB", ["561 MB", "2.5GB"]),
    ("4.2 times faster", ["4.2 times"]), ("about 10 % faster", ["10 %"]), ("at 24 fps", ["24 fps"]),
    ("a 3×3 grid, 1280 × 800, MSE×100 of 768×512 targets", []), ("3 sources", []),
])
def test_the_guard_sees_speed_and_memory_figures(text, found):
    assert [m.group(0) for m in _figures_of(text)] == found


def test_every_row_is_a_figure_of_its_page():
    for f in FIGURES:
        found = [m.group(0) for m in _figures_of(_collapsed(_REPO / f.doc))]
        assert f.text in found, (f.doc, f.text, found)
        kind = KINDS[f.kind]
        assert not kind.speed, f"{f}: speed and memory figures are held by run_all.py --check, not here"
        assert f.values and (f.tol is None or f.tol <= kind.tol), f
    for a in NOT_RESULTS:
        text = _collapsed(_REPO / a.doc)
        assert a.phrase in text, f"{a.doc} no longer says '{a.phrase}': drop it from NOT_RESULTS"
        assert any(m.group(0) in a.phrase for m in _figures_of(a.phrase)), a
        assert a.reason, a


@pytest.mark.parametrize("fig", [f for f in FIGURES if "::" in f.source], ids=lambda f: f.text)
def test_figures_held_by_existing_tests(fig):
    """The named test exists and asserts, for each number of the figure, a bound within the
    figure's tolerance of the page's number."""
    path, name = fig.source.split("::")
    src = (_REPO / path).read_text(encoding="utf-8")
    funcs = {n.name: n for n in ast.walk(ast.parse(src)) if isinstance(n, ast.FunctionDef)}
    assert name in funcs, f"{fig.source} not found"
    body = ast.get_source_segment(src, funcs[name])
    assert len(fig.floor) == len(fig.values), (fig.text, fig.floor)
    for floor, value, limit in zip(fig.floor, fig.values, fig.limits()):
        assert floor in body, (fig.source, floor)
        bound = float(_NUMBER.findall(floor)[-1]) * fig.per
        assert abs(bound - value) <= limit + 1e-9, (floor, fig.text)


# -- the recomputed figures -------------------------------------------------------------


@pytest.fixture(scope="module")
def cotton_stride2(cotton_dir):
    """Cotton's centre and the samples of its 8 neighbours at stride 2, ground-truth depth, as
    benchmarks/quality/cotton_table.py and quality_table.py compute them."""
    from vibr.geometry import compute_samples
    from vibr.io import load_scene
    from vibr.pipeline import prepare

    # only the 9 views read (the benchmarks load all 81 and take the same subset)
    grid = {f"input_Cam{9 * (4 + dr * 2) + 4 + dc * 2:03d}": (4 + dr * 2, 4 + dc * 2)
            for dr in (-1, 0, 1) for dc in (-1, 0, 1)}
    scene = load_scene(cotton_dir, views=list(grid))
    assert {n: scene.meta["grid_pos"][n] for n in scene.names} == grid
    src, tgt = prepare(scene, "input_Cam040", depth="gt")
    return compute_samples(src, tgt.camera), np.array([v.camera.centre for v in src.views]), tgt


def _cotton_psnr(cotton_stride2, method, **kw):
    """PSNR over the covered pixels, 2-pixel border excluded (the two benchmarks' measure)."""
    from vibr.metrics import psnr
    from vibr.render.api import render_samples

    S, centres, tgt = cotton_stride2
    r = render_samples(S, method, source_centres=centres, target_centre=tgt.camera.centre, **kw)
    return psnr(r.image, tgt.image, mask=r.coverage, border=2)


@pytest.fixture(scope="module")
def cotton_intensity_scale(cotton_stride2):
    """`python3 benchmarks/quality/cotton_table.py --strides 2 --depth gt [scale=1.0]`, gradient."""
    return _cotton_psnr(cotton_stride2, "gradient"), _cotton_psnr(cotton_stride2, "gradient", scale=1.0)


@pytest.fixture(scope="module")
def cotton_paper_gamma_sweep(cotton_stride2):
    """`python3 benchmarks/quality/quality_table.py cotton --strides 2,4 --settings "gradient
    preset=paper gamma=G"`, G = 0, 1, 2, 3, at stride 2."""
    return tuple(_cotton_psnr(cotton_stride2, "gradient", preset="paper", gamma=float(g)) for g in (0, 1, 2, 3))


@pytest.fixture(scope="module")
def grid64():
    """The renderer page's `python -c` command for `robust="cauchy"`: a 64×64 grid's centre."""
    from vibr.render import render
    from vibr.synthetic import make_scene

    sc = make_scene("grid", n_views=9, width=64, height=64, seed=2)
    return {(m, robust): render(sc, sc.views[4], m, **({"robust": "cauchy"} if robust else {})).metrics["psnr"]
            for m in ("bvs", "gradient") for robust in (False, True)}


@pytest.fixture(scope="module")
def grid64_robust_bvs(grid64):
    return grid64["bvs", False], grid64["bvs", True]


@pytest.fixture(scope="module")
def grid64_robust_gradient(grid64):
    return grid64["gradient", False], grid64["gradient", True]


@pytest.fixture(scope="module")
def planar_proxy_sigma():
    """`python3 benchmarks/quality/uncertainty_table.py --figure docs/img/uncertainty_planar.png`:
    a 256² synthetic grid's centre rendered through the planar proxy, σ scored against the error."""
    from vibr.metrics import uncertainty_metrics
    from vibr.pipeline import prepare
    from vibr.render import render
    from vibr.synthetic import make_scene

    src, tg = prepare(make_scene("grid", width=256, height=256, seed=0), 4, depth="planar")
    r = render(src, tg, "gradient", uncertainty=True)
    return uncertainty_metrics(r.uncertainty, r.image, tg.image, border=2)


@pytest.fixture(scope="module")
def planar_proxy_sigma_rho(planar_proxy_sigma):
    return (planar_proxy_sigma["spearman"],)


@pytest.fixture(scope="module")
def planar_proxy_sigma_ause(planar_proxy_sigma):
    return (planar_proxy_sigma["ause"],)


@pytest.mark.slow
@pytest.mark.parametrize("fig", [f for f in FIGURES if "::" not in f.source], ids=lambda f: f.text)
def test_documented_figure_holds(fig, request):
    """The page's numbers, recomputed, within the figure's tolerance either way."""
    got = tuple(float(v) for v in request.getfixturevalue(fig.source))
    assert len(got) == len(fig.values), (fig.text, got)
    off = [(want, round(g, 3)) for want, g, lim in zip(fig.values, got, fig.limits()) if abs(g - want) > lim]
    assert not off, (f"{fig.doc}: '{fig.text}' now computes as {[round(g, 3) for g in got]}; "
                     f"update the page if this is an improvement, else fix the regression: {off}")
