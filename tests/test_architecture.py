"""The server side never imports the simulator, where ground truth lives."""

from __future__ import annotations

import ast
from pathlib import Path

import acslam

PACKAGE = Path(acslam.__file__).parent
SERVER_SIDE = (
    "slam",
    "mapping",
    "exploration",
    "planning",
    "server.py",
    "messages.py",
    "features.py",
)


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_server_side_does_not_import_the_simulator() -> None:
    checked = 0
    for part in SERVER_SIDE:
        target = PACKAGE / part
        files = sorted(target.rglob("*.py")) if target.is_dir() else [target]
        for path in files:
            if not path.exists():
                continue
            checked += 1
            offending = {name for name in _imports(path) if name.startswith("acslam.sim")}
            assert not offending, f"{path.relative_to(PACKAGE)} imports {offending}"
    assert checked >= 1
