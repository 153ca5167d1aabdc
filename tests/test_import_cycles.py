"""No import cycles between pushtoknow modules (docs/DESIGN.md §1), lazy imports included.

Every module under src/pushtoknow is parsed with `ast` and every `import pushtoknow.a.b` and
`from pushtoknow.a import b` in it is an edge, wherever it stands: at the top, inside a
function or method, under a runtime `if`/`try`, and under `if TYPE_CHECKING:` too. A
function-level import only hides a loop until the function runs. TYPE_CHECKING-only imports
never run, but they are counted all the same (as `tests/test_layers.py` counts them): a type
that two modules both need belongs in a lower module, and a loop that is annotation-only today
becomes a runtime one the first time the type is used at run time (`isinstance`, a default).

Resolution: `from pushtoknow.a import b` names module `pushtoknow.a.b` when b is a submodule
and `pushtoknow.a` otherwise; importing a package (`pushtoknow.a`) is importing its
`__init__`; `import pushtoknow.a.b` imports `pushtoknow.a.b` (its parent packages'
`__init__`s run first, but they are not counted as edges of the importer: a package whose
`__init__` re-exports a submodule would otherwise form a cycle with every module that imports
from one of its siblings). Relative imports (`from . import b`, `from .a import b`; the code
has none at present) are resolved against the importing module's package the same way.

A cycle is a strongly connected component of more than one module (Tarjan's algorithm, below,
so the test needs no graph library); a module importing itself is reported too.
"""

from __future__ import annotations

import ast
from collections.abc import Mapping
from pathlib import Path

import pushtoknow

ROOT = Path(pushtoknow.__file__).parent
PACKAGE = "pushtoknow"


def module_name(path: Path, root: Path = ROOT) -> str:
    """Dotted name of the module at `path` under `root` (a package is its `__init__`)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join([PACKAGE, *parts])


def all_modules(root: Path = ROOT) -> dict[str, Path]:
    """{dotted name: path} of every module under `root`, the package `PACKAGE`."""
    return {module_name(p, root): p for p in sorted(root.rglob("*.py"))}


def _absolute(node: ast.ImportFrom, importer: str, is_package: bool) -> str:
    """The module a `from ... import` names, relative levels resolved against `importer`."""
    if node.level == 0:
        return node.module or ""
    base = importer.split(".")
    if not is_package:
        base = base[:-1]  # a module's `.` is its package; a package's `.` is itself
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def imported_modules(path: Path, modules: Mapping[str, Path], root: Path = ROOT) -> set[str]:
    """The modules among `modules` that the module at `path` imports, anywhere in it."""
    importer = module_name(path, root)
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            target = _absolute(node, importer, is_package)
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                found.add(sub if sub in modules else target)
    return {m for m in found if m in modules}


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """{module: the pushtoknow modules it imports} for every module under `root`."""
    modules = all_modules(root)
    return {name: imported_modules(path, modules, root) for name, path in modules.items()}


def find_cycles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of `graph` (node → successors) that hold a cycle: more
    than one node, or one node with an edge to itself. Each sorted; the list sorted too.
    Tarjan's algorithm, iterative (no recursion limit on deep graphs)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    nodes = set(graph) | {n for succ in graph.values() for n in succ}
    for root in sorted(nodes):
        if root in index:
            continue
        work = [(root, iter(sorted(graph.get(root, ()))))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            for nxt in successors:
                if nxt not in index:
                    index[nxt] = low[nxt] = len(index)
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(sorted(graph.get(nxt, ())))))
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1 or node in graph.get(node, ()):
                        found.append(sorted(component))
    return sorted(found)


def _describe(cycle: list[str], graph: Mapping[str, set[str]]) -> str:
    members = set(cycle)
    edges = [f"    {a} -> {b}" for a in cycle for b in sorted(graph[a] & members)]
    return " <-> ".join(cycle) + "\n" + "\n".join(edges)


# ------------------------------------------------------------------------------------------
def test_no_import_cycles_between_pushtoknow_modules():
    graph = import_graph()
    cycles = find_cycles(graph)
    assert not cycles, "import cycles (move what both need into a lower module):\n" + "\n".join(
        _describe(c, graph) for c in cycles
    )


def test_the_graph_sees_lazy_relative_type_checking_and_submodule_imports(tmp_path):
    """The parser on a toy package: function-level, relative and TYPE_CHECKING imports are
    edges, `from pkg import sub` names the submodule and `from pkg.mod import name` the
    module; the loops they hide are found."""
    src = {
        "__init__.py": "",
        "a.py": "import typing\n"
        "if typing.TYPE_CHECKING:\n    from pushtoknow.e import Thing\n"
        "def f():\n    from pushtoknow import b\n",
        "b.py": "from . import a\nimport numpy\n",
        "c.py": "from pushtoknow.sub import d\nfrom pushtoknow.e import name_in_e\n",
        "e.py": "",
        "sub/__init__.py": "from ..c import x\n",
        "sub/d.py": "def g():\n    from .. import c\n",
    }
    for rel, text in src.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    graph = import_graph(tmp_path)
    p = PACKAGE
    assert graph == {
        p: set(),
        f"{p}.a": {f"{p}.b", f"{p}.e"},
        f"{p}.b": {f"{p}.a"},
        f"{p}.c": {f"{p}.sub.d", f"{p}.e"},
        f"{p}.e": set(),
        f"{p}.sub": {f"{p}.c"},
        f"{p}.sub.d": {f"{p}.c"},
    }
    assert find_cycles(graph) == [[f"{p}.a", f"{p}.b"], [f"{p}.c", f"{p}.sub.d"]]


def test_find_cycles_on_a_toy_graph():
    graph = {
        "a": {"b"},
        "b": {"c"},
        "c": {"a", "d"},  # a → b → c → a
        "d": {"e"},
        "e": {"f"},
        "f": set(),  # d → e → f: no cycle
        "g": {"g"},  # a self-import
        "h": {"i"},
        "i": {"h", "j"},  # h ↔ i, reached from nowhere else
        "j": {"k"},  # k only as a successor
    }
    assert find_cycles(graph) == [["a", "b", "c"], ["g"], ["h", "i"]]
    assert find_cycles({"x": {"y"}, "y": set()}) == []
    chain = {str(i): {str(i + 1)} for i in range(5000)}  # deep: no recursion limit
    chain["5000"] = {"0"}
    assert find_cycles(chain) == [sorted(str(i) for i in range(5001))]
