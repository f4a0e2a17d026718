"""The architecture rules of docs/ARCHITECTURE.md, checked on the source (ast, no import):

* the import rules between vibr's areas (module-level and function-level imports alike);
* only ``vibr.cli`` prints;
* no function in src/ is longer than 120 lines.

Each test lists every violation (file:line) in its failure message.
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = SRC / "vibr"

#: The areas whose imports are ruled: a module's area is its first component below
#: ``vibr`` (``vibr.render.api`` → "render", ``vibr.camera`` → "camera").
FOUNDATION = ("camera", "scene", "errors", "metrics")
#: area → the areas it must never import (docs/ARCHITECTURE.md, "Import rules").
FORBIDDEN = {
    **{a: {"io", "geometry", "render", "stereo", "pipeline", "evaluate", "calibrate", "video_frames",
           "pan_calibration", "synthetic", "figures", "cli"} for a in FOUNDATION},
    "io": {"geometry", "render", "stereo", "pipeline", "evaluate", "calibrate", "video_frames", "cli"},
    "geometry": {"render", "io", "stereo", "pipeline", "evaluate", "calibrate", "video_frames", "cli"},
    "render": {"io", "stereo", "pipeline", "evaluate", "calibrate", "video_frames", "cli"},
    # stereo resamples images with vibr.io.images.resize_image (the one resize of vibr)
    "stereo": {"render", "geometry", "pipeline", "evaluate", "calibrate", "video_frames", "cli"},
    "synthetic": {"render", "geometry", "io", "stereo", "pipeline", "evaluate", "calibrate", "video_frames", "cli"},
    # a solver of COLMAP's matches: it knows nothing of vibr's scenes, images or renders
    "pan_calibration": {"io", "geometry", "render", "stereo", "pipeline", "evaluate", "calibrate", "video_frames",
                        "synthetic", "figures", "camera", "scene", "depthcache", "cli"},
}
#: area → modules of a forbidden area it may import all the same: the renderer resizes
#: sources finer than the target with vibr's one image resize (``reduce_sources``).
ALLOWED = {"render": {"vibr.io.images"}}
#: Nothing outside the CLI imports it.
CLI_IMPORTERS = {"cli", "__main__"}
MAX_FUNCTION_LINES = 120


def _modules():
    for p in sorted(PKG.rglob("*.py")):
        parts = list(p.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        yield p, ".".join(parts)


def _is_module(dotted: str) -> bool:
    rel = Path(*dotted.split("."))
    return (SRC / rel).with_suffix(".py").is_file() or (SRC / rel / "__init__.py").is_file()


def imported_modules(path: Path, module: str):
    """``(line, imported vibr module)`` for every import in the file, at any depth (function
    bodies included); ``from vibr.x import name`` counts as importing ``vibr.x.name`` when
    that is a module, else ``vibr.x``."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, a.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for a in node.names:
                sub = f"{target}.{a.name}"
                yield node.lineno, sub if _is_module(sub) else target


def area(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def import_violations() -> list[str]:
    out = []
    for path, module in _modules():
        src_area = area(module)
        for line, target in imported_modules(path, module):
            if target != "vibr" and not target.startswith("vibr."):
                continue
            dst = area(target)
            if not dst or dst == src_area:
                continue
            if target in ALLOWED.get(src_area, ()):
                continue
            if dst in FORBIDDEN.get(src_area, ()) or (dst == "cli" and src_area not in CLI_IMPORTERS):
                out.append(f"{path.relative_to(SRC.parent)}:{line}: {module} imports {target} "
                           f"({src_area} must not import {dst})")
    return out


def print_calls() -> list[str]:
    out = []
    for path, module in _modules():
        if area(module) == "cli":
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                out.append(f"{path.relative_to(SRC.parent)}:{node.lineno}: print( in {module}")
    return out


def long_functions(limit: int = MAX_FUNCTION_LINES) -> list[str]:
    out = []
    for path, _ in _modules():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    out.append(f"{path.relative_to(SRC.parent)}:{node.lineno}: {node.name} is {n} lines")
    return out


#: The most keyword options a public function of the library may take before they belong in
#: an options dataclass (docs/ARCHITECTURE.md; compiled kernels, which take arrays, aside).
MAX_OPTIONS = 11


def many_options(limit: int = MAX_OPTIONS) -> list[str]:
    out = []
    for path, _ in _modules():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.FunctionDef) or node.name.startswith("_"):
                continue
            if any("jit" in ast.unparse(d) for d in node.decorator_list):
                continue
            n = len(node.args.kwonlyargs) + len(node.args.defaults)
            if n > limit:
                out.append(f"{path.relative_to(SRC.parent)}:{node.lineno}: {node.name} takes {n} options")
    return out


def test_import_rules():
    bad = import_violations()
    assert not bad, "imports across the rules of docs/ARCHITECTURE.md:\n" + "\n".join(bad)


def test_only_the_cli_prints():
    bad = print_calls()
    assert not bad, "print( outside src/vibr/cli/ (use logging.getLogger(__name__)):\n" + "\n".join(bad)


def test_no_function_over_120_lines():
    bad = long_functions()
    assert not bad, f"functions over {MAX_FUNCTION_LINES} lines (split into named steps):\n" + "\n".join(bad)


def test_no_public_function_with_more_than_11_options():
    bad = many_options()
    assert not bad, f"more than {MAX_OPTIONS} keyword options (take an options dataclass):\n" + "\n".join(bad)


def test_the_checks_can_fail(tmp_path, monkeypatch):
    """Each rule catches a planted violation: a function-level import of vibr.render in
    geometry, a print in the library, a long function, a function of many options."""
    import sys

    pkg = tmp_path / "vibr"
    (pkg / "geometry").mkdir(parents=True)
    (pkg / "render").mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "render" / "__init__.py").write_text("")
    (pkg / "geometry" / "__init__.py").write_text("")
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    opts = ", ".join(f"o{i}=0" for i in range(MAX_OPTIONS + 1))
    (pkg / "geometry" / "bad.py").write_text(
        "def f():\n    from ..render import api\n    print('x')\n" + body + "\n"
        f"def g(a, *, {opts}):\n    pass\n")
    (pkg / "render" / "api.py").write_text("")
    mod = sys.modules[__name__]
    monkeypatch.setattr(mod, "SRC", tmp_path)
    monkeypatch.setattr(mod, "PKG", pkg)
    assert any("geometry must not import render" in v for v in import_violations())
    assert any("print(" in v for v in print_calls())
    assert any("f is" in v for v in long_functions())
    assert any("g takes 12 options" in v for v in many_options())


def test_doc_references_resolve():
    """Every "docs/NAME.md" the code cites exists, and every "docs/METHOD.md §N" names a
    numbered section of it (a user of the package has the repository, nothing else)."""
    import re

    root = SRC.parent
    method = (root / "docs" / "METHOD.md").read_text()
    sections = set(re.findall(r"^## (\d+)\. ", method, re.M))
    bad = []
    for path, _ in _modules():
        text = path.read_text()
        for m in re.finditer(r"docs/([A-Za-z_]+\.md)", text):
            if not (root / "docs" / m.group(1)).is_file():
                bad.append(f"{path.relative_to(root)}: cites missing docs/{m.group(1)}")
        for m in re.finditer(r"docs/METHOD\.md §(\d+)(?:[-–](\d+))?", text):
            for n in filter(None, m.groups()):
                if n not in sections:
                    bad.append(f"{path.relative_to(root)}: docs/METHOD.md §{n} does not exist")
        for m in re.finditer(r"(?<![/\w])METHOD(?:\.md)? (?:§|eq)", text):
            bad.append(f"{path.relative_to(root)}: a reference to METHOD outside docs/ ({m.group(0)!r})")
    assert len(sections) >= 10
    assert not bad, "\n".join(bad)
