"""HDDL import (parser, conversion, located errors), the plan verifier and the commands around them.

The HDDL files under tests/htn/hddl/ were written for these tests (the IPC files are not shipped).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bt_meta.htn import load_task_file, plan
from bt_meta.htn.hddl import HddlError, find_domain_file, import_hddl, load_hddl
from bt_meta.htn.hddl.parser import parse_domain, parse_problem
from bt_meta.htn.loader import load_task_text
from bt_meta.htn.state import State
from bt_meta.htn.verify import verify_plan

HERE = Path(__file__).parent / "hddl"
DELIVERY_DOMAIN = HERE / "delivery-domain.hddl"
DELIVERY = HERE / "delivery.hddl"
FEATURES = HERE / "features.hddl"
TREES = Path(__file__).parents[2] / "trees"


def _plan_hddl(problem: Path):
    taskfile = load_hddl(find_domain_file(problem), [problem])
    chosen = next(iter(taskfile.problems.values()))
    return taskfile, chosen, plan(taskfile.domain, chosen, max_seconds=30)


def _verify(taskfile, problem, result):
    return verify_plan(taskfile.domain, problem, [a.as_list() for a in result.plan], result.tree.to_dict())


# -- import -------------------------------------------------------------------------------------------------------
def test_delivery_plans_with_left_recursion_ordering_constants_and_a_forall_goal():
    taskfile, problem, result = _plan_hddl(DELIVERY)
    assert result.status == "success"
    # the :ordering puts 'first' (deliver p1 c) before 'second' although it is written after it
    assert [str(a) for a in result.plan] == [
        "drive(t1, hq, a)", "pick(t1, p1, a)", "drive(t1, a, b)", "drive(t1, b, c)", "drop(t1, p1, c)",
        "drive(t1, c, b)", "pick(t1, p2, b)", "drive(t1, b, a)", "drive(t1, a, hq)", "drop(t1, p2, hq)"]
    # the constant hq is an object of every problem, with its type and the ancestors of its type
    assert ("depot", "hq") in problem.state and ("place", "hq") in problem.state
    assert _verify(taskfile, problem, result).ok


def test_features_either_exists_imply_equality_constraints_and_a_disjunctive_goal():
    taskfile, problem, result = _plan_hddl(FEATURES)
    assert result.status == "success"
    # the :htn constraint (not (= ?c k1)) leaves k2; imply(red, big) excludes k1 anyway; (true ?y) binds u
    assert [str(a) for a in result.plan] == ["do-mark(k2, u)", "do-mark(s1, u)"]
    root = result.tree.nodes[result.tree.roots[0]]
    assert root.task == ("htn_pick",) and root.bindings == {"c": "k2"}
    assert _verify(taskfile, problem, result).ok


def test_import_keeps_names_and_maps_the_ones_it_cannot_spell():
    converted = import_hddl(HERE / "features-domain.hddl", [FEATURES])
    # 'true' is a keyword of the condition language: renamed, and the map says so
    assert converted.names == {"true_": "true"}
    assert "htn_pick" in converted.synthetic and "goal_pick" in converted.synthetic
    assert "do-mark:" in converted.text and "mark-pair: []" in converted.text  # names with '-' kept
    taskfile = load_task_text(converted.text)  # the text is an ordinary task file
    assert set(taskfile.problems) == {"pick"}


def test_hddl_is_case_insensitive_and_the_first_spelling_is_kept():
    domain = parse_domain("""(define (domain Cases) (:types Box)
      (:predicates (Open ?b - box))
      (:task OPEN-ALL :parameters ())
      (:method m :parameters (?B - BOX) :task (open-all) :precondition (not (OPEN ?b))
        :ordered-subtasks (DoOpen ?b))
      (:action doopen :parameters (?x - box) :effect (open ?X)))""")
    problem = parse_problem("(define (problem p) (:domain cases) (:objects b1 - BOX) (:htn :ordered-subtasks "
                            "(open-all)) (:init))")
    from bt_meta.htn.hddl.convert import convert

    converted = convert(domain, [problem])
    taskfile = load_task_text(converted.text)
    result = plan(taskfile.domain, taskfile.problems["p"])
    assert [str(a) for a in result.plan] == ["DoOpen(b1)"] or [str(a) for a in result.plan] == ["doopen(b1)"]
    assert "Open: [Box]" in converted.text and "OPEN-ALL: []" in converted.text


# -- located errors -----------------------------------------------------------------------------------------------
def _domain_error(text: str) -> HddlError:
    with pytest.raises(HddlError) as info:
        from bt_meta.htn.hddl.convert import convert

        convert(parse_domain(text, "d.hddl"))
    return info.value


def test_unbalanced_parenthesis_is_located():
    error = _domain_error("(define (domain d)\n  (:predicates (p ?x)\n")
    assert str(error) == "d.hddl:2:3: '(' opened at line 2, column 3 is never closed"
    error = _domain_error("(define (domain d)))")
    assert str(error) == "d.hddl:1:20: unbalanced ')': no '(' is open here"


def test_unknown_keyword_and_predicate_are_located():
    error = _domain_error("(define (domain d) (:action a :pre (p)))")
    assert str(error).startswith("d.hddl:1:31: unknown keyword ':pre' in action a (expected one of: :effect")
    error = _domain_error("(define (domain d) (:predicates (p))\n (:action a :precondition (q)))")
    assert str(error) == "d.hddl:2:28: unknown predicate 'q' in the precondition of action a (known: p)"


def test_partial_order_is_refused_with_the_method_position():
    error = _domain_error("""(define (domain d) (:task t :parameters ())
 (:method m :parameters () :task (t)
   :subtasks (and (a1 (x)) (a2 (x)) (a3 (x))) :ordering (and (< a1 a3)))
 (:action x))""")
    assert str(error) == ("d.hddl:2:2: method m is partially ordered (a1 and a2 are not ordered); only totally "
                          "ordered HDDL is supported")


def test_a_cost_inside_a_conditional_effect_is_refused_with_its_position():
    error = _domain_error("(define (domain d) (:predicates (p) (q))\n"
                          " (:action a :effect (when (p) (increase (total-cost) 2))))")
    assert str(error) == ("d.hddl:2:31: action a: (increase (total-cost) ...) inside forall / when is not "
                          "supported (a primitive has one cost)")


def test_a_forall_effect_variable_that_reuses_a_parameter_is_refused():
    error = _domain_error("(define (domain d) (:predicates (p ?x))\n"
                          " (:action a :parameters (?x) :effect (forall (?x) (p ?x))))")
    assert str(error) == ("d.hddl:2:47: action a: the forall variable ?x is already a variable here; give it "
                          "another name")


def test_arity_mismatch_and_unknown_task_are_located():
    error = _domain_error("(define (domain d) (:predicates (p ?x))\n (:action a :parameters (?y) :effect (p)))")
    assert str(error) == "d.hddl:2:39: predicate p takes 1 argument(s), got 0"
    error = _domain_error("(define (domain d) (:task t :parameters ())\n (:method m :task (t) :ordered-subtasks (u)))")
    assert str(error) == "d.hddl:2:42: unknown task or action 'u' in the subtasks of method m"


# -- the verifier -------------------------------------------------------------------------------------------------
def test_verifier_rejects_a_broken_plan_a_wrong_method_and_an_unreached_goal():
    taskfile, problem, result = _plan_hddl(DELIVERY)
    steps = [a.as_list() for a in result.plan]
    tree = result.tree.to_dict()
    swapped = [steps[1], steps[0], *steps[2:]]
    verdict = verify_plan(taskfile.domain, problem, swapped, tree)
    assert not verdict.ok
    assert verdict.errors[0].startswith("step 0 pick(t1, p1, a): the precondition of pick(t1, p1, a) does not hold")
    bad_tree = json.loads(json.dumps(tree))
    node = next(n for n in bad_tree["nodes"] if n["method"] == "m-via")
    node["method"] = "m-drive"
    verdict = verify_plan(taskfile.domain, problem, steps, bad_tree)
    assert not verdict.ok and any("method m-drive's head" in e or "are not the subtasks of m-drive" in e
                                  or "precondition of method m-drive" in e for e in verdict.errors)
    short = steps[:5]  # p2 is never delivered: the forall goal fails
    verdict = verify_plan(taskfile.domain, problem, short, None)
    assert not verdict.ok and verdict.errors[0].startswith("the goal does not hold at the end: goal_two_parcels()")


@pytest.mark.parametrize("name", ["letters.yaml", "magnetic_attach.yaml", "housing_insertion.yaml"])
def test_every_plan_of_the_shipped_task_files_verifies(name):
    taskfile = load_task_file(TREES / name)
    for problem in taskfile.problems.values():
        if taskfile.domain.external:
            pytest.skip("external predicates need plugins")
        result = plan(taskfile.domain, problem, max_seconds=30)
        if result.ok:
            verdict = verify_plan(taskfile.domain, problem, [a.as_list() for a in result.plan], result.tree.to_dict())
            assert verdict.ok, verdict.errors


# -- the state hash and the failure memo --------------------------------------------------------------------------
def test_states_that_swap_arguments_between_atoms_hash_apart():
    first = State([("on", "r1", "t3"), ("on", "r3", "r4"), ("top", "r1", "t3"), ("top", "r2", "t1")])
    second = State([("on", "r1", "r4"), ("on", "r3", "t3"), ("top", "r1", "t1"), ("top", "r2", "t3")])
    assert first != second and hash(first) != hash(second)
    moved = first.apply(add=[("on", "r1", "r4"), ("on", "r3", "t3")], delete=[("on", "r1", "t3"), ("on", "r3", "r4")])
    assert hash(moved) == hash(State(moved))  # the incremental hash is the hash of the atoms


MEMO = """
domain:
  predicates: {at: [x], road: [x, y], done: []}
  primitives:
    go:
      parameters: [?a, ?b]
      precondition: at(?a) and road(?a, ?b)
      add: [at(?b)]
      delete: [at(?a)]
    finish:
      parameters: []
      precondition: at(z)
      add: [done()]
  tasks: {reach: [?b], job: [], wrap: []}
  methods:
    - name: direct
      task: reach(?b)
      precondition: at(?a) and road(?a, ?b)
      subtasks: [go(?a, ?b)]
    - name: via
      task: reach(?b)
      precondition: road(?m, ?b)
      subtasks: [reach(?m), go(?m, ?b)]
    - name: j
      task: job()
      subtasks: [reach(d), wrap()]
    - name: w
      task: wrap()
      subtasks: [finish()]
problems:
  p:
    init: [at(s), road(s, a), road(s, b), road(a, c), road(b, c), road(c, d), road(d, z)]
    tasks: [job()]
"""


def test_a_search_node_that_failed_is_not_explored_again():
    # both routes s-a-c-d and s-b-c-d end in the same state with wrap() left, which fails: the second
    # arrival is skipped; there is no plan either way
    taskfile = load_task_text(MEMO)
    result = plan(taskfile.domain, taskfile.problems["p"])
    assert result.status == "no_plan"
    assert result.stats["memo_pruned"] >= 1


# -- commands -----------------------------------------------------------------------------------------------------
class _Done:
    def __init__(self, returncode: int, stdout: str, stderr: str) -> None:
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


@pytest.fixture
def cli(capsys):
    from bt_meta.cli import main

    def run(*args: str) -> _Done:
        capsys.readouterr()
        code = main(list(args))
        captured = capsys.readouterr()
        return _Done(code, captured.out, captured.err)

    return run


def test_import_plan_and_verify_commands(tmp_path, cli):
    out = tmp_path / "delivery.yaml"
    mapping = tmp_path / "map.json"
    done = cli("import", "hddl", str(DELIVERY_DOMAIN), str(DELIVERY), "-o", str(out), "--map", str(mapping))
    assert done.returncode == 0, done.stderr
    assert json.loads(mapping.read_text())["names"] == {}
    planned = cli("plan", str(out), "--json")
    assert planned.returncode == 0, planned.stderr
    plan_file = tmp_path / "plan.json"
    plan_file.write_text(planned.stdout)
    checked = cli("verify", str(DELIVERY_DOMAIN), str(plan_file), "--problem", str(DELIVERY))
    assert checked.returncode == 0 and "plan verified: 10 step(s), 18 tree node(s)" in checked.stdout
    data = json.loads(planned.stdout)
    data["plan"] = data["plan"][1:]
    plan_file.write_text(json.dumps(data))
    checked = cli("verify", str(DELIVERY), str(plan_file))
    assert checked.returncode == 1 and "plan INVALID" in checked.stdout
    plan_file.write_text("{\"plan\": [\n")
    checked = cli("verify", str(DELIVERY), str(plan_file))
    assert checked.returncode == 2 and f"{plan_file}:2:1: JSON syntax error" in checked.stderr


def test_plan_validate_and_compile_accept_hddl(tmp_path, cli):
    planned = cli("plan", str(DELIVERY_DOMAIN), "--problem", str(DELIVERY))
    assert planned.returncode == 0 and "plan found: 10 steps" in planned.stdout
    validated = cli("validate", str(DELIVERY_DOMAIN))
    assert validated.returncode == 0 and "ok (3 primitives, 4 methods, 0 problems)" in validated.stdout
    compiled = cli("compile", str(FEATURES))
    assert compiled.returncode == 0 and "do-mark" in compiled.stdout
    bad = tmp_path / "bad-domain.hddl"
    bad.write_text("(define (domain d) (:action a :effect (p)))")
    failed = cli("validate", str(bad))
    assert failed.returncode == 2
    assert failed.stderr.strip() == f"{bad}:1:40: unknown predicate 'p' in the effect of action a"


def test_bench_ipc_on_a_folder_of_domains(tmp_path, cli):
    folder = tmp_path / "total-order" / "Delivery"
    folder.mkdir(parents=True)
    (folder / "domain.hddl").write_text(DELIVERY_DOMAIN.read_text())
    (folder / "p01.hddl").write_text(DELIVERY.read_text())
    done = cli("bench", "ipc", "--path", str(tmp_path), "--timeout", "20", "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    row = report["domains"]["Delivery"]
    assert row["solved"] == 1 and row["problems"] == 1 and row["invalid"] == 0
    assert row["runs"][0]["verified"] is True and row["hypertension_ipc2020"] is None
    missing = cli("bench", "ipc", "--path", str(tmp_path), "--domains", "Towers")
    assert missing.returncode == 2 and "--domains: no domain 'Towers'" in missing.stderr


def test_conditions_later_subtasks_need_are_tested_with_the_method_when_nothing_before_can_change_them():
    text = DELIVERY_DOMAIN.read_text().replace("    :precondition (at ?p ?from)\n", "")
    converted = import_hddl_text(text)
    method = converted.split("- name: m-deliver", 1)[1].split("- name:", 1)[0]
    # pick's (at ?p ?from): goto before it moves trucks only, so the package's place binds ?from ...
    assert "- at(?p, ?from)" in method
    # ... while pick's (at ?t ?from) is left to pick itself: goto changes where the truck is
    assert "at(?t, ?from)" not in method
    # and the via method tests road(?mid, ?to) (static) before driving anywhere
    via = converted.split("- name: m-via", 1)[1]
    assert via.split("subtasks:")[0].strip().endswith("- road(?mid, ?to)")


def import_hddl_text(domain_text: str) -> str:
    from bt_meta.htn.hddl.convert import convert

    converted = convert(parse_domain(domain_text, "d.hddl"), [parse_problem(DELIVERY.read_text(), "p.hddl")])
    taskfile = load_task_text(converted.text)
    result = plan(taskfile.domain, taskfile.problems["two-parcels"])
    assert result.ok and verify_plan(taskfile.domain, taskfile.problems["two-parcels"],
                                     [a.as_list() for a in result.plan], result.tree.to_dict()).ok
    return converted.text


def test_a_type_named_like_a_predicate_is_renamed_and_mapped():
    from bt_meta.htn.hddl.convert import convert

    domain = parse_domain("""(define (domain clash) (:types block - thing thing)
      (:predicates (block ?a - thing ?b - thing) (free ?x - block))
      (:task free-one :parameters (?x - block))
      (:method m :parameters (?x - block ?y - thing) :task (free-one ?x) :precondition (block ?y ?x)
        :ordered-subtasks (unblock ?y ?x))
      (:action unblock :parameters (?y - thing ?x - block) :precondition (block ?y ?x)
        :effect (and (not (block ?y ?x)) (free ?x))))""")
    problem = parse_problem("(define (problem p) (:domain clash) (:objects b1 - block t - thing) "
                            "(:htn :ordered-subtasks (free-one b1)) (:init (block t b1)))")
    converted = convert(domain, [problem])
    assert converted.names == {"block_type": "block"}
    taskfile = load_task_text(converted.text)
    result = plan(taskfile.domain, taskfile.problems["p"])
    assert [str(a) for a in result.plan] == ["unblock(t, b1)"]
    assert ("block_type", "b1") in taskfile.problems["p"].state
    assert ("block", "t", "b1") in result.tree.nodes["n0"].state_before
