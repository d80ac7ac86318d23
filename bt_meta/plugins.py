"""The plugin manager: which plugins are loaded, and calling their hooks without letting one crash a run.

Plugins come from three places, loaded in this order (pluggy calls later-registered plugins first):

1. built-ins of the framework itself (the fake world; the simulator world, imported only when asked for);
2. the ``bt_meta`` entry-point group -- the shipped strategies (``bt_meta_plugins.*``) and any installed
   package's plugins;
3. plugin folders: every ``*.py`` file (not ``_*.py``) in each ``--plugins DIR``, and the project's own folder.

The *project plugins folder* is the ``plugins/`` folder **next to the task file or tree XML being run**
(``<folder of FILE>/plugins``), not ``./plugins`` of the current directory: the same command then behaves the same
from any directory, and running from a bt-meta checkout does not load the shipped ``plugins/`` package twice.

Offers:

* :data:`hookimpl` -- the marker plugin functions are decorated with
* :class:`PluginHost` -- a pluggy manager plus safe, cached hook calls (:meth:`PluginHost.call`)
* :class:`HookResult`, :class:`HookError` -- what a safe call returns: results and contained exceptions, results of
  the wrong type (:mod:`bt_meta.hook_contracts`) and calls past their time budget (:mod:`bt_meta.hook_budget`)
* :func:`create_plugin_host` -- a host with the hookspecs, built-ins, entry points and folders loaded
* :func:`project_plugins_dir` -- the project plugins folder for a task file
* :class:`PluginLoadError` -- a plugin file or entry point that fails to import (``path:line: message``)
* :class:`ConfiguredPlugin` -- the one settable instance behind a plugin module's module-level hooks
"""

from __future__ import annotations

import importlib.metadata
import time
import traceback
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, TypeVar

import pluggy

from bt_meta import hookspecs
from bt_meta._plugin_loading import PluginLoadError, import_plugin_file, plugin_files
from bt_meta.errors import PluginError
from bt_meta.hook_budget import HookBudgetExceeded, HookTimeout, budget_from_environment, enter, leave
from bt_meta.hook_contracts import HookContractError, check_result
from bt_meta.hookspecs import PROJECT_NAME, hookimpl

__all__ = [
    "ENTRY_POINT_GROUP",
    "ConfiguredPlugin",
    "HookError",
    "HookResult",
    "PluginHost",
    "PluginLoadError",
    "create_plugin_host",
    "hookimpl",
    "project_plugins_dir",
]

ENTRY_POINT_GROUP = "bt_meta"
BUILTIN_PLUGINS: tuple[tuple[str, str], ...] = (("fake_world", "bt_meta.world.fake"),)
LAZY_WORLDS: dict[str, str] = {"sim": "bt_meta.world.simulation.sim_world", "ros2": "bt_meta.ros2.world"}


P = TypeVar("P")


class ConfiguredPlugin(Generic[P]):
    """The one instance behind a plugin module's module-level hooks, replaceable with other settings.

    A plugin loaded as a module (an entry point, a ``plugins/`` file) is called through module-level functions;
    they delegate to :attr:`current`, and the module exposes :meth:`configure` as its ``configure``.
    """

    def __init__(self, factory: Callable[..., P]) -> None:
        self.factory = factory
        self.current: P = factory()

    def configure(self, **settings: Any) -> P:
        """Replace the module-level plugin by one built with these settings (keyword arguments of its class)."""
        self.current = self.factory(**settings)
        return self.current


class _LazyWorlds:
    """Built-in plugin for worlds whose modules are heavy to import (the pybullet simulator): imported on demand."""

    @hookimpl(trylast=True)
    def bt_meta_make_world(self, name: str, domain: Any, problem: Any, options: dict[str, Any]) -> Any:
        module_name = LAZY_WORLDS.get(name)
        if module_name is None:
            return None
        import importlib

        module = importlib.import_module(module_name)
        return module.bt_meta_make_world(name=name, domain=domain, problem=problem, options=options)
HOOK_NAMES: tuple[str, ...] = tuple(name for name in dir(hookspecs) if name.startswith("bt_meta_"))


@dataclass
class HookError:
    """An exception one plugin raised inside one hook, contained by :meth:`PluginHost.call`."""

    plugin: str
    hook: str
    error: BaseException
    traceback: str

    @property
    def message(self) -> str:
        if isinstance(self.error, HookContractError):
            return f"plugin {self.plugin!r} broke the contract of {self.hook}: {self.error}"
        if isinstance(self.error, HookBudgetExceeded):
            return f"plugin {self.plugin!r}: {self.error}"
        return f"plugin {self.plugin!r} raised in {self.hook}: {type(self.error).__name__}: {self.error}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "plugin": self.plugin,
            "hook": self.hook,
            "error": f"{type(self.error).__name__}: {self.error}",
            "traceback": self.traceback,
        }


@dataclass
class HookResult:
    """What a safe hook call gathered: ``(plugin name, value)`` for every non-``None`` result, and the errors."""

    results: list[tuple[str, Any]] = field(default_factory=list)
    errors: list[HookError] = field(default_factory=list)

    @property
    def values(self) -> list[Any]:
        return [value for _, value in self.results]

    @property
    def first(self) -> Any:
        return self.results[0][1] if self.results else None

    @property
    def first_plugin(self) -> str | None:
        return self.results[0][0] if self.results else None


_EMPTY: tuple[Any, ...] = ()


class _FromEnvironment:
    """The default of a hook budget: ``$BT_META_HOOK_BUDGET``, else :data:`bt_meta.hook_budget.DEFAULT_HOOK_BUDGET`."""


FROM_ENVIRONMENT = _FromEnvironment()


class PluginHost:
    """A pluggy :class:`~pluggy.PluginManager` for the ``bt_meta`` hooks, with safe calls and a fast "anyone?".

    Register plugins through :meth:`register` (not on :attr:`manager` directly) so the cached implementation
    lists stay right. ``hook_budget`` is the time budget of each implementation call in seconds (``None``: no
    budget; default: ``$BT_META_HOOK_BUDGET``, else 60 s; see :mod:`bt_meta.hook_budget`).
    """

    def __init__(self, hook_budget: float | _FromEnvironment | None = FROM_ENVIRONMENT) -> None:
        self.hook_budget: float | None = (budget_from_environment() if isinstance(hook_budget, _FromEnvironment)
                                          else hook_budget)
        self.manager = pluggy.PluginManager(PROJECT_NAME)
        self.manager.add_hookspecs(hookspecs)
        self.sources: dict[str, str] = {}
        self._impls: dict[str, tuple[Any, ...]] = {}
        self._firstresult: dict[str, bool] = {}

    # -- registration -------------------------------------------------------------------------------------------

    def register(self, plugin: Any, name: str, source: str = "") -> None:
        """Register ``plugin`` under ``name``; a name taken twice or a bad hook signature is a :class:`PluginError`."""
        if self.manager.has_plugin(name):
            raise PluginError(f"two plugins are named {name!r} ({self.sources.get(name)} and {source or plugin!r})")
        try:
            self.manager.register(plugin, name=name)
        except pluggy.PluginValidationError as error:
            raise PluginError(f"plugin {name!r} ({source or plugin!r}): {error}") from error
        try:
            self._check(name)
        except PluginError:
            self.manager.unregister(name=name)
            raise
        self.sources[name] = source or getattr(plugin, "__file__", None) or repr(plugin)
        self._impls.clear()

    def unregister(self, name: str) -> None:
        self.manager.unregister(name=name)
        self.sources.pop(name, None)
        self._impls.clear()

    def _check(self, name: str) -> None:
        for caller in self.manager.get_hookcallers(self.manager.get_plugin(name)) or []:
            for impl in caller.get_hookimpls():
                if impl.plugin_name != name:
                    continue
                if caller.spec is None:
                    known = ", ".join(HOOK_NAMES)
                    raise PluginError(f"plugin {name!r} implements unknown hook {caller.name!r}; known hooks: {known}")
                if impl.wrapper or impl.hookwrapper:
                    raise PluginError(
                        f"plugin {name!r}: hook wrappers are not supported ({caller.name}); write a plain hook"
                    )

    def plugin_names(self) -> list[str]:
        return [name for name, _ in self.manager.list_name_plugin() if name is not None]

    def hooks_of(self, name: str) -> list[str]:
        """The hooks plugin ``name`` implements, sorted."""
        plugin = self.manager.get_plugin(name)
        return sorted(caller.name for caller in self.manager.get_hookcallers(plugin) or [])

    def describe(self) -> list[dict[str, Any]]:
        """Every loaded plugin with its source and hooks, in registration order (pluggy calls later ones first)."""
        names = self.plugin_names()
        return [{"name": name, "source": self.sources.get(name, ""), "hooks": self.hooks_of(name)} for name in names]

    # -- calling ------------------------------------------------------------------------------------------------

    def implementations(self, hook: str) -> tuple[Any, ...]:
        """The hook's implementations in call order (pluggy's: tryfirst, then last registered first)."""
        impls = self._impls.get(hook)
        if impls is None:
            caller = getattr(self.manager.hook, hook, None)
            if caller is None:
                raise PluginError(f"unknown hook {hook!r}; known hooks: {', '.join(HOOK_NAMES)}")
            impls = tuple(reversed(caller.get_hookimpls())) or _EMPTY
            self._impls[hook] = impls
        return impls

    def implements(self, hook: str) -> bool:
        """Whether any plugin implements ``hook`` (cheap; monitors skip hooks nobody implements)."""
        return bool(self.implementations(hook))

    def call(self, hook: str, /, **kwargs: Any) -> HookResult:
        """Call every implementation of ``hook`` one by one; what goes wrong is contained as a :class:`HookError`.

        Contained: an exception (``SystemExit`` included; ``KeyboardInterrupt`` still stops the program), a result
        of the wrong type (:mod:`bt_meta.hook_contracts`), and a call past :attr:`hook_budget` (its result is
        discarded). For a firstresult hook the call stops at the first valid non-``None`` result, like pluggy.
        """
        result = HookResult()
        impls = self.implementations(hook)
        if not impls:
            return result
        first = self._is_firstresult(hook)
        budget = self.hook_budget
        for impl in impls:
            args = [kwargs[name] for name in impl.argnames]
            deadline = None
            started = 0.0
            try:
                if budget is None:
                    value = impl.function(*args)
                else:
                    started = time.monotonic()
                    deadline = enter(budget)
                    try:
                        value = impl.function(*args)
                    finally:
                        leave(deadline)
            except HookTimeout as late:
                leave(deadline)  # again: the interruption may have landed inside the first leave
                if deadline is None or late.deadline != deadline:
                    raise  # an outer call's budget ran out: that call records it
                overrun = HookBudgetExceeded(hook, budget or 0.0, time.monotonic() - started, interrupted=True)
                result.errors.append(HookError(impl.plugin_name, hook, overrun, traceback.format_exc(limit=8)))
                continue
            except (Exception, SystemExit) as error:
                result.errors.append(HookError(impl.plugin_name, hook, error, traceback.format_exc(limit=8)))
                continue
            if budget is not None and time.monotonic() - started > budget:
                overrun = HookBudgetExceeded(hook, budget, time.monotonic() - started, interrupted=False)
                result.errors.append(HookError(impl.plugin_name, hook, overrun, ""))
                continue
            if value is not None:
                try:
                    check_result(hook, value)
                except HookContractError as error:
                    result.errors.append(HookError(impl.plugin_name, hook, error, ""))
                    continue
                result.results.append((impl.plugin_name, value))
                if first:
                    break
        return result

    def _is_firstresult(self, hook: str) -> bool:
        first = self._firstresult.get(hook)
        if first is None:
            caller = getattr(self.manager.hook, hook)
            first = self._firstresult[hook] = bool(caller.spec and caller.spec.opts.get("firstresult"))
        return first

    def implemented_hooks(self) -> frozenset[str]:
        """The hooks at least one plugin implements (a run takes this snapshot when it starts)."""
        return frozenset(hook for hook in HOOK_NAMES if self.implementations(hook))

    def external_predicate(self, name: str, args: tuple[str, ...], state: Any) -> bool:
        """The planner's ``external`` callable: ask the plugins; no answer or a raising plugin is a PluginError."""
        result = self.call("bt_meta_external_predicate", name=name, args=tuple(args), state=state)
        if result.results:
            return bool(result.first)
        if result.errors:
            raise PluginError(result.errors[0].message)
        raise PluginError(f"no plugin evaluates the external predicate {name}/{len(args)}")

    # -- loading ------------------------------------------------------------------------------------------------

    def load_builtins(self) -> None:
        import importlib

        for name, module_name in BUILTIN_PLUGINS:
            if not self.manager.has_plugin(name):
                self.register(importlib.import_module(module_name), name, source=f"builtin {module_name}")
        if not self.manager.has_plugin("lazy_worlds"):
            worlds = ", ".join(f"{world} ({module})" for world, module in LAZY_WORLDS.items())
            self.register(_LazyWorlds(), "lazy_worlds", source=f"builtin: {worlds}, imported on first use")

    def load_entry_points(self, group: str = ENTRY_POINT_GROUP) -> int:
        """Load every entry point of ``group``; an entry point that fails to import is a :class:`PluginLoadError`."""
        count = 0
        seen: set[str] = set()
        for entry_point in installed_entry_points(group):
            if entry_point.name in seen or self.manager.has_plugin(entry_point.name):
                continue
            seen.add(entry_point.name)
            try:
                plugin = entry_point.load()
            except (Exception, SystemExit) as error:
                raise PluginLoadError(
                    f"entry point {entry_point.name} = {entry_point.value} failed to import: "
                    f"{type(error).__name__}: {error}"
                ) from error
            self.register(plugin, entry_point.name, source=f"entry point {entry_point.value}")
            count += 1
        return count

    def load_folder(self, folder: str | Path) -> list[str]:
        """Load every plugin file of ``folder``; the plugin name is the file's stem. Returns the names loaded."""
        folder = Path(folder)
        if not folder.is_dir():
            raise PluginLoadError("plugin folder does not exist or is not a folder", path=folder)
        loaded = []
        for path in plugin_files(folder):
            known = {Path(src).resolve() for src in self.sources.values() if src.endswith(".py")}
            if path.resolve() in known:
                continue
            module = import_plugin_file(path)
            try:
                self.register(module, path.stem, source=str(path))
            except PluginError as error:
                raise PluginLoadError(str(error), path=path) from error
            loaded.append(path.stem)
        return loaded


def installed_entry_points(group: str = ENTRY_POINT_GROUP) -> tuple[importlib.metadata.EntryPoint, ...]:
    """The installed entry points of ``group``, read once per process while ``sys.path`` and its folders stay as
    they are (a worker makes a plugin host per episode, and reading every distribution's metadata took ~60 ms;
    installing a distribution changes its folder, so it is seen)."""
    import os
    import sys

    from bt_meta.model_cache import cached

    folders = []
    for entry in sys.path:
        try:
            folders.append((entry, os.stat(entry or ".").st_mtime_ns))
        except OSError:
            folders.append((entry, None))
    return cached(("entry_points", group, tuple(folders)),
                  lambda: tuple(importlib.metadata.entry_points(group=group)))


def project_plugins_dir(file: str | Path | None) -> Path | None:
    """``<folder of file>/plugins`` when it exists (the project plugins folder), else ``None``."""
    if file is None:
        return None
    try:
        candidate = Path(file).resolve().parent / "plugins"
        return candidate if candidate.is_dir() else None
    except (OSError, RuntimeError, ValueError):  # a NUL byte, a symlink loop: the file's loader reports it
        return None


def create_plugin_host(
    plugin_dirs: Iterable[str | Path] = (),
    *,
    project_file: str | Path | None = None,
    entry_points: bool = True,
    builtins: bool = True,
    plugins: Iterable[tuple[str, Any]] = (),
    hook_budget: float | _FromEnvironment | None = FROM_ENVIRONMENT,
) -> PluginHost:
    """A :class:`PluginHost` with built-ins, entry points, the project plugins folder of ``project_file`` and
    each of ``plugin_dirs`` loaded, then the extra ``(name, plugin)`` pairs (tests use these); ``hook_budget``
    as for :class:`PluginHost`."""
    host = PluginHost(hook_budget)
    if builtins:
        host.load_builtins()
    if entry_points:
        host.load_entry_points()
    project_dir = project_plugins_dir(project_file)
    folders = [Path(folder) for folder in plugin_dirs]
    if project_dir is not None and all(project_dir.resolve() != f.resolve() for f in folders):
        folders.insert(0, project_dir)
    for folder in folders:
        host.load_folder(folder)
    for name, plugin in plugins:
        host.register(plugin, name, source="registered by caller")
    return host
