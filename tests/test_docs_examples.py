"""The examples of the README and docs/ stay true to the code: every Python block compiles
and imports names that exist, the README's runs as printed, and every command of the how-to
pages runs as written, on a synthetic scene laid out as the pages assume (``scene/``: a
transforms.json scene with depth, views 0000…0008; ``photos/``: its photographs)."""

from __future__ import annotations

import ast
import contextlib
import importlib
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

_REPO = Path(__file__).resolve().parents[1]
_DOCS = [_REPO / "README.md", *sorted((_REPO / "docs").rglob("*.md"))]
_HOWTO = sorted(p for p in (_REPO / "docs" / "how-to").glob("*.md"))
#: The pages whose blocks run here (the viewer's start a server: they are ```text).


def _blocks(path: Path, lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", path.read_text(encoding="utf-8"), re.S)


def _all_blocks():
    return [(p.relative_to(_REPO).as_posix(), i, b) for p in _DOCS for i, b in enumerate(_blocks(p, "python"))]


def test_the_docs_have_examples():
    names = {name for name, _, _ in _all_blocks()}
    assert {"README.md", "docs/how-to/estimate-depth.md", "docs/how-to/fly-through.md"} <= names
    assert len(_HOWTO) >= 5 and all(_blocks(p, "bash") or p.name == "viewer.md" for p in _HOWTO)


@pytest.mark.parametrize("name,i,block", _all_blocks(), ids=lambda v: v if isinstance(v, str) and len(v) < 40 else "")
def test_every_imported_name_exists(name, i, block):
    tree = ast.parse(block, filename=f"{name} block {i}")
    # the extension examples register themselves when imported: tests/test_registries.py
    # imports them (and unregisters them); here they need only exist
    examples = {p.stem for p in (_REPO / "examples" / "extend").glob("*.py")}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module in examples or (
                isinstance(node, ast.Import) and all(a.name in examples for a in node.names)):
            continue
        if isinstance(node, ast.ImportFrom):
            mod = importlib.import_module(node.module)
            for alias in node.names:
                assert hasattr(mod, alias.name), f"{name}: {node.module} has no {alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                importlib.import_module(alias.name)


@pytest.mark.slow
def test_readme_example_runs(data_dir, capsys):
    (block,) = _blocks(_REPO / "README.md", "python")
    assert '"../shared/data/hci2016_cotton"' in block
    code = block.replace('"../shared/data/hci2016_cotton"', repr(str(data_dir / "hci2016_cotton")))
    exec(compile(code, "README.md", "exec"), {"__name__": "readme_example"})
    out = capsys.readouterr().out
    psnr = float(re.search(r"'psnr': ([0-9.]+)", out).group(1))
    assert "'solve':" in out
    # cotton's centre from its 8 best neighbours with their ground-truth depth: 50.7 dB
    assert psnr > 49.7, out


@pytest.fixture(scope="module")
def howto_inputs(tmp_path_factory):
    """``scene/`` and ``photos/`` as the how-to pages assume them."""
    from vibr.io import save_scene, write_image
    from vibr.synthetic import make_scene

    root = tmp_path_factory.mktemp("howto")
    sc = make_scene("grid", width=64, height=64)
    views = [v.replace(name=f"{i:04d}") for i, v in enumerate(sc.views)]
    meta = {k: v for k, v in sc.meta.items() if k != "grid_pos"}
    save_scene(sc.replace(views=views, meta=meta, grid=None), root / "scene")
    (root / "photos").mkdir()
    for v in views:
        write_image(root / "photos" / f"{v.name}.png", v.image)
    return root


def _commands(block: str) -> list[str]:
    """The block's commands, one a line (continuation lines joined, comments dropped)."""
    joined = re.sub(r"\\\n\s*", " ", block)
    out = []
    for line in joined.splitlines():
        line = re.sub(r"\s+#.*$", "", line).strip()
        if line and not line.startswith("#"):
            out.append(line)
    return out


@contextlib.contextmanager
def _cwd(path):
    old = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(old)


@pytest.mark.slow
@pytest.mark.parametrize("page", [p for p in _HOWTO if _blocks(p, "bash") or _blocks(p, "python")],
                         ids=lambda p: p.stem)
def test_howto_commands_run(page, howto_inputs, tmp_path):
    """Every ```bash block of the page, in order, then its ```python blocks, run in a folder
    holding fresh copies of scene/ and photos/; a command that fails fails the test. The
    ``vibr`` commands and the Python blocks run in this process (an interpreter and its
    cached kernels load in seconds, per command); other commands run in bash."""
    import shutil

    bash = _blocks(page, "bash")
    python = _blocks(page, "python")
    for d in ("scene", "photos"):
        shutil.copytree(howto_inputs / d, tmp_path / d)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    from vibr.cli import main

    for i, block in enumerate(bash):
        for line in _commands(block):
            if line.startswith("vibr "):  # in this process: no interpreter and numba start per command
                with _cwd(tmp_path):
                    rc = main(shlex.split(line)[1:])
                assert rc == 0, f"{page.name} bash block {i}: {line} exited {rc}"
                continue
            r = subprocess.run(["bash", "-euo", "pipefail", "-c", line], cwd=tmp_path, env=env,
                               capture_output=True, text=True, timeout=900)
            assert r.returncode == 0, f"{page.name} bash block {i} failed:\n{line}\n{r.stderr[-2000:]}"
    for i, block in enumerate(python):
        # in this process too, as a script (__main__), in fresh globals: a block that raises fails
        with _cwd(tmp_path):
            exec(compile(block, f"{page.name} python block {i}", "exec"), {"__name__": "__main__"})


def test_every_relative_link_resolves():
    """A link of the README, the contributors' pages or docs/ to a file of the repository
    names one that exists (a page moved or renamed breaks no reader's path)."""
    pages = [_REPO / "CONTRIBUTING.md", _REPO / "CHANGELOG.md", _REPO / "benchmarks" / "README.md", *_DOCS]
    bad = []
    for page in pages:
        for m in re.finditer(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text(encoding="utf-8")):
            target = m.group(1)
            if not target.startswith(("http://", "https://", "mailto:")) and not (page.parent / target).exists():
                bad.append(f"{page.relative_to(_REPO)}: {target}")
    assert not bad, "links to missing files:\n" + "\n".join(bad)
