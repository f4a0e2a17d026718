"""The architecture rules of docs/explanation/architecture.md, checked on the source (ast, no import):

* the import rules between vibr's areas (module-level and function-level imports alike);
* only ``vibr.cli`` prints;
* no function in src/ is longer than 120 lines.

Each test lists every violation (file:line) in its failure message.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = SRC / "vibr"

#: A module's area is its first component below ``vibr`` (``vibr.render.api`` → "render",
#: ``vibr.camera`` → "camera"). The allow-list: area → the other areas it may import, at any
#: depth (function bodies included). A new package or root module must be added here, so
#: that its place in the layers is decided, not inherited (docs/explanation/architecture.md).
FOUNDATION = {"errors", "camera", "scene", "metrics", "progress"}
_LIB = FOUNDATION | {"_runtime"}
ALLOWED_AREAS = {
    "": {"camera", "errors", "scene", "render"},
    "errors": set(),
    "progress": set(),
    "camera": {"errors"},
    "scene": {"errors", "camera"},
    "metrics": {"errors"},
    "_runtime": {"errors"},
    "synthetic": _LIB | {"geometry"},
    "geometry": _LIB,
    "io": _LIB | {"geometry"},
    "render": _LIB | {"geometry"},
    "executor": _LIB,
    "stereo": _LIB | {"geometry", "executor"},
    "pipeline": _LIB | {"geometry", "io", "stereo", "render"},
    "calib": _LIB | {"io"},
    "eval": _LIB | {"geometry", "io", "render", "stereo", "pipeline", "executor"},
    "paths": _LIB | {"geometry", "io", "render", "stereo", "pipeline", "executor", "eval"},
    "viewer": _LIB | {"geometry", "io", "render", "stereo", "pipeline", "executor", "eval", "paths", "synthetic"},
    "cli": _LIB | {"", "synthetic", "geometry", "io", "render", "stereo", "pipeline", "executor", "calib", "eval",
                   "paths", "viewer"},
    "__main__": {"cli"},
}
#: Modules held to a narrower rule than their area: the one-centre solver of COLMAP's
#: matches knows nothing of vibr's scenes, images or renders.
ALLOWED_MODULES = {"vibr.calib.pan": {"_runtime"}}
#: The package root holds the shared vocabulary and the glue, nothing else.
MAX_ROOT_MODULES = 10
MAX_FUNCTION_LINES = 120


def _modules():
    for p in sorted(PKG.rglob("*.py")):
        parts = list(p.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        yield p, ".".join(parts)


def _tree(path: Path) -> ast.Module:
    """The file's syntax tree, parsed once per version of the file (each rule below walks
    every module: 0.6 s of parsing each time)."""
    return _parsed(path, path.stat().st_mtime_ns)


@functools.lru_cache(maxsize=None)
def _parsed(path: Path, mtime_ns: int) -> ast.Module:
    return ast.parse(path.read_text(), str(path))


def _is_module(dotted: str) -> bool:
    rel = Path(*dotted.split("."))
    return (SRC / rel).with_suffix(".py").is_file() or (SRC / rel / "__init__.py").is_file()


def imported_modules(path: Path, module: str):
    """``(line, imported vibr module)`` for every import in the file, at any depth (function
    bodies included); ``from vibr.x import name`` counts as importing ``vibr.x.name`` when
    that is a module, else ``vibr.x``."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(_tree(path)):
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
        if src_area not in ALLOWED_AREAS:
            out.append(f"{path.relative_to(SRC.parent)}: area {src_area!r} is not in the allow-list "
                       "(tests/test_architecture.py, ALLOWED_AREAS)")
            continue
        allowed = ALLOWED_MODULES.get(module, ALLOWED_AREAS[src_area])
        for line, target in imported_modules(path, module):
            if target != "vibr" and not target.startswith("vibr."):
                continue
            dst = area(target)
            if dst == src_area or (not dst and src_area == ""):
                if module not in ALLOWED_MODULES:
                    continue
            if dst not in allowed and not (dst == src_area and module not in ALLOWED_MODULES):
                out.append(f"{path.relative_to(SRC.parent)}:{line}: {module} imports {target} "
                           f"({src_area or 'vibr'} must not import {dst or 'vibr'})")
    return out


def import_graph() -> dict[str, set[str]]:
    """module → the vibr modules it imports, at any depth."""
    graph = {}
    for path, module in _modules():
        graph[module] = {t for _, t in imported_modules(path, module)
                         if (t == "vibr" or t.startswith("vibr.")) and t != module}
    return graph


def import_cycles(graph=None) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    graph = import_graph() if graph is None else graph
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def root_modules() -> list[str]:
    return sorted(p.stem for p in PKG.glob("*.py"))


def print_calls() -> list[str]:
    out = []
    for path, module in _modules():
        if area(module) == "cli":
            continue
        for node in ast.walk(_tree(path)):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                out.append(f"{path.relative_to(SRC.parent)}:{node.lineno}: print( in {module}")
    return out


def long_functions(limit: int = MAX_FUNCTION_LINES) -> list[str]:
    out = []
    for path, _ in _modules():
        for node in ast.walk(_tree(path)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    out.append(f"{path.relative_to(SRC.parent)}:{node.lineno}: {node.name} is {n} lines")
    return out


#: The most keyword options a public function of the library may take before they belong in
#: an options dataclass (docs/explanation/architecture.md; compiled kernels, which take arrays, aside).
MAX_OPTIONS = 11


def many_options(limit: int = MAX_OPTIONS) -> list[str]:
    out = []
    for path, _ in _modules():
        for node in ast.walk(_tree(path)):
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
    assert not bad, "imports outside the allow-list (docs/explanation/architecture.md):\n" + "\n".join(bad)


def test_no_import_cycles():
    cycles = import_cycles()
    assert not cycles, "modules that import each other (at any depth):\n" + "\n".join(map(str, cycles))


def test_few_modules_at_the_root():
    mods = root_modules()
    assert len(mods) <= MAX_ROOT_MODULES, f"{len(mods)} modules at src/vibr/: {mods}"


def test_render_and_stereo_do_not_import_io():
    bad = [f"{m} imports {t}" for m, ts in import_graph().items() for t in ts
           if area(m) in ("render", "stereo") and area(t) == "io"]
    assert not bad, "\n".join(bad)


#: packages only the benchmarks use (pyproject.toml's ``bench`` extra): vibr never imports them
BENCH_ONLY = ("open3d",)


def test_vibr_never_imports_the_benchmark_extras():
    """The ``bench`` extra (open3d, for benchmarks/quality/mesh_peer.py) is not a dependency of vibr."""
    import re

    bad = [f"{path.relative_to(SRC.parent)}:{line}: imports {name}" for path, module in _modules()
           for line, name in imported_modules(path, module) if name.split(".")[0] in BENCH_ONLY]
    assert not bad, "\n".join(bad)
    toml = (SRC.parent / "pyproject.toml").read_text()  # (tomllib is Python 3.11+)
    dependencies = re.search(r"^dependencies = \[(.*?)\]", toml, re.S | re.M).group(1)
    bench = re.search(r"^bench = \[(.*?)\]", toml, re.S | re.M)
    assert bench and "open3d-cpu" in bench.group(1) and "open3d" not in dependencies


def test_the_architecture_page_lists_the_allow_list():
    """docs/explanation/architecture.md's table is the allow-list, row for row."""
    import re

    page = (SRC.parent / "docs" / "explanation" / "architecture.md").read_text()
    rows = {}
    for m in re.finditer(r"^\| `([\w_]*)`[^|]*\|[^|]*\| ([^|]*) \|$", page, re.M):
        rows[m.group(1)] = {x.strip(" `") for x in m.group(2).split(",") if x.strip(" `—-")}
    want = {k or "vibr": v for k, v in ALLOWED_AREAS.items()}
    rows = {k: {("vibr" if x == "vibr" else x) for x in v} for k, v in rows.items()}
    missing = sorted(set(want) - set(rows))
    differ = sorted(k for k in want if k in rows and rows[k] != {x or "vibr" for x in want[k]})
    assert not missing and not differ, f"architecture.md rows missing {missing}, differing {differ}"


def test_cycles_are_found():
    assert import_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []


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
    assert any("area 'bogus'" in v for v in _planted_area(pkg))
    assert any("print(" in v for v in print_calls())
    assert any("f is" in v for v in long_functions())
    assert any("g takes 12 options" in v for v in many_options())


def _planted_area(pkg):
    (pkg / "bogus.py").write_text("")
    return import_violations()


def test_doc_references_resolve():
    """Every "docs/NAME.md" the code cites exists, and every "docs/explanation/method.md §N" names a
    numbered section of it (a user of the package has the repository, nothing else)."""
    import re

    root = SRC.parent
    method = (root / "docs" / "explanation" / "method.md").read_text()
    sections = set(re.findall(r"^## (\d+)\. ", method, re.M))
    bad = []
    for path, _ in _modules():
        text = path.read_text()
        for m in re.finditer(r"docs/([\w/.-]+\.md)", text):
            if not (root / "docs" / m.group(1)).is_file():
                bad.append(f"{path.relative_to(root)}: cites missing docs/{m.group(1)}")
        for m in re.finditer(r"docs/explanation/method\.md §(\d+)(?:[-–](\d+))?", text):
            for n in filter(None, m.groups()):
                if n not in sections:
                    bad.append(f"{path.relative_to(root)}: docs/explanation/method.md §{n} does not exist")
        for m in re.finditer(r"(?<![/\w])METHOD(?:\.md)? (?:§|eq)", text):
            bad.append(f"{path.relative_to(root)}: a reference to METHOD outside docs/ ({m.group(0)!r})")
    assert len(sections) >= 10
    assert not bad, "\n".join(bad)
