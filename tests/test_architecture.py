"""The package's import graph runs one way (issue 20): its nodes are mtwin's subpackages and
top-level modules, its edges every import between them — at module top and inside functions
alike (a function-level import hides a cycle, it does not remove it).  Read from the source
with ast, so the test needs nothing imported."""
from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

from conftest import ROOT

SRC = ROOT / "src"
PKG = SRC / "mtwin"


def _module_name(path: Path) -> tuple[str, str]:
    """(the module's dotted name, the package its relative imports start from)."""
    rel = path.relative_to(SRC).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
        return ".".join(parts), ".".join(parts)
    return ".".join(parts), ".".join(parts[:-1])


def _node(module: str) -> str:
    return ".".join(module.split(".")[:2])


def import_graph():
    """(edges node -> {node: [module that imports]}, number of imports of mtwin inside functions)."""
    edges: dict = defaultdict(lambda: defaultdict(list))
    in_functions = 0
    for path in sorted(PKG.rglob("*.py")):
        name, package = _module_name(path)
        tree = ast.parse(path.read_text(encoding="utf-8"))
        inside = set()
        for fn in ast.walk(tree):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                inside.update(id(n) for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom)))
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom):
                if n.level:
                    base = package.split(".")[:len(package.split(".")) - (n.level - 1)]
                    targets = [".".join(base + [n.module])] if n.module else [".".join(base + [a.name]) for a in n.names]
                else:
                    targets = [n.module or ""]
            elif isinstance(n, ast.Import):
                targets = [a.name for a in n.names]
            else:
                continue
            targets = [t for t in targets if t == "mtwin" or t.startswith("mtwin.")]
            if targets and id(n) in inside:
                in_functions += 1
            for t in targets:
                a, b = _node(name), _node(t)
                if a != b and b != "mtwin":
                    edges[a][b].append(name)
    return edges, in_functions


def _cycles(edges) -> list:
    """The strongly connected components with more than one node (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, {}):
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

    for v in list(edges):
        if v not in index:
            visit(v)
    return out


def test_the_package_import_graph_has_no_cycle():
    edges, _ = import_graph()
    cycles = _cycles(edges)
    detail = "; ".join(" ↔ ".join(c) + " (" + ", ".join(f"{a}→{b} in {sorted(set(edges[a][b]))[:3]}" for a in c
                                                       for b in edges[a] if b in c) + ")" for c in cycles)
    assert not cycles, f"import cycles between mtwin's packages: {detail}"


def test_the_graph_is_read_as_it_is():
    # the reader itself: it sees the edges that exist (a test that could not fail would prove nothing)
    edges, in_functions = import_graph()
    assert "mtwin.motion" in edges["mtwin.optimize"] and "mtwin.layout" in edges["mtwin.cutting"]
    assert "mtwin.api" in edges["mtwin.cli"] and "mtwin.cli" not in edges["mtwin.api"]
    assert in_functions > 0
    assert _cycles({"a": {"b": []}, "b": {"c": []}, "c": {"a": []}}) == [["a", "b", "c"]]


# ------------------------------------------------------------------------- the commands

CLI = PKG / "cli"
COMMAND_LINES = 60  # the longest a command function may be


def _commands():
    """(module, function) of every command: functions decorated with ``<typer>.command``,
    ``<typer>.callback`` or a module's ``…_command`` helper."""
    for path in sorted(CLI.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for fn in tree.body:
            if not isinstance(fn, ast.FunctionDef):
                continue
            for d in fn.decorator_list:
                f = d.func if isinstance(d, ast.Call) else d
                if (isinstance(f, ast.Attribute) and f.attr in ("command", "callback")) or \
                        (isinstance(f, ast.Name) and f.id.endswith("_command")):
                    yield path.name, fn
                    break


def test_no_command_function_is_longer_than_60_lines():
    found = list(_commands())
    assert len(found) >= 20  # (the reader sees the commands)
    long = [f"{m}:{fn.name} {fn.end_lineno - fn.lineno + 1} lines" for m, fn in found
            if fn.end_lineno - fn.lineno + 1 > COMMAND_LINES]
    assert not long, f"commands over {COMMAND_LINES} lines (move the work into the library): {long}"


def test_the_cli_imports_nothing_private_and_builds_no_twin():
    bad = []
    for path in sorted(CLI.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom):
                inside = n.level == 1 or (n.module or "").startswith("mtwin.cli")
                module = (n.module or "").split(".")
                if inside:
                    continue
                private = [x for x in module + [a.name for a in n.names]
                           if x.startswith("_") and not (x.startswith("__") and x.endswith("__"))]
                if private:
                    bad.append(f"{path.name}:{n.lineno} from {'.' * n.level}{n.module or ''} import "
                               f"{', '.join(a.name for a in n.names)}")
            elif isinstance(n, ast.Call):
                f = n.func
                name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
                if name in ("Twin", "build", "from_toml"):
                    bad.append(f"{path.name}:{n.lineno} builds a twin ({name})")
    assert not bad, bad
