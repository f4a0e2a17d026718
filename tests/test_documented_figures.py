"""Every dB figure the README and the hand-written docs state is recomputed and held here.

``FIGURES`` is the table: the page, the figure as the page writes it, and how it is held:
either a fixture of this module that recomputes its numbers (the command the page names
beside it, at the page's settings) and must give each within ``tol`` dB of the page, both
ways (a drop fails, and so does a gain the page does not yet state), or an existing test,
named ``tests/FILE.py::TEST``, whose source asserts ``floor``. The guard test scans README.md
and docs/**/*.md (pages that say they are generated, e.g. docs/results/*.md with their own
floors, excepted) and fails on any dB figure the table does not list: a new figure in the
docs needs a row here, and so a test.

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


@dataclass(frozen=True)
class Figure:
    """One figure of the docs and how it is held."""

    doc: str  # the page, from the repository root
    text: str  # the figure as the page writes it (line breaks as spaces)
    source: str  # a fixture of this module giving its numbers, or "tests/FILE.py::TEST"
    floor: str = ""  # for a figure held by another test: what that test asserts
    tol: float = 1.0  # dB, either way

    @property
    def values(self) -> tuple[float, ...]:
        return tuple(float(x.replace("−", "-")) for x in _SIGNED.findall(self.text))


FIGURES = [
    Figure("docs/explanation/renderer.md", "40 dB",
           "tests/test_render_solver.py::test_synthetic_exact_depth_40db", floor='r.metrics["psnr"] >= 40.0'),
    Figure("docs/explanation/renderer.md", "51.15 to 33.84 dB", "cotton_intensity_scale"),
    Figure("docs/explanation/renderer.md", "49.66 / 49.85 / 49.94 / 49.96 dB", "cotton_paper_gamma_sweep"),
    Figure("docs/explanation/renderer.md", "35.98 → 32.69 dB", "grid64_robust_bvs"),
    Figure("docs/explanation/renderer.md", "39.25 → 39.43 dB", "grid64_robust_gradient"),
]

_NUMBER = re.compile(r"\d+(?:\.\d+)?")
_SIGNED = re.compile(r"[−+-]?\d+(?:\.\d+)?")
# a dB figure: one number, or several joined by "/", "→", "–", "to", "against", then "dB"
_DB_FIGURE = re.compile(r"[−+-]?\d+(?:\.\d+)?(?:\s*(?:/|→|–|to|against)\s*[−+-]?\d+(?:\.\d+)?)*\s*dB\b")


def _collapsed(path: Path) -> str:
    return " ".join(path.read_text(encoding="utf-8").split())


def _hand_written_pages() -> list[Path]:
    """README.md and docs/**/*.md, less the pages that say in their head they are generated."""
    pages = [_REPO / "README.md", *sorted((_REPO / "docs").rglob("*.md"))]
    return [p for p in pages if "generated" not in "".join(p.read_text(encoding="utf-8").splitlines(True)[:5]).lower()]


def test_every_db_figure_in_the_docs_is_in_the_table():
    listed = {(f.doc, f.text) for f in FIGURES}
    pages = _hand_written_pages()
    assert any(p.name == "renderer.md" for p in pages) and not any(p.parent.name == "results" for p in pages)
    missing = [(str(p.relative_to(_REPO)), m.group(0)) for p in pages for m in _DB_FIGURE.finditer(_collapsed(p))
               if (str(p.relative_to(_REPO)), m.group(0)) not in listed]
    assert not missing, f"dB figures with no row in FIGURES (add one, and so a test): {missing}"


def test_every_row_is_a_figure_of_its_page():
    for f in FIGURES:
        found = [m.group(0) for m in _DB_FIGURE.finditer(_collapsed(_REPO / f.doc))]
        assert f.text in found, (f.doc, f.text, found)
        assert f.values and f.tol <= 1.0


@pytest.mark.parametrize("fig", [f for f in FIGURES if "::" in f.source], ids=lambda f: f.text)
def test_figures_held_by_existing_tests(fig):
    """The named test exists and asserts the figure's floor, which is the page's figure."""
    path, name = fig.source.split("::")
    src = (_REPO / path).read_text(encoding="utf-8")
    funcs = {n.name: n for n in ast.walk(ast.parse(src)) if isinstance(n, ast.FunctionDef)}
    assert name in funcs, f"{fig.source} not found"
    body = ast.get_source_segment(src, funcs[name])
    assert fig.floor in body, (fig.source, fig.floor)
    (page_value,) = fig.values
    assert float(_NUMBER.findall(fig.floor)[-1]) == page_value, (fig.floor, fig.text)


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


@pytest.mark.slow
@pytest.mark.parametrize("fig", [f for f in FIGURES if "::" not in f.source], ids=lambda f: f.text)
def test_documented_figure_holds(fig, request):
    """The page's numbers, recomputed, within ``fig.tol`` dB either way."""
    got = tuple(float(v) for v in request.getfixturevalue(fig.source))
    assert len(got) == len(fig.values), (fig.text, got)
    off = [(want, round(g, 2)) for want, g in zip(fig.values, got) if abs(g - want) > fig.tol]
    assert not off, (f"{fig.doc}: '{fig.text}' now computes as {[round(g, 2) for g in got]}; "
                     f"update the page if this is an improvement, else fix the regression: {off}")
