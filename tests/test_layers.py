"""The layers of docs/architecture.md hold: every tdmon import, read from the source with ast
(imports inside functions and under ``if TYPE_CHECKING`` included), points down, and no two
modules import each other, directly or around a circle.

model <- calib <- ingest/record <- daemon/replay <- cli, with config adapting TOML and the
bottom modules (units, errors, vocabulary, messages, channels) usable by every layer.
"""

from __future__ import annotations

import ast
import itertools
from collections.abc import Iterator
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "tdmon"

#: Modules every layer may use: they import nothing of tdmon above them.
BOTTOM = frozenset({"tdmon.units", "tdmon.errors", "tdmon.vocabulary", "tdmon.messages",
                    "tdmon.channels", "tdmon.slots"})

#: What each layer may import besides itself (module prefixes). None: anything.
ALLOWED: dict[str, frozenset[str] | None] = {
    "model": frozenset({"tdmon.units", "tdmon.errors", "tdmon.vocabulary"}),
    "calib": BOTTOM | {"tdmon.model"},
    "config": BOTTOM | {"tdmon.model", "tdmon.calib"},
}

#: Layers each layer must never import.
FORBIDDEN: dict[str, frozenset[str]] = {
    "ingest": frozenset({"daemon", "replay", "cli"}),
    "record": frozenset({"daemon", "replay", "cli"}),
    "config": frozenset({"ingest", "record", "daemon", "replay", "cli"}),
    "model": frozenset({"calib", "config", "ingest", "record", "daemon", "replay", "cli"}),
    "calib": frozenset({"config", "ingest", "record", "daemon", "replay", "cli"}),
}

#: Known upward imports, (importing module, imported module) -> why it is still there. Each
#: entry is a debt to pay off; the test fails when one disappears, so the list stays true.
KNOWN: dict[tuple[str, str], str] = {}

#: Known import circles between modules, each the set of its modules -> why it is still there.
#: Both go: they are being broken in parallel in issue 27, and each entry is removed when its
#: fix is merged (the test fails on a circle that is gone, so the list stays true).
KNOWN_CYCLES: dict[frozenset[str], str] = {
    frozenset({"tdmon.record.mcap_recorder", "tdmon.record.sink"}):
        "RecorderStats moves to the sink contract (issue 27)",
}


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@cache
def _modules() -> dict[str, Path]:
    return {_module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def _resolve(module: str, node: ast.ImportFrom) -> str:
    """The absolute module of a ``from ... import`` (relative imports resolved)."""
    if node.level == 0:
        return node.module or ""
    is_package = _modules()[module].name == "__init__.py"
    base = module.split(".")[: len(module.split(".")) - node.level + (1 if is_package else 0)]
    return ".".join([*base, *([node.module] if node.module else [])])


def _import_module_name(node: ast.Call) -> str | None:
    """The module of ``importlib.import_module("tdmon....")`` with a literal name, else None."""
    func = node.func
    named = ((isinstance(func, ast.Attribute) and func.attr == "import_module")
             or (isinstance(func, ast.Name) and func.id == "import_module"))
    if not named or not node.args:
        return None
    first = node.args[0]
    return first.value if isinstance(first, ast.Constant) and isinstance(first.value, str) else None


def tdmon_imports(module: str) -> Iterator[str]:
    """Every tdmon module ``module`` imports, anywhere in its source."""
    tree = ast.parse(_modules()[module].read_text(), filename=str(_modules()[module]))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(module, node)
            # `from tdmon import vocabulary` imports the module tdmon.vocabulary
            targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in _modules() else base
                       for alias in node.names]
        elif isinstance(node, ast.Call) and (name := _import_module_name(node)) is not None:
            targets = [name]
        else:
            continue
        yield from (t for t in targets if t == "tdmon" or t.startswith("tdmon."))


def layer(module: str) -> str:
    """``tdmon.calib.alarms`` -> ``calib``; a bottom module is its own (``tdmon.units`` ->
    ``units``); the package ``tdmon`` itself -> ``""``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _edges() -> Iterator[tuple[str, str]]:
    for module in _modules():
        for target in tdmon_imports(module):
            yield module, target


def _violations() -> list[tuple[str, str]]:
    found = []
    for module, target in _edges():
        own, other = layer(module), layer(target)
        if own == other or target == "tdmon":
            continue
        allowed = ALLOWED.get(own)
        outside = allowed is not None and not any(
            target == prefix or target.startswith(prefix + ".") for prefix in allowed)
        if outside or other in FORBIDDEN.get(own, ()):
            found.append((module, target))
    return sorted(set(found))


def test_the_scan_sees_imports_inside_functions() -> None:
    # config/well.py imports tdmon.units inside a function: the scan must find it
    assert "tdmon.units" in set(tdmon_imports("tdmon.config.well"))
    assert "tdmon.vocabulary" in set(tdmon_imports("tdmon.calib.backcalc"))  # `from tdmon import`
    # model/kernels.py loads the JIT kernels with importlib.import_module("tdmon.model._kernels")
    assert "tdmon.model._kernels" in set(tdmon_imports("tdmon.model.kernels"))
    # steps/compose.py names WellFile only under `if TYPE_CHECKING`
    assert "tdmon.config.well_file" in set(tdmon_imports("tdmon.daemon.steps.compose"))


def test_bottom_modules_import_nothing_of_tdmon_above_them() -> None:
    for module in BOTTOM:
        above = set(tdmon_imports(module)) - BOTTOM
        assert not above, f"{module} imports {above}"
    assert not set(tdmon_imports("tdmon.vocabulary")), "the vocabulary must import nothing"


def test_no_upward_import() -> None:
    found = _violations()
    unexpected = [edge for edge in found if edge not in KNOWN]
    assert not unexpected, "upward imports:\n" + "\n".join(f"  {a} -> {b}" for a, b in unexpected)
    gone = [edge for edge in KNOWN if edge not in found]
    assert not gone, f"fixed, remove from KNOWN: {gone}"


def _package_graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for module, target in _edges():
        own, other = layer(module), layer(target)
        if own == "cli" or not own or not other or own == other:
            continue  # cli may import everything; bottom modules are checked above
        graph.setdefault(own, set()).add(other)
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the directed graph, or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(node: str, path: list[str]) -> list[str] | None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:  # back to a node of the current path
                return [*path[path.index(nxt):], nxt]
            if nxt not in state and (found := visit(nxt, [*path, nxt])):
                return found
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start, [start])):
            return found
    return None


def test_no_import_cycle_between_subpackages() -> None:
    cycle = _cycle(_package_graph())
    assert cycle is None, " -> ".join(cycle or ())


@pytest.mark.parametrize(("graph", "cyclic"), [
    ({"a": {"b"}, "b": {"c"}}, False),
    ({"a": {"b"}, "b": {"c"}, "c": {"a"}}, True),
    ({"config": {"ingest"}, "ingest": {"config"}}, True),
])
def test_cycle_finder(graph: dict[str, set[str]], cyclic: bool) -> None:
    assert (_cycle(graph) is not None) is cyclic


def test_config_and_ingest_do_not_import_each_other_both_ways() -> None:
    graph = _package_graph()
    assert "ingest" not in graph.get("config", set())


def _module_graph() -> dict[str, set[str]]:
    """Module -> the tdmon modules it imports. The root package ``tdmon`` is left out: every
    import of a submodule runs it first anyway, and it imports the API only lazily (on the
    first use of one of its names), so an edge to it orders nothing."""
    graph: dict[str, set[str]] = {}
    for module, target in _edges():
        if target not in ("tdmon", module):
            graph.setdefault(module, set()).add(target)
    return graph


def _reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    """Every node an import path from ``start`` reaches (``start`` itself only round a circle)."""
    seen: set[str] = set()
    todo = [start]
    while todo:
        for nxt in graph.get(todo.pop(), ()):
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen


def _circles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """The import circles of ``graph``: each the set of nodes that reach one another (a
    strongly connected component of more than one node)."""
    reach = {node: _reachable(graph, node) for node in graph}
    circles = {frozenset({node} | {other for other in reach[node] if node in reach.get(other, ())})
               for node in graph if node in reach[node]}
    return sorted(circles, key=sorted)


def _describe(circle: frozenset[str], graph: dict[str, set[str]]) -> str:
    """One closed import path inside ``circle``, for the failure message."""
    inside = {module: graph.get(module, set()) & circle for module in circle}
    return " -> ".join(_cycle(inside) or sorted(circle))


def test_no_import_cycle_between_modules() -> None:
    graph = _module_graph()
    circles = _circles(graph)
    unexpected = [circle for circle in circles if circle not in KNOWN_CYCLES]
    assert not unexpected, "import circles:\n" + "\n".join(
        f"  {_describe(circle, graph)}" for circle in unexpected)
    gone = [sorted(circle) for circle in KNOWN_CYCLES if circle not in circles]
    assert not gone, f"broken, remove from KNOWN_CYCLES: {gone}"


@pytest.mark.parametrize(("graph", "circles"), [
    ({"a": {"b"}, "b": {"c"}}, []),
    ({"a": {"b"}, "b": {"a"}, "c": {"a"}}, [{"a", "b"}]),
    # a triangle, a separate pair, and a module hanging off them that is in no circle
    ({"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": {"e"}, "e": {"d"}, "f": {"a"}},
     [{"a", "b", "c"}, {"d", "e"}]),
    # two circles through one module are one component
    ({"a": {"b", "c"}, "b": {"a"}, "c": {"a"}}, [{"a", "b", "c"}]),
    # the circle this test was written for: the builder and the steps it builds
    ({"tdmon.daemon.build": {"tdmon.daemon.steps.compose"},
      "tdmon.daemon.steps.compose": {"tdmon.daemon.build"}},
     [{"tdmon.daemon.build", "tdmon.daemon.steps.compose"}]),
])
def test_circle_finder(graph: dict[str, set[str]], circles: list[set[str]]) -> None:
    assert sorted(map(sorted, _circles(graph))) == sorted(map(sorted, circles))
    for circle in _circles(graph):
        path = _describe(circle, graph).split(" -> ")
        assert path[0] == path[-1] and set(path) <= circle  # closed, inside the circle
        assert all(b in graph[a] for a, b in itertools.pairwise(path))  # along real imports
