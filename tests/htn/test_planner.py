"""Planner semantics: unification, method order, backtracking, axioms, externals, loops, budgets, unordered."""

from __future__ import annotations

import itertools
import subprocess
import sys
import textwrap
import time

import pytest

from bt_meta.htn import ExternalPredicateError, State, load_task_text, plan, problem_from_atoms


def load(text: str):
    return load_task_text(textwrap.dedent(text))


def plan_of(text: str, problem: str = "p", **kwargs):
    """Plan, and check every plan found with the independent verifier (bt_meta.htn.verify)."""
    from bt_meta.htn.verify import verify_plan

    taskfile = load(text)
    result = plan(taskfile.domain, taskfile.problems[problem], **kwargs)
    if result.ok and not taskfile.domain.external:
        verdict = verify_plan(taskfile.domain, taskfile.problems[problem], [a.as_list() for a in result.plan],
                              result.tree.to_dict())
        assert verdict.ok, verdict.errors
    return result


def steps(result) -> list[str]:
    return [str(action) for action in result.plan]


MOVE_DOMAIN = """
domain:
  predicates: {at: [x], link: [x, x], visited: [x]}
  primitives:
    go:
      parameters: [?from, ?to]
      precondition: at(?from) and link(?from, ?to)
      add: [at(?to), visited(?to)]
      delete: [at(?from)]
  tasks: {reach: [?goal], step_to: [?goal]}
  methods:
    - name: already_there
      task: reach(?g)
      precondition: at(?g)
    - name: one_hop
      task: reach(?g)
      precondition: at(?here) and link(?here, ?next) and not visited(?next)
      subtasks: [go(?here, ?next), reach(?g)]
problems:
  p:
    init: [at(a), link(a, b), link(b, c), link(a, d), link(d, e), link(c, f)]
    tasks: [reach(e)]
"""


def test_free_variables_are_bound_from_facts_and_backtracking_finds_the_right_branch():
    result = plan_of(MOVE_DOMAIN)
    assert result.status == "success"
    # a -> b -> c -> f is a dead end; the planner backtracks to a and takes d -> e
    assert steps(result) == ["go(a, d)", "go(d, e)"]
    assert result.stats["backtracks"] >= 1
    root = result.tree.nodes[result.tree.roots[0]]
    assert root.method == "one_hop"
    assert root.bindings == {"g": "e", "here": "a", "next": "d"}


def test_methods_are_tried_in_file_order_and_heads_unify_with_constants_and_repeated_variables():
    text = """
    domain:
      predicates: {p: [x], q: [x]}
      primitives:
        mark:
          parameters: [?x]
          add: [q(?x)]
      tasks: {t: [?a, ?b]}
      methods:
        - name: same_args
          task: t(?x, ?x)
          subtasks: [mark(same)]
        - name: first_is_k
          task: t(k, ?y)
          subtasks: [mark(?y)]
        - name: fallback
          task: t(?a, ?b)
          subtasks: [mark(other)]
    problems:
      p: {tasks: [t(z, z), t(k, w), t(u, v)]}
    """
    result = plan_of(text)
    assert steps(result) == ["mark(same)", "mark(w)", "mark(other)"]
    methods = [n.method for n in result.tree.walk() if n.kind == "compound"]
    assert methods == ["same_args", "first_is_k", "fallback"]


def test_tree_nodes_record_state_before_steps_and_parents():
    result = plan_of(MOVE_DOMAIN)
    tree = result.tree
    prims = tree.primitives()
    assert [p.step for p in prims] == [0, 1]
    assert [a.node_id for a in result.plan] == [p.id for p in prims]
    assert ("at", "a") in prims[0].state_before
    assert ("at", "d") in prims[1].state_before
    assert tree.nodes[prims[0].parent].kind == "compound"
    as_dict = tree.to_dict()
    assert as_dict["roots"] == tree.roots
    assert {"id", "task", "kind", "method", "bindings", "parent", "children", "step"} <= set(as_dict["nodes"][0])
    assert "state_before" in tree.to_dict(states=True)["nodes"][0]
    assert result.state is not None and ("at", "e") in result.state


def test_no_plan_reports_the_deepest_dead_end():
    text = MOVE_DOMAIN.replace("tasks: [reach(e)]", "tasks: [reach(zz)]")
    result = plan_of(text)
    assert result.status == "no_plan"
    assert result.tree is None and result.plan == []
    assert result.message.startswith("no plan: every method and binding failed; deepest dead end after")
    assert "reach(zz): no method applies (tried already_there, one_hop)" in result.message


def test_goal_facts_are_checked_and_a_failing_goal_makes_the_planner_backtrack():
    text = MOVE_DOMAIN.replace("tasks: [reach(e)]", "tasks: [reach(e)]\n    goal: [visited(d)]")
    assert plan_of(text).status == "success"
    text = MOVE_DOMAIN.replace("tasks: [reach(e)]", "tasks: [reach(e)]\n    goal: [visited(b)]")
    result = plan_of(text)
    assert result.status == "no_plan"
    assert "goal facts do not hold at the end: visited(b)" in result.message


def test_primitive_argument_types_must_hold():
    text = """
    domain:
      types: [block]
      predicates: {done: [block]}
      primitives:
        finish:
          parameters: [?b - block]
          add: [done(?b)]
      tasks: {}
    problems:
      typed: {objects: {block: [b1]}, tasks: [finish(b1)]}
      untyped: {tasks: [finish(b1)]}
    """
    assert plan_of(text, "typed").status == "success"
    result = plan_of(text, "untyped")
    assert result.status == "no_plan"
    assert "finish(b1): its argument types do not hold" in result.message


AXIOMS = """
domain:
  predicates: {edge: [x, x], blocked: [x], start: [x]}
  axioms:
    - head: reach(?x, ?y)
      when: edge(?x, ?y) and not blocked(?y)
    - head: reach(?x, ?z)
      when: reach(?x, ?y) and edge(?y, ?z) and not blocked(?z)
    - head: isolated(?x)
      when: start(?x) and not reach(?x, ?x)
  primitives:
    visit:
      parameters: [?x]
      precondition: start(?s) and reach(?s, ?x)
      add: [blocked(?x)]
  tasks: {tour: []}
  methods:
    - name: visit_one
      task: tour()
      precondition: start(?s) and reach(?s, ?x) and not isolated(?s)
      subtasks: [visit(?x)]
problems:
  p:
    init: [start(a), edge(a, b), edge(b, c), edge(c, a), edge(c, d), blocked(b)]
    tasks: [tour()]
  chain:
    init: [start(a), edge(a, b), edge(b, c)]
    tasks: [tour()]
"""


def test_recursive_axioms_on_a_cyclic_graph_and_negation_of_derived_predicates():
    taskfile = load(AXIOMS)
    domain = taskfile.domain
    state = taskfile.problems["p"].state
    derived = set(domain.derived_atoms(state))
    # b is blocked, so nothing is reachable from a (a -> b is its only edge)
    assert ("isolated", "a") in derived
    assert not [atom for atom in derived if atom[:2] == ("reach", "a")]
    assert {("reach", "b", "c"), ("reach", "b", "a"), ("reach", "b", "d"), ("reach", "c", "d")} <= derived
    assert ("reach", "c", "c") not in derived
    unblocked = state.apply(delete=[("blocked", "b")])
    derived = set(domain.derived_atoms(unblocked))
    assert {("reach", "a", "a"), ("reach", "a", "d"), ("reach", "c", "b")} <= derived
    assert ("reach", "d", "a") not in derived and ("isolated", "a") not in derived
    # top-down queries on fresh states (nothing cached) agree with the bottom-up extension
    for atom in [("reach", "a", "a"), ("reach", "a", "d"), ("reach", "c", "b"), ("reach", "d", "a")]:
        assert domain.axiom_set.holds(State(unblocked), atom) == (atom in derived), atom
    assert plan_of(AXIOMS).status == "no_plan"
    assert plan_of(AXIOMS, "chain").status == "no_plan"  # isolated(a): nothing leads back to a


PATH = """
domain:
  predicates: {edge: [x, x], here: [x], seen: [x]}
  axioms:
    - head: path(?x, ?z)
      when: edge(?x, ?z)
    - head: path(?x, ?z)
      when: edge(?x, ?y) and path(?y, ?z)
  primitives:
    look:
      parameters: [?x]
      precondition: here(?h) and path(?h, ?x)
      add: [seen(?x)]
  tasks: {}
problems:
  p: {init: [here(a)], tasks: []}
"""


def test_top_down_axiom_proofs_fall_back_to_the_fixpoint_on_cycles_and_depth():
    from bt_meta.htn import axioms as axioms_module

    domain = load(PATH).domain
    axiom_set = domain.axiom_set
    cycle = State([("edge", "a", "b"), ("edge", "b", "c"), ("edge", "c", "a")])
    assert axiom_set.holds(State(cycle), ("path", "a", "a"))
    assert not axiom_set.holds(State(cycle), ("path", "a", "zz"))  # proof meets path(a, zz) again: fixpoint
    n = axioms_module.MAX_DEPTH + 5  # deeper than a top-down proof may go
    chain = State([("edge", f"c{i}", f"c{i + 1}") for i in range(n)])
    assert axiom_set.holds(State(chain), ("path", "c0", f"c{n}"))
    assert not axiom_set.holds(State(chain), ("path", f"c{n}", "c0"))
    problem = problem_from_atoms(domain, "deep", init=[("here", "c0"), *chain], tasks=[("look", f"c{n}")])
    assert steps(plan(domain, problem)) == [f"look(c{n})"]


def test_external_predicates_are_asked_through_the_callable():
    text = """
    domain:
      predicates: {block: [x], moved: [x]}
      external: {reachable: [x]}
      primitives:
        move:
          parameters: [?b]
          precondition: block(?b) and reachable(?b) and not moved(?b)
          add: [moved(?b)]
      tasks: {move_one: []}
      methods:
        - name: any_reachable
          task: move_one()
          precondition: block(?b) and reachable(?b)
          subtasks: [move(?b)]
    problems:
      p: {init: [block(b1), block(b2), block(b3)], tasks: [move_one()]}
    """
    calls: list[tuple] = []

    def external(name, args, state):
        calls.append((name, args))
        return args == ("b2",)

    result = plan_of(text, external=external)
    assert steps(result) == ["move(b2)"]
    assert ("reachable", ("b1",)) in calls and ("reachable", ("b2",)) in calls
    with pytest.raises(ExternalPredicateError, match="external predicate 'reachable'"):
        plan_of(text)


LOOP = """
domain:
  predicates: {done: []}
  primitives:
    finish: {add: [done()]}
  tasks: {work: []}
  methods:
    - name: again
      task: work()
      precondition: not done()
      subtasks: [work()]
    - name: do_it
      task: work()
      subtasks: [finish()]
problems:
  p: {tasks: [work()]}
"""


def test_loop_detection_prunes_a_task_that_recurs_in_the_same_state():
    result = plan_of(LOOP)
    assert result.status == "success"
    assert steps(result) == ["finish()"]
    assert result.stats["loops_pruned"] >= 1
    # work() -> again -> work() recurs in the same state: that branch fails and the root takes do_it
    assert result.stats["loops_pruned"] == 1
    root = result.tree.nodes[result.tree.roots[0]]
    assert root.method == "do_it"
    assert len(result.tree) == 2


def test_node_budget_ends_with_budget_exhausted():
    result = plan_of(MOVE_DOMAIN, max_nodes=3)
    assert result.status == "budget_exhausted"
    assert result.message.startswith("budget exhausted: node budget of 3 expansions exhausted")
    assert result.plan == [] and result.tree is None


def test_time_budget_ends_with_budget_exhausted():
    # every ordering of 9 unordered steps is tried before failing: far more than a millisecond of work. The goal
    # is one a task could add (finish), so the goal-directed pruning, which ignores preconditions, does not see
    # that it cannot hold
    subtasks = ", ".join(f"mark(m{i})" for i in range(9))
    text = f"""
    domain:
      predicates: {{marked: [x], never: []}}
      primitives:
        mark: {{parameters: [?x], add: [marked(?x)]}}
        finish: {{precondition: never(), add: [never()]}}
      tasks: {{all: []}}
      methods:
        - name: any_order
          task: all()
          unordered: [{subtasks}]
    problems:
      p: {{tasks: [all(), finish()], goal: [never()]}}
    """
    started = time.perf_counter()
    result = plan_of(text, max_seconds=0.05)
    assert result.status == "budget_exhausted"
    assert "time budget of 0.05 s exhausted" in result.message
    assert time.perf_counter() - started < 5


def test_unordered_subtasks_take_the_first_order_that_plans():
    text = """
    domain:
      predicates: {open: [], done: [x]}
      primitives:
        unlock: {add: [open()]}
        enter: {parameters: [?r], precondition: open(), add: [done(?r)]}
      tasks: {visit: []}
      methods:
        - name: both
          task: visit()
          unordered: [enter(room), unlock()]
    problems:
      p: {tasks: [visit()]}
    """
    result = plan_of(text)
    assert steps(result) == ["unlock()", "enter(room)"]
    root = result.tree.nodes[result.tree.roots[0]]
    assert [result.tree.nodes[c].task for c in root.children] == [("unlock",), ("enter", "room")]


def test_a_plan_of_twelve_thousand_steps_needs_no_recursion():
    n = 12_000
    domain = load("""
    domain:
      predicates: {count: [x], next: [x, x]}
      primitives:
        tick:
          parameters: [?n, ?m]
          precondition: count(?n) and next(?n, ?m)
          add: [count(?m)]
          delete: [count(?n)]
      tasks: {countdown: []}
      methods:
        - name: step
          task: countdown()
          precondition: count(?n) and next(?n, ?m)
          subtasks: [tick(?n, ?m), countdown()]
        - name: stop
          task: countdown()
          precondition: count(c0)
    """).domain
    init = [("count", f"c{n}")] + [("next", f"c{i}", f"c{i - 1}") for i in range(n, 0, -1)]
    problem = problem_from_atoms(domain, "count", init=init, tasks=[("countdown",)])
    result = plan(domain, problem)
    assert result.status == "success"
    assert len(result.plan) == n
    assert str(result.plan[0]) == f"tick(c{n}, c{n - 1})" and str(result.plan[-1]) == "tick(c1, c0)"
    assert result.tree.depth(result.plan[-1].node_id) == n
    assert sum(1 for _ in result.tree.walk()) == 2 * n + 1
    assert len(result.tree.pretty().splitlines()) == 2 * n + 1


def test_plans_do_not_depend_on_the_string_hash_seed():
    script = (
        "from bt_meta.htn import load_task_text, plan\n"
        f"tf = load_task_text({MOVE_DOMAIN!r})\n"
        "print([str(a) for a in plan(tf.domain, tf.problems['p']).plan])\n"
    )
    outputs = {
        subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True,
                       env={"PYTHONHASHSEED": seed, "PATH": ""}).stdout
        for seed in ("1", "2")
    }
    assert len(outputs) == 1


@pytest.mark.parametrize(("text", "acyclic"), [(AXIOMS, False), (PATH, True), (PATH, False)])
def test_inherited_axiom_memos_agree_with_fresh_proofs_along_random_changes(text, acyclic):
    import random

    domain = load(text).domain
    rng = random.Random(7)
    nodes = ["a", "b", "c", "d", "e", "f"]
    state = State([("start", "a"), ("here", "a"), ("edge", "a", "b"), ("edge", "b", "c")])
    derived = sorted(domain.axiom_set.rules)
    arity = {a.head_pred: len(a.head_args) for a in domain.axioms}
    queries = [(p, x, y) for p in derived if arity[p] == 2 for x in nodes for y in nodes]
    queries += [(p, x) for p in derived if arity[p] == 1 for x in nodes]
    for _ in range(80):
        x, y = sorted(rng.sample(nodes, 2)) if acyclic else (rng.choice(nodes), rng.choice(nodes))
        change = [("edge", x, y)] if rng.random() < 0.7 else [("blocked", y)]
        state = state.apply(add=change) if rng.random() < 0.6 else state.apply(delete=change)
        asked = rng.sample(queries, 10)
        inherited = [domain.axiom_set.holds(state, q) for q in asked]  # memo inherited from the parent state
        fresh = [domain.axiom_set.holds(State(state), q) for q in asked]  # no parent: proved from scratch
        assert inherited == fresh, asked


def test_states_are_immutable_values_that_copy_and_pickle_without_their_history():
    import copy
    import pickle

    state = State([("a", "1"), ("b", "2", "3")])
    later = state
    for i in range(3000):  # a long parent chain must not make pickling recurse
        later = later.apply(add=[("c", str(i))], delete=[("c", str(i - 1))])
    assert copy.deepcopy(later) is later and copy.copy(later) is later
    again = pickle.loads(pickle.dumps(later))
    assert again == later and hash(again) == hash(later) and sorted(again) == sorted(later)
    assert later.holds(("c", "2999")) and not later.holds(("c", "2998")) and len(later) == 3
    assert later.with_arg("b", 2, "3") == (("b", "2", "3"),)
    assert state.apply() is state  # no change, no new state


def _random_towers(blocks: list[str], rng) -> list[list[str]]:
    towers: list[list[str]] = []
    for block in rng.sample(blocks, len(blocks)):
        if towers and rng.random() < 0.7:
            rng.choice(towers).append(block)
        else:
            towers.append([block])
    return towers


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_incremental_axiom_evaluation_changes_no_plan(seed):
    """Memo inheritance and per-seed units are an optimisation: plans are identical without them."""
    import random
    from pathlib import Path

    from bt_meta.htn import load_task_file

    rng = random.Random(seed)
    blocks = [f"b{i}" for i in range(30)]
    init: list[tuple[str, ...]] = [("hand_empty",), *(("block", block) for block in blocks)]  # the methods' block order
    for tower in _random_towers(blocks, rng):
        init.append(("on_table", tower[0]))
        init.extend(("on", upper, lower) for lower, upper in itertools.pairwise(tower))
        init.append(("clear", tower[-1]))
    goal: list[tuple[str, ...]] = []
    for tower in _random_towers(blocks, rng):
        init.append(("goal_on_table", tower[0]))
        init.extend(("goal_on", upper, lower) for lower, upper in itertools.pairwise(tower))
        goal.extend(("on", upper, lower) for lower, upper in itertools.pairwise(tower))
    path = Path(__file__).resolve().parents[2] / "bt_meta" / "bench" / "problems" / "blocks_htn.yaml"
    plans = []
    for incremental in (True, False):
        domain = load_task_file(path).domain
        domain.axiom_set.incremental = incremental
        problem = problem_from_atoms(domain, "random", init=init, tasks=[("achieve",)], goal=goal)
        result = plan(domain, problem)
        assert result.status == "success", result.message
        plans.append([a.as_list() for a in result.plan])
    assert plans[0] == plans[1]
