"""Tick-by-tick test harness and pytest fixtures for bt-meta trees (registered as the ``pytest11`` plugin).

Load a task file (planned and compiled) or a tree XML, tick it once, N times or until a status, and inspect what
each node did, the blackboard and the recorded failures -- without the simulator: the fake world runs the skills.

Offers:

* :class:`TreeHarness` -- :meth:`~TreeHarness.from_file`, :meth:`~TreeHarness.from_text`,
  :meth:`~TreeHarness.tick`, :meth:`~TreeHarness.tick_n`, :meth:`~TreeHarness.tick_until`,
  :meth:`~TreeHarness.status`, :meth:`~TreeHarness.statuses`, :meth:`~TreeHarness.node`,
  :meth:`~TreeHarness.blackboard`, :attr:`~TreeHarness.failures`, :attr:`~TreeHarness.state`,
  :attr:`~TreeHarness.history`
* :class:`HarnessError` -- a node that does not exist, a status never reached
* fixtures: ``bt_harness`` (a factory: ``bt_harness(path_or_yaml_text, problem=..., faults=[...])``),
  ``bt_plugins`` (a factory for plugin hosts), ``bt_blackboard`` (clears bt-meta's blackboard keys around a test)
* :func:`free_groot2_port` -- a port P with P and P+1 free on 127.0.0.1, for a test that serves Groot2 (it uses both)

Statuses are recorded *during* each tick, as every node finishes its part of it: BehaviorTree.CPP control nodes
reset their children when they finish, so reading ``behaviour.status`` afterwards would mostly show INVALID.
A monitored action reports its Monitor's status (what the tree sees); pass ``raw=True`` for the action's own.
"""

from __future__ import annotations

import random
import re
import shutil
import socket
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import py_trees
from py_trees.common import Status

from bt_meta.bt.context import FAILURES_KEY, RUN_KEY, STATE_KEY, WORLD_KEY, RunContext
from bt_meta.bt.failures import Failure
from bt_meta.errors import BtMetaError, PluginError, UnknownWorldError

__all__ = ["HarnessError", "TreeHarness", "bt_blackboard", "bt_harness", "bt_plugins", "free_groot2_port"]

_BT_META_KEYS = (RUN_KEY, WORLD_KEY, STATE_KEY, FAILURES_KEY)
_POLICY_KEY = re.compile(r"^/p\d+_")


class HarnessError(BtMetaError):
    """A harness request that cannot be answered: an unknown or ambiguous node, a status never reached."""


class HarnessWorldError(HarnessError, UnknownWorldError):
    """No plugin makes the world the harness was asked for: a harness error and bad input (CLI exit 2)."""


def _status(value: Status | str) -> Status:
    if isinstance(value, Status):
        return value
    try:
        return Status(value.upper())
    except ValueError:
        raise HarnessError(f"unknown status {value!r}; expected RUNNING, SUCCESS, FAILURE or INVALID") from None


def clear_blackboard() -> None:
    """Remove bt-meta's keys (and bindings written by policy guards) from py_trees' process-wide blackboard."""
    storage = py_trees.blackboard.Blackboard.storage
    for key in list(storage):
        if key in _BT_META_KEYS or key.startswith("/bt_meta/") or _POLICY_KEY.match(key):
            del storage[key]


class TreeHarness:
    """A tree, the run it ticks in, and what every node did on every tick."""

    def __init__(self, root: py_trees.behaviour.Behaviour, run: RunContext, compiled: Any = None) -> None:
        self.root = root
        self.run = run
        self.compiled = compiled
        self.history: list[dict[str, Any]] = []
        self._last: dict[str, Status] = {}
        self._by_name: dict[str, list[py_trees.behaviour.Behaviour]] = {}
        self._temporary: Path | None = None
        for behaviour in root.iterate():
            self._by_name.setdefault(behaviour.name, []).append(behaviour)
        run.install()

    # -- construction -------------------------------------------------------------------------------------------

    @classmethod
    def from_file(
        cls,
        path: str | Path,
        problem: str | None = None,
        *,
        task_file: str | Path | None = None,
        policy: bool = False,
        world: str | Any = "fake",
        faults: Iterable[Any] = (),
        ticks_per_skill: int | dict[str, int] = 1,
        world_options: dict[str, Any] | None = None,
        plugins: Any = None,
        plugin_dirs: Iterable[str | Path] = (),
        entry_points: bool = True,
        extra_plugins: Iterable[tuple[str, Any]] = (),
        tree_id: str | None = None,
        xml_sources: Any = None,
        stubs: Any = None,
    ) -> TreeHarness:
        """Load a task file or tree XML, build the world (``"fake"``, another name a plugin provides, a World
        object, or ``None``) and a plugin host (given, or built-ins + entry points + folders + ``extra_plugins``).

        A named world gets ``options`` with ``faults``, ``ticks_per_skill``, ``task_file`` and ``world_options``.
        ``tree_id``, ``xml_sources`` and ``stubs`` are passed to :func:`~bt_meta.bt.loading.load_runnable`.
        """
        from bt_meta.bt.loading import load_runnable
        from bt_meta.plugins import create_plugin_host

        if plugins is None:
            plugins = create_plugin_host(plugin_dirs, project_file=path, entry_points=entry_points,
                                         plugins=extra_plugins)
        compiled = load_runnable(path, problem=problem, task_file=task_file, policy=policy, plugins=plugins,
                                 tree_id=tree_id, xml_sources=xml_sources, stubs=stubs)
        if isinstance(world, str):
            options = {"faults": list(faults), "ticks_per_skill": ticks_per_skill,
                       "task_file": getattr(compiled.task_file, "path", None), **(world_options or {})}
            made = plugins.call("bt_meta_make_world", name=world, domain=compiled.domain,
                                problem=compiled.problem, options=options)
            if made.errors:
                error = made.errors[0]
                if isinstance(error.error, BtMetaError) and not isinstance(error.error, PluginError):
                    raise error.error  # e.g. the simulator's located error in a scene file
                raise PluginError(error.message) from error.error
            if not made.results:
                raise HarnessWorldError(f"no plugin provides a world named {world!r} (shipped: fake, sim)")
            world = made.first
        run = RunContext(world, plugins, domain=compiled.domain, problem=compiled.problem,
                         task_file=compiled.task_file)
        harness = cls(compiled.root, run, compiled)
        run.start()
        return harness

    @classmethod
    def from_text(cls, text: str, problem: str | None = None, *, suffix: str | None = None,
                  **kwargs: Any) -> TreeHarness:
        """Like :meth:`from_file` for YAML or XML text (written to a temporary file, so errors name a path)."""
        if suffix is None:
            suffix = ".xml" if text.lstrip().startswith("<") else ".yaml"
        folder = Path(tempfile.mkdtemp(prefix="bt_meta_harness_"))
        path = folder / f"tree{suffix}"
        path.write_text(text, encoding="utf-8")
        try:
            harness = cls.from_file(path, problem, **kwargs)
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
        harness._temporary = folder
        return harness

    # -- ticking ------------------------------------------------------------------------------------------------

    def tick(self) -> Status:
        """Tick the tree once; returns the root's status."""
        seen: dict[str, Status] = {}

        def visit(behaviour: py_trees.behaviour.Behaviour) -> None:
            seen[behaviour.name] = behaviour.status

        status = self.run.tick(self.root, visit)
        self._last = seen
        self.history.append({"tick": self.run.tick_count, "status": status,
                             "statuses": {name: s.value for name, s in seen.items()}})
        return status

    def tick_n(self, count: int) -> list[Status]:
        return [self.tick() for _ in range(count)]

    def tick_until(self, status: Status | str | Callable[[TreeHarness], bool] = "done",
                   max_ticks: int = 1000) -> Status:
        """Tick until the root has ``status`` (``"done"``: anything but RUNNING) or ``status(harness)`` is true."""
        if callable(status):
            def reached(root: Status) -> bool:
                return bool(status(self))
        elif status == "done":
            def reached(root: Status) -> bool:
                return root is not Status.RUNNING
        else:
            wanted = _status(status)

            def reached(root: Status) -> bool:
                return root is wanted
        for _ in range(max_ticks):
            root = self.tick()
            if reached(root):
                return root
        raise HarnessError(f"not reached after {max_ticks} ticks: {status!r} (root is {self.root.status.value})")

    # -- inspection ---------------------------------------------------------------------------------------------

    def node(self, name: str, *, raw: bool = False) -> py_trees.behaviour.Behaviour:
        """The behaviour named ``name``, or whose name starts with the node id ``name`` (``"n3"``)."""
        matches = self._by_name.get(name)
        if not matches:
            matches = [b for n, bs in self._by_name.items() if n.startswith(name + " ") for b in bs
                       if not getattr(b, "is_monitor", False)]
        if not matches:
            close = ", ".join(sorted(self._by_name)[:20])
            raise HarnessError(f"no node named {name!r}; nodes: {close}")
        if len(matches) > 1:
            raise HarnessError(f"{len(matches)} nodes match {name!r}: {', '.join(b.name for b in matches)}")
        behaviour = matches[0]
        parent = behaviour.parent
        if not raw and parent is not None and getattr(parent, "is_monitor", False):
            return parent
        return behaviour

    def status(self, name: str, *, raw: bool = False) -> Status:
        """The status ``name`` had when last ticked (INVALID if never ticked)."""
        behaviour = self.node(name, raw=raw)
        for tick in reversed(self.history):
            value = tick["statuses"].get(behaviour.name)
            if value is not None:
                return Status(value)
        return Status.INVALID

    def statuses(self, tick: int | None = None) -> dict[str, str]:
        """Name -> status of every node ticked in the last tick (or in tick number ``tick``, 1-based)."""
        if not self.history:
            return {}
        entry = self.history[-1] if tick is None else self.history[tick - 1]
        return dict(entry["statuses"])

    def blackboard(self, key: str) -> Any:
        storage = py_trees.blackboard.Blackboard.storage
        name = key if key.startswith("/") else "/" + key
        if name not in storage:
            raise HarnessError(f"no blackboard entry {name!r}")
        return storage[name]

    @property
    def failures(self) -> list[Failure]:
        return list(self.run.failures)

    @property
    def failure_kinds(self) -> list[str]:
        return [failure.kind.value for failure in self.run.failures]

    @property
    def state(self) -> Any:
        return self.run.state

    @property
    def world(self) -> Any:
        return self.run.world

    def close(self) -> None:
        """Clear bt-meta's blackboard keys and remove the temporary file of :meth:`from_text`."""
        clear_blackboard()
        if self._temporary is not None:
            shutil.rmtree(self._temporary, ignore_errors=True)
            self._temporary = None


# -- pytest fixtures ------------------------------------------------------------------------------------------------

# Fixtures only when pytest is already loaded (it imports this module as its ``pytest11`` plugin): every executor
# run uses the harness, and importing pytest for it cost ~0.3 s per process idle, ~1 s under load.
pytest = sys.modules.get("pytest")

if pytest is not None:

    @pytest.fixture
    def bt_blackboard() -> Iterator[Any]:
        """Clear bt-meta's blackboard keys before and after the test; yields py_trees' blackboard storage."""
        clear_blackboard()
        yield py_trees.blackboard.Blackboard.storage
        clear_blackboard()

    @pytest.fixture
    def bt_harness(bt_blackboard: Any) -> Iterator[Callable[..., TreeHarness]]:
        """Factory: ``bt_harness(path_or_text, problem=None, **options)`` -> :class:`TreeHarness` (closed after)."""
        made: list[TreeHarness] = []

        def make(source: str | Path, problem: str | None = None, **options: Any) -> TreeHarness:
            if isinstance(source, Path) or ("\n" not in str(source) and Path(str(source)).is_file()):
                harness = TreeHarness.from_file(source, problem, **options)
            else:
                harness = TreeHarness.from_text(str(source), problem, **options)
            made.append(harness)
            return harness

        yield make
        for harness in made:
            harness.close()

    @pytest.fixture
    def bt_plugins() -> Callable[..., Any]:
        """Factory for plugin hosts: ``bt_plugins(("name", plugin), ..., entry_points=True, dirs=())``."""
        from bt_meta.plugins import create_plugin_host

        def make(*plugins: tuple[str, Any], entry_points: bool = True, dirs: Iterable[str | Path] = ()) -> Any:
            return create_plugin_host(dirs, entry_points=entry_points, plugins=plugins)

        return make


def _ephemeral_port_range() -> tuple[int, int]:
    """The kernel's range for outgoing connections' local ports (Linux; the IANA range elsewhere)."""
    try:
        low, high = Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()
        return int(low), int(high)
    except (OSError, ValueError):
        return 49152, 65535


def free_groot2_port() -> int:
    """A port P with P and P+1 free on 127.0.0.1 right now (a Groot2 server binds both); free, not reserved.

    Drawn at random from below the kernel's ephemeral range: a port the kernel handed out for a probe is the kind it
    hands out next to an outgoing connection (every ZeroMQ client's local end), which then takes the port before the
    server binds it ("Address already in use" in a long sweep, or with other test runs on the machine)."""
    low, _ = _ephemeral_port_range()
    top = max(low, 12000) - 2
    draw = random.SystemRandom()
    for _ in range(200):
        port = draw.randrange(10000, top)
        try:
            with socket.socket() as first, socket.socket() as second:
                first.bind(("127.0.0.1", port))
                second.bind(("127.0.0.1", port + 1))
        except OSError:
            continue
        return port
    raise RuntimeError("no free port pair on 127.0.0.1")
