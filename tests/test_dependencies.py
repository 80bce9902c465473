"""Every package tdmon imports is declared in pyproject.toml: read from the source with ast
(imports inside functions included), each top-level module outside the standard library is
mapped to the distribution that installs it and looked up among the dependencies and extras."""

from __future__ import annotations

import ast
import importlib.metadata
import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _imported_modules() -> dict[str, str]:
    """Top-level modules imported anywhere in tdmon/ (standard library and tdmon aside), each
    with one file that imports it."""
    found: dict[str, str] = {}
    for path in sorted((ROOT / "tdmon").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                if top != "tdmon" and top not in sys.stdlib_module_names:
                    found.setdefault(top, str(path.relative_to(ROOT)))
    return found


def _normalised(name: str) -> str:
    """A distribution name as the package index compares them (PEP 503)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def _declared() -> set[str]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    requirements = list(project["dependencies"])
    for extra in project.get("optional-dependencies", {}).values():
        requirements += extra
    return {_normalised(re.split(r"[\s<>=!~;\[]", requirement, maxsplit=1)[0])
            for requirement in requirements}


def test_every_imported_package_is_declared() -> None:
    distributions = importlib.metadata.packages_distributions()
    declared = _declared()
    undeclared = []
    for module, where in _imported_modules().items():
        names = {_normalised(name) for name in distributions.get(module, [])}
        assert names, f"{module} (imported in {where}) is not installed"
        if not names & declared:
            undeclared.append(f"{module} ({', '.join(sorted(names))}, imported in {where})")
    assert not undeclared, "imported but not in pyproject.toml: " + "; ".join(undeclared)


def test_the_check_sees_the_imports_it_must() -> None:
    # the imports the check reads include ones inside functions (pyarrow, dask, serial)
    modules = _imported_modules()
    assert {"numpy", "aiomqtt", "paho", "orjson", "mcap", "pyarrow", "dask", "serial"} <= set(
        modules)
    assert "msgspec" not in modules and "zstandard" not in modules
