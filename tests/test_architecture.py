"""The package's import graph runs one way (issue 20): its nodes are mtwin's subpackages and
top-level modules, its edges every import between them — at module top and inside functions
alike (a function-level import hides a cycle, it does not remove it).  Read from the source
with ast, so the test needs nothing imported."""
from __future__ import annotations

import ast
import re
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
                if a != b:
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


DOC = ROOT / "docs" / "architecture.md"


def documented_layers() -> list[list[str]]:
    """The layers of ``docs/architecture.md``'s drawing, top first: each line of the drawing that
    starts with a name (one space in) is a layer, its names two spaces apart, a description
    after three or more."""
    text = DOC.read_text(encoding="utf-8")
    start = text.index("```", text.index("## Layers: imports run one way")) + 3
    block = text[start:text.index("```", start)]
    layers = []
    for line in block.splitlines():
        m = re.match(r"^ ([A-Za-z_]\w*/?(?:  [A-Za-z_]\w*/?)*)(?:\s{3,}|$)", line)
        if m:
            layers.append(["mtwin" if n == "mtwin" else "mtwin." + n.rstrip("/") for n in m.group(1).split("  ")])
    return layers


def test_imports_run_down_the_documented_layers():
    layers = documented_layers()
    level = {n: k for k, names in enumerate(layers) for n in names}
    edges, _ = import_graph()
    nodes = set(edges) | {b for a in edges for b in edges[a]}
    nodes |= {_node(_module_name(p)[0]) for p in PKG.rglob("*.py")}
    missing = sorted(nodes - set(level))
    assert not missing, f"packages and modules the drawing in docs/architecture.md does not name: {missing}"
    named_only = sorted(set(level) - nodes)
    assert not named_only, f"the drawing names what the code does not have: {named_only}"
    up = [f"{a} → {b} (in {sorted(set(edges[a][b]))[:2]})" for a in edges for b in edges[a] if level[b] < level[a]]
    assert not up, f"imports upwards, against the layers of docs/architecture.md: {up}"


def test_the_layers_are_read_as_drawn():
    layers = documented_layers()
    assert layers[0] == ["mtwin", "mtwin.__main__"] and layers[1] == ["mtwin.cli"]
    assert ["mtwin.loop", "mtwin.optimize", "mtwin.grind", "mtwin.report"] in layers
    assert "mtwin.layout" in layers[-1] and "mtwin.warmup" in sum(layers, [])


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


def private_imports() -> list[str]:
    """``from <another package> import _name`` anywhere in mtwin (its own package's private names
    are its own business)."""
    bad = []
    for path in sorted(PKG.rglob("*.py")):
        name, package = _module_name(path)
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for n in ast.walk(tree):
            if not isinstance(n, ast.ImportFrom):
                continue
            if n.level:
                base = package.split(".")[:len(package.split(".")) - (n.level - 1)]
                target = ".".join(base + ([n.module] if n.module else []))
            else:
                target = n.module or ""
            if not target.startswith("mtwin"):
                continue
            names = [a.name for a in n.names] if n.module else []
            parts = target.split(".")
            private = [x for x in parts[1:] + names if x.startswith("_") and not (x.startswith("__") and x.endswith("__"))]
            for a in ([] if n.module else [a.name for a in n.names]):
                if _node(target + "." + a) != _node(name) and a.startswith("_") and not a.startswith("__"):
                    private.append(a)
            # (a kernel calls another package's kernel directly: numba types it as a global)
            kernel_to_kernel = name.split(".")[-1].endswith("kernel") and all(x.endswith("kernel") for x in private)
            if private and _node(target) != _node(name) and not kernel_to_kernel:
                bad.append(f"{name}:{n.lineno} imports {', '.join(private)} from {target}")
    return bad


def test_no_module_imports_a_private_name_of_another_package():
    bad = private_imports()
    assert not bad, bad


# ------------------------------------------------------------------ kernel arrays by name

#: arrays that cross a kernel boundary, by the names the code gives them: the planner's
#: profile, the loop's cut outputs and counters, the engagement's step scalars and sums; their
#: columns are named once, in mtwin.layout
KERNEL_NAMES = {"prof", "cut_out", "segp", "eng_q", "eng_sums"}
KERNEL_ATTRS = {"prof", "cut", "seg", "q", "sums"}  # plan.prof, trace.cut, state.seg, engagement.q, .sums


def literal_kernel_indices() -> list[str]:
    """``prof[i, 3]``, ``trace.cut[:, 2]``, ``state.seg[5]``…: an integer literal in the index of
    a kernel array, anywhere but ``layout.py`` (the run kernel's axis-state rows too)."""
    bad = []
    for path in sorted(PKG.rglob("*.py")):
        if path.name == "layout.py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for n in ast.walk(tree):
            if not isinstance(n, ast.Subscript):
                continue
            v = n.value
            named = (isinstance(v, ast.Name) and (v.id in KERNEL_NAMES or
                                                  (v.id == "axes" and path.name == "_runkernel.py"))) or \
                (isinstance(v, ast.Attribute) and v.attr in KERNEL_ATTRS)
            if not named:
                continue
            parts = n.slice.elts if isinstance(n.slice, ast.Tuple) else [n.slice]
            if any(isinstance(p, ast.Constant) and isinstance(p.value, int) and not isinstance(p.value, bool)
                   for p in parts):
                bad.append(f"{path.relative_to(SRC)}:{n.lineno} {ast.unparse(n)}")
    return bad


def test_no_literal_index_into_a_kernel_array():
    bad = literal_kernel_indices()
    assert not bad, f"index kernel arrays by the names of mtwin.layout: {bad}"


def test_the_memory_guard_counts_the_widths_the_loop_allocates():
    import numpy as np

    from mtwin.motion import _runkernel as RK

    n = 10
    out = RK.allocate_outputs(n)
    # a trace keeps the line and the record (int32) where the loop keeps the segment number
    allocated = sum(a.nbytes for a in out) - out.segno.nbytes + 2 * n * np.dtype(np.int32).itemsize
    assert RK.bytes_per_sample() * n == allocated
    assert out.cut.shape[1] == len(__import__("mtwin.layout", fromlist=["x"]).CUT_SIGNALS)


def test_no_module_sets_attributes_on_another_modules_objects_behind_their_back():
    # (the program's cutting set-up was cached by object.__setattr__ on the Program, and the
    # optimiser wrote that hidden cache itself: now the twin owns the cache)
    bad = []
    for path in sorted(PKG.rglob("*.py")):
        for n in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == "__setattr__" and \
                    isinstance(n.func.value, ast.Name) and n.func.value.id == "object":
                bad.append(f"{path.relative_to(SRC)}:{n.lineno}")
    assert not bad, bad


def test_a_programs_cutting_set_up_is_read_once_per_twin_and_lives_with_the_program():
    import gc

    import mtwin
    from mtwin.motion.simulate import program_cutting

    tw = mtwin.Twin()
    prog = tw.load(b"G21 G90\n(T1 D=3 CR=0 - flat end mill)\nT1 M6\nS9000 M3\nG0 X0 Y0 Z5\nG1 Z-1 F100\nM30\n",
                   path="c.nc")
    a = program_cutting(tw, prog)
    assert program_cutting(tw, prog) is a and program_cutting(tw.replace(), prog) is a
    assert a.tool(1).diameter == 3.0
    other = tw.with_material("1045")  # another cutting part: read again
    b = program_cutting(other, prog)
    assert b is not a and program_cutting(tw, prog) is a and program_cutting(other, prog) is b
    # a twin copy per evaluation (a calibration's): the program keeps the last few set-ups
    for k in range(10):
        program_cutting(tw.with_params({"cutting.al6061.ktc": 1000.0 + k}), prog)
    assert len(tw.cutting_cache) == tw.cutting_cache.PER_PROGRAM
    n = len(tw.cutting_cache._entries)
    del prog
    gc.collect()
    assert len(tw.cutting_cache._entries) == n - 1 and len(tw.cutting_cache) == 0


def test_one_door_to_a_simulation():
    # motion.simulate.simulate_plan runs the kernels; only the Twin calls it (Twin.simulate, and
    # Twin.simulate_batch for parts in a row) — the use cases and the optimiser go through the twin
    callers = []
    for path in sorted(PKG.rglob("*.py")):
        name, _ = _module_name(path)
        for n in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(n, ast.ImportFrom) and any(a.name == "simulate_plan" for a in n.names):
                callers.append(name)
    assert callers and set(callers) == {"mtwin.twin"}, callers


# the library the commands may reach: the use cases (``api``, and the packages whose door is
# their own: optimize, grind, fleet — the package, not its modules), the report renderers, and
# what every layer shares (errors, units, io, version); ``warmup``, the kernel cache's use cases
CLI_MAY_IMPORT = ("mtwin.api", "mtwin.optimize", "mtwin.grind", "mtwin.fleet", "mtwin.warmup", "mtwin.errors",
                  "mtwin.units", "mtwin.io", "mtwin.version")
CLI_MAY_IMPORT_UNDER = ("mtwin.api.", "mtwin.report.")


def test_the_cli_reaches_the_library_through_its_use_cases():
    """Issue 36: the CLI only parses, calls a use case and renders — it imports no library
    module but the use cases' doors and the renderers."""
    bad = []
    for path in sorted(CLI.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for n in ast.walk(tree):
            if not isinstance(n, ast.ImportFrom) or n.level == 1:
                continue
            target = "mtwin." + (n.module or "") if n.level == 2 else (n.module or "")
            if not target.startswith("mtwin") or target.startswith("mtwin.cli"):
                continue
            if target in CLI_MAY_IMPORT or target.startswith(CLI_MAY_IMPORT_UNDER):
                continue
            bad.append(f"{path.name}:{n.lineno} from {target} import {', '.join(a.name for a in n.names)}")
    assert not bad, bad
