"""Plugin configurations of a monitored, repaired run: which expectation and repair plugins are registered.

A configuration is only a choice of plugins -- the executor, the monitors, the reasoner and the verifications (the
problem's goal, the staging move of MagneticAttach) are the same:

* ``dual`` -- symbolic expectations and grid-map monitors; object substitution by grid-map retrieval; pose
  backtracking, which compares R_p / R_n with the remembered traces (section 7.4: the staging verification
  detects the failure, the keypoint relations localise and repair it); re-orientation by the task file's regrasp
  methods when the part's normal is grossly off and no pose is feasible; the retry baseline
* ``symbolic`` -- symbolic expectations only; object substitution by symbolic matching; no pose backtracking
  nor re-orientation (they need the keypoint relations); the retry baseline
* ``low_level`` -- grid-map monitors only (no symbolic expectation plugin); the repairs of ``dual``
* ``retry`` -- the expectations of ``dual``; the retry / replan baseline as the only repair plugin
* ``dual_kp_monitor`` -- ``dual`` plus keypoint monitors (R_p / R_n checked after the last primitive of every task):
  failures are caught earlier, before the attach, where pose backtracking has less to work with

Offers:

* :data:`CONFIGURATIONS` -- name -> one-line description
* :func:`plugin_host` -- a :class:`~bt_meta.plugins.PluginHost` for a task file in a configuration, its memory-backed
  plugins bound to the given episodic memory
* :data:`EXPERIENCE_REPAIRS` -- the experience-based repair plugins (registered when installed)
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from bt_meta.errors import BtMetaError

__all__ = ["CONFIGURATIONS", "EXPERIENCE_REPAIRS", "MAIN_CONFIGURATIONS", "ConfigurationError", "available_repairs",
           "plugin_host"]

CONFIGURATIONS = {
    "dual": "symbolic expectations + grid-map monitors; substitution by grid-maps, pose backtracking by "
            "R_p/R_n",
    "symbolic": "symbolic expectations only; substitution by symbolic matching, no pose backtracking",
    "low_level": "grid-map monitors only; substitution by grid-maps, pose backtracking by R_p/R_n",
    "retry": "expectations as dual; the retry / replan baseline is the only repair",
    "dual_kp_monitor": "dual plus keypoint (R_p/R_n) monitors at the end of every task",
}

#: The four configurations of the paper's comparison (the ablation's default).
MAIN_CONFIGURATIONS = ("dual", "symbolic", "low_level", "retry")

#: Experience-based repair plugins of the paper (module names under ``bt_meta_plugins``).
EXPERIENCE_REPAIRS = ("object_substitution", "pose_backtracking", "reorientation")

_MEMORY_EXPECTATIONS = ("gridmap_expectations", "keypoint_expectations")
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


def _repair_plugin(name: str, memory: Any, configuration: str, seed: int) -> Any:
    """The repair plugin ``name`` bound to the run's memory (and seed); the symbolic configuration's object
    substitution matches symbolically (the paper's symbol-only baseline), the others by grid-maps."""
    module = importlib.import_module(f"bt_meta_plugins.{name}")
    if name == "object_substitution" and hasattr(module, "ObjectSubstitution"):
        matcher = "symbolic" if configuration == "symbolic" else "gridmap"
        return module.ObjectSubstitution(memory, matcher=matcher)
    if name == "pose_backtracking" and hasattr(module, "PoseBacktracking"):
        return module.PoseBacktracking(memory, seed=seed)
    if name == "reorientation" and hasattr(module, "Reorientation"):
        return module.Reorientation(memory)
    return module


def plugin_host(task_file: str | Path, memory: Any, *, configuration: str = "dual", seed: int = 0,
                extra: Iterable[tuple[str, Any]] = ()) -> Any:
    """The plugins of ``configuration`` for a run of ``task_file``: entry points and the project plugins folder,
    with the memory-backed expectation and repair plugins replaced by instances bound to ``memory`` (the repairs'
    random draws to ``seed``) as the configuration chooses them, then ``extra`` ``(name, plugin)`` pairs."""
    from bt_meta.plugins import create_plugin_host

    if configuration not in CONFIGURATIONS:
        raise ConfigurationError(f"unknown configuration {configuration!r}; known: {', '.join(CONFIGURATIONS)}")
    host = create_plugin_host(project_file=task_file)
    for name in (*EXPERIENCE_REPAIRS, *_MEMORY_EXPECTATIONS):  # entry points replaced by memory-bound instances
        if name in host.plugin_names():
            host.unregister(name)
    repairs = [] if configuration == "retry" else available_repairs()
    if configuration == "symbolic":
        repairs = [name for name in repairs if name not in ("pose_backtracking", "reorientation")]
    for name in repairs:
        host.register(_repair_plugin(name, memory, configuration, seed), name, source="bt-meta demo (memory-bound)")
    if configuration != "symbolic":
        from bt_meta_plugins.gridmap_expectations import GridMapExpectations

        host.register(GridMapExpectations(memory), "gridmap_expectations", source="bt-meta demo (memory-bound)")
    if configuration == "dual_kp_monitor":
        from bt_meta_plugins.keypoint_expectations import KeypointExpectations

        # checked after the last primitive of each task (the task's bubbled-up expectation)
        host.register(KeypointExpectations(memory, check="task_end"), "keypoint_expectations",
                      source="bt-meta demo (memory-bound)")
    if configuration == "low_level":
        for name in _SYMBOLIC:
            if name in host.plugin_names():
                host.unregister(name)
    for name, plugin in extra:
        host.register(plugin, name, source="bt-meta demo")
    return host
