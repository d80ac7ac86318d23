"""Native quantifiers (``forall``, ``exists``), ``implies`` and conditional effects (``effects:`` with ``forall`` /
``when``) in task files and in HDDL import: parsing, located errors, planner and verifier semantics, generated
code against the reference path, compiled behaviour trees."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from bt_meta.errors import TaskFileError
from bt_meta.htn import load_task_text, plan
from bt_meta.htn.conditions import QEX, QNEX, ConditionSyntaxError, parse_condition
from bt_meta.htn.hddl import HddlError, import_hddl, load_hddl
from bt_meta.htn.state import State
from bt_meta.htn.verify import verify_plan

DOMAIN = textwrap.dedent("""\
    domain:
      types: [block, room, ghost]
      predicates:
        on: [block, block]
        clear: [block]
        lit: [room]
        painted: [block]
        flag: []
        seen: [ghost]
      axioms:
        - head: covered(?b)
          when: on(?c, ?b)
      primitives:
        paint_all:
          parameters: [?r - room]
          precondition: "lit(?r) and (forall ?b - block: clear(?b) implies not painted(?b))"
          effects:
            - forall: [?b - block]
              when: clear(?b)
              add: [painted(?b)]
              delete: [clear(?b)]
        toggle:
          parameters: []
          delete: [flag()]
          effects:
            - when: flag()
              delete: [flag()]
            - when: not flag()
              add: [flag()]
        haunt:
          parameters: []
          effects:
            - forall: [?g - ghost]
              add: [seen(?g)]
            - forall: [?g - ghost]
              when: "true"
              delete: [flag()]
      tasks:
        go: [?r]
        spook: []
      methods:
        - name: m
          task: go(?r)
          precondition: "exists ?b - block: clear(?b) and covered(?b) and (exists ?c - block: on(?c, ?b))"
          subtasks: [paint_all(?r), toggle()]
        - name: spooky
          task: spook()
          precondition: "(forall ?g - ghost: seen(?g)) and (forall ?g - ghost: exists ?b - block: on(?b, ?b))"
          subtasks: [haunt(), toggle()]
    """)

PROBLEMS = textwrap.dedent("""\
    problems:
      p:
        objects: {block: [a, b, c], room: [r1]}
        init: [clear(a), clear(b), on(c, a), lit(r1)]
        tasks: [go(r1)]
        goal: [painted(a), painted(b), flag()]
      ghosts:
        objects: {block: [a]}
        init: []
        tasks: [spook()]
        goal: [flag()]
    """)


@pytest.fixture(scope="module")
def taskfile():
    return load_task_text(DOMAIN + PROBLEMS)


def _condition(taskfile, text: str, bound=()):
    from bt_meta.htn.conditions import compile_condition

    return compile_condition(text, parse_condition(text), taskfile.domain.context, bound)


def _plan_and_verify(taskfile, name: str):
    problem = taskfile.problems[name]
    result = plan(taskfile.domain, problem, max_seconds=20)
    assert result.status == "success", result.message
    verdict = verify_plan(taskfile.domain, problem, [a.as_list() for a in result.plan], result.tree.to_dict())
    assert verdict.ok, verdict.errors
    return result


# -- condition language -------------------------------------------------------------------------------------------
def test_quantifiers_and_implies_parse_with_the_body_reaching_right():
    expr = parse_condition("forall ?b - block, ?c - block: on(?b, ?c) implies clear(?b) or flag()")
    assert expr.op == "forall" and [v[:2] for v in expr.variables] == [("b", "block"), ("c", "block")]
    # implies: not A or B, and the body of the quantifier holds the whole implication
    assert type(expr.body).__name__ == "OrExpr"
    assert type(parse_condition("(exists ?b - block: clear(?b)) and flag()")).__name__ == "AndExpr"
    # predicates and constants named like the new words keep working
    assert parse_condition("forall(a) and exists(?x) and ?y == implies").children[0].pred == "forall"


@pytest.mark.parametrize(("text", "message", "offset"), [
    ("forall ?x: p(?x)", "expected '- type' after ?x (write forall ?x - type: ...)", 9),
    ("exists ?x - t p(?x)", "expected ',' or ':' after the variables of 'exists', found 'p'", 14),
    ("forall ?x - t:", "expected the condition of 'forall' after ':', found end of text", 14),
    ("forall ?x - t, ?x - t: p()", "variable ?x is quantified twice", 15),
    ("forall ?x - t:p(?x)", "put a space after the ':' that ends the variables of 'forall' ('t:p' reads as one "
     "name)", 12),
    ("a() implies", "expected an atom like pred(?x), 'not', '(', 'true' or a comparison, found end of text", 11),
])
def test_malformed_quantifiers_name_the_offending_offset(text, message, offset):
    with pytest.raises(ConditionSyntaxError) as caught:
        parse_condition(text)
    assert (caught.value.message, caught.value.offset) == (message, offset)


def test_forall_and_exists_over_states_including_an_empty_type(taskfile):
    state = State([("block", "a"), ("block", "b"), ("clear", "a"), ("on", "b", "a")])
    holds = lambda text, env=None: _condition(taskfile, text, env or ()).holds(state, env)  # noqa: E731
    assert holds("exists ?b - block: clear(?b)")
    assert not holds("forall ?b - block: clear(?b)")
    assert holds("forall ?b - block: clear(?b) implies not on(?b, ?b)")
    assert holds("not (forall ?b - block: clear(?b))")
    # over an empty type: forall is true, exists is false, whatever the body
    assert holds("forall ?g - ghost: false")
    assert not holds("exists ?g - ghost: true")
    # nested, with the outer variable free in the inner quantifier
    assert holds("exists ?x - block: forall ?y - block: on(?y, ?x) or ?y == ?x or clear(?y)")
    assert not holds("forall ?x - block: exists ?y - block: on(?x, ?y)")
    # a free variable bound from outside
    assert _condition(taskfile, "forall ?y - block: not on(?y, ?x)", ["x"]).holds(state, {"x": "b"})
    assert not _condition(taskfile, "forall ?y - block: not on(?y, ?x)", ["x"]).holds(state, {"x": "a"})
    # a derived type (any unary predicate) and a derived atom in the body
    assert holds("forall ?b - covered: exists ?c - block: on(?c, ?b)")
    # implies
    assert holds("clear(b) implies flag()") and not holds("clear(a) implies flag()")


def test_a_quantifier_is_one_test_literal_that_binds_nothing_outside(taskfile):
    condition = _condition(taskfile, "clear(?b) and (forall ?c - block: not on(?c, ?b))")
    kinds = [step[0] for step in condition.clauses[0]]
    assert kinds[1] == QNEX and condition.variables_bound == frozenset({"b"})
    assert _condition(taskfile, "not (forall ?c - block: clear(?c))").clauses[0][0][0] == QEX
    state = State([("block", "a"), ("block", "b"), ("clear", "a"), ("clear", "b"), ("on", "b", "a")])
    assert [env["b"] for env in condition.satisfiers(state)] == ["b"]


# -- planning and verifying -----------------------------------------------------------------------------------------
def test_conditional_effects_see_the_state_before_the_step(taskfile):
    result = _plan_and_verify(taskfile, "p")
    assert [a.as_list() for a in result.plan] == [["paint_all", "r1"], ["toggle"]]
    final = result.state
    # paint_all's when tests clear(?b), which the same step deletes: every clear block is painted
    assert ("painted", "a") in final and ("painted", "b") in final and ("painted", "c") not in final
    assert ("clear", "a") not in final and ("clear", "b") not in final
    # toggle deletes flag() and adds it when it was false before the step: flag() ends true
    assert ("flag",) in final


def test_forall_effects_over_an_empty_type_do_nothing_and_forall_preconditions_hold(taskfile):
    result = _plan_and_verify(taskfile, "ghosts")
    assert [a.as_list() for a in result.plan] == [["haunt"], ["toggle"]]
    assert not any(atom[0] == "seen" for atom in result.state)


def test_the_verifier_applies_conditional_effects_itself(taskfile):
    problem = taskfile.problems["p"]
    result = plan(taskfile.domain, problem, max_seconds=20)
    tree = result.tree.to_dict()
    # toggling twice leaves flag() false (each toggle decides on the state before it): the goal fails
    verdict = verify_plan(taskfile.domain, problem, [["paint_all", "r1"], ["toggle"], ["toggle"]], tree)
    assert any("the goal does not hold at the end: flag()" in error for error in verdict.errors), verdict.errors
    # without toggle flag() is never added, and the conditional paint leaves c unpainted
    verdict = verify_plan(taskfile.domain, problem, [["paint_all", "r1"]], tree)
    assert any("the goal does not hold at the end: flag()" in error for error in verdict.errors), verdict.errors


def test_the_verifier_bounds_the_forall_bindings_it_enumerates(taskfile, monkeypatch):
    import bt_meta.htn.verify as verify

    problem = taskfile.problems["p"]
    result = plan(taskfile.domain, problem, max_seconds=20)
    monkeypatch.setattr(verify, "MAX_FORALL_COMBINATIONS", 2)  # paint_all's forall has 3 blocks to try
    verdict = verify_plan(taskfile.domain, problem, [a.as_list() for a in result.plan], result.tree.to_dict())
    assert not verdict.ok
    assert any("paint_all(r1): a conditional effect has 3 forall bindings, more than the 2 the verifier "
               "enumerates" in error for error in verdict.errors), verdict.errors


def test_generated_code_and_the_reference_path_give_the_same_plans(taskfile):
    plans = []
    for codegen in (True, False):
        taskfile.domain.axiom_set.codegen = codegen
        try:
            plans.append([[a.as_list() for a in plan(taskfile.domain, p, max_seconds=20).plan]
                          for p in taskfile.problems.values()])
        finally:
            taskfile.domain.axiom_set.codegen = True
    assert plans[0] == plans[1]


def test_primitive_effects_without_the_state_are_refused_when_conditional(taskfile):
    from bt_meta.errors import PlanningError

    with pytest.raises(PlanningError, match="conditional"):
        taskfile.domain.primitives["toggle"].effects({})
    state = State([("flag",)])
    assert taskfile.domain.primitives["toggle"].effects({}, state) == ([], [("flag",)])


# -- located errors -----------------------------------------------------------------------------------------------
def _error(old: str, new: str) -> str:
    assert old in DOMAIN
    with pytest.raises(TaskFileError) as caught:
        load_task_text(DOMAIN.replace(old, new, 1))
    return str(caught.value)


@pytest.mark.parametrize(("old", "new", "expected"), [
    ('"lit(?r) and (forall ?b - block: clear(?b)', '"lit(?r) and (forall ?b: clear(?b)',
     "<string>:16:44: expected '- type' after ?b (write forall ?b - type: ...)"),
    ('"lit(?r) and (forall ?b - block: clear(?b)', '"lit(?r) and (forall ?b - blok: clear(?b)',
     "<string>:16:42: the type 'blok' of ?b is not a type or a unary predicate (known: block, clear, covered, "
     "ghost, lit, painted, room, seen)"),
    ('"lit(?r) and (forall ?b - block: clear(?b)', '"lit(?r) and (forall ?b - block: on(?b, ?q)',
     "<string>:16:35: variable ?q in 'forall' is not bound: bind it first"),
    ("        - forall: [?b - block]\n", "        - forall: [?b]\n",
     "<string>:18:20: forall variable ?b of conditional effect 1 of primitive paint_all needs a type: ?b - type"),
    ("        - forall: [?b - block]\n", "        - forall: [?r - block]\n",
     "<string>:18:20: forall variable ?r of conditional effect 1 of primitive paint_all is already bound by the "
     "primitive"),
    ("          add: [painted(?b)]\n", "          add: [painted(?z)]\n",
     "<string>:20:25: variable ?z in effect of conditional effect 1 of primitive paint_all is not bound by its "
     "forall"),
    ("          when: clear(?b)\n", "          when: clear(?b) and\n",
     "<string>:19:30: expected an atom like pred(?x), 'not', '(', 'true' or a comparison, found end of text"),
    ("          add: [painted(?b)]\n          delete: [clear(?b)]\n", "",
     "<string>:18:11: conditional effect 1 of primitive paint_all has neither 'add:' nor 'delete:'"),
    ("      effects:\n        - forall: [?b - block]\n          when: clear(?b)\n          add: [painted(?b)]\n"
     "          delete: [clear(?b)]\n", "      effects: painted(?r)\n",
     "<string>:17:16: the effects of primitive paint_all must be a list of {forall: ..., when: ..., add: ..., "
     "delete: ...}, found the value 'painted(?r)'"),
    ("      when: on(?c, ?b)\n", '      when: "block(?b) and (exists ?c - block: on(?c, ?b))"\n',
     "<string>:12:29: axiom covered uses 'exists'; axiom conditions may not use quantifiers"),
])
def test_malformed_quantifiers_and_conditional_effects_are_located(old, new, expected):
    message = _error(old, new)
    assert message.startswith(expected), message


# -- HDDL import --------------------------------------------------------------------------------------------------
HDDL_DOMAIN = """\
(define (domain paint)
  (:requirements :typing :conditional-effects :universal-preconditions)
  (:types block room - object tall - block)
  (:predicates (clear ?b - block) (painted ?b - block) (on ?a ?b - block) (lit ?r - room) (flag) (mark ?x))
  (:task go :parameters (?r - room))
  (:method m :parameters (?r - room) :task (go ?r)
    :precondition (exists (?b - block) (and (clear ?b) (exists (?c - block) (on ?c ?b))))
    :ordered-subtasks (and (paint_all ?r) (toggle) (mark_all)))
  (:action paint_all :parameters (?r - room)
    :precondition (and (lit ?r) (forall (?b - block) (imply (clear ?b) (not (painted ?b)))))
    :effect (forall (?b - block) (when (clear ?b) (and (painted ?b) (not (clear ?b))))))
  (:action toggle :parameters ()
    :precondition ()
    :effect (and (not (flag)) (when (flag) (not (flag))) (when (not (flag)) (flag))))
  (:action mark_all :parameters ()
    :precondition (not (exists (?x - (either tall room)) (mark ?x)))
    :effect (forall (?x) (when (not (clear ?x)) (forall (?y - tall) (when (on ?x ?y) (mark ?x)))))))
"""

HDDL_PROBLEM = """\
(define (problem p01) (:domain paint)
  (:objects a b - block c - tall r1 - room)
  (:htn :ordered-subtasks (go r1))
  (:init (clear a) (clear b) (on b a) (on a c) (lit r1))
  (:goal (and (painted a) (painted b) (flag) (forall (?t - tall) (not (mark ?t))) (mark a))))
"""


@pytest.fixture(scope="module")
def hddl_files(tmp_path_factory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("hddl")
    (folder / "domain.hddl").write_text(HDDL_DOMAIN)
    (folder / "p01.hddl").write_text(HDDL_PROBLEM)
    return folder / "domain.hddl", folder / "p01.hddl"


def test_hddl_quantifiers_and_conditional_effects_import_natively(hddl_files):
    text = import_hddl(*hddl_files[:1], [hddl_files[1]]).text
    assert "(forall ?b - block: (not clear(?b)) or (not painted(?b)))" in text
    assert "(exists ?b - block: clear(?b) and (exists ?c - block: on(?c, ?b)))" in text
    # a negated exists becomes a forall of the negated body; an either type is a derived unary predicate
    assert "(forall ?x - either_room_tall: not mark(?x))" in text
    assert "        - forall: [?b - block]\n          when: clear(?b)\n" in text
    # nested forall / when: the variables concatenate and the conditions conjoin; untyped means object
    assert "        - forall: [?x - object, ?y - tall]\n          when: not clear(?x) and on(?x, ?y)\n" in text
    domain_part = text.split("  primitives:")[0]
    # the only axioms: the either type's, and the goal's (an axiom, where a quantifier becomes a derived predicate)
    assert domain_part.count("- head:") == 4 and "head: forall_fails()" in domain_part


def test_hddl_conditional_effects_plan_and_verify(hddl_files):
    taskfile = load_hddl(hddl_files[0], [hddl_files[1]])
    result = _plan_and_verify(taskfile, "p01")
    assert [a.as_list() for a in result.plan] == [["paint_all", "r1"], ["toggle"], ["mark_all"]]
    assert ("mark", "a") in result.state and ("mark", "c") not in result.state


def test_hddl_errors_inside_conditional_effects_are_located(tmp_path):
    path = tmp_path / "d.hddl"
    path.write_text("(define (domain d) (:predicates (p ?x))\n (:action a :effect (forall (?y) (when (q) (p ?y)))))")
    with pytest.raises(HddlError) as caught:
        load_hddl(path)
    assert str(caught.value).endswith("d.hddl:2:41: unknown predicate 'q' in a when condition of action a (known: "
                                      "p)"), str(caught.value)


# -- compiled behaviour trees -------------------------------------------------------------------------------------
def test_quantified_guards_compile_into_behaviour_trees(taskfile):
    from bt_meta.bt.compiler import compile_task_file
    from bt_meta.bt.guards import compile_guard

    guard = compile_guard("forall ?b - block: clear(?b) implies not painted(?b)", taskfile.domain, [])
    assert guard.holds(State([("block", "a"), ("clear", "a")]))
    assert not guard.holds(State([("block", "a"), ("clear", "a"), ("painted", "a")]))
    compiled = compile_task_file(taskfile, "p")
    assert compiled.root is not None


def test_a_domain_with_quantifiers_and_conditional_effects_is_written_back_unchanged(taskfile):
    from bt_meta.meta.refinements import task_file_yaml

    again = load_task_text(task_file_yaml(taskfile.domain, taskfile.problems.values()))
    for name, primitive in taskfile.domain.primitives.items():
        copy = again.domain.primitives[name]
        assert [(e.variables, e.types, e.when.source, e.add, e.delete) for e in copy.conditional] == \
            [(e.variables, e.types, e.when.source, e.add, e.delete) for e in primitive.conditional]
    for name in taskfile.problems:
        assert [a.as_list() for a in plan(again.domain, again.problems[name], max_seconds=20).plan] == \
            [a.as_list() for a in plan(taskfile.domain, taskfile.problems[name], max_seconds=20).plan]


def test_a_quantifier_copied_into_many_clauses_is_compiled_once():
    disjunctions = " and ".join("(a() or b())" for _ in range(12))  # 4096 alternatives
    condition = disjunctions
    for _ in range(3):  # each level nests the previous one inside a forall: compiled per clause, 4096 ** 3
        condition = f"{disjunctions} and (forall ?x - t: {condition})"
    taskfile = load_task_text(f"domain:\n  types: [t]\n  predicates: {{a: [], b: []}}\n  primitives:\n    p:\n"
                              f"      precondition: \"{condition}\"\n")
    clauses = taskfile.domain.primitives["p"].precondition.clauses
    assert len(clauses) == 4096
    assert len({id(clause[-1]) for clause in clauses}) == 1 and clauses[0][-1][0] == QNEX
    assert taskfile.domain.primitives["p"].precondition.holds(State([("a",)]))


def test_a_primitive_with_a_quantified_precondition_gets_a_generated_stepper():
    from bt_meta.htn.compiled import compiled_domain

    taskfile = load_task_text(textwrap.dedent("""\
        domain:
          types: [block]
          predicates: {clear: [block], on: [block, block], done: [block]}
          axioms:
            - head: free(?b)
              when: clear(?b)
          primitives:
            finish:
              parameters: [?b]
              precondition: "free(?b) and (forall ?c - block: not on(?c, ?b)) and not done(?b)"
              add: [done(?b)]
          tasks: {all: []}
          methods:
            - name: one
              task: all()
              precondition: free(?b) and not done(?b)
              subtasks: [finish(?b), all()]
            - name: none
              task: all()
              precondition: "forall ?b - block: done(?b) or not free(?b) or (exists ?c - block: on(?c, ?b))"
        problems:
          p:
            objects: {block: [a, b, c]}
            init: [clear(a), clear(b), on(a, c), clear(c)]
            tasks: [all()]
        """))
    _, steppers = compiled_domain(taskfile.domain).variant(False)
    assert "finish" in steppers
    plans = []
    for codegen in (True, False):
        taskfile.domain.axiom_set.codegen = codegen
        try:
            plans.append([a.as_list() for a in _plan_and_verify(taskfile, "p").plan])
        finally:
            taskfile.domain.axiom_set.codegen = True
    # c has a on it: finish(c) fails its forall, and the method 'none' accepts a covered block left undone
    assert plans[0] == plans[1] == [["finish", "a"], ["finish", "b"]]


def test_ticking_the_compiled_tree_applies_conditional_effects_on_the_fake_world(tmp_path, capsys):
    import json

    from bt_meta.cli import main

    path = tmp_path / "paint.yaml"
    path.write_text(DOMAIN + PROBLEMS)
    assert main(["tick", str(path), "--problem", "p", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "SUCCESS"
    state = {tuple(atom) for atom in out["state"]}
    assert {("painted", "a"), ("painted", "b"), ("flag",)} <= state
    assert ("clear", "a") not in state and ("painted", "c") not in state
