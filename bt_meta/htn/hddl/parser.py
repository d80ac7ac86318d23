"""Parsing HDDL domains and problems (the IPC 2020/2023 HTN tracks' language) into :mod:`.syntax`.

Offers:

* :func:`parse_domain` -- ``(define (domain ...) ...)`` text to an :class:`~.syntax.HDomain`
* :func:`parse_problem` -- ``(define (problem ...) ...)`` text to an :class:`~.syntax.HProblem`
* :func:`parse_file` -- either, read from a path (``kind`` says which was found)

Every mistake is an :class:`~.sexpr.HddlError` naming ``path:line:column`` and what was expected there.
"""

from __future__ import annotations

from pathlib import Path

from bt_meta.htn.hddl.sexpr import HddlError, SExpr, SList, Sym, read_sexprs
from bt_meta.htn.hddl.syntax import (
    Effect,
    Formula,
    HAction,
    HDomain,
    HMethod,
    HProblem,
    HTask,
    Subtask,
    TaskNetwork,
    Typed,
)

_NETWORK_KEYS = {":subtasks": False, ":tasks": False, ":ordered-subtasks": True, ":ordered-tasks": True}


class _Parser:
    def __init__(self, path: str) -> None:
        self.path = path

    def error(self, message: str, where: SExpr | None) -> HddlError:
        if where is None:
            return HddlError(message, self.path)
        return HddlError(message, self.path, where.line, where.column)

    # -- small pieces ---------------------------------------------------------------------------------------
    def sym(self, node: SExpr, what: str) -> Sym:
        if not isinstance(node, Sym):
            raise self.error(f"expected {what}, found a list", node)
        return node

    def name(self, node: SExpr, what: str) -> Sym:
        sym = self.sym(node, what)
        if sym.is_var or sym.text.startswith(":") or sym.text in ("-", "<", "="):
            raise self.error(f"expected {what}, found {sym.text!r}", sym)
        return sym

    def var(self, node: SExpr, what: str) -> Sym:
        sym = self.sym(node, what)
        if not sym.is_var or len(sym.text) < 2:
            raise self.error(f"expected {what} (a variable like ?x), found {sym.text!r}", sym)
        return sym

    def slist(self, node: SExpr, what: str) -> SList:
        if not isinstance(node, SList):
            raise self.error(f"expected {what} in parentheses, found {node.text!r}", node)
        return node

    def typed_list(self, node: SExpr, what: str, variables: bool) -> list[Typed]:
        """``?a ?b - t ?c - (either u v) ?d``: untyped trailing entries are of type object."""
        items = self.slist(node, what).items
        result: list[Typed] = []
        pending: list[Sym] = []
        index = 0
        while index < len(items):
            item = items[index]
            if isinstance(item, Sym) and item.text == "-":
                if not pending:
                    raise self.error(f"'-' without a name before it in {what}", item)
                if index + 1 >= len(items):
                    raise self.error(f"expected a type after '-' in {what}", item)
                types = self.type_ref(items[index + 1], what)
                result.extend(Typed(p, types) for p in pending)
                pending = []
                index += 2
                continue
            kind = "a parameter" if variables else "a name"
            pending.append(self.var(item, kind) if variables else self.name(item, kind))
            index += 1
        result.extend(Typed(p, ()) for p in pending)
        return result

    def type_ref(self, node: SExpr, what: str) -> tuple[Sym, ...]:
        if isinstance(node, Sym):
            return (self.name(node, f"a type in {what}"),)
        if node.head() != "either" or len(node.items) < 2:
            raise self.error(f"expected a type name or (either type ...) in {what}", node)
        return tuple(self.name(item, f"a type in (either ...) of {what}") for item in node.items[1:])

    def terms(self, items: list[SExpr], what: str) -> list[Sym]:
        terms = []
        for item in items:
            sym = self.sym(item, f"a variable or a constant in {what}")
            if sym.text.startswith(":") or sym.text in ("-", "<"):
                raise self.error(f"expected a variable or a constant in {what}, found {sym.text!r}", sym)
            terms.append(sym)
        return terms

    def keyword_sections(self, items: list[SExpr], what: str, allowed: set[str]) -> dict[str, tuple[Sym, SExpr]]:
        """``:key value`` pairs (methods, actions, tasks, :htn); unknown or repeated keys are errors."""
        sections: dict[str, tuple[Sym, SExpr]] = {}
        index = 0
        while index < len(items):
            key = self.sym(items[index], f"a keyword such as {', '.join(sorted(allowed))}")
            if key.key not in allowed:
                raise self.error(f"unknown keyword {key.text!r} in {what} (expected one of: "
                                 f"{', '.join(sorted(allowed))})", key)
            if key.key in sections:
                raise self.error(f"{key.text} given twice in {what}", key)
            if index + 1 >= len(items):
                raise self.error(f"expected a value after {key.text} in {what}", key)
            sections[key.key] = (key, items[index + 1])
            index += 2
        return sections

    # -- formulas -------------------------------------------------------------------------------------------
    def formula(self, node: SExpr, what: str) -> Formula:
        node = self.slist(node, f"a condition in {what}")
        if not node.items:
            return Formula("true", node)
        head = node.head()
        if head is None:
            raise self.error(f"expected a predicate name or and/or/not/imply/exists/forall/= in {what}", node)
        rest = node.items[1:]
        if head == "and" or head == "or":
            return Formula(head, node, [self.formula(child, what) for child in rest])
        if head == "not":
            if len(rest) != 1:
                raise self.error(f"(not ...) takes one condition in {what}, found {len(rest)}", node)
            return Formula("not", node, [self.formula(rest[0], what)])
        if head == "imply":
            if len(rest) != 2:
                raise self.error(f"(imply A B) takes two conditions in {what}, found {len(rest)}", node)
            return Formula("imply", node, [self.formula(rest[0], what), self.formula(rest[1], what)])
        if head in ("exists", "forall"):
            if len(rest) != 2:
                raise self.error(f"({head} (?x - type) condition) expects a variable list and a condition in "
                                 f"{what}", node)
            params = self.typed_list(rest[0], f"the variables of {head}", variables=True)
            return Formula(head, node, [self.formula(rest[1], what)], params=params)
        if head == "=":
            if len(rest) != 2:
                raise self.error(f"(= a b) takes two terms in {what}, found {len(rest)}", node)
            return Formula("=", node, terms=self.terms(rest, what))
        pred = self.name(node.items[0], f"a predicate name in {what}")
        return Formula("atom", node, pred=pred, terms=self.terms(rest, f"the arguments of {pred.text}"))

    def effects(self, node: SExpr, what: str) -> list[Effect]:
        node = self.slist(node, f"an effect in {what}")
        if not node.items:
            return []
        head = node.head()
        rest = node.items[1:]
        if head == "and":
            found: list[Effect] = []
            for child in rest:
                found.extend(self.effects(child, what))
            return found
        if head == "not":
            if len(rest) != 1:
                raise self.error(f"(not ...) takes one atom in {what}", node)
            inner = self.slist(rest[0], f"an atom in {what}")
            pred = self.name(inner.items[0] if inner.items else inner, f"a predicate name in {what}")
            return [Effect("delete", inner, pred=pred, terms=self.terms(inner.items[1:], what))]
        if head == "forall":
            if len(rest) != 2:
                raise self.error(f"(forall (?x - type) effect) expects a variable list and an effect in {what}",
                                 node)
            params = self.typed_list(rest[0], "the variables of forall", variables=True)
            return [Effect("forall", node, params=params, effects=self.effects(rest[1], what))]
        if head == "when":
            if len(rest) != 2:
                raise self.error(f"(when condition effect) expects a condition and an effect in {what}", node)
            return [Effect("when", node, condition=self.formula(rest[0], what), effects=self.effects(rest[1], what))]
        if head in ("increase", "decrease", "assign", "scale-up", "scale-down"):
            if head != "increase" or len(rest) != 2 or not isinstance(rest[1], Sym):
                raise self.error(f"only (increase (total-cost) N) is supported among numeric effects in {what}",
                                 node)
            try:
                amount = float(rest[1].text)
            except ValueError:
                raise self.error(f"expected a number in (increase ...), found {rest[1].text!r}", rest[1]) from None
            return [Effect("cost", node, amount=amount)]
        if head is None:
            raise self.error(f"expected a predicate name or and/not/forall/when in {what}", node)
        pred = self.name(node.items[0], f"a predicate name in {what}")
        return [Effect("add", node, pred=pred, terms=self.terms(rest, f"the arguments of {pred.text}"))]

    # -- task networks ----------------------------------------------------------------------------------------
    def network(self, sections: dict[str, tuple[Sym, SExpr]], what: str) -> TaskNetwork:
        net = TaskNetwork()
        keys = [k for k in _NETWORK_KEYS if k in sections]
        if len(keys) > 1:
            raise self.error(f"{what} has both {keys[0]} and {keys[1]}; give one", sections[keys[1]][0])
        if keys:
            key_sym, value = sections[keys[0]]
            net.declared_ordered = _NETWORK_KEYS[keys[0]]
            net.where = key_sym
            value = self.slist(value, f"the subtasks of {what}")
            entries = value.items[1:] if value.head() == "and" else ([value] if value.items else [])
            for entry in entries:
                net.subtasks.append(self.subtask(entry, what))
        if ":ordering" in sections:
            key_sym, value = sections[":ordering"]
            value = self.slist(value, f"the ordering of {what}")
            entries = value.items[1:] if value.head() == "and" else ([value] if value.items else [])
            for entry in entries:
                entry = self.slist(entry, f"an ordering constraint (< task1 task2) in {what}")
                if entry.head() not in ("<", ">") or len(entry.items) != 3:
                    raise self.error(f"expected an ordering constraint (< task1 task2) in {what}", entry)
                first = self.name(entry.items[1], "a task id")
                second = self.name(entry.items[2], "a task id")
                net.ordering.append((first, second) if entry.head() == "<" else (second, first))
        if ":constraints" in sections:
            net.constraints = self.formula(sections[":constraints"][1], f"the constraints of {what}")
        return net

    def subtask(self, entry: SExpr, what: str) -> Subtask:
        entry = self.slist(entry, f"a subtask (id (task args)) or (task args) in {what}")
        if len(entry.items) == 2 and isinstance(entry.items[0], Sym) and isinstance(entry.items[1], SList):
            ident = self.name(entry.items[0], "a task id")
            inner = entry.items[1]
            name = self.name(inner.items[0] if inner.items else inner, f"a task name in {what}")
            return Subtask(ident, name, self.terms(inner.items[1:], f"the arguments of {name.text}"), inner)
        if not entry.items:
            raise self.error(f"empty subtask in {what}", entry)
        name = self.name(entry.items[0], f"a task name in {what}")
        return Subtask(None, name, self.terms(entry.items[1:], f"the arguments of {name.text}"), entry)

    # -- domain ---------------------------------------------------------------------------------------------
    def define(self, text: str, kind: str) -> tuple[Sym, list[SExpr], SList]:
        exprs = read_sexprs(text, self.path)
        if not exprs:
            raise self.error(f"empty HDDL file: expected (define ({kind} NAME) ...)", None)
        if len(exprs) > 1:
            raise self.error("unexpected text after the (define ...) form", exprs[1])
        root = self.slist(exprs[0], "(define ...)")
        if root.head() != "define" or len(root.items) < 2:
            raise self.error(f"expected (define ({kind} NAME) ...)", root)
        header = self.slist(root.items[1], f"({kind} NAME)")
        if header.head() != kind or len(header.items) != 2:
            found = header.head() or "?"
            raise self.error(f"expected ({kind} NAME) after define, found ({found} ...)", header)
        return self.name(header.items[1], f"the {kind} name"), root.items[2:], root

    def domain(self, text: str) -> HDomain:
        name, sections, _ = self.define(text, "domain")
        domain = HDomain(name, self.path)
        for section in sections:
            section = self.slist(section, "a domain section like (:predicates ...)")
            head = section.head()
            rest = section.items[1:]
            if head in (":requirements", ":functions"):
                continue
            if head == ":types":
                domain.types.extend(self.typed_list(SList(rest, section.line, section.column), "the types",
                                                    variables=False))
            elif head == ":constants":
                domain.constants.extend(self.typed_list(SList(rest, section.line, section.column),
                                                        "the constants", variables=False))
            elif head == ":predicates":
                for entry in rest:
                    entry = self.slist(entry, "a predicate declaration (name ?arg - type ...)")
                    if not entry.items:
                        raise self.error("empty predicate declaration", entry)
                    pred = self.name(entry.items[0], "a predicate name")
                    args = self.typed_list(SList(entry.items[1:], entry.line, entry.column),
                                           f"the arguments of predicate {pred.text}", variables=True)
                    domain.predicates.append((pred, args))
            elif head == ":task":
                if not rest:
                    raise self.error("expected a task name after :task", section)
                task = self.name(rest[0], "a task name")
                keys = self.keyword_sections(rest[1:], f"task {task.text}", {":parameters"})
                params = self.typed_list(keys[":parameters"][1], f"the parameters of task {task.text}", True) \
                    if ":parameters" in keys else []
                domain.tasks.append(HTask(task, params))
            elif head == ":method":
                domain.methods.append(self.method(section))
            elif head == ":action":
                domain.actions.append(self.action(section))
            else:
                raise self.error(f"unknown domain section {section.items[0].text if head else '(...)'!r} "
                                 "(expected :requirements, :types, :constants, :predicates, :task, :method or "
                                 ":action)", section)
        return domain

    def method(self, section: SList) -> HMethod:
        rest = section.items[1:]
        if not rest:
            raise self.error("expected a method name after :method", section)
        name = self.name(rest[0], "a method name")
        what = f"method {name.text}"
        allowed = {":parameters", ":task", ":precondition", ":ordering", ":constraints", *_NETWORK_KEYS}
        keys = self.keyword_sections(rest[1:], what, allowed)
        if ":task" not in keys:
            raise self.error(f"{what} has no :task", name)
        head = self.slist(keys[":task"][1], f"the task of {what}")
        if not head.items:
            raise self.error(f"empty :task in {what}", head)
        task = self.name(head.items[0], f"a task name in {what}")
        params = self.typed_list(keys[":parameters"][1], f"the parameters of {what}", True) \
            if ":parameters" in keys else []
        precondition = self.formula(keys[":precondition"][1], f"the precondition of {what}") \
            if ":precondition" in keys else None
        return HMethod(name, params, task, self.terms(head.items[1:], f"the task of {what}"), precondition,
                       self.network(keys, what), section)

    def action(self, section: SList) -> HAction:
        rest = section.items[1:]
        if not rest:
            raise self.error("expected an action name after :action", section)
        name = self.name(rest[0], "an action name")
        what = f"action {name.text}"
        keys = self.keyword_sections(rest[1:], what, {":parameters", ":precondition", ":effect"})
        params = self.typed_list(keys[":parameters"][1], f"the parameters of {what}", True) \
            if ":parameters" in keys else []
        precondition = self.formula(keys[":precondition"][1], f"the precondition of {what}") \
            if ":precondition" in keys else None
        effects = self.effects(keys[":effect"][1], f"the effect of {what}") if ":effect" in keys else []
        return HAction(name, params, precondition, effects, section)

    # -- problem --------------------------------------------------------------------------------------------
    def problem(self, text: str) -> HProblem:
        name, sections, _ = self.define(text, "problem")
        problem = HProblem(name, None, self.path)
        for section in sections:
            section = self.slist(section, "a problem section like (:init ...)")
            head = section.head()
            rest = section.items[1:]
            if head == ":domain":
                if len(rest) != 1:
                    raise self.error("expected (:domain NAME)", section)
                problem.domain_name = self.name(rest[0], "the domain name")
            elif head in (":requirements", ":metric"):
                continue
            elif head == ":objects":
                problem.objects.extend(self.typed_list(SList(rest, section.line, section.column), "the objects",
                                                       variables=False))
            elif head == ":htn":
                allowed = {":parameters", ":ordering", ":constraints", *_NETWORK_KEYS}
                keys = self.keyword_sections(rest, "the problem's :htn", allowed)
                if ":parameters" in keys:
                    problem.htn_params = self.typed_list(keys[":parameters"][1], "the parameters of :htn", True)
                problem.htn = self.network(keys, "the problem's :htn")
                problem.htn.where = problem.htn.where or section
            elif head == ":init":
                for entry in rest:
                    entry = self.slist(entry, "an initial fact (pred arg ...)")
                    if not entry.items:
                        raise self.error("empty initial fact", entry)
                    if entry.head() == "=":
                        raise self.error("numeric fluents and (= ...) are not supported in :init", entry)
                    pred = self.name(entry.items[0], "a predicate name")
                    problem.init.append((pred, self.terms(entry.items[1:], f"the initial fact {pred.text}")))
            elif head == ":goal":
                if len(rest) != 1:
                    raise self.error("expected (:goal condition)", section)
                problem.goal = self.formula(rest[0], "the goal")
            else:
                raise self.error(f"unknown problem section {section.items[0].text if head else '(...)'!r} "
                                 "(expected :domain, :objects, :htn, :init or :goal)", section)
        return problem


def parse_domain(text: str, path: str = "<string>") -> HDomain:
    """Parse an HDDL domain; raises :class:`HddlError` with the position of the first mistake."""
    return _Parser(path).domain(text)


def parse_problem(text: str, path: str = "<string>") -> HProblem:
    """Parse an HDDL problem; raises :class:`HddlError` with the position of the first mistake."""
    return _Parser(path).problem(text)


def read_text(path: str | Path) -> str:
    file_path = Path(path)
    if not file_path.is_file():
        raise HddlError("no such HDDL file" if not file_path.exists() else "not a file", str(path))
    try:
        return file_path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise HddlError(f"cannot read the HDDL file: {exc}", str(path)) from None


def file_kind(text: str, path: str) -> str:
    """``"domain"`` or ``"problem"``: what the ``(define (...))`` header of an HDDL text declares."""
    exprs = read_sexprs(text, path)
    if exprs and isinstance(exprs[0], SList) and len(exprs[0].items) > 1 and isinstance(exprs[0].items[1], SList):
        header = exprs[0].items[1].head()
        if header in ("domain", "problem"):
            return header
    where = exprs[0] if exprs else None
    raise HddlError("expected (define (domain NAME) ...) or (define (problem NAME) ...)", path,
                    where.line if where else None, where.column if where else None)
