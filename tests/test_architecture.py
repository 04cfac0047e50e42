"""Layering: the server side never imports the simulator, where ground truth lives; the
stage packages import neither the simulator, the evaluation nor matplotlib; every
registered plugin satisfies its stage's protocol."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import acslam
from acslam.config import AlgorithmsConfig, RobotsConfig
from acslam.grid import GridSpec
from acslam.pipeline.registry import REGISTRIES

PACKAGE = Path(acslam.__file__).parent
STAGE_PACKAGES = ("slam", "mapping", "exploration", "planning", "pipeline")
SERVER_SIDE = (*STAGE_PACKAGES, "messages.py", "sources/orb.py")
FORBIDDEN_IN_STAGES = ("acslam.sim", "acslam.eval", "matplotlib")


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def _files(parts: tuple[str, ...]) -> list[Path]:
    files = []
    for part in parts:
        target = PACKAGE / part
        files += sorted(target.rglob("*.py")) if target.is_dir() else [target]
    assert all(path.exists() for path in files) and len(files) >= len(parts)
    return files


def _offending(path: Path, prefixes: tuple[str, ...]) -> set[str]:
    return {name for name in _imports(path) if name.startswith(prefixes)}


def test_server_side_does_not_import_the_simulator() -> None:
    for path in _files(SERVER_SIDE):
        offending = _offending(path, ("acslam.sim",))
        assert not offending, f"{path.relative_to(PACKAGE)} imports {offending}"


def test_stage_packages_import_neither_sim_nor_eval_nor_matplotlib() -> None:
    for path in _files(STAGE_PACKAGES):
        offending = _offending(path, FORBIDDEN_IN_STAGES)
        assert not offending, f"{path.relative_to(PACKAGE)} imports {offending}"


def test_matplotlib_is_set_up_in_one_module() -> None:
    users = [p for p in PACKAGE.rglob("*.py") if "matplotlib" in _imports(p)]
    assert [p.relative_to(PACKAGE).as_posix() for p in users] == ["eval/plotting.py"]


def _context(kind: str) -> dict:
    """What the server builds each kind of stage with (see acslam.pipeline.stages)."""
    algorithms = AlgorithmsConfig()
    spec = GridSpec(0.0, 0.0, 0.05, 40, 40)
    return {
        "localizer": {
            "scan_matching": algorithms.scan_matching,
            "starts": {0: np.zeros(3)},
        },
        "mapper": {"spec": spec},
        "frontier_detector": {"spec": spec, "mapping": algorithms.mapper},
        "local_planner": {"planning": algorithms.planning, "robots": RobotsConfig()},
    }.get(kind, {})


@pytest.mark.parametrize(
    ("kind", "name"),
    [(kind, name) for kind, registry in REGISTRIES.items() for name in registry.names()],
)
def test_every_registered_plugin_satisfies_its_protocol(kind: str, name: str) -> None:
    registry = REGISTRIES[kind]
    plugin = registry.get(name)
    assert plugin.params.model_fields["name"].default == name
    stage = registry.create(plugin.params(), **_context(kind))
    assert isinstance(stage, registry.protocol), f"{kind} {name!r} misses protocol methods"
