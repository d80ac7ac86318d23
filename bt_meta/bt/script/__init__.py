"""BehaviorTree.CPP 4's script language: our own lexer, parser and evaluator (no ``eval``).

Used by the ``Script``, ``ScriptCondition`` and ``Precondition`` nodes and by the pre/post-condition attributes
(``_skipIf`` ...). Modules: :mod:`~bt_meta.bt.script.lexer` (tokens), :mod:`~bt_meta.bt.script.parser` (syntax,
BT.CPP's precedence), :mod:`~bt_meta.bt.script.ast` (the tree), :mod:`~bt_meta.bt.script.values` (BT.CPP's
conversions), :mod:`~bt_meta.bt.script.evaluator` (running it), :mod:`~bt_meta.bt.script.errors`.

Offers:

* :class:`CompiledScript` -- a parsed script: ``run(env)`` -> last value, ``test(env)`` -> bool (BT.CPP's
  ``cast<bool>``), the names it reads or writes
* :func:`compile_script` -- text -> :class:`CompiledScript` (raises :class:`ScriptSyntaxError`)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bt_meta.bt.script import values
from bt_meta.bt.script.ast import Expr
from bt_meta.bt.script.errors import ScriptRuntimeError, ScriptSyntaxError
from bt_meta.bt.script.evaluator import DictEnvironment, Environment, run
from bt_meta.bt.script.parser import parse

__all__ = [
    "CompiledScript",
    "DictEnvironment",
    "Environment",
    "ScriptRuntimeError",
    "ScriptSyntaxError",
    "compile_script",
]


@dataclass(frozen=True)
class CompiledScript:
    source: str
    exprs: tuple[Expr, ...]

    def run(self, env: Environment) -> Any:
        try:
            return run(list(self.exprs), env)
        except ScriptRuntimeError as error:
            raise ScriptRuntimeError(f"error in script [{self.source}]: {error}") from None

    def test(self, env: Environment) -> bool:
        result = self.run(env)
        try:
            return values.to_bool(result)
        except ScriptRuntimeError as error:
            raise ScriptRuntimeError(f"script [{self.source}] does not give true or false: {error}") from None


def compile_script(text: str) -> CompiledScript:
    return CompiledScript(text, tuple(parse(text)))
