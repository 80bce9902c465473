"""The layers of docs/architecture.md hold: every tdmon import, read from the source with ast
(imports inside functions and under ``if TYPE_CHECKING`` included), points down.

model <- calib <- ingest/record <- daemon/replay <- cli, with config adapting TOML and the
bottom modules (units, errors, vocabulary, messages, channels) usable by every layer.
"""

from __future__ import annotations

import ast
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
