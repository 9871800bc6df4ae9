"""The package's layers, enforced on the source (an AST walk, so lazy imports count).

Layers, lowest first (a layer imports only layers below it, never a sibling):

    errors  <-  _shared  <-  io, neighbors, stats, synth  <-  features
            <-  classify, segment  <-  pipeline, report  <-  cli

``synth`` depends on NumPy only: of lidarstat it imports ``_shared`` and ``errors`` alone.
No module imports a private module or a private name (``_x``) of another subpackage; only
``_shared`` is private to the package and shared by all of it.  Module-level imports form
no cycle.
"""

from __future__ import annotations

import ast
import dataclasses
import textwrap
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = "lidarstat"

#: The layer of each top-level module or subpackage (higher imports lower).
LEVELS = {
    "errors": 0,
    "_shared": 1,
    "io": 2, "neighbors": 2, "stats": 2, "synth": 2,
    "features": 3,
    "classify": 4, "segment": 4,
    "pipeline": 5, "report": 5,
    "cli": 6,
}
#: Units that may import only these (a stricter rule than their level).
ONLY = {"synth": {"errors", "_shared"}}
#: Units that may import anything: the package root (lazy attributes) and ``python -m``.
TOP = {"", "__main__"}


@dataclasses.dataclass(frozen=True)
class Import:
    """One import statement: who imports what, where, and whether at module level."""

    source: str          # dotted name of the importing module
    target: str          # dotted name of the imported module (or of the name's module)
    name: str | None     # the imported name for ``from m import name`` when not a module
    lineno: int
    module_level: bool


def _module_name(path: Path, root: Path) -> tuple[str, bool]:
    parts = list(path.relative_to(root).with_suffix("").parts)
    is_package = parts[-1] == "__init__"
    if is_package:
        parts = parts[:-1]
    return ".".join(parts), is_package


def collect_imports(root: Path, package: str = PACKAGE) -> list[Import]:
    """Every import of `package`'s modules under `root`, inside functions included."""
    modules = {}
    for path in sorted((root / package).rglob("*.py")):
        modules[_module_name(path, root)] = path
    known = {name for name, _ in modules}
    found = []
    for (source, is_package), path in modules.items():
        here = source.split(".") if is_package else source.split(".")[:-1]
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        top = {id(node) for node in tree.body}
        top |= {id(n) for node in tree.body if isinstance(node, (ast.If, ast.Try))
                for n in ast.walk(node)}
        for node in ast.walk(tree):
            level = id(node) in top
            if isinstance(node, ast.Import):
                for alias in node.names:
                    found.append(Import(source, alias.name, None, node.lineno, level))
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here[: len(here) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    if sub in known:
                        found.append(Import(source, sub, None, node.lineno, level))
                    else:
                        found.append(Import(source, target, alias.name, node.lineno, level))
    return [imp for imp in found if imp.target == package or imp.target.startswith(package + ".")]


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _private_part(target: str, name: str | None) -> str | None:
    parts = target.split(".")[2:] + ([name] if name else [])
    for part in parts:
        if part.startswith("_") and not (part.startswith("__") and part.endswith("__")):
            return part
    return None


def check(imports: list[Import], levels=None, only=None) -> list[str]:
    """Broken layer rules, one message each naming importer, imported module and rule."""
    levels = LEVELS if levels is None else levels
    only = ONLY if only is None else only
    problems = []
    for imp in imports:
        src, dst = _unit(imp.source), _unit(imp.target)
        where = f"{imp.source} (line {imp.lineno}) imports {imp.target}" + (
            f".{imp.name}" if imp.name else "")
        if src == dst or src in TOP or dst == "":
            continue
        if src not in levels or dst not in levels:
            problems.append(f"{where}: unknown layer {src if src not in levels else dst!r}")
        elif src in only and dst not in only[src]:
            problems.append(f"{where}: {src} may import only {sorted(only[src])}")
        elif levels[dst] > levels[src]:
            problems.append(f"{where}: upward import ({src} is below {dst})")
        elif levels[dst] == levels[src]:
            problems.append(f"{where}: sibling import ({src} and {dst} are one layer)")
        elif dst != "_shared" and (part := _private_part(imp.target, imp.name)):
            problems.append(f"{where}: private {part!r} of {dst} (import the public name from {dst})")
    problems += [f"import cycle at module level: {' -> '.join(c)}" for c in _cycles(imports)]
    return problems


def _cycles(imports: list[Import]) -> list[list[str]]:
    graph: dict[str, set[str]] = {}
    for imp in imports:
        if imp.module_level and imp.target != imp.source:
            graph.setdefault(imp.source, set()).add(imp.target)
    cycles, state = [], {}

    def visit(node, stack):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    return cycles


def test_lidarstat_layers():
    problems = check(collect_imports(SRC))
    assert not problems, "layer rules broken:\n" + "\n".join(problems)


def public_names(root: Path, package: str = PACKAGE) -> dict[str, set[str]]:
    """``__all__`` of every subpackage's ``__init__.py`` (the names other layers may use)."""
    names = {}
    for init in sorted((root / package).glob("*/__init__.py")):
        tree = ast.parse(init.read_text(encoding="utf-8"))
        for node in tree.body:
            if (isinstance(node, ast.Assign) and len(node.targets) == 1
                    and getattr(node.targets[0], "id", None) == "__all__"):
                names[f"{package}.{init.parent.name}"] = set(ast.literal_eval(node.value))
    return names


def test_names_used_across_layers_are_in_all():
    exported = public_names(SRC)
    missing = [f"{imp.source} (line {imp.lineno}) imports {imp.target}.{imp.name}: "
               f"not in {imp.target}.__all__"
               for imp in collect_imports(SRC)
               if imp.name and imp.target in exported and _unit(imp.source) not in TOP
               and _unit(imp.source) != _unit(imp.target)
               and imp.name not in exported[imp.target]]
    assert not missing, "\n".join(missing)


def test_every_unit_has_a_layer():
    units = {p.stem if p.suffix == ".py" else p.name for p in (SRC / PACKAGE).iterdir()
             if (p.suffix == ".py" or (p / "__init__.py").exists())}
    assert units - {"__init__", "__main__"} == set(LEVELS)


# The checker itself: each rule fails on a synthetic package.
def _tree(tmp_path, files):
    for rel, text in files.items():
        path = tmp_path / "lidarstat" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text), encoding="utf-8")
    for pkg in ("", "io", "features", "classify", "segment", "synth"):
        init = tmp_path / "lidarstat" / pkg / "__init__.py"
        init.parent.mkdir(parents=True, exist_ok=True)
        if not init.exists():
            init.write_text("", encoding="utf-8")
    return check(collect_imports(tmp_path))


def test_checker_fails_on_a_lazy_upward_import(tmp_path):
    problems = _tree(tmp_path, {"features/_model.py": """
        def f():
            from ..classify import labels
            return labels
        """})
    assert problems == [("lidarstat.features._model (line 3) imports lidarstat.classify.labels: "
                         "upward import (features is below classify)")]


@pytest.mark.parametrize("files, rule", [
    ({"classify/_a.py": "from ..segment import grow\n"}, "sibling import"),
    ({"segment/_a.py": "from ..features._kernels import fit\n",
      "features/_kernels.py": "fit = 1\n"}, "private '_kernels' of features"),
    ({"segment/_a.py": "from lidarstat.features import _helper\n"}, "private '_helper'"),
    ({"synth/_a.py": "import lidarstat.io\n"}, "synth may import only"),
    ({"features/_a.py": "from ._b import x\n", "features/_b.py": "from ._a import y\n"},
     "import cycle at module level: lidarstat.features._a -> lidarstat.features._b"),
])
def test_checker_fails_on_each_rule(tmp_path, files, rule):
    problems = _tree(tmp_path, files)
    assert len(problems) == 1 and rule in problems[0], problems


def test_checker_accepts_downward_public_imports(tmp_path):
    assert _tree(tmp_path, {"classify/_a.py": "from ..features import fit\nimport numpy\n",
                            "features/_b.py": "from .._shared._jit import njit\n",
                            "_shared/_jit.py": "from ..errors import E\n",
                            "errors.py": ""}) == []
