"""Plugin containment as the hookspecs promise: wrong result types, SystemExit, time budgets, broken observers."""

from __future__ import annotations

import signal
import sys
import time

import pytest
from py_trees.common import Status

from bt_meta.bt.expectations import Expectation
from bt_meta.bt.failures import FailureKind
from bt_meta.errors import PluginError, UnknownWorldError, UserInputError
from bt_meta.hook_budget import budget_from_environment, parse_budget
from bt_meta.meta import MetaExecutor, run_task_file
from bt_meta.plugins import PluginHost, create_plugin_host, hookimpl
from bt_meta.world.fake import FakeWorld

from .conftest import BLOCKS, make_host


class Returns:
    """Returns ``value`` from one hook."""

    def __init__(self, hook: str, value: object) -> None:
        self.hook = hook
        self.value = value

    @hookimpl
    def bt_meta_expectations(self, context):
        return self.value if self.hook == "bt_meta_expectations" else None

    @hookimpl(tryfirst=True)
    def bt_meta_compare(self, expectation, observations, context):
        return self.value if self.hook == "bt_meta_compare" else None

    @hookimpl
    def bt_meta_observe(self, world, context):
        return self.value if self.hook == "bt_meta_observe" else None


def host_with(*extra):
    return create_plugin_host(entry_points=False, plugins=list(extra), hook_budget=5.0)


@pytest.mark.parametrize("hook", ["bt_meta_expectations", "bt_meta_compare", "bt_meta_observe"])
@pytest.mark.parametrize("value", [42, "a string", object()])
def test_a_result_of_the_wrong_type_is_an_internal_failure_naming_plugin_and_hook(blocks, hook, value):
    problem = blocks.problem("two")
    plugins = make_host(("garbage", Returns(hook, value)))
    report = MetaExecutor(blocks.domain, problem, FakeWorld(blocks.domain, problem), plugins).run()
    internal = [f for f in report.failures if f["kind"] == "internal"]
    assert internal, report.failures
    message = internal[0]["message"]
    assert message.startswith(f"plugin 'garbage' broke the contract of {hook}: returned {type(value).__name__}")
    assert internal[0]["plugin"] == "garbage"


def test_contract_checks_at_the_host():
    class Worlds:
        @hookimpl
        def bt_meta_make_world(self, name, domain, problem, options):
            return {"moon": 42, "text": "not a world", "none": None}.get(name, object())

        @hookimpl
        def bt_meta_external_predicate(self, name, args, state):
            return "yes"

    host = host_with(("worlds", Worlds()))
    for name in ("moon", "text"):
        made = host.call("bt_meta_make_world", name=name, domain=None, problem=None, options={})
        assert not made.results
        assert made.errors[0].message.startswith("plugin 'worlds' broke the contract of bt_meta_make_world: returned")
        assert "must return a World" in made.errors[0].message
    with pytest.raises(PluginError, match=r"broke the contract of bt_meta_external_predicate: returned str 'yes'"):
        host.external_predicate("p", (), None)
    good = [Expectation(kind="symbolic", description="ok")]
    host = host_with(("good", Returns("bt_meta_expectations", good)), ("bad", Returns("bt_meta_expectations", [1])))
    result = host.call("bt_meta_expectations", context=None)
    assert result.results == [("good", good)]
    assert [error.plugin for error in result.errors] == ["bad"]


def test_a_bad_world_from_a_plugin_is_a_plugin_error_not_a_traceback(tmp_path):
    class BadWorld:
        @hookimpl
        def bt_meta_make_world(self, name, domain, problem, options):
            return 42 if name == "bad" else None

    path = tmp_path / "blocks.yaml"
    path.write_text(BLOCKS)
    with pytest.raises(PluginError, match="broke the contract of bt_meta_make_world"):
        run_task_file(path, "two", world="bad", plugins=make_host(("bad", BadWorld())))
    with pytest.raises(UnknownWorldError, match="no plugin provides a world named 'moon'"):
        run_task_file(path, "two", world="moon", plugins=make_host())
    assert issubclass(UnknownWorldError, UserInputError)


class Exits:
    @hookimpl
    def bt_meta_observe(self, world, context):
        sys.exit(3)


def test_system_exit_from_a_plugin_is_contained(blocks):
    problem = blocks.problem("two")
    report = MetaExecutor(blocks.domain, problem, FakeWorld(blocks.domain, problem),
                          make_host(("exits", Exits()))).run()
    internal = [f for f in report.failures if f["kind"] == "internal"]
    assert internal[0]["message"] == "plugin 'exits' raised in bt_meta_observe: SystemExit: 3"


class Sleeps:
    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.calls = 0
        self.finished = 0

    @hookimpl
    def bt_meta_observe(self, world, context):
        self.calls += 1
        try:
            time.sleep(self.seconds)
        except Exception:  # a broad except in a plugin does not swallow the budget's interruption
            return {"swallowed": True}
        self.finished += 1
        return {"late": True}


@pytest.mark.timeout(60)
def test_a_call_past_its_budget_is_interrupted_and_an_internal_failure():
    sleeper = Sleeps(30.0)
    host = create_plugin_host(entry_points=False, builtins=False, plugins=[("sleepy", sleeper)], hook_budget=0.2)
    started = time.monotonic()
    result = host.call("bt_meta_observe", world=None, context=None)
    elapsed = time.monotonic() - started
    assert elapsed < 10, "the late call was not interrupted"
    assert not result.results and sleeper.finished == 0
    [error] = result.errors
    assert error.message == ("plugin 'sleepy': bt_meta_observe ran past its budget of 0.2 s (interrupted); its "
                             "result is discarded")


@pytest.mark.timeout(60)
def test_a_late_call_that_cannot_be_interrupted_still_loses_its_result():
    import threading

    sleeper = Sleeps(0.3)
    host = create_plugin_host(entry_points=False, builtins=False, plugins=[("sleepy", sleeper)], hook_budget=0.1)
    outcome = {}
    worker = threading.Thread(target=lambda: outcome.update(r=host.call("bt_meta_observe", world=None, context=None)))
    worker.start()
    worker.join(20)
    result = outcome["r"]
    assert sleeper.finished == 1 and not result.results
    assert "ran past its budget of 0.1 s (it could not be interrupted and ran" in result.errors[0].message


@pytest.mark.timeout(60)
def test_the_budget_keeps_an_outer_interval_timer():
    fired = []
    previous = signal.signal(signal.SIGALRM, lambda signum, frame: fired.append(signum))
    try:
        signal.setitimer(signal.ITIMER_REAL, 30.0)
        host = create_plugin_host(entry_points=False, builtins=False, plugins=[("quick", Sleeps(0.0))],
                                  hook_budget=1.0)
        assert host.call("bt_meta_observe", world=None, context=None).results
        remaining, _ = signal.getitimer(signal.ITIMER_REAL)
        assert 25 < remaining <= 30
        signal.setitimer(signal.ITIMER_REAL, 0.05)
        host.call("bt_meta_observe", world=None, context=None)
        time.sleep(0.2)
        assert fired == [signal.SIGALRM]  # the foreign timer's own handler ran, not a HookTimeout
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def test_budget_settings(monkeypatch):
    assert parse_budget("2.5") == 2.5
    assert parse_budget("0") is None and parse_budget("off") is None
    with pytest.raises(UserInputError, match=r"--hook-budget must be a number of seconds .*found 'soon'"):
        parse_budget("soon", "--hook-budget")
    with pytest.raises(UserInputError, match="must be a positive number"):
        parse_budget("-1", "--hook-budget")
    monkeypatch.delenv("BT_META_HOOK_BUDGET", raising=False)
    assert budget_from_environment() == 60.0 and PluginHost().hook_budget == 60.0
    monkeypatch.setenv("BT_META_HOOK_BUDGET", "off")
    assert PluginHost().hook_budget is None
    assert PluginHost(hook_budget=3.0).hook_budget == 3.0


class RaisingObserver:
    @hookimpl
    def bt_meta_on_failure(self, failure, context):
        raise RuntimeError("observer broke")


def test_a_raising_on_failure_observer_does_not_change_the_repair(blocks):
    from .test_executor import StealAfterFirstPut

    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem)
    report = MetaExecutor(blocks.domain, problem, world,
                          make_host(("thief", StealAfterFirstPut()), ("observer", RaisingObserver()))).run()
    assert report.ok, report.stop_reason
    assert [(a.kind, a.proposal["action"]) for a in report.attempts] == [("precondition", "replan")]
    assert [f["kind"] for f in report.failures] == ["precondition"]
    [note] = report.failures[0]["evidence"]["observer_errors"]
    assert note == {"plugin": "observer", "hook": "bt_meta_on_failure",
                    "error": "plugin 'observer' raised in bt_meta_on_failure: RuntimeError: observer broke"}


def test_the_monitor_fails_the_node_on_garbage_and_keeps_ticking(bt_harness):
    h = bt_harness(BLOCKS, "two", extra_plugins=[("garbage", Returns("bt_meta_expectations", 42))])
    assert h.tick_until("done") is Status.FAILURE
    failure = h.failures[0]
    assert failure.kind is FailureKind.INTERNAL and failure.plugin == "garbage"
    assert failure.evidence["hook"] == "bt_meta_expectations"


def test_a_plugin_file_calling_sys_exit_at_import_is_a_located_load_error(tmp_path):
    from bt_meta.plugins import PluginLoadError

    folder = tmp_path / "plugins"
    folder.mkdir()
    (folder / "quitter.py").write_text("import sys\n\nsys.exit(4)\n")
    with pytest.raises(PluginLoadError) as caught:
        create_plugin_host([folder], entry_points=False, builtins=False)
    assert caught.value.location_message() == (f"{folder / 'quitter.py'}:3: plugin file failed to import: "
                                                "SystemExit: 4")
