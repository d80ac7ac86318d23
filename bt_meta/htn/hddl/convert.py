"""Turning a parsed HDDL domain and its problems into a YAML task file (text) and a map of renamed names.

Offers:

* :func:`convert` -- :class:`~.syntax.HDomain` + problems -> :class:`Converted` (YAML text, names map)
* :class:`Converted` -- ``text`` (a task file the ordinary loader reads) and ``names`` (task-file name -> HDDL
  name for every name the task-file syntax could not spell as written) and ``synthetic`` (names we made up)

How each HDDL feature is spelled in the task file (see docs/task-files.md, "HDDL"):

* types and their hierarchy -> ``types:`` (a type is a 1-argument predicate); ``(either a b)`` -> a derived
  predicate ``either_a_b`` with one axiom per member type
* a typed parameter -> a type atom in the precondition: a test when the variable is bound (head, arguments),
  a generator for a method parameter that nothing else binds (HDDL's free method parameters)
* ``forall`` / ``exists`` -> the task file's own ``forall ?v - t: F`` / ``exists ?v - t: F`` (inside a goal
  that becomes an axiom, where quantifiers are not allowed: derived predicates over the free variables);
  ``imply`` and ``not`` are pushed inwards (negation normal form); ``=`` -> ``==`` / ``!=``
* ``forall`` / ``when`` effects, nested in any way -> ``effects:`` entries ``{forall: [...], when: ..., add:
  [...], delete: [...]}`` (nested ``forall``s concatenate their variables, nested ``when``s conjoin)
* a goal that is not a conjunction of atoms -> a 0-ary derived predicate that the goal names
* ``:htn`` with parameters or constraints -> a synthetic root task with one method
* ``:ordering`` -> the total order it implies; no ordering at all -> ``unordered:``; a partial order is refused
  with the position of the method
* ``(increase (total-cost) N)`` -> ``cost: N``

Refused with a located error: a type with several parents, partially ordered methods, a ``forall`` effect
variable that reuses a name in scope, a cost increase inside ``forall`` / ``when``.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

from bt_meta.htn.hddl.sexpr import HddlError, SList, Sym
from bt_meta.htn.hddl.syntax import Effect, Formula, HDomain, HMethod, HProblem, Subtask, TaskNetwork, Typed

_KEYWORDS = {"and", "or", "not", "true", "false"}
_NAME_OK = re.compile(r"[A-Za-z0-9_.+\-](?:[A-Za-z0-9_.+\-/:]*[A-Za-z0-9_.+\-/])?\Z")
_VAR_OK = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]*\Z")
_PLAIN_YAML = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]*\Z")
_YAML_SPECIAL = {"y", "n", "yes", "no", "on", "off", "true", "false", "null", "~"}
OBJECT = "object"


@dataclass
class Converted:
    text: str
    names: dict[str, str] = field(default_factory=dict)  # task-file name -> HDDL name (renamed ones only)
    synthetic: dict[str, str] = field(default_factory=dict)  # made-up name -> what it stands for
    problems: list[str] = field(default_factory=list)  # problem names in the file, in order

    def map_json(self) -> str:
        return json.dumps({"names": self.names, "synthetic": self.synthetic}, indent=2, sort_keys=True) + "\n"


def _yaml_scalar(text: str) -> str:
    if _PLAIN_YAML.match(text) and text.casefold() not in _YAML_SPECIAL:
        return text
    return json.dumps(text)


def _yaml_item(text: str) -> str:
    """An atom or condition as a YAML list item: plain when it starts with a letter, quoted otherwise."""
    if text[:1].isalpha() and ": " not in text and " #" not in text and not text.endswith(":"):
        return text
    return json.dumps(text)


class _Names:
    """Spellings of HDDL names in the task file: as written (first spelling, case-insensitively) when possible."""

    def __init__(self) -> None:
        self.spelled: dict[tuple[str, str], str] = {}  # (space, casefolded) -> task-file name
        self.taken: dict[str, set[str]] = {"pred": set(), "call": set(), "method": set(), "term": set()}
        self.renamed: dict[str, str] = {}
        self.synthetic: dict[str, str] = {}

    def _fresh(self, space: str, base: str) -> str:
        candidate, index = base, 1
        while candidate.casefold() in self.taken[space]:
            index += 1
            candidate = f"{base}_{index}"
        self.taken[space].add(candidate.casefold())
        return candidate

    def name(self, space: str, sym: Sym | str, *, declare: bool = False) -> str:
        text = sym.text if isinstance(sym, Sym) else sym
        key = (space, text.casefold())
        found = self.spelled.get(key)
        if found is not None:
            return found
        if space == "term":
            spelled = text  # terms that are keywords or odd are quoted instead (see term())
            self.taken[space].add(text.casefold())
        elif _NAME_OK.match(text) and text.casefold() not in _KEYWORDS and text.casefold() not in self.taken[space]:
            spelled = text
            self.taken[space].add(text.casefold())
        else:
            cleaned = re.sub(r"[^A-Za-z0-9_.+\-]", "_", text) or "name"
            if not cleaned[0].isalnum():
                cleaned = "n" + cleaned
            spelled = self._fresh(space, f"{cleaned}_" if cleaned.casefold() in _KEYWORDS else cleaned)
            self.renamed[spelled] = text
        self.spelled[key] = spelled
        return spelled

    def make(self, space: str, base: str, meaning: str) -> str:
        """A made-up name (auxiliary axioms, root tasks), never equal to an HDDL name."""
        spelled = self._fresh(space, base)
        self.synthetic[spelled] = meaning
        return spelled


class _Scope:
    """Variables of one method, action, axiom or quantifier: their task-file spellings and HDDL types."""

    def __init__(self, parent: _Scope | None = None) -> None:
        self.parent = parent
        self.vars: dict[str, tuple[str, tuple[Sym, ...]]] = {}  # casefolded ?name -> (spelling, types)

    def declare(self, typed: Typed, spelling: str) -> None:
        self.vars[typed.name.key] = (spelling, typed.types)

    def lookup(self, sym: Sym) -> tuple[str, tuple[Sym, ...]] | None:
        scope: _Scope | None = self
        while scope is not None:
            if sym.key in scope.vars:
                return scope.vars[sym.key]
            scope = scope.parent
        return None

    def all_spellings(self) -> set[str]:
        found: set[str] = set()
        scope: _Scope | None = self
        while scope is not None:
            found.update(v[0] for v in scope.vars.values())
            scope = scope.parent
        return found


class _Converter:
    def __init__(self, domain: HDomain) -> None:
        self.domain = domain
        self.path = domain.path
        self.names = _Names()
        self.types: dict[str, str | None] = {}  # spelled type -> spelled parent (None: object)
        self.type_pos: dict[str, Sym] = {}
        self.predicates: dict[str, list[str]] = {}
        self.axioms: list[tuple[str, str]] = []  # (head, condition)
        self.axiom_keys: dict[tuple, str] = {}
        self.primitives: dict[str, dict] = {}
        self.tasks: dict[str, list[str]] = {}
        self.methods: list[dict] = []
        self.constants: list[tuple[str, list[str]]] = []
        self.need_object = False
        self.either: dict[tuple[str, ...], str] = {}
        self.axiom_body = False  # converting a condition that becomes an axiom (no quantifiers there)

    def error(self, message: str, where: Sym | SList | None, path: str | None = None) -> HddlError:
        path = path or self.path
        if where is None:
            return HddlError(message, path)
        return HddlError(message, path, where.line, where.column)

    # -- declarations ---------------------------------------------------------------------------------------
    def declare(self) -> None:
        d = self.domain
        # predicate names first (they keep their spelling; a type of the same name is renamed)
        for pred, _args in d.predicates:
            self.names.name("pred", pred)
        parents: dict[str, tuple[str | None, Sym]] = {}
        for entry in d.types:
            if entry.name.key == OBJECT:
                continue
            if len(entry.types) > 1:
                raise self.error(f"type {entry.name.text} has an (either ...) parent; a type's parent must be "
                                 "one type", entry.name)
            spelled = self._type_name(entry.name)
            parent = None
            if entry.types and entry.types[0].key != OBJECT:
                parent = self._type_name(entry.types[0])
            if spelled in parents and parents[spelled][0] != parent:
                raise self.error(f"type {entry.name.text} is given a second parent ({entry.types[0].text}); types "
                                 "with several parents are not supported", entry.name)
            parents[spelled] = (parent, entry.name)
        for spelled, (parent, sym) in parents.items():
            self.types[spelled] = parent
            self.type_pos[spelled] = sym
            if parent is not None and parent not in parents:
                self.types.setdefault(parent, None)
        for pred, args in d.predicates:
            spelled = self.names.name("pred", pred)
            if spelled in self.predicates:
                raise self.error(f"predicate {pred.text} is declared twice", pred)
            self.predicates[spelled] = [self._arg_type(a.types) for a in args]
        for entry in d.constants:
            self.constants.append((self.term_of_object(entry.name), self._object_types(entry)))
        for action in d.actions:
            self.names.name("call", action.name)
        for task in d.tasks:
            spelled = self.names.name("call", task.name)
            if any(self.names.name("call", a.name) == spelled for a in d.actions):
                raise self.error(f"task {task.name.text} has the name of an action", task.name)
            self.tasks[spelled] = [f"?{self._var_name(p.name)}" for p in task.params]
        self.task_arity = {self.names.name("call", t.name): len(t.params) for t in d.tasks}
        self.actions_by_key = {a.name.key: a for a in d.actions}
        self.methods_by_task_key: dict[str, list[HMethod]] = {}
        for method in d.methods:
            self.methods_by_task_key.setdefault(method.task.key, []).append(method)
        self.constant_types = {c.name.key: c.types for c in d.constants}
        self._changes: dict[str, set[tuple[str, tuple[str | None, ...]]]] | None = None
        changed: set[str] = set()
        pending = [e for a in d.actions for e in a.effects]
        while pending:
            effect = pending.pop()
            if effect.pred is not None:
                changed.add(effect.pred.key)
            pending.extend(effect.effects)
        self.static_keys = {pred.key for pred, _ in d.predicates} - changed
        self.action_arity = {self.names.name("call", a.name): len(a.params) for a in d.actions}

    def _type_name(self, sym: Sym) -> str:
        if ("pred", sym.key) in self.names.spelled and ("type", sym.key) not in self.names.spelled:
            # a predicate already has this name: the type gets a new one
            spelled = self.names.make("pred", f"{sym.text}_type", f"type {sym.text}")
            self.names.synthetic.pop(spelled)
            self.names.renamed[spelled] = sym.text
            self.names.spelled[("type", sym.key)] = spelled
            return spelled
        found = self.names.spelled.get(("type", sym.key))
        if found is not None:
            return found
        spelled = self.names.name("pred", sym)
        self.names.spelled[("type", sym.key)] = spelled
        return spelled

    def _arg_type(self, types: tuple[Sym, ...]) -> str:
        if len(types) != 1 or types[0].key == OBJECT:
            return OBJECT
        spelled = self._type_name(types[0])
        self.types.setdefault(spelled, None)
        return spelled

    def _object_types(self, entry: Typed) -> list[str]:
        if len(entry.types) > 1:
            raise self.error(f"object {entry.name.text} has an (either ...) type; give one type", entry.name)
        if not entry.types or entry.types[0].key == OBJECT:
            return []
        spelled = self._type_name(entry.types[0])
        self.types.setdefault(spelled, None)
        return [spelled]

    def _var_name(self, sym: Sym) -> str:
        body = sym.text[1:]
        if _VAR_OK.match(body):
            return body
        return "v_" + re.sub(r"[^A-Za-z0-9_\-]", "_", body)

    def term_of_object(self, sym: Sym) -> str:
        spelled = self.names.name("term", sym)
        return spelled

    def term(self, sym: Sym, scope: _Scope, where: str) -> str:
        if sym.is_var:
            found = scope.lookup(sym)
            if found is None:
                raise self.error(f"variable {sym.text} in {where} is not a parameter", sym)
            return f"?{found[0]}"
        spelled = self.term_of_object(sym)
        if _NAME_OK.match(spelled) and spelled.casefold() not in _KEYWORDS:
            return spelled
        return "'" + spelled + "'" if "'" not in spelled else json.dumps(spelled)

    # -- type atoms -----------------------------------------------------------------------------------------
    def type_atom(self, types: tuple[Sym, ...], var_text: str, *, needed: bool) -> str | None:
        """The atom that says ``var`` has one of ``types``; None for object unless it must bind (``needed``)."""
        if not types or any(t.key == OBJECT for t in types):
            if not needed:
                return None
            self.need_object = True
            return f"{OBJECT}({var_text})"
        if len(types) == 1:
            spelled = self._type_name(types[0])
            self.types.setdefault(spelled, None)
            return f"{spelled}({var_text})"
        members = tuple(sorted({self._type_name(t) for t in types}))
        pred = self.either.get(members)
        if pred is None:
            pred = self.names.make("pred", "either_" + "_".join(members), f"(either {' '.join(members)})")
            self.either[members] = pred
            for member in members:
                self.types.setdefault(member, None)
                self.axioms.append((f"{pred}(?x)", f"{member}(?x)"))
        return f"{pred}({var_text})"

    # -- conditions -----------------------------------------------------------------------------------------
    def free_vars(self, f: Formula, scope: _Scope, bound_here: frozenset[str] = frozenset()) -> list[Sym]:
        """Variables of ``f`` not quantified inside it, in order of appearance (first spelling)."""
        found: dict[str, Sym] = {}

        def walk(node: Formula, inner: frozenset[str]) -> None:
            if node.op in ("exists", "forall"):
                inner = inner | {p.name.key for p in node.params}
            for term in node.terms:
                if term.is_var and term.key not in inner:
                    found.setdefault(term.key, term)
            for child in node.children:
                walk(child, inner)

        walk(f, bound_here)
        return list(found.values())

    def condition(self, f: Formula, scope: _Scope, negate: bool, where: str) -> str:
        """``f`` in the condition language, in negation normal form; quantifiers become derived atoms."""
        op = f.op
        if op == "true":
            return "false" if negate else "true"
        if op == "atom":
            assert f.pred is not None
            pred = self.names.spelled.get(("pred", f.pred.key))
            if pred is None or pred not in self.predicates:
                known = ", ".join(sorted(self.predicates)) or "none"
                raise self.error(f"unknown predicate {f.pred.text!r} in {where} (known: {known})", f.pred)
            if len(f.terms) != len(self.predicates[pred]):
                raise self.error(f"predicate {f.pred.text} takes {len(self.predicates[pred])} argument(s), got "
                                 f"{len(f.terms)}", f.pred)
            text = f"{pred}({', '.join(self.term(t, scope, where) for t in f.terms)})"
            return f"not {text}" if negate else text
        if op == "=":
            left, right = (self.term(t, scope, where) for t in f.terms)
            return f"{left} {'!=' if negate else '=='} {right}"
        if op == "not":
            return self.condition(f.children[0], scope, not negate, where)
        if op in ("and", "or"):
            if not f.children:
                empty_true = op == "and"
                return "true" if empty_true != negate else "false"
            joiner = " and " if (op == "and") != negate else " or "
            parts = [self.condition(c, scope, negate, where) for c in f.children]
            return joiner.join(f"({p})" if (" or " in p or " and " in p) else p for p in parts)
        if op == "imply":
            premise, conclusion = f.children
            if negate:  # not (a -> b) == a and not b
                parts = [self.condition(premise, scope, False, where), self.condition(conclusion, scope, True, where)]
                return " and ".join(f"({p})" for p in parts)
            parts = [self.condition(premise, scope, True, where), self.condition(conclusion, scope, False, where)]
            return " or ".join(f"({p})" for p in parts)
        if op in ("exists", "forall"):
            return self.quantifier(f, scope, negate, where)
        raise self.error(f"unsupported condition {op!r} in {where}", f.where)

    def quantifier(self, f: Formula, scope: _Scope, negate: bool, where: str) -> str:
        """``(forall ?v - t: F)`` / ``(exists ...)``, negation pushed into the body; in an axiom, a derived atom."""
        if self.axiom_body:
            return self.quantifier_axiom(f, scope, negate, where)
        inner = _Scope(scope)
        for p in f.params:
            inner.declare(p, self._var_name(p.name))
        for sym in self.free_vars(f, scope):
            if scope.lookup(sym) is None:
                raise self.error(f"variable {sym.text} in {where} is not a parameter", sym)
        variables = []
        for p in f.params:
            var = self._var_name(p.name)
            atom = self.type_atom(p.types, f"?{var}", needed=True)
            assert atom is not None
            variables.append(f"?{var} - {atom[:atom.index('(')]}")
        op = f.op if not negate else ("exists" if f.op == "forall" else "forall")
        body = self.condition(f.children[0], inner, negate, where)
        return f"({op} {', '.join(variables)}: {body})"

    def quantifier_axiom(self, f: Formula, scope: _Scope, negate: bool, where: str) -> str:
        inner = _Scope(scope)
        for p in f.params:
            inner.declare(p, self._var_name(p.name))
        free = self.free_vars(f, scope)
        free_texts = []
        prefix = []
        for sym in free:
            found = scope.lookup(sym)
            if found is None:
                raise self.error(f"variable {sym.text} in {where} is not a parameter", sym)
            free_texts.append(f"?{found[0]}")
            # the head's variables must be bound by the axiom's condition: their types bind them (as tests,
            # since the derived atom is only asked with its arguments bound)
            prefix.append(self.type_atom(found[1], f"?{found[0]}", needed=True))
        binders = [self.type_atom(p.types, f"?{self._var_name(p.name)}", needed=True) for p in f.params]
        # exists: body = types and F; forall: violation = types and not F (the forall holds when none exists)
        body = self.condition(f.children[0], inner, f.op == "forall", where)
        parts = [*[p for p in prefix if p], *[b for b in binders if b], f"({body})"]
        condition = " and ".join(parts)
        key = (f.op, tuple(free_texts), condition)
        pred = self.axiom_keys.get(key)
        if pred is None:
            base = "exists" if f.op == "exists" else "forall_fails"
            pred = self.names.make("pred", base, f"({f.op} ...) at {self.path}:{f.where.line}:{f.where.column}")
            self.axiom_keys[key] = pred
            self.axioms.append((f"{pred}({', '.join(free_texts)})", condition))
        atom = f"{pred}({', '.join(free_texts)})"
        holds = f.op == "exists"
        return atom if holds != negate else f"not {atom}"

    def conjuncts(self, f: Formula | None) -> list[Formula]:
        if f is None or f.op == "true":
            return []
        if f.op == "and":
            found: list[Formula] = []
            for child in f.children:
                found.extend(self.conjuncts(child))
            return found
        return [f]

    def precondition(self, pre: Formula | None, scope: _Scope, bound: set[str], needed: Iterable[Sym],
                     where: str, params: Sequence[Typed], tested: set[str]) -> list[str]:
        """Conjuncts in order, with type atoms that bind free parameters before their first test.

        ``bound``: spellings bound on entry (typed ones in ``tested`` already have their type checked by a
        positive atom of a declared type, or need a test added here). ``needed``: variables used afterwards
        (subtasks) that must be bound by the end.
        """
        out: list[str] = []
        type_of = {self._var_name(p.name): p.types for p in params}

        def bind(var_text: str) -> None:
            if var_text in bound:
                return
            atom = self.type_atom(type_of.get(var_text, ()), f"?{var_text}", needed=True)
            out.append(atom or "")
            bound.add(var_text)
            tested.add(var_text)

        def unbound(conj: Formula) -> list[str]:
            names = []
            for sym in self.free_vars(conj, scope):
                found = scope.lookup(sym)
                if found is not None and found[0] not in bound:
                    names.append(found[0])
            return names

        # positive atoms in order, each test (not, =, quantifiers, or) as soon as atoms before it bound its
        # variables; tests still unbound at the end get type atoms that bind them (HDDL's conjunction has no order)
        waiting: list[Formula] = []
        for conj in self.conjuncts(pre):
            if conj.op != "atom":
                if unbound(conj):
                    waiting.append(conj)
                else:
                    out.append(self.condition(conj, scope, False, where))
                continue
            out.append(self.condition(conj, scope, False, where))
            pred_types = self.predicates.get(self.names.spelled.get(("pred", conj.pred.key), ""), [])
            for position, term in enumerate(conj.terms):
                if not term.is_var:
                    continue
                found = scope.lookup(term)
                if found is None:
                    continue
                spelled = found[0]
                declared = pred_types[position] if position < len(pred_types) else OBJECT
                covered = self.subtype(declared, found[1])  # the fact's declared type implies the var's
                if spelled not in bound:
                    bound.add(spelled)
                    if not covered:
                        atom = self.type_atom(found[1], f"?{spelled}", needed=False)
                        if atom:
                            out.append(atom)
                    tested.add(spelled)
                elif covered:
                    tested.add(spelled)
            ready = [w for w in waiting if not unbound(w)]
            for conj_ready in ready:
                waiting.remove(conj_ready)
                out.append(self.condition(conj_ready, scope, False, where))
        for conj in waiting:
            for spelled in unbound(conj):
                bind(spelled)
            out.append(self.condition(conj, scope, False, where))
        for sym in needed:
            found = scope.lookup(sym)
            if found is not None:
                bind(found[0])
        for spelled in sorted(bound - tested):
            atom = self.type_atom(type_of.get(spelled, ()), f"?{spelled}", needed=False)
            if atom:
                out.append(atom)
            tested.add(spelled)
        kept: list[str] = []
        for conjunct in out:  # a lifted action precondition often repeats the method's own conjuncts
            if conjunct and conjunct != "true" and conjunct not in kept:
                kept.append(conjunct)
        return kept

    def subtype(self, declared: str, wanted: tuple[Sym, ...]) -> bool:
        """Whether every object of type ``declared`` has one of the ``wanted`` types."""
        if not wanted or any(t.key == OBJECT for t in wanted):
            return True
        targets = {self._type_name(t) for t in wanted}
        cursor: str | None = declared
        seen: set[str] = set()
        while cursor is not None and cursor != OBJECT and cursor not in seen:
            if cursor in targets:
                return True
            seen.add(cursor)
            cursor = self.types.get(cursor)
        return False

    # -- actions, methods -----------------------------------------------------------------------------------
    def convert_domain(self) -> None:
        self.declare()
        for action in self.domain.actions:
            name = self.names.name("call", action.name)
            what = f"action {action.name.text}"
            scope = _Scope()
            for p in action.params:
                if scope.lookup(p.name) is not None:
                    raise self.error(f"duplicate parameter {p.name.text} in {what}", p.name)
                scope.declare(p, self._var_name(p.name))
            params = [f"?{self._var_name(p.name)}" for p in action.params]
            bound = {self._var_name(p.name) for p in action.params}
            pre = self.precondition(action.precondition, scope, bound, [], f"the precondition of {what}",
                                    action.params, set())
            add, delete, cost = [], [], 1.0
            cost_given = False
            conditional: dict[tuple, dict] = {}  # (forall variables, when) -> entry, in first-seen order
            for effect_params, conditions, effect_scope, effect in self.flat_effects(action.effects, scope, [], [],
                                                                                     what):
                if effect.kind == "cost":
                    cost = effect.amount if not cost_given else cost + effect.amount
                    cost_given = True
                    continue
                text = self.effect_atom(effect, effect_scope, what)
                if not effect_params and not conditions:
                    (add if effect.kind == "add" else delete).append(text)
                    continue
                variables = []
                for p in effect_params:
                    var = self._var_name(p.name)
                    atom = self.type_atom(p.types, f"?{var}", needed=True)
                    assert atom is not None
                    variables.append(f"?{var} - {atom[:atom.index('(')]}")
                when = None
                if conditions:
                    where = conditions[0].where
                    when = self.condition(Formula("and", where, list(conditions)), effect_scope, False,
                                          f"a when condition of {what}")
                    when = None if when == "true" else when
                entry = conditional.setdefault((tuple(variables), when),
                                               {"forall": variables, "when": when, "add": [], "delete": []})
                entry["add" if effect.kind == "add" else "delete"].append(text)
            self.primitives[name] = {"parameters": params, "precondition": pre, "add": add, "delete": delete,
                                     "cost": cost if cost_given else None, "effects": list(conditional.values())}
        for method in self.domain.methods:
            self.methods.append(self.convert_method(method))

    def flat_effects(self, effects: Sequence[Effect], scope: _Scope, params: list[Typed], conditions: list[Formula],
                     what: str) -> list[tuple[list[Typed], list[Formula], _Scope, Effect]]:
        """Every add / delete / cost effect with the ``forall`` variables and ``when`` conditions around it."""
        found: list[tuple[list[Typed], list[Formula], _Scope, Effect]] = []
        for effect in effects:
            if effect.kind == "forall":
                inner = _Scope(scope)
                for p in effect.params:
                    if scope.lookup(p.name) is not None or inner.lookup(p.name) is not None:
                        raise self.error(f"{what}: the forall variable {p.name.text} is already a variable here; "
                                         "give it another name", p.name)
                    inner.declare(p, self._var_name(p.name))
                found.extend(self.flat_effects(effect.effects, inner, [*params, *effect.params], conditions, what))
            elif effect.kind == "when":
                assert effect.condition is not None
                found.extend(self.flat_effects(effect.effects, scope, params, [*conditions, effect.condition],
                                               what))
            elif effect.kind == "cost" and (params or conditions):
                raise self.error(f"{what}: (increase (total-cost) ...) inside forall / when is not supported (a "
                                 "primitive has one cost)", effect.where)
            else:
                found.append((params, conditions, scope, effect))
        return found

    def effect_atom(self, effect: Effect, scope: _Scope, what: str) -> str:
        assert effect.pred is not None
        pred = self.names.spelled.get(("pred", effect.pred.key))
        if pred is None or pred not in self.predicates:
            raise self.error(f"unknown predicate {effect.pred.text!r} in the effect of {what}", effect.pred)
        if len(effect.terms) != len(self.predicates[pred]):
            raise self.error(f"predicate {effect.pred.text} takes {len(self.predicates[pred])} argument(s), got "
                             f"{len(effect.terms)}", effect.pred)
        return f"{pred}({', '.join(self.term(t, scope, f'the effect of {what}') for t in effect.terms)})"

    def call(self, sub: Subtask, scope: _Scope, what: str) -> str:
        spelled = self.names.spelled.get(("call", sub.name.key))
        if spelled is None:
            raise self.error(f"unknown task or action {sub.name.text!r} in {what}", sub.name)
        arity = self.task_arity.get(spelled, self.action_arity.get(spelled))
        if arity != len(sub.args):
            raise self.error(f"{sub.name.text} takes {arity} argument(s), got {len(sub.args)}", sub.name)
        return f"{spelled}({', '.join(self.term(t, scope, what) for t in sub.args)})"

    def order(self, net: TaskNetwork, what: str, where: Sym | SList) -> tuple[list[Subtask], bool]:
        """The subtasks in their total order (and True), or as given with False when no order is imposed."""
        subs = net.subtasks
        if net.declared_ordered or len(subs) <= 1:
            return subs, True
        if not net.ordering:
            return subs, False
        index = {}
        for position, sub in enumerate(subs):
            if sub.ident is not None:
                index[sub.ident.key] = position
        after: dict[int, set[int]] = {i: set() for i in range(len(subs))}
        for first, second in net.ordering:
            for sym in (first, second):
                if sym.key not in index:
                    raise self.error(f"unknown task id {sym.text!r} in the ordering of {what}", sym)
            after[index[first.key]].add(index[second.key])
        indegree = {i: 0 for i in after}
        for targets in after.values():
            for t in targets:
                indegree[t] += 1
        result: list[Subtask] = []
        ready = [i for i in range(len(subs)) if indegree[i] == 0]
        while ready:
            if len(ready) > 1:
                a, b = subs[ready[0]], subs[ready[1]]
                raise self.error(f"{what} is partially ordered ({(a.ident or a.name).text} and "
                                 f"{(b.ident or b.name).text} are not ordered); only totally ordered HDDL is "
                                 "supported", where)
            current = ready.pop()
            result.append(subs[current])
            for t in sorted(after[current]):
                indegree[t] -= 1
                if indegree[t] == 0:
                    ready.append(t)
        if len(result) != len(subs):
            raise self.error(f"the ordering of {what} has a cycle", where)
        return result, True

    def network_method(self, name: str, task_text: str, scope: _Scope, params: Sequence[Typed],
                       head_vars: set[str], head_types: dict[str, tuple[Sym, ...]], pre: Formula | None,
                       net: TaskNetwork, what: str, where: Sym | SList) -> dict:
        ordered_subs, ordered = self.order(net, what, where)
        needed = [t for sub in ordered_subs for t in sub.args if t.is_var]
        bound = set(head_vars)
        tested = {v for v in head_vars if self.subtype_of_types(head_types.get(v, ()), self._types_of(v, params))}
        conjuncts = [pre] if pre is not None else []
        if net.constraints is not None:
            conjuncts.append(net.constraints)
        if ordered and ordered_subs:
            lifted = self.first_action_precondition(ordered_subs[0])
            if lifted is not None:
                conjuncts.append(lifted)
        if ordered:
            for position, sub in enumerate(ordered_subs):
                conjuncts.extend(self.lifted_precondition(sub, ordered_subs[:position], scope))
        else:
            for sub in ordered_subs:
                conjuncts.extend(self.static_precondition(sub))
        combined = Formula("and", where, conjuncts) if conjuncts else None
        precondition = self.precondition(combined, scope, bound, needed, f"the precondition of {what}", params,
                                         tested)
        subtasks = [self.call(sub, scope, f"the subtasks of {what}") for sub in ordered_subs]
        return {"name": name, "task": task_text, "precondition": precondition,
                "subtasks" if ordered else "unordered": subtasks}

    def first_action_precondition(self, sub: Subtask) -> Formula | None:
        """The precondition of an action that comes first in a method, in the method's terms.

        The first subtask starts in the state the method is applied in, so a method binding whose first action
        cannot apply is a dead end; testing that precondition with the method's lets its atoms bind the free
        parameters the action uses, instead of trying every object of their types. Plans are unchanged (it
        only removes alternatives that fail at the next step); the order of bindings follows the atoms.
        """
        action = self.actions_by_key.get(sub.name.key)
        if action is None or action.precondition is None or len(action.params) != len(sub.args):
            return None
        mapping = {p.name.key: arg for p, arg in zip(action.params, sub.args, strict=True)}
        return _substitute(action.precondition, mapping)

    def lifted_precondition(self, sub: Subtask, before: Sequence[Subtask], scope: _Scope) -> list[Formula]:
        """Conjuncts that must hold when ``sub`` starts and that the subtasks ``before`` it cannot change.

        ``sub``'s conditions: an action's precondition, or the precondition of a task's only method (the
        conjuncts over its head's variables). A conjunct whose atom no action reachable from ``before`` can add
        or delete -- no effect on its predicate with compatible argument types -- is true when ``sub`` starts
        iff it is true when the method is applied, so it is tested there too: only bindings that would fail
        later go (Transport's (at ?p ?l1) of load, past get_to that moves vehicles only, binds the pick-up
        place instead of every place being tried with a whole route driven to each).
        """
        if not before and sub.name.key in self.actions_by_key:
            return []  # the first action's whole precondition is lifted by first_action_precondition
        conditions: list[Formula] = []
        action = self.actions_by_key.get(sub.name.key)
        if action is not None:
            if action.precondition is None or len(action.params) != len(sub.args):
                return []
            mapping = {p.name.key: arg for p, arg in zip(action.params, sub.args, strict=True)}
            conditions = [_substitute(c, mapping) for c in self.conjuncts(action.precondition)]
        else:
            methods = self.methods_by_task_key.get(sub.name.key, [])
            if len(methods) != 1:
                return []
            method = methods[0]
            head = method.task_args
            if len(head) != len(sub.args) or not all(t.is_var for t in head) or len({t.key for t in head}) != len(head):
                return []
            mapping = {t.key: arg for t, arg in zip(head, sub.args, strict=True)}
            own = self.conjuncts(method.precondition)
            sub_order, sub_ordered = self.order(method.network, f"method {method.name.text}", method.where)
            first = sub_order[:1] if sub_ordered else []
            if first:  # the method's first action must apply where the method does, so its precondition counts
                first_pre = self.first_action_precondition(first[0])
                own = [*own, *self.conjuncts(first_pre)]
            for conj in own:
                atom = conj.children[0] if conj.op == "not" and conj.children else conj
                if atom.op == "atom" and all(not t.is_var or t.key in mapping for t in atom.terms):
                    conditions.append(_substitute(conj, mapping))
        changes = set()
        for earlier in before:
            changes |= self.changes_of(earlier.name.key)
        lifted = []
        for conj in conditions:
            atom = conj.children[0] if conj.op == "not" and conj.children else conj
            if atom.op != "atom" or atom.pred is None:
                continue
            wanted = tuple(self._term_type(t, scope) for t in atom.terms)
            if not any(pred == atom.pred.key and len(types) == len(wanted)
                       and all(self._compatible(a, b) for a, b in zip(types, wanted, strict=True))
                       for pred, types in changes):
                lifted.append(conj)
        return lifted

    def _term_type(self, term: Sym, scope: _Scope) -> str | None:
        if term.is_var:
            found = scope.lookup(term)
            types = found[1] if found is not None else ()
        else:
            types = self.constant_types.get(term.key, ())
        if len(types) != 1 or types[0].key == OBJECT:
            return None
        return self._type_name(types[0])

    def _compatible(self, first: str | None, second: str | None) -> bool:
        """Whether an object can have both types (one is the other or an ancestor of it); None: any type."""
        if first is None or second is None or first == second:
            return True
        return self._below(first, second) or self._below(second, first)

    def _below(self, lower: str, upper: str) -> bool:
        """Whether task-file type ``lower`` is ``upper`` or one of its descendants."""
        cursor: str | None = lower
        seen: set[str] = set()
        while cursor is not None and cursor not in seen:
            if cursor == upper:
                return True
            seen.add(cursor)
            cursor = self.types.get(cursor)
        return False

    def changes_of(self, key: str) -> set[tuple[str, tuple[str | None, ...]]]:
        """(predicate, argument types) of every atom the action, or any decomposition of the task, can change."""
        if self._changes is None:
            changes: dict[str, set[tuple[str, tuple[str | None, ...]]]] = {}
            for action in self.domain.actions:
                scope = _Scope()
                for p in action.params:
                    scope.declare(p, self._var_name(p.name))
                found: set[tuple[str, tuple[str | None, ...]]] = set()
                pending = list(action.effects)
                while pending:
                    effect = pending.pop()
                    pending.extend(effect.effects)
                    if effect.pred is not None:
                        inner = scope
                        if effect.kind == "forall" or effect.params:
                            inner = _Scope(scope)
                        found.add((effect.pred.key, tuple(
                            self._term_type(t, inner) if inner.lookup(t) or not t.is_var else None
                            for t in effect.terms)))
                    for nested in effect.effects:  # forall / when bodies may use their own variables
                        if nested.pred is not None:
                            found.add((nested.pred.key, tuple(None for _ in nested.terms)))
                changes[action.name.key] = found
            for task in self.domain.tasks:
                changes.setdefault(task.name.key, set())
            grew = True
            while grew:
                grew = False
                for method in self.domain.methods:
                    target = changes.setdefault(method.task.key, set())
                    size = len(target)
                    for sub in method.network.subtasks:
                        target |= changes.get(sub.name.key, set())
                    grew = grew or len(target) != size
            self._changes = changes
        return self._changes.get(key, set())

    def static_precondition(self, sub: Subtask) -> list[Formula]:
        """The conjuncts of a subtask action's precondition on static predicates, in the method's terms.

        A predicate no action changes holds in every state exactly as in the initial one, so such a conjunct
        is true when the action runs iff it is true when the method is applied: testing it with the method's
        precondition only removes bindings that would fail later (``road(?l2, ?l3)`` binds a route's next
        location instead of every location being tried, with everything between done first).
        """
        action = self.actions_by_key.get(sub.name.key)
        if action is None or action.precondition is None or len(action.params) != len(sub.args):
            return []
        mapping = {p.name.key: arg for p, arg in zip(action.params, sub.args, strict=True)}
        found = []
        for conj in self.conjuncts(action.precondition):
            atom = conj.children[0] if conj.op == "not" and conj.children[0].op == "atom" else conj
            if atom.op == "atom" and atom.pred is not None and atom.pred.key in self.static_keys:
                found.append(_substitute(conj, mapping))
        return found

    def _types_of(self, var: str, params: Sequence[Typed]) -> tuple[Sym, ...]:
        for p in params:
            if self._var_name(p.name) == var:
                return p.types
        return ()

    def subtype_of_types(self, have: tuple[Sym, ...], wanted: tuple[Sym, ...]) -> bool:
        if not wanted or any(t.key == OBJECT for t in wanted):
            return True
        if len(have) != 1:
            return False
        return self.subtype(self._type_name(have[0]) if have[0].key != OBJECT else OBJECT, wanted)

    def convert_method(self, method: HMethod) -> dict:
        what = f"method {method.name.text}"
        name = self.names.name("method", method.name)
        scope = _Scope()
        for p in method.params:
            if scope.lookup(p.name) is not None:
                raise self.error(f"duplicate parameter {p.name.text} in {what}", p.name)
            scope.declare(p, self._var_name(p.name))
        task = self.names.spelled.get(("call", method.task.key))
        if task is None or task not in self.tasks:
            kind = "an action" if task in self.primitives else "not a declared task"
            raise self.error(f"{what} decomposes {method.task.text}, which is {kind}", method.task)
        if len(method.task_args) != self.task_arity[task]:
            raise self.error(f"{method.task.text} takes {self.task_arity[task]} argument(s), got "
                             f"{len(method.task_args)}", method.task)
        head_vars: set[str] = set()
        head_types: dict[str, tuple[Sym, ...]] = {}
        decl = next(t for t in self.domain.tasks if self.names.name("call", t.name) == task)
        for position, term in enumerate(method.task_args):
            if term.is_var:
                found = scope.lookup(term)
                if found is None:
                    raise self.error(f"variable {term.text} in the task of {what} is not a parameter", term)
                head_vars.add(found[0])
                head_types[found[0]] = decl.params[position].types
        task_text = f"{task}({', '.join(self.term(t, scope, what) for t in method.task_args)})"
        return self.network_method(name, task_text, scope, method.params, head_vars, head_types,
                                   method.precondition, method.network, what, method.where)

    # -- problems -------------------------------------------------------------------------------------------
    def convert_problem(self, problem: HProblem) -> tuple[str, dict]:
        path = problem.path
        saved = self.path
        self.path = path
        try:
            return self._convert_problem(problem)
        finally:
            self.path = saved

    def _convert_problem(self, problem: HProblem) -> tuple[str, dict]:
        name = problem.name.text
        objects: dict[str, list[str]] = {}
        untyped: list[str] = []
        seen: set[tuple[str, str]] = set()
        for obj_name, obj_types in self.constants:
            self._add_object(objects, untyped, seen, obj_name, obj_types)
        for entry in problem.objects:
            self._add_object(objects, untyped, seen, self.term_of_object(entry.name), self._object_types(entry))
        scope = _Scope()
        init = []
        for pred_sym, terms in problem.init:
            pred = self.names.spelled.get(("pred", pred_sym.key))
            if pred is None or pred not in self.predicates:
                if ("type", pred_sym.key) in self.names.spelled and len(terms) == 1:
                    pred = self.names.spelled[("type", pred_sym.key)]
                else:
                    raise self.error(f"unknown predicate {pred_sym.text!r} in the initial state", pred_sym)
            elif len(terms) != len(self.predicates[pred]):
                raise self.error(f"predicate {pred_sym.text} takes {len(self.predicates[pred])} argument(s), got "
                                 f"{len(terms)}", pred_sym)
            init.append(f"{pred}({', '.join(self.term(t, scope, 'the initial state') for t in terms)})")
        tasks: list[str] = []
        net = problem.htn or TaskNetwork()
        where = net.where or problem.name
        constraints = net.constraints if net.constraints is not None and net.constraints.op != "true" else None
        if problem.htn_params or constraints is not None:
            for p in problem.htn_params:
                scope.declare(p, self._var_name(p.name))
            top = self.names.make("call", f"htn_{re.sub(r'[^A-Za-z0-9_]', '_', name)}",
                                  f"the initial task network of problem {name}")
            self.tasks[top] = []
            self.task_arity[top] = 0
            method_name = self.names.make("method", f"{top}_method", f"the initial task network of problem {name}")
            self.methods.append(self.network_method(method_name, f"{top}()", scope, problem.htn_params, set(), {},
                                                    None, net, f"the :htn of problem {name}", where))
            tasks.append(f"{top}()")
        else:
            ordered_subs, ordered = self.order(net, f"the :htn of problem {name}", where)
            if not ordered:
                raise self.error(f"the :htn of problem {name} has several tasks and no ordering; only totally "
                                 "ordered HDDL is supported", where)
            tasks = [self.call(sub, scope, f"the :htn of problem {name}") for sub in ordered_subs]
        goal: list[str] = []
        goal_parts = self.conjuncts(problem.goal)
        if goal_parts and all(g.op == "atom" for g in goal_parts):
            goal = [self.condition(g, scope, False, "the goal") for g in goal_parts]
        elif goal_parts:
            self.axiom_body = True
            try:
                text = self.condition(Formula("and", problem.goal.where, goal_parts), scope, False, "the goal")
            finally:
                self.axiom_body = False
            pred = self.names.make("pred", f"goal_{re.sub(r'[^A-Za-z0-9_]', '_', name)}",
                                   f"the goal of problem {name}")
            self.axioms.append((f"{pred}()", text))
            goal = [f"{pred}()"]
        if untyped or self.need_object:
            objects.setdefault(OBJECT, []).extend(untyped)
        return name, {"objects": objects, "init": init, "tasks": tasks, "goal": goal}

    def _add_object(self, objects: dict[str, list[str]], untyped: list[str], seen: set[tuple[str, str]], name: str,
                    types: list[str]) -> None:
        for type_name in types or [OBJECT]:
            if (name, type_name) in seen:
                continue
            seen.add((name, type_name))
            if type_name == OBJECT:
                untyped.append(name)
            else:
                objects.setdefault(type_name, []).append(name)

    # -- writing --------------------------------------------------------------------------------------------
    def write(self, problems: list[tuple[str, dict]]) -> str:
        out: list[str] = [f"# imported from HDDL: {self.domain.path}", "domain:",
                          f"  name: {_yaml_scalar(self.domain.name.text)}"]
        types = dict(self.types)
        if self.need_object:
            types = {OBJECT: None, **{k: (v if v is not None else OBJECT) for k, v in types.items()}}
        if types:
            out.append("  types:")
            for type_name, parent in types.items():
                out.append(f"    {_yaml_scalar(type_name)}: {_yaml_scalar(parent) if parent else 'null'}")
        out.append("  predicates:" if self.predicates else "  predicates: {}")
        for pred, arg_types in self.predicates.items():
            out.append(f"    {_yaml_scalar(pred)}: [{', '.join(_yaml_scalar(t) for t in arg_types)}]")
        if self.axioms:
            out.append("  axioms:")
            for head, condition in self.axioms:
                out.append(f"    - head: {_yaml_item(head)}")
                out.append(f"      when: {_yaml_item(condition)}")
        out.append("  primitives:" if self.primitives else "  primitives: {}")
        for prim, body in self.primitives.items():
            out.append(f"    {_yaml_scalar(prim)}:")
            out.append(f"      parameters: [{', '.join(body['parameters'])}]")
            self._list(out, "      precondition", body["precondition"])
            self._list(out, "      add", body["add"])
            self._list(out, "      delete", body["delete"])
            if body["effects"]:
                out.append("      effects:")
                for entry in body["effects"]:
                    lead = "        - "
                    if entry["forall"]:
                        out.append(f"{lead}forall: [{', '.join(entry['forall'])}]")
                        lead = "          "
                    if entry["when"] is not None:
                        out.append(f"{lead}when: {_yaml_item(entry['when'])}")
                        lead = "          "
                    for key in ("add", "delete"):
                        if entry[key]:
                            out.append(f"{lead}{key}:")
                            out.extend(f"            - {_yaml_item(atom)}" for atom in entry[key])
                            lead = "          "
            if body["cost"] is not None:
                out.append(f"      cost: {body['cost']:g}")
        out.append("  tasks:" if self.tasks else "  tasks: {}")
        for task, params in self.tasks.items():
            out.append(f"    {_yaml_scalar(task)}: [{', '.join(params)}]")
        out.append("  methods:" if self.methods else "  methods: []")
        for method in self.methods:
            out.append(f"    - name: {_yaml_scalar(method['name'])}")
            out.append(f"      task: {_yaml_item(method['task'])}")
            if method["precondition"]:
                self._list(out, "      precondition", method["precondition"])
            key = "subtasks" if "subtasks" in method else "unordered"
            self._list(out, f"      {key}", method[key])
        if problems:
            out.append("problems:")
        for name, body in problems:
            out.append(f"  {_yaml_scalar(name)}:")
            if body["objects"]:
                out.append("    objects:")
                for type_name, names in body["objects"].items():
                    out.append(f"      {_yaml_scalar(type_name)}: [{', '.join(_yaml_scalar(n) for n in names)}]")
            self._list(out, "    init", body["init"])
            self._list(out, "    tasks", body["tasks"])
            if body["goal"]:
                self._list(out, "    goal", body["goal"])
        return "\n".join(out) + "\n"

    @staticmethod
    def _list(out: list[str], key: str, items: list[str]) -> None:
        if not items:
            out.append(f"{key}: []")
            return
        out.append(f"{key}:")
        indent = " " * (len(key) - len(key.lstrip()))
        for item in items:
            out.append(f"{indent}  - {_yaml_item(item)}")


def _substitute(f: Formula, mapping: dict[str, Sym]) -> Formula:
    """``f`` with variables replaced by ``mapping`` (by case-folded name); quantified variables are kept."""
    if f.op in ("exists", "forall"):
        mapping = {k: v for k, v in mapping.items() if k not in {p.name.key for p in f.params}}
    terms = [mapping.get(t.key, t) if t.is_var else t for t in f.terms]
    return Formula(f.op, f.where, [_substitute(c, mapping) for c in f.children], f.pred, terms, f.params)


def convert(domain: HDomain, problems: Sequence[HProblem] = ()) -> Converted:
    """The task file for ``domain`` and ``problems``; HDDL mistakes raise a located :class:`HddlError`."""
    converter = _Converter(domain)
    converter.convert_domain()
    converted_problems = []
    names_seen: dict[str, HProblem] = {}
    for problem in problems:
        if problem.name.key in names_seen:
            raise converter.error(f"two problems are named {problem.name.text} (first in "
                                  f"{names_seen[problem.name.key].path})", problem.name, problem.path)
        names_seen[problem.name.key] = problem
        converted_problems.append(converter.convert_problem(problem))
    text = converter.write(converted_problems)
    return Converted(text, dict(converter.names.renamed), dict(converter.names.synthetic),
                     [name for name, _ in converted_problems])
