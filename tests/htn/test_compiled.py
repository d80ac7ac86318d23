"""The planner's generated fast path (bt_meta.htn.compiled) plans exactly as its reference path does."""

from __future__ import annotations

import textwrap

import pytest

from bt_meta.htn import load_task_text, method_from_text, plan
from bt_meta.htn.compiled import compiled_domain

MODES = {"reference": (False, None), "generated": (True, False), "inherited-proofs": (True, True), "auto": (True, None)}

FEATURES = """
domain:
  types: [x, room]
  predicates:
    at: [x]
    door: [x, x]
    key: [x]
    holding: [x]
    visited: [x]
    goal_at: [x]
    lit: [x]
    fragile: [x]
    mark_a: [x]
    mark_b: [x]
    bad: [x]
    used: [x]
  axioms:
    - head: reachable(?a, ?b)
      when: door(?a, ?b)
    - head: reachable(?a, ?c)
      when: reachable(?a, ?b) and door(?b, ?c)
    - head: safe(?r)
      when: lit(?r) and not fragile(?r)
    - head: safe(?r)
      when: key(?r)
    - head: exit_of(?r, ?s)
      when: door(?r, ?s) and safe(?s)
    - head: exit_of(?r, outside)
      when: lit(?r)
  primitives:
    go:
      parameters: [?from, ?to]
      precondition: at(?from) and door(?from, ?to) and not visited(?to)
      add: [at(?to), visited(?to)]
      delete: [at(?from)]
    grab:
      parameters: [?r]
      precondition: at(?r) and key(?r)
      add: [holding(?r)]
      delete: [key(?r)]
    light:
      parameters: [?r]
      precondition: "at(?r)"
      add: [lit(?r)]
    # binds a variable of its own: several satisfiers, so the planner keeps a choice point
    hop:
      parameters: [?r]
      precondition: at(?r) and door(?r, ?s) and not visited(?s)
      add: [visited(?s)]
    use:
      parameters: [?x]
      precondition: not bad(?x)
      add: [used(?x)]
    check:
      parameters: [?r - room]
      precondition: visited(?r)
      add: [lit(?r)]
  tasks:
    tour: []
    reach: [?goal]
    tidy: [?a, ?b]
    pair: [?x, ?x2]
    inspect: [?r - room]
    choose: []
  methods:
    # both clauses give x = a: it is tried once (the reference keeps a binding once across clauses)
    - name: either
      task: choose()
      precondition: mark_a(?x) or mark_b(?x)
      subtasks: [use(?x)]
    - name: arrived
      task: reach(?g)
      precondition: at(?g)
    - name: step_safe
      task: reach(?g)
      precondition: at(?h) and exit_of(?h, ?n) and reachable(?n, ?g) or at(?h) and door(?h, ?n) and ?n == ?g
      subtasks: [go(?h, ?n), reach(?g)]
    - name: step_any
      task: reach(?g)
      precondition: at(?h) and door(?h, ?n)
      subtasks: [go(?h, ?n), reach(?g)]
    - name: same_twice
      task: pair(?x, ?x)
      precondition: "true"
      subtasks: [light(?x)]
    - name: to_outside
      task: pair(?x, outside)
      precondition: at(?x)
      subtasks: [light(?x)]
    - name: different
      task: pair(?x, ?y)
      precondition: ?x != ?y
    - name: either_order
      task: tidy(?a, ?b)
      unordered: [grab(?a), light(?b)]
    - name: look
      task: inspect(?r)
      precondition: "true"
      subtasks: [check(?r)]
    - name: go_round
      task: tour()
      precondition: at(?h) and goal_at(?g)
      subtasks: [hop(?h), reach(?g), tidy(?g, ?g), pair(?g, ?g), pair(?g, outside), pair(?g, elsewhere)]
problems:
  p:
    objects: {room: [a, b, c, d, e]}
    init: [at(a), visited(a), door(a, b), door(b, c), door(a, d), door(d, e), door(c, e), key(e), goal_at(e),
           lit(c), fragile(d), key(b)]
    tasks: [tour()]
    goal: [holding(e), lit(e)]
  dead_end:
    init: [at(a), visited(a), door(a, b), goal_at(c), key(c)]
    tasks: [tour()]
  choose:
    init: [mark_a(a), mark_b(a), mark_b(c), bad(a)]
    tasks: [choose()]
  typed:
    objects: {room: [a]}
    init: [visited(a)]
    tasks: [inspect(a), inspect(z)]
"""


def _set_mode(axiom_set, mode: str) -> None:
    axiom_set.codegen, axiom_set.reference_proofs = MODES[mode]


def _outcome(domain, problem, mode: str):
    _set_mode(domain.axiom_set, mode)
    try:
        result = plan(domain, problem)
    finally:
        _set_mode(domain.axiom_set, "auto")
    nodes = list(result.tree.nodes.values()) if result.tree is not None else []
    stats = {k: v for k, v in result.stats.items() if k != "seconds"}
    return (result.status, [str(a) for a in result.plan], stats, result.message,
            [(n.id, n.task, n.kind, n.method, list(n.bindings.items()), n.parent, n.children, n.step) for n in nodes],
            [n.state_before for n in nodes])


@pytest.mark.parametrize("problem", ["p", "dead_end", "choose", "typed"])
def test_generated_and_reference_paths_give_the_same_plan_tree_stats_and_message(problem):
    taskfile = load_task_text(textwrap.dedent(FEATURES))
    domain = taskfile.domain
    outcomes = {mode: _outcome(domain, taskfile.problems[problem], mode) for mode in MODES}
    for mode, outcome in outcomes.items():
        assert outcome == outcomes["reference"], mode


def test_the_features_problem_exercises_what_it_claims():
    taskfile = load_task_text(textwrap.dedent(FEATURES))
    domain = taskfile.domain
    result = plan(domain, taskfile.problems["p"])
    assert result.status == "success"
    assert result.stats["backtracks"] >= 1  # hop's choice point and the goal facts force backtracking
    methods = {node.method for node in result.tree.nodes.values() if node.kind == "compound"}
    assert {"step_safe", "same_twice", "to_outside", "different", "either_order"} <= methods
    compiled = compiled_domain(domain)
    expanders, steppers = compiled.variant(False)
    assert set(expanders) == {"tour", "reach", "tidy", "pair", "inspect", "choose"}
    assert set(steppers) == {"go", "grab", "light", "use"}  # hop binds a variable of its own; check is typed
    chosen = plan(domain, taskfile.problems["choose"])
    assert [str(a) for a in chosen.plan] == ["use(c)"] and chosen.stats["backtracks"] == 1
    assert compiled.recursive == {"reach"}
    assert compiled.typed_tasks == {"inspect"}
    typed = plan(domain, taskfile.problems["typed"])
    assert typed.status == "no_plan" and "inspect(z): its argument types do not hold" in typed.message


MUTUAL = """
domain:
  predicates: {flag: [], done: []}
  primitives:
    finish: {add: [done()]}
    toggle: {precondition: "not flag()", add: [flag()]}
  tasks: {ping: [], pong: [], top: [], leaf: []}
  methods:
    - name: ping_to_pong
      task: ping()
      subtasks: [pong()]
    - name: pong_to_ping
      task: pong()
      subtasks: [ping()]
    - name: pong_done
      task: pong()
      subtasks: [finish()]
    - name: top_first
      task: top()
      subtasks: [leaf(), ping()]
    - name: leaf
      task: leaf()
      subtasks: [toggle()]
problems:
  p: {tasks: [top()]}
"""


def test_only_tasks_that_reach_themselves_are_watched_for_loops():
    taskfile = load_task_text(textwrap.dedent(MUTUAL))
    domain = taskfile.domain
    assert compiled_domain(domain).recursive == {"ping", "pong"}
    outcomes = {mode: _outcome(domain, taskfile.problems["p"], mode) for mode in MODES}
    assert all(outcome == outcomes["reference"] for outcome in outcomes.values())
    status, steps, stats, *_ = outcomes["auto"]
    # ping -> pong -> ping recurs in the same state: pruned, and pong's second method finishes
    assert status == "success" and steps == ["toggle()", "finish()"] and stats["loops_pruned"] == 1


def test_a_method_added_later_is_planned_with():
    taskfile = load_task_text(textwrap.dedent(MUTUAL))
    domain = taskfile.domain
    before = compiled_domain(domain)
    assert [str(a) for a in plan(domain, taskfile.problems["p"]).plan] == ["toggle()", "finish()"]
    domain.add_method(method_from_text(domain, name="ping_directly", task="ping()",
                                       subtasks=["finish()", "finish()"]), first=True)
    after = compiled_domain(domain)
    assert after is not before
    assert [str(a) for a in plan(domain, taskfile.problems["p"]).plan] == ["toggle()", "finish()", "finish()"]
    assert compiled_domain(domain) is after  # made once per change, not per plan


EXTERNAL = """
domain:
  predicates: {at: [x]}
  external: {reachable: [x]}
  primitives:
    go:
      parameters: [?x]
      precondition: reachable(?x)
      add: [at(?x)]
  tasks:
    visit: [?x]
  methods:
    - name: when_reachable
      task: visit(?x)
      precondition: reachable(?x)
      subtasks: [go(?x)]
problems:
  p: {tasks: [visit(a), visit(b)]}
"""


def test_external_predicates_keep_the_reference_path_and_are_still_asked():
    taskfile = load_task_text(textwrap.dedent(EXTERNAL))
    domain = taskfile.domain
    expanders, steppers = compiled_domain(domain).variant(False)
    assert "visit" not in expanders and "go" not in steppers
    asked: list[tuple[str, ...]] = []

    def external(pred, args, state):
        asked.append((pred, *args))
        return args[0] == "a"

    result = plan(domain, taskfile.problems["p"], external=external)
    assert result.status == "no_plan"
    assert ("reachable", "a") in asked and ("reachable", "b") in asked


def test_threads_planning_a_fresh_domain_at_once_get_the_sequential_answers():
    import threading
    from pathlib import Path

    blocks = Path(__file__).resolve().parents[2] / "bt_meta" / "bench" / "problems" / "blocks_htn.yaml"
    expected_file = load_task_text(blocks.read_text())
    expected = [str(a) for a in plan(expected_file.domain, expected_file.problems["sussman"]).plan]
    features = load_task_text(textwrap.dedent(FEATURES))
    expected_features = [str(a) for a in plan(features.domain, features.problems["p"]).plan]
    for _ in range(3):
        fresh = load_task_text(blocks.read_text())  # nothing generated yet: the threads generate it together
        fresh_features = load_task_text(textwrap.dedent(FEATURES))
        results: list[list[str]] = []
        errors: list[BaseException] = []
        barrier = threading.Barrier(6)

        def work(taskfile, problem: str, barrier=barrier, results=results, errors=errors) -> None:
            try:
                barrier.wait()
                results.append([str(a) for a in plan(taskfile.domain, taskfile.problems[problem]).plan])
            except BaseException as error:  # reported by the assertion below
                errors.append(error)

        threads = [threading.Thread(target=work, args=(fresh, "sussman")) for _ in range(3)]
        threads += [threading.Thread(target=work, args=(fresh_features, "p")) for _ in range(3)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        assert errors == []
        assert sorted(results) == sorted([expected] * 3 + [expected_features] * 3)


EFFECTS = """
domain:
  predicates: {a: [x], b: [x], c: [x, x], w: [x], z: [x], flag: []}
  primitives:
    swap: {parameters: [?x, ?y], delete: [c(?x, ?y), a(?y)], add: [c(?y, ?x), a(?x)]}
    twice: {parameters: [?x], delete: [a(?x), a(?x), flag()], add: [b(?x)]}
    fresh_pred: {parameters: [?x], add: [z(?x), flag()]}
    drop_last: {parameters: [?x], delete: [w(?x)]}
    keep: {parameters: [?x], delete: [b(?x)], add: [b(?x)]}
    same_pred_adds: {parameters: [?x, ?y], delete: [a(?x)], add: [b(?y), b(?x)]}
  tasks: {}
"""


@pytest.mark.parametrize("seed", range(4))
def test_generated_effects_build_the_successor_apply_builds(seed):
    import random

    from bt_meta.htn import State

    domain = load_task_text(textwrap.dedent(EFFECTS)).domain
    _, steppers = compiled_domain(domain).variant(False)
    assert set(steppers) == set(domain.primitives)
    rng = random.Random(seed)
    objects = ["p", "q", "r"]
    for _ in range(200):
        atoms = [atom for atom in [("a", o) for o in objects] + [("b", o) for o in objects]
                 + [("c", x, y) for x in objects for y in objects] + [("w", "p"), ("flag",)] if rng.random() < 0.4]
        rng.shuffle(atoms)
        state = State(atoms)
        if rng.random() < 0.5:
            state.index("a", 1)  # successors must drop the indexes of changed predicates, keep the others
            state.index("c", 2)
        name = rng.choice(sorted(domain.primitives))
        primitive = domain.primitives[name]
        args = tuple(rng.choice(objects) for _ in primitive.parameters)
        bindings, successor = steppers[name](state, *args)
        assert bindings == dict(zip(primitive.parameters, args, strict=True))
        expected = state._apply(*primitive.effects(bindings))
        assert (successor is state) == (expected is state), (name, args)
        assert [(pred, list(found)) for pred, found in successor._preds.items()] == \
            [(pred, list(found)) for pred, found in expected._preds.items()], (name, args, atoms)
        assert (successor._hash, successor._len, successor._delta) == (expected._hash, expected._len, expected._delta)
        assert list(successor._by_arg) == list(expected._by_arg)
        assert successor == expected and hash(successor) == hash(State(list(expected)))


def _random_domain(rng) -> str:
    """A small random domain in the task-file format: facts, derived predicates (one recursive), primitives and
    methods whose preconditions mix patterns, negations, comparisons, constants, repeated variables and 'or'."""
    def pick(*options):
        return rng.choice(options)

    def literals(bound: list[str], count: int) -> tuple[str, list[str]]:
        bound = list(bound)
        parts: list[str] = []
        for _ in range(count):
            var = pick("?x", "?y", "?z")
            known = pick(*bound) if bound else "a"
            kind = rng.random()
            if kind < 0.35:
                atom = pick(f"p({var})", f"q({known}, {var})", f"q({var}, {var})", f"d1({var})", f"d2({known}, {var})",
                            f"d3({var})", f"q({var}, b)", f"d2({var}, c)")
                parts.append(atom)
                bound += [v for v in ("?x", "?y", "?z") if v in atom and v not in bound]
            elif kind < 0.6 and bound:
                parts.append(pick(f"not p({known})", f"not d1({known})", f"not d3({known})", f"not q({known}, a)",
                                  f"not d2({known}, {known})"))
            elif kind < 0.75 and bound:
                parts.append(pick(f"{known} != a", f"{known} == b", f"{known} != {pick(*bound)}"))
            else:
                parts.append(pick("r()", "not r()", "p(a)", "d1(b)"))
        return " and ".join(parts) or "true", bound

    def condition(bound: list[str]) -> tuple[str, list[str]]:
        first, have = literals(bound, rng.randint(1, 3))
        if rng.random() < 0.25:
            second, other = literals(bound, rng.randint(1, 2))
            common = [v for v in have if v in other]
            return f"{first} or {second}", common
        return first, have

    lines = ["domain:", "  predicates: {p: [x], q: [x, x], r: []}", "  axioms:"]
    lines += ['    - {head: "d1(?x)", when: "p(?x) and not r()"}',
              '    - {head: "d1(?x)", when: "q(?x, ?x)"}',
              '    - {head: "d2(?x, ?y)", when: "q(?x, ?y) and not d1(?y) or p(?x) and q(?y, ?x) and ?y != c"}',
              '    - {head: "d2(?x, a)", when: "d1(?x)"}',
              '    - {head: "d3(?x)", when: "p(?x)"}',
              '    - {head: "d3(?x)", when: "q(?x, ?y) and d3(?y)"}']
    lines.append("  primitives:")
    for name, params, effects in (("setp", '["?x"]', 'add: ["p(?x)"]'), ("clearp", '["?x"]', 'delete: ["p(?x)"]'),
                                  ("link", '["?x", "?y"]', 'add: ["q(?x, ?y)"], delete: ["p(?y)"]'),
                                  ("unlink", '["?x", "?y"]', 'delete: ["q(?x, ?y)"], add: ["q(?y, ?x)"]'),
                                  ("flip", "[]", 'add: ["r()"]'), ("flop", "[]", 'delete: ["r()"]')):
        bound = [v.strip().strip('"') for v in params.strip("[]").split(",") if v.strip()]
        pre, _ = literals(bound, rng.randint(0, 2)) if rng.random() < 0.7 else ("true", bound)
        lines.append(f"    {name}: {{parameters: {params}, precondition: \"{pre}\", {effects}}}")
    lines += ["  tasks: {t0: [], t1: [?x]}", "  methods:"]
    for k in range(rng.randint(3, 7)):
        task, bound = pick(("t0()", []), ("t1(?x)", ["?x"]), ("t1(b)", []))
        pre, have = condition(bound)
        usable = have or ["a"]
        subtasks = []
        for _ in range(rng.randint(0, 3)):
            v, w = pick(*usable), pick(*usable, "c")
            subtasks.append(pick(f"setp({v})", f"clearp({v})", f"link({v}, {w})", f"unlink({w}, {v})", "flip()",
                                 "flop()", f"t1({v})", "t0()"))
        form = "unordered" if rng.random() < 0.15 else "subtasks"
        listed = ", ".join(f'"{sub}"' for sub in subtasks)
        lines.append(f'    - {{name: m{k}, task: "{task}", precondition: "{pre}", {form}: [{listed}]}}')
    # last resorts, so most searches get somewhere (and backtrack into them)
    lines.append('    - {name: t0_done, task: "t0()", precondition: "true", subtasks: []}')
    lines.append('    - {name: t1_done, task: "t1(?x)", precondition: "true", subtasks: []}')
    init = [f'"{f}"' for f in ("p(a)", "p(b)", "q(a, b)", "q(b, c)", "q(c, c)", "r()", "q(b, a)") if rng.random() < 0.5]
    goal = pick("", ', goal: ["p(c)"]', ', goal: ["r()"]')
    lines += ["problems:", f'  p: {{init: [{", ".join(init)}], tasks: ["t0()", "t1(a)"]{goal}}}']
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("seed", range(60))
def test_random_domains_plan_the_same_on_both_paths(seed):
    import random

    from bt_meta.errors import TaskFileError

    rng = random.Random(seed)
    text = _random_domain(rng)
    try:
        taskfile = load_task_text(text)
    except TaskFileError as error:  # a generated condition the loader rejects (e.g. an unbound variable)
        pytest.skip(f"not a valid domain: {error}")
    domain, problem = taskfile.domain, taskfile.problems["p"]
    outcomes = {}
    for mode in MODES:
        _set_mode(domain.axiom_set, mode)
        try:
            result = plan(domain, problem, max_nodes=3000)
        finally:
            _set_mode(domain.axiom_set, "auto")
        nodes = list(result.tree.nodes.values()) if result.tree is not None else []
        outcomes[mode] = (result.status, [str(a) for a in result.plan], result.message,
                          {k: v for k, v in result.stats.items() if k != "seconds"},
                          [(n.task, n.method, list(n.bindings.items()), n.parent) for n in nodes])
    for mode, outcome in outcomes.items():
        assert outcome == outcomes["reference"], (mode, text)
