"""A task's success check: its goal, atom by atom, mapped to geometric checks on the simulator's true state.

Each goal atom becomes one check of :mod:`bt_meta.judge.checks`: a predicate named like a check kind is that kind
(``at`` with one argument is ``at_pose``, with three ``at_cell``); a ``success:`` mapping (a campaign family file's)
maps other predicates to a kind, and may add checks, including ``from_plan: PREDICATE`` -- every atom of that
predicate the nominal plan adds (a letter's cells, where the goal names only the last block). No code here knows a
task: what differs is the goal and the mapping. A predicate with no check, an unknown kind, key or object is a
:class:`SuccessError` at ``path:line:column``. docs/campaigns.md describes the format.

Offers:

* :class:`SuccessCheck` -- the checks of a task; ``evaluate(world)`` -> ``(ok, reason)``
* :class:`Check` -- one check (kind, arguments, options, where it came from)
* :func:`success_check` -- build it from a task file's problem, its grounding and an optional ``success:`` node
* :func:`success_check_file` -- the same with the ``success:`` node of a file (a campaign family file)
* :class:`SuccessError`
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bt_meta.errors import ConfigError
from bt_meta.judge.checks import KINDS, evaluate

__all__ = ["Check", "SuccessCheck", "SuccessError", "success_check", "success_check_file"]

_SUCCESS_KEYS = {"predicates", "checks"}
_MAPPING_KEYS = {"check", "args", "options"}
_CHECK_KEYS = {"check", "args", "options", "from_plan"}
#: argument names of :data:`~bt_meta.judge.checks.KINDS` that are task-file symbols the world must know
_SYMBOLS = {"object", "other", "feature", "pose", "..."}


class SuccessError(ConfigError):
    """A success check that is wrong (an unknown key, kind, predicate or object), at ``path:line:column``."""


@dataclass(frozen=True)
class Check:
    kind: str
    args: tuple[str, ...]
    options: dict[str, Any] = field(default_factory=dict)
    source: str = ""
    """What it checks for: ``goal at(show)``, ``plan at(b0, 0, 0)``, ``family file line 12``."""

    def text(self) -> str:
        return f"{self.kind}({', '.join(self.args)})"


@dataclass(frozen=True)
class SuccessCheck:
    checks: tuple[Check, ...]

    def evaluate(self, world: Any) -> tuple[bool | None, str]:
        """``(ok, reason)``: every check holds in ``world`` (the first that does not says why); ``None`` when the
        world has no simulator to ask."""
        if getattr(world, "sim", None) is None:
            return None, "no simulator to ask"
        held: list[str] = []
        for check in self.checks:
            if check.kind == "ignore":
                continue
            ok, why = evaluate(check.kind, check.args, check.options, world)
            if not ok:
                return False, f"{check.source or check.text()}: {why}"
            held.append(why)
        return True, "; ".join(held) if held else "nothing to check"

    def to_list(self) -> list[dict[str, Any]]:
        return [{"check": c.kind, "args": list(c.args), "options": dict(c.options), "source": c.source}
                for c in self.checks]


def success_check(task_file: Any, problem: Any, grounding: Any, node: yaml.Node | None = None,
                  path: str | Path | None = None, *, scene_objects: Iterable[str] = ()) -> SuccessCheck:
    """The success check of ``problem``: its goal through the mapping of ``node`` (a ``success:`` YAML node of the
    file ``path``, or None: the goal's predicates as check kinds), plus the node's ``checks``."""
    return _Builder(task_file, problem, grounding, path, set(scene_objects)).build(node)


def success_check_file(path: str | Path, task_file: Any, problem: Any, grounding: Any, *,
                       scene_objects: Iterable[str] = ()) -> SuccessCheck:
    """:func:`success_check` with the ``success:`` entry of the YAML mapping in ``path`` (its other keys are the
    reader of that file's to check); none there: the goal alone."""
    path = Path(path)
    try:
        root = yaml.compose(path.read_text(encoding="utf-8"), Loader=yaml.SafeLoader)
    except OSError as error:
        raise SuccessError(f"cannot read: {error.strerror or error}", path) from None
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        raise SuccessError(f"not valid YAML: {error.problem or error}", path, mark.line + 1 if mark else None,
                           mark.column + 1 if mark else None) from None
    node = None
    if isinstance(root, yaml.MappingNode):
        node = next((value for key, value in root.value if str(key.value) == "success"), None)
    return success_check(task_file, problem, grounding, node, path, scene_objects=scene_objects)


class _Builder:
    def __init__(self, task_file: Any, problem: Any, grounding: Any, path: str | Path | None,
                 scene_objects: set[str]) -> None:
        self.task_file = task_file
        self.problem = problem
        self.grounding = grounding
        self.path = Path(path) if path is not None else None
        symbols: set[str] = set(scene_objects)
        objects = getattr(problem, "objects", None) or {}
        for group in (objects.values() if isinstance(objects, Mapping) else [objects]):
            symbols |= {str(s) for s in group}
        for table in ("objects", "features", "poses"):
            symbols |= {str(k) for k in (getattr(grounding, table, None) or {})}
        symbols |= {str(v) for v in (getattr(grounding, "objects", None) or {}).values()}
        self.symbols = symbols
        self.predicates = set(getattr(task_file.domain, "predicates", {}) or {})

    # -- errors -----------------------------------------------------------------------------------------------

    def error(self, message: str, node: yaml.Node | None) -> SuccessError:
        if node is None or self.path is None:
            where = self.task_file.path if self.path is None else self.path
            line = getattr(self.problem, "line", None) if self.path is None else None
            column = getattr(self.problem, "column", None) if self.path is None else None
            return SuccessError(message, where, line, column)
        return SuccessError(message, self.path, node.start_mark.line + 1, node.start_mark.column + 1)

    # -- building ---------------------------------------------------------------------------------------------

    def build(self, node: yaml.Node | None) -> SuccessCheck:
        mapping: dict[str, tuple[str, tuple[str, ...] | None, dict[str, Any], yaml.Node | None]] = {}
        extra: list[yaml.Node] = []
        if node is not None:
            top = self.entries(node, "success", _SUCCESS_KEYS)
            if "predicates" in top:
                for key, value in self.entries(top["predicates"][1], "success.predicates", None).values():
                    name = str(key.value)
                    if self.predicates and name not in self.predicates:
                        known = ", ".join(sorted(self.predicates))
                        raise self.error(f"unknown predicate {name!r}; the domain's: {known}", key)
                    mapping[name] = self.mapped(value, name)
            if "checks" in top:
                items = top["checks"][1]
                if not isinstance(items, yaml.SequenceNode):
                    raise self.error("success.checks: a list of {check: KIND, args: [...]} or {from_plan: PREDICATE}",
                                     items)
                extra = list(items.value)
        checks = [self.atom_check(atom, "goal", mapping, node) for atom in getattr(self.problem, "goal", []) or []]
        for item in extra:
            checks += self.extra_check(item, mapping)
        unique: dict[tuple[str, tuple[str, ...]], Check] = {}
        for check in checks:  # a plan atom the goal names too is checked once, as the goal's
            unique.setdefault((check.kind, check.args), check)
        return SuccessCheck(tuple(unique.values()))

    def mapped(self, node: yaml.Node, predicate: str
               ) -> tuple[str, tuple[str, ...] | None, dict[str, Any], yaml.Node | None]:
        """A predicate's mapping: ``KIND`` (the atom's arguments) or ``{check: KIND, args: [...], options: {}}``
        (``args`` fixed: the atom's own are dropped)."""
        if isinstance(node, yaml.ScalarNode):
            return self.kind(node), None, {}, node
        entries = self.entries(node, f"success.predicates.{predicate}", _MAPPING_KEYS)
        if "check" not in entries:
            raise self.error(f"success.predicates.{predicate}: give `check: KIND`", node)
        kind = self.kind(entries["check"][1])
        args = tuple(self.strings(entries["args"][1], "args")) if "args" in entries else None
        options = self.options(entries["options"][1], kind) if "options" in entries else {}
        return kind, args, options, node

    def extra_check(self, node: yaml.Node, mapping: dict[str, Any]) -> list[Check]:
        entries = self.entries(node, "a success check", _CHECK_KEYS)
        if "from_plan" in entries:
            if len(entries) != 1:
                raise self.error("from_plan: PREDICATE stands alone", node)
            predicate_node = entries["from_plan"][1]
            predicate = str(getattr(predicate_node, "value", ""))
            if self.predicates and predicate not in self.predicates:
                raise self.error(f"unknown predicate {predicate!r}; the domain's: "
                                 f"{', '.join(sorted(self.predicates))}", predicate_node)
            return [self.atom_check(atom, "plan", mapping, predicate_node) for atom in self.plan_adds(predicate)]
        if "check" not in entries:
            raise self.error("a success check is {check: KIND, args: [...]} or {from_plan: PREDICATE}", node)
        kind = self.kind(entries["check"][1])
        args = tuple(self.strings(entries["args"][1], "args")) if "args" in entries else ()
        self.check_args(kind, args, entries.get("args", (None, node))[1])
        options = self.options(entries["options"][1], kind) if "options" in entries else {}
        line = f" (line {node.start_mark.line + 1})" if self.path is not None else ""
        return [Check(kind, args, options, f"{kind}({', '.join(args)}){line}")]

    def atom_check(self, atom: Any, origin: str, mapping: dict[str, Any], node: yaml.Node | None) -> Check:
        predicate, args = str(atom[0]), tuple(str(a) for a in atom[1:])
        text = f"{origin} {predicate}({', '.join(args)})"
        if predicate in mapping:
            kind, fixed, options, where = mapping[predicate]
            args = fixed if fixed is not None else args
        elif predicate in KINDS:
            kind, options, where = predicate, {}, node
        elif predicate == "at" and len(args) in (1, 3):
            kind, options, where = ("at_pose" if len(args) == 1 else "at_cell"), {}, node
        else:
            raise self.error(f"the {origin}'s predicate {predicate!r} has no geometric check: map it under "
                             f"`success: predicates:` to one of {', '.join(KINDS)}", node)
        self.check_args(kind, args, where)
        return Check(kind, args, options, text)

    def check_args(self, kind: str, args: tuple[str, ...], node: yaml.Node | None) -> None:
        names = KINDS[kind][0]
        if names != ("...",) and len(args) != len(names):
            raise self.error(f"check {kind!r} takes {len(names)} argument(s) ({', '.join(names)}), got "
                             f"{len(args)}", node)
        for index, (name, value) in enumerate(zip(names * (len(args) if names == ("...",) else 1), args,
                                                  strict=True)):
            if kind != "ignore" and name in _SYMBOLS and value not in self.symbols:
                item = node.value[index] if isinstance(node, yaml.SequenceNode) and index < len(node.value) else node
                raise self.error(f"check {kind!r}: unknown object {value!r} (not a symbol of the problem, the "
                                 "grounding or the scene)", item)

    def plan_adds(self, predicate: str) -> list[tuple[str, ...]]:
        """The atoms of ``predicate`` the nominal plan adds (in its final state, not in the initial one)."""
        from bt_meta.htn.planner import plan

        result = plan(self.task_file.domain, self.problem)
        if not result.ok or result.state is None:
            raise self.error(f"from_plan: the problem {self.problem.name!r} has no plan ({result.message})", None)
        initial = {tuple(map(str, a)) for a in self.problem.state}
        final = [tuple(map(str, a)) for a in result.state]
        return sorted(a for a in final if a and a[0] == predicate and a not in initial)

    # -- YAML nodes -------------------------------------------------------------------------------------------

    def kind(self, node: yaml.Node) -> str:
        name = str(getattr(node, "value", ""))
        if not isinstance(node, yaml.ScalarNode) or name not in KINDS:
            raise self.error(f"unknown check kind {name!r}; known: {', '.join(KINDS)}", node)
        return name

    def options(self, node: yaml.Node, kind: str) -> dict[str, Any]:
        known = KINDS[kind][1]
        out = {}
        for key, value in self.entries(node, f"options of {kind!r}", set(known)).values():
            out[str(key.value)] = yaml.safe_load(value.value) if isinstance(value, yaml.ScalarNode) else None
            if out[str(key.value)] is None and known[str(key.value)] is not None:
                raise self.error(f"options of {kind!r}: {key.value} must be a value", value)
        return out

    def strings(self, node: yaml.Node, what: str) -> list[str]:
        if not isinstance(node, yaml.SequenceNode) or not all(isinstance(i, yaml.ScalarNode) for i in node.value):
            raise self.error(f"{what}: a list of names or numbers", node)
        return [str(i.value) for i in node.value]

    def entries(self, node: yaml.Node, what: str, allowed: set[str] | None
                ) -> dict[str, tuple[yaml.Node, yaml.Node]]:
        if not isinstance(node, yaml.MappingNode):
            raise self.error(f"{what} must be a mapping", node)
        out: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        for key, value in node.value:
            name = str(key.value)
            if name in out:
                raise self.error(f"{what}: duplicate key {name!r}", key)
            if allowed is not None and name not in allowed:
                raise self.error(f"{what}: unknown key {name!r}; expected one of {', '.join(sorted(allowed))}", key)
            out[name] = (key, value)
        return out
