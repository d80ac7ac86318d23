"""The plugin host: hookspecs, loading from entry points and folders, clear load errors, contained hook calls."""

from __future__ import annotations

import inspect
import textwrap

import pytest

from bt_meta import hookspecs
from bt_meta.errors import PluginError, UserInputError
from bt_meta.plugins import (
    HOOK_NAMES,
    PluginHost,
    PluginLoadError,
    create_plugin_host,
    hookimpl,
    project_plugins_dir,
)

SHIPPED = {"reporting", "symbolic_expectations", "ground_truth_perception"}


def test_every_hook_is_documented_with_when_and_what_to_return():
    assert set(HOOK_NAMES) == {
        "bt_meta_register_nodes", "bt_meta_make_world", "bt_meta_external_predicate", "bt_meta_trace_event",
        "bt_meta_observation_needs", "bt_meta_observe", "bt_meta_expectations", "bt_meta_compare",
        "bt_meta_classify_failure", "bt_meta_on_failure", "bt_meta_propose_repairs",
    }
    for name in HOOK_NAMES:
        doc = inspect.getdoc(getattr(hookspecs, name))
        assert doc and "return" in doc.lower(), name
        assert name in hookspecs.__doc__  # the table in the module docstring lists it


def test_entry_points_load_the_shipped_plugins():
    host = create_plugin_host()
    names = set(host.plugin_names())
    assert names >= SHIPPED and "fake_world" in names
    assert host.hooks_of("symbolic_expectations") == ["bt_meta_compare", "bt_meta_expectations",
                                                          "bt_meta_observation_needs"]
    assert "entry point bt_meta_plugins.reporting" in {p["source"] for p in host.describe()}


def test_installed_entry_points_are_read_once_while_the_path_stays(tmp_path, monkeypatch):
    """A worker makes a plugin host per episode: the distributions' metadata is read once, again when sys.path
    or one of its folders changes (a distribution installed), and every time with the model cache off."""
    import importlib.metadata
    import os
    import sys

    reads = []
    real = importlib.metadata.entry_points

    def counting(**options):
        reads.append(options)
        return real(**options)

    monkeypatch.setattr(importlib.metadata, "entry_points", counting)
    monkeypatch.syspath_prepend(str(tmp_path))
    first = create_plugin_host()
    assert len(reads) == 1 and create_plugin_host().plugin_names() == first.plugin_names() and len(reads) == 1
    from bt_meta.plugins import installed_entry_points

    assert installed_entry_points() == installed_entry_points() and len(reads) == 1
    stat = os.stat(tmp_path)
    os.utime(tmp_path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    installed_entry_points()
    assert len(reads) == 2
    monkeypatch.setattr(sys, "path", [*sys.path, str(tmp_path / "elsewhere")])
    installed_entry_points()
    assert len(reads) == 3
    monkeypatch.setenv("BT_META_MODEL_CACHE", "0")
    installed_entry_points()
    installed_entry_points()
    assert len(reads) == 5


def test_folder_plugin_is_loaded_and_called(tmp_path):
    (tmp_path / "colours.py").write_text(textwrap.dedent("""
        from bt_meta.plugins import hookimpl

        @hookimpl
        def bt_meta_external_predicate(name, args, state):
            if name == "reachable":
                return args[0] != "far"
            return None
    """))
    (tmp_path / "_private.py").write_text("raise RuntimeError('never imported')\n")
    host = create_plugin_host([tmp_path], entry_points=False)
    assert "colours" in host.plugin_names() and "_private" not in host.plugin_names()
    assert host.external_predicate("reachable", ("b0",), None) is True
    assert host.external_predicate("reachable", ("far",), None) is False
    with pytest.raises(PluginError, match="no plugin evaluates the external predicate heavy/1"):
        host.external_predicate("heavy", ("b0",), None)


def test_broken_plugin_file_names_file_and_line(tmp_path):
    (tmp_path / "broken.py").write_text("from bt_meta.plugins import hookimpl\n\ndef oops(:\n    pass\n")
    with pytest.raises(PluginLoadError) as caught:
        create_plugin_host([tmp_path], entry_points=False)
    error = caught.value
    assert isinstance(error, UserInputError)
    assert error.path.endswith("broken.py") and error.line == 3
    assert "SyntaxError" in error.message and "broken.py:3" in str(error)


def test_plugin_file_raising_at_import_names_the_line(tmp_path):
    (tmp_path / "bad_import.py").write_text("import os\n\nVALUE = {}['missing']\n")
    with pytest.raises(PluginLoadError, match=r"bad_import.py:3: plugin file failed to import: KeyError"):
        create_plugin_host([tmp_path], entry_points=False)


def test_missing_plugin_folder_is_a_clear_error(tmp_path):
    with pytest.raises(PluginLoadError, match="plugin folder does not exist"):
        create_plugin_host([tmp_path / "nope"], entry_points=False)


def test_unknown_hook_and_wrappers_are_refused():
    class Typo:
        @hookimpl
        def bt_meta_obsrve(self, world):
            return None

    class Wrapper:
        @hookimpl(wrapper=True)
        def bt_meta_observe(self, world, context):
            return (yield)

    host = PluginHost()
    with pytest.raises(PluginError, match="unknown hook 'bt_meta_obsrve'"):
        host.register(Typo(), "typo")
    with pytest.raises(PluginError, match="hook wrappers are not supported"):
        host.register(Wrapper(), "wrapper")
    assert host.plugin_names() == []


def test_bad_signature_and_duplicate_names_are_refused():
    class BadArgs:
        @hookimpl
        def bt_meta_observe(self, world, colour):
            return None

    class Fine:
        @hookimpl
        def bt_meta_observe(self, world):
            return {"x": 1}

    host = PluginHost()
    with pytest.raises(PluginError, match="colour"):
        host.register(BadArgs(), "bad")
    host.register(Fine(), "fine")
    with pytest.raises(PluginError, match="two plugins are named 'fine'"):
        host.register(Fine(), "fine")


def test_call_contains_exceptions_and_keeps_calling_the_others():
    class Raises:
        @hookimpl
        def bt_meta_observe(self, world, context):
            raise ZeroDivisionError("oops")

    class Answers:
        @hookimpl
        def bt_meta_observe(self, world):
            return {"answer": 42}

    host = PluginHost()
    host.register(Answers(), "answers")
    host.register(Raises(), "raises")
    result = host.call("bt_meta_observe", world=None, context=None)
    assert result.results == [("answers", {"answer": 42})]
    [error] = result.errors
    assert error.plugin == "raises" and error.hook == "bt_meta_observe"
    assert "ZeroDivisionError: oops" in error.message and "Traceback" in error.traceback


def test_firstresult_stops_at_the_first_answer_in_pluggy_order():
    class Low:
        @hookimpl
        def bt_meta_classify_failure(self, failure):
            return "physical"

    class High:
        @hookimpl(tryfirst=True)
        def bt_meta_classify_failure(self, failure):
            return "collision"

    class Silent:
        @hookimpl
        def bt_meta_classify_failure(self, failure):
            return None

    host = PluginHost()
    for plugin, name in ((Low(), "low"), (High(), "high"), (Silent(), "silent")):
        host.register(plugin, name)
    result = host.call("bt_meta_classify_failure", failure=None, mismatches=[], context=None)
    assert result.results == [("high", "collision")]
    assert not host.implements("bt_meta_propose_repairs")
    host.unregister("high")
    assert host.call("bt_meta_classify_failure", failure=None, mismatches=[], context=None).first == "physical"


def test_project_plugins_folder_is_next_to_the_task_file(tmp_path):
    (tmp_path / "plugins").mkdir()
    (tmp_path / "plugins" / "mine.py").write_text(
        "from bt_meta.plugins import hookimpl\n\n@hookimpl\ndef bt_meta_trace_event(event):\n    pass\n")
    task = tmp_path / "task.yaml"
    task.write_text("domain: {name: x}\n")
    assert project_plugins_dir(task) == tmp_path / "plugins"
    assert project_plugins_dir(tmp_path / "plugins" / "mine.py") is None
    host = create_plugin_host(project_file=task, entry_points=False)
    assert "mine" in host.plugin_names() and host.implements("bt_meta_trace_event")
    # Giving the same folder with --plugins does not load it twice.
    host = create_plugin_host([tmp_path / "plugins"], project_file=task, entry_points=False)
    assert host.plugin_names().count("mine") == 1


def test_register_nodes_hook_adds_node_types_usable_in_xml(tmp_path, bt_blackboard):
    from py_trees.common import Status

    from bt_meta.testing import TreeHarness

    (tmp_path / "plugins").mkdir()
    (tmp_path / "plugins" / "beeper.py").write_text(textwrap.dedent('''
        import py_trees
        from bt_meta.bt.registry import NodeType, PortSpec
        from bt_meta.plugins import hookimpl

        class Beep(py_trees.behaviour.Behaviour):
            count = 0

            def update(self):
                Beep.count += 1
                return py_trees.common.Status.SUCCESS

        @hookimpl
        def bt_meta_register_nodes(registry, domain):
            registry.register(NodeType("Beep", "Action", [PortSpec("times", "input", "int", "1")],
                                       lambda name, ports, children: Beep(name)))
    '''))
    (tmp_path / "beep.xml").write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="Main"><Sequence><Beep times="2"/><Beep/></Sequence>'
        "</BehaviorTree></root>")
    harness = TreeHarness.from_file(tmp_path / "beep.xml", world=None)
    assert harness.tick() is Status.SUCCESS
    assert "beeper" in harness.run.plugins.plugin_names()
    assert harness.root.children[0].is_monitor  # a plugin's custom action is monitored like a primitive
