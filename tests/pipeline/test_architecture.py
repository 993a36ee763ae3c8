"""The architecture of ``pipeline``, read from its own imports (``ast`` only).

Every import counts, at the top of a module or inside a function (the command line and the
robot-side packages load lazily; a lazy import is still a dependency), and so does every
``"module:function"`` a registry names. Checked: no import cycle between modules, no import
from a layer up to a higher one (the layers below, bottom to top, as docs/architecture.md
draws them), no private name imported across packages, the robot side of the consistency
stage apart from the simulator's engines, and every package saying what it holds and what
it may import.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: bottom to top: a module may import modules of its own layer and of the layers below.
#: An entry is a module or a package (all its modules); the longest entry naming a module wins.
LAYERS = (
    ("shared words", ("pipeline", "pipeline.errors", "pipeline.types", "pipeline.validate",
                      "pipeline.progress", "pipeline.outcome", "pipeline.outputs",
                      "pipeline.runfolder")),
    ("inputs", ("pipeline.inputs",)),
    ("pycolmap adapter", ("pipeline.colmap",)),
    ("graphs", ("pipeline.association", "pipeline.commgraph", "pipeline.budget")),
    ("transport", ("pipeline.transport",)),
    ("matching", ("pipeline.matching",)),
    ("consistency", ("pipeline.consistency",)),
    ("fusion", ("pipeline.fusion",)),
    ("faults", ("pipeline.faults",)),
    ("evaluation", ("pipeline.evaluation",)),
    ("stage chain", ("pipeline.stages",)),
    ("team", ("pipeline.team",)),
    ("runs", ("pipeline.runs",)),
    ("commands", ("pipeline.commands",)),
    ("programs", ("pipeline.__main__", "pipeline.team.zygote")),
)

_HOOK = re.compile(r"^(pipeline(?:\.\w+)+):\w+$")


def _modules() -> dict[str, Path]:
    mods = {}
    for path in sorted((ROOT / "pipeline").rglob("*.py")):
        name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        mods[name.removesuffix(".__init__")] = path
    return mods


MODULES = _modules()


def _known(name: str) -> str | None:
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _imports(module: str) -> list[tuple[str, str | None]]:
    """``(imported module, imported name or None)`` of every import and registry hook."""
    path = MODULES[module]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[:len(parts) - (node.level - 1)]
                base = ".".join(parts + ([node.module] if node.module else []))
            for a in node.names:
                sub = f"{base}.{a.name}"
                out.append((sub, None) if sub in MODULES else (base, a.name))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            hook = _HOOK.match(node.value)
            if hook:
                out.append((hook.group(1), None))
    return out


def _graph() -> dict[str, set[str]]:
    graph = {}
    for m in MODULES:
        graph[m] = {t for name, _ in _imports(m) if (t := _known(name)) and t != m}
    return graph


GRAPH = _graph()


def layer_of(module: str) -> int:
    best, where = -1, None
    for k, (_, entries) in enumerate(LAYERS):
        for e in entries:
            inside = module == e or (e != "pipeline" and module.startswith(e + "."))
            if inside and len(e) > best:
                best, where = len(e), k
    if where is None:
        raise AssertionError(f"{module} is in no layer of {__name__}.LAYERS; place it")
    return where


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan), and self-imports."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                out.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle_between_modules():
    assert _cycles(GRAPH) == []


def test_the_cycle_check_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_runs_up_a_layer():
    up = [f"{m} ({LAYERS[layer_of(m)][0]}) imports {t} ({LAYERS[layer_of(t)][0]})"
          for m, targets in GRAPH.items() for t in sorted(targets)
          if layer_of(t) > layer_of(m)]
    assert up == []


def test_every_module_is_in_a_layer_and_the_root_holds_only_shared_words():
    for m in MODULES:
        layer_of(m)
    root = sorted(m for m, p in MODULES.items() if m.count(".") == 1 and p.name != "__init__.py")
    assert root == ["pipeline.__main__", "pipeline.association", "pipeline.budget",
                    "pipeline.commgraph", "pipeline.errors", "pipeline.faults",
                    "pipeline.outcome", "pipeline.outputs", "pipeline.progress",
                    "pipeline.runfolder", "pipeline.stages", "pipeline.types",
                    "pipeline.validate"]


def _package(module: str) -> str:
    """A module's package: ``pipeline.X`` for everything under ``pipeline/X``; each module of
    the root is its own."""
    return ".".join(module.split(".")[:2])


def test_no_private_name_imported_across_packages():
    private = [f"{m} imports {t}.{name}" for m in MODULES for t, name in _imports(m)
               if name and name.startswith("_") and not name.startswith("__")
               and _package(_known(t) or t) != _package(m)]
    assert private == []


def test_the_robot_side_never_imports_the_simulator():
    robot_side = [m for m in MODULES if m.startswith("pipeline.consistency.")
                  and not m.startswith("pipeline.consistency.engines")
                  and m not in ("pipeline.consistency.rules",)]
    robot_side += ["pipeline.team.robot", "pipeline.fusion.robot"]
    bad = [f"{m} imports {t}" for m in robot_side for t in sorted(GRAPH[m])
           if t.startswith("pipeline.consistency.engines")
           or t == "pipeline.transport.simulated"]
    assert bad == []


@pytest.mark.parametrize("package", sorted(m for m, p in MODULES.items()
                                           if p.name == "__init__.py"))
def test_every_package_says_what_it_holds_and_what_it_may_import(package):
    doc = ast.get_docstring(ast.parse(MODULES[package].read_text(encoding="utf-8")))
    assert doc and len(doc.split()) >= 15, f"{package}: no docstring saying what it holds"
    assert "may import" in doc.lower(), f"{package}: its docstring does not say what it may import"


def test_the_architecture_notes_list_every_module_and_layer():
    notes = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    missing = [m for m in MODULES if m != "pipeline" and
               f"{m.removeprefix('pipeline.').replace('.', '/')}" not in notes]
    assert missing == []
    for name, _ in LAYERS:
        assert name in notes, name
