"""Plugin configurations of a monitored, repaired run: which expectation and repair plugins are registered.

A configuration is only a choice of plugins -- the executor, the monitors and the reasoner are the same:

* ``dual`` -- symbolic and low-level expectations (grid-maps, keypoints R_p / R_n), every repair plugin
* ``symbolic`` -- symbolic expectations only (no grid-map or keypoint plugin), every repair plugin
* ``low_level`` -- grid-map and keypoint expectations only (no symbolic expectation plugin), every repair plugin
* ``retry`` -- every expectation, but the only repair plugin is the retry / replan baseline

Offers:

* :data:`CONFIGURATIONS` -- name -> one-line description
* :func:`plugin_host` -- a :class:`~bt_meta.plugins.PluginHost` for a task file in a configuration, its memory-backed
  expectation plugins bound to the given episodic memory
* :data:`EXPERIENCE_REPAIRS` -- the experience-based repair plugins (registered when installed)
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from bt_meta.errors import BtMetaError

__all__ = ["CONFIGURATIONS", "EXPERIENCE_REPAIRS", "ConfigurationError", "available_repairs", "plugin_host"]

CONFIGURATIONS = {
    "dual": "symbolic + low-level expectations, all repair plugins",
    "symbolic": "symbolic expectations only, all repair plugins",
    "low_level": "grid-map and keypoint expectations only, all repair plugins",
    "retry": "all expectations, retry / replan baseline only",
}

#: Experience-based repair plugins of the paper (module names under ``bt_meta_plugins``).
EXPERIENCE_REPAIRS = ("object_substitution", "pose_backtracking")

_LOW_LEVEL = ("gridmap_expectations", "keypoint_expectations")
_SYMBOLIC = ("symbolic_expectations",)


class ConfigurationError(BtMetaError):
    """An unknown configuration name."""


def available_repairs() -> list[str]:
    """The experience-based repair plugins installed (importable) in this environment."""
    found = []
    for name in EXPERIENCE_REPAIRS:
        try:
            importlib.import_module(f"bt_meta_plugins.{name}")
        except ImportError:
            continue
        found.append(name)
    return found


def plugin_host(task_file: str | Path, memory: Any, *, configuration: str = "dual",
                extra: Iterable[tuple[str, Any]] = ()) -> Any:
    """The plugins of ``configuration`` for a run of ``task_file``: entry points and the project plugins folder,
    the grid-map and keypoint expectations bound to ``memory``, the installed experience-based repairs, then
    ``extra`` ``(name, plugin)`` pairs (the demo's capture and recorder)."""
    from bt_meta.plugins import create_plugin_host

    if configuration not in CONFIGURATIONS:
        raise ConfigurationError(f"unknown configuration {configuration!r}; known: {', '.join(CONFIGURATIONS)}")
    host = create_plugin_host(project_file=task_file)
    names = set(host.plugin_names())
    for name in EXPERIENCE_REPAIRS:  # not every install registers them as entry points yet
        if name not in names and name in available_repairs():
            host.register(importlib.import_module(f"bt_meta_plugins.{name}"), name, source="bt-meta demo")
    for name in _LOW_LEVEL:
        if name in host.plugin_names():
            host.unregister(name)
    if configuration != "symbolic":
        from bt_meta_plugins.gridmap_expectations import GridMapExpectations
        from bt_meta_plugins.keypoint_expectations import KeypointExpectations

        host.register(GridMapExpectations(memory), "gridmap_expectations", source="bt-meta demo (memory-bound)")
        host.register(KeypointExpectations(memory), "keypoint_expectations", source="bt-meta demo (memory-bound)")
    if configuration == "low_level":
        for name in _SYMBOLIC:
            if name in host.plugin_names():
                host.unregister(name)
    if configuration == "retry":
        for name in EXPERIENCE_REPAIRS:
            if name in host.plugin_names():
                host.unregister(name)
    for name, plugin in extra:
        host.register(plugin, name, source="bt-meta demo")
    return host
