"""The code's structure: imports only go downward (orchestrator -> builder -> fmus -> models)
and no two modules import each other, directly or round a longer cycle. Read from the source with `ast`."""
from __future__ import annotations

import ast
from pathlib import Path

from conftest import ROOT

LAYERS = ("models", "fmus", "builder", "orchestrator")  # lowest first
ALLOWED = {"models": {"models"}, "fmus": {"fmus", "models"}, "builder": {"builder", "fmus", "models"},
           "orchestrator": set(LAYERS)}


def _modules() -> dict[str, Path]:
    """Dotted module name (pantohil.<layer>....) -> source file."""
    out = {}
    for layer in LAYERS:
        for path in sorted((ROOT / layer).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(["pantohil", *parts])] = path
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The project modules `name` imports, anywhere in its source (also inside functions)."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1] + ([base] if base else []))
            targets = [base] + [f"{base}.{a.name}" for a in node.names]
        else:
            continue
        found |= {t for t in targets if t in modules}
    return found - {name}


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


# import cycles still to be removed (none may join)
PENDING_CYCLES: set[frozenset[str]] = set()


def _layer(module: str) -> str:
    return module.split(".")[1]


def test_imports_only_go_downward():
    wrong = [f"{a} imports {b}" for a, deps in _graph().items() for b in sorted(deps)
             if _layer(b) not in ALLOWED[_layer(a)]]
    assert not wrong, "\n".join(wrong)


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of the graph, or None (depth-first search, a package's own __init__ excluded)."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for dep in sorted(graph[node]):
            if node.startswith(dep + "."):
                continue  # a module importing its own package's __init__ is not a cycle of modules
            if state.get(dep) == 1:
                return stack[stack.index(dep):] + [dep]
            if dep not in state and (found := visit(dep)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_there_is_no_import_cycle():
    graph = _graph()
    for pair in PENDING_CYCLES:
        a, b = sorted(pair)
        graph[b].discard(a)
    cycle = _cycle(graph)
    assert cycle is None, " -> ".join(cycle)


def test_the_cycle_finder_finds_a_cycle():
    graph = {"pantohil.a": {"pantohil.b"}, "pantohil.b": {"pantohil.c"}, "pantohil.c": {"pantohil.a"}}
    assert _cycle(graph) == ["pantohil.a", "pantohil.b", "pantohil.c", "pantohil.a"]
