"""The Python examples of the README and docs/ stay true to the code: every block compiles
and imports names that exist, the README's runs as printed, and DEPTH.md's list of
``DepthOptions`` defaults is the dataclass's."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import re
from pathlib import Path

import pytest

_REPO = Path(__file__).resolve().parents[1]
_DOCS = [_REPO / "README.md", *sorted((_REPO / "docs").glob("*.md"))]


def _python_blocks(path: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", path.read_text(encoding="utf-8"), re.S)


def _all_blocks():
    return [(p.relative_to(_REPO).as_posix(), i, b) for p in _DOCS for i, b in enumerate(_python_blocks(p))]


def test_the_docs_have_python_examples():
    names = {name for name, _, _ in _all_blocks()}
    assert {"README.md", "docs/explanation/depth.md", "docs/explanation/flythrough.md"} <= names


@pytest.mark.parametrize("name,i,block", _all_blocks(), ids=lambda v: v if isinstance(v, str) and len(v) < 40 else "")
def test_every_imported_name_exists(name, i, block):
    tree = ast.parse(block, filename=f"{name} block {i}")
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            mod = importlib.import_module(node.module)
            for alias in node.names:
                assert hasattr(mod, alias.name), f"{name}: {node.module} has no {alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                importlib.import_module(alias.name)


@pytest.mark.slow
def test_readme_example_runs(data_dir, capsys):
    (block,) = _python_blocks(_REPO / "README.md")
    assert '"../shared/data/hci2016_cotton"' in block
    code = block.replace('"../shared/data/hci2016_cotton"', repr(str(data_dir / "hci2016_cotton")))
    exec(compile(code, "README.md", "exec"), {"__name__": "readme_example"})
    out = capsys.readouterr().out
    psnr = float(re.search(r"'psnr': ([0-9.]+)", out).group(1))
    assert psnr > 45.0, out  # cotton's centre view from its 8 neighbours, ground-truth depth
    assert "'solve':" in out


def test_depth_doc_lists_the_defaults():
    from vibr.stereo import DepthOptions

    (block,) = _python_blocks(_REPO / "docs" / "DEPTH.md")
    call = re.search(r"opt = (DepthOptions\(.*?\))\n", block, re.S).group(1)
    documented = {kw.arg: ast.literal_eval(kw.value) for kw in ast.parse(call, mode="eval").body.keywords}
    actual = {f.name: (f.default if f.default is not dataclasses.MISSING else f.default_factory())
              for f in dataclasses.fields(DepthOptions)}
    assert documented == actual
