"""BehaviorTree.CPP's script nodes (see :mod:`bt_meta.bt.script` for the language).

Offers:

* :class:`Script` -- runs its ``code``; SUCCESS (an empty ``code`` does nothing, as in BT.CPP)
* :class:`ScriptCondition` -- SUCCESS when its ``code`` gives true, else FAILURE
* :class:`Precondition` -- ticks its child when ``if`` gives true (and keeps ticking it while it is RUNNING),
  otherwise returns ``else`` (FAILURE by default; SUCCESS, RUNNING or SKIPPED allowed)

Every node gets its environment from the loader (``bind_environment``): script names mapped to root keys, enums.
A ``code`` given as ``{key}`` is read from the blackboard at tick time and parsed when it changes.
"""

from __future__ import annotations

from typing import Any

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import DecoratorNode, PortValue, PortValueError, TickGenerator
from bt_meta.bt.nodes.entries import BlackboardEnvironment
from bt_meta.bt.nodes.status import parse_status, returned
from bt_meta.bt.script import CompiledScript, ScriptRuntimeError, ScriptSyntaxError, compile_script


class _ScriptSource:
    """A ``code`` port: compiled once when literal, re-compiled when a ``{key}`` changes."""

    def __init__(self, code: PortValue) -> None:
        self.code = code
        self.env = BlackboardEnvironment()
        self._text: str | None = None
        self._script: CompiledScript | None = None
        if code.key is None and code.text:
            self._script = compile_script(code.text)
            self._text = code.text

    def script(self) -> CompiledScript | None:
        text = self.code.get() if self.code.key is not None else self.code.text
        if not isinstance(text, str):
            raise PortValueError(f"port {self.code.spec.name!r} must hold a script (a string)")
        if text == "":
            return None
        if text != self._text:
            try:
                self._script = compile_script(text)
            except ScriptSyntaxError as error:
                raise ScriptRuntimeError(f"cannot parse script [{text}]: {error.message}") from None
            self._text = text
        return self._script


class _ScriptNode(py_trees.behaviour.Behaviour):
    """A leaf that runs the script of its ``code`` port in the blackboard environment bound at load."""

    def __init__(self, name: str, code: PortValue) -> None:
        super().__init__(name)
        self.source = _ScriptSource(code)

    def bind_environment(self, env: BlackboardEnvironment) -> None:
        self.source.env = env


class Script(_ScriptNode):
    """BT.CPP ``Script``."""

    def update(self) -> Status:
        script = self.source.script()
        if script is not None:
            script.run(self.source.env)
        return Status.SUCCESS


class ScriptCondition(_ScriptNode):
    """BT.CPP ``ScriptCondition``."""

    def update(self) -> Status:
        script = self.source.script()
        if script is None:
            raise ScriptRuntimeError(f"{self.name}: ScriptCondition has an empty script")
        return Status.SUCCESS if script.test(self.source.env) else Status.FAILURE


class Precondition(DecoratorNode):
    """BT.CPP ``Precondition``: once the child started, it is ticked until it finishes (``if`` is not re-read)."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, condition: PortValue, otherwise: Any) -> None:
        super().__init__(name, child)
        self.source = _ScriptSource(condition)
        self.otherwise = otherwise
        self.children_running = False

    def bind_environment(self, env: BlackboardEnvironment) -> None:
        self.source.env = env

    def execute(self) -> TickGenerator:
        script = self.source.script()
        otherwise = self.otherwise.get() if isinstance(self.otherwise, PortValue) else self.otherwise
        if isinstance(otherwise, str):
            otherwise = parse_status(otherwise)
        if not self.children_running:
            if script is None:
                raise ScriptRuntimeError(f"{self.name}: Precondition has an empty 'if' script")
            self.children_running = script.test(self.source.env)
        if not self.children_running:
            return otherwise
        yield from self.decorated.tick()
        child_status = returned(self.decorated)
        if child_status in (Status.SUCCESS, Status.FAILURE):
            self.reset_child()
            self.children_running = False
        return child_status
