"""Name -> plugin registries, one per pipeline stage kind.

A plugin is a class implementing the stage's protocol (:mod:`acslam.pipeline.stages`)
plus the pydantic model of its parameters. It registers under a name with a decorator::

    @ALLOCATORS.register("nearest", NearestParams)
    class NearestAllocator: ...

and a scenario picks it by that name, ``algorithms.allocator: {name: nearest, ...}``; the
section is validated by the plugin's own ``Params``. A third-party package adds its own by
naming a module in the ``acslam.plugins`` entry-point group, imported on first lookup.

A plugin may instead be *declared* on its ``Params`` model with the ``"module:attribute"``
of its implementation, which is imported when the plugin is first built::

    @ALLOCATORS.declare("my_package.nearest:NearestAllocator")
    class NearestParams(StageParams):
        name: Literal["nearest"] = "nearest"

The built-ins are declared so, in the ``params`` module of each stage package
(:data:`BUILTIN_PARAMS_MODULES`): validating a scenario, ``--help`` or a one-line error
then imports none of GTSAM, numba or SciPy.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any, TypeVar

from acslam.config import StageParams
from acslam.errors import PluginError
from acslam.pipeline import stages

ENTRY_POINT_GROUP = "acslam.plugins"

BUILTIN_PARAMS_MODULES = (
    "acslam.slam.params",
    "acslam.mapping.params",
    "acslam.exploration.params",
    "acslam.planning.params",
)

T = TypeVar("T")
P = TypeVar("P", bound=type[StageParams])


@dataclass
class Plugin:
    """One registered implementation of a stage: its factory (a class or function called
    with the params and the stage's context), or where to import it from."""

    kind: str
    name: str
    params: type[StageParams]
    _factory: Callable[..., Any] | str

    @property
    def factory(self) -> Callable[..., Any]:
        if isinstance(self._factory, str):
            module, _, attribute = self._factory.partition(":")
            try:
                self._factory = getattr(importlib.import_module(module), attribute)
            except (ImportError, AttributeError) as exc:
                raise PluginError(
                    f"{self.kind} {self.name!r}: cannot import {self._factory!r}: {exc}"
                ) from None
        return self._factory


class Registry:
    """The plugins of one stage kind, e.g. every allocator."""

    def __init__(self, kind: str, default: str, protocol: type) -> None:
        self.kind = kind
        self.default = default
        self.protocol = protocol
        self._plugins: dict[str, Plugin] = {}

    def register(self, name: str, params: type[StageParams]) -> Callable[[T], T]:
        """Decorator: register the decorated class as the ``name`` plugin of this kind."""

        def decorate(factory: T) -> T:
            self._add(name, params, factory)  # type: ignore[arg-type]
            return factory

        return decorate

    def declare(self, implementation: str) -> Callable[[P], P]:
        """Decorator on a Params model: register the plugin its ``name`` field names,
        whose factory ``"module:attribute"`` is imported when the plugin is first built."""
        if implementation.count(":") != 1:
            raise PluginError(f"{self.kind}: expected 'module:attribute', got {implementation!r}")

        def decorate(params: P) -> P:
            self._add(params.model_fields["name"].default, params, implementation)
            return params

        return decorate

    def _add(self, name: str, params: type[StageParams], factory: Callable | str) -> None:
        declared = params.model_fields["name"].default
        if declared != name:
            raise PluginError(f"{self.kind} {name!r}: its Params model declares name {declared!r}")
        existing = self._plugins.get(name)
        if existing is not None and existing._factory != factory:
            raise PluginError(f"{self.kind} {name!r} is registered twice")
        self._plugins[name] = Plugin(self.kind, name, params, factory)

    def unregister(self, name: str) -> None:
        """Remove a plugin (for tests that register their own)."""
        self._plugins.pop(name, None)

    def get(self, name: str) -> Plugin:
        load_plugins()
        try:
            return self._plugins[name]
        except KeyError:
            raise PluginError(
                f"unknown {self.kind} {name!r} (registered: {', '.join(self.names())})"
            ) from None

    def names(self) -> list[str]:
        """The registered names, sorted: CLI choices and config validation use these."""
        load_plugins()
        return sorted(self._plugins)

    def default_params(self) -> StageParams:
        return self.get(self.default).params()

    def create(self, params: StageParams, **context: Any) -> Any:
        """An instance of the plugin ``params.name``, built from its params and the
        stage's context (what the protocol's docstring lists)."""
        return self.get(params.name).factory(params, **context)


_loaded = False


def load_plugins() -> None:
    """Declare the built-in plugins and import every ``acslam.plugins`` entry point, once."""
    global _loaded
    if _loaded:
        return
    _loaded = True
    for module in BUILTIN_PARAMS_MODULES:
        importlib.import_module(module)
    for entry in entry_points(group=ENTRY_POINT_GROUP):
        try:
            entry.load()
        except Exception as exc:
            raise PluginError(
                f"entry point {entry.name!r} ({entry.value}) of group {ENTRY_POINT_GROUP!r} "
                f"cannot be loaded: {type(exc).__name__}: {exc}"
            ) from None


LOCALIZERS = Registry("localizer", "isam2", stages.Localizer)
MAPPERS = Registry("mapper", "log-odds", stages.Mapper)
FRONTIER_DETECTORS = Registry("frontier_detector", "ewfd", stages.FrontierDetector)
CLUSTERERS = Registry("clusterer", "dbscan", stages.Clusterer)
ALLOCATORS = Registry("allocator", "factor-graph", stages.Allocator)
GLOBAL_PLANNERS = Registry("global_planner", "astar", stages.GlobalPlanner)
LOCAL_PLANNERS = Registry("local_planner", "fgp", stages.LocalPlanner)

REGISTRIES: dict[str, Registry] = {
    r.kind: r
    for r in (
        LOCALIZERS,
        MAPPERS,
        FRONTIER_DETECTORS,
        CLUSTERERS,
        ALLOCATORS,
        GLOBAL_PLANNERS,
        LOCAL_PLANNERS,
    )
}
"""Kind -> registry; the kinds are also the stage sections of ``algorithms``."""
