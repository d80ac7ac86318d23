"""The planner's search refinements lose no plan: goal-directed dead ends and deepening of same-state chains.

Each refinement is compared with the plain search (``Search(goal_pruning=False, deepening=False)``) on small
problems where it applies, and on seeded random domains with goals and recursive methods: the same problems are
solvable, and every plan found is checked by the independent verifier.
"""

from __future__ import annotations

import random
import textwrap

import pytest

from bt_meta.htn import load_task_text
from bt_meta.htn.planner import TASK, Search
from bt_meta.htn.verify import verify_plan


def search(taskfile, problem: str = "p", **options):
    prob = taskfile.problems[problem]
    engine = Search(taskfile.domain, goal=prob.goal, max_nodes=options.pop("max_nodes", 200_000), **options)
    result = engine.run(prob.state, [(TASK, task, None, None) for task in prob.tasks])
    if result.ok:
        verdict = verify_plan(taskfile.domain, prob, [a.as_list() for a in result.plan], result.tree.to_dict())
        assert verdict.ok, verdict.errors
    return result


def plain(taskfile, problem: str = "p"):
    return search(taskfile, problem, goal_pruning=False, deepening=False)


def steps(result) -> list[str]:
    return [str(action) for action in result.plan]


# A method that tears down what an earlier task built is tried first; only the second keeps the goal reachable.
TEARDOWN = """
domain:
  predicates: {built: [x], spare: []}
  primitives:
    build: {parameters: [?x], add: [built(?x)]}
    wreck: {parameters: [?x], delete: [built(?x)]}
    rest: {add: [spare()]}
  tasks: {make: [?x], tidy: [?x]}
  methods:
    - name: make_it
      task: make(?x)
      subtasks: [build(?x)]
    - name: tidy_by_wrecking
      task: tidy(?x)
      subtasks: [wreck(?x)]
    - name: tidy_by_resting
      task: tidy(?x)
      subtasks: [rest()]
problems:
  p: {tasks: [make(a), tidy(a), tidy(a), make(b)], goal: [built(a), built(b)]}
  rebuilt: {tasks: [make(a), tidy(a), make(a)], goal: [built(a)]}
"""


def test_a_goal_fact_no_task_left_can_add_ends_the_branch_at_once():
    taskfile = load_task_text(textwrap.dedent(TEARDOWN))
    result = search(taskfile)
    assert result.ok and steps(result) == ["build(a)", "rest()", "rest()", "build(b)"]
    assert result.stats["goal_pruned"] >= 1
    reference = plain(taskfile)
    assert steps(reference) == steps(result)  # the same first plan: only failing branches were cut
    assert result.stats["backtracks"] < reference.stats["backtracks"]


def test_a_goal_fact_a_later_task_can_add_again_does_not_prune():
    taskfile = load_task_text(textwrap.dedent(TEARDOWN))
    result = search(taskfile, "rebuilt")
    # wrecking first is fine here: make(a) comes again and rebuilds it
    assert result.ok and steps(result) == ["build(a)", "wreck(a)", "build(a)"]
    assert result.stats["goal_pruned"] == 0


def test_goal_facts_of_derived_predicates_are_never_pruned_on():
    text = """
    domain:
      predicates: {base: [x]}
      axioms:
        - head: good(?x)
          when: base(?x)
      primitives:
        noop: {}
        set: {parameters: [?x], add: [base(?x)]}
      tasks: {go: []}
      methods:
        - name: nothing
          task: go()
          subtasks: [noop()]
    problems:
      p: {init: [base(a)], tasks: [go()], goal: [good(a)]}
    """
    result = search(load_task_text(textwrap.dedent(text)))
    assert result.ok and result.stats["goal_pruned"] == 0


# Left-recursive routes (as IPC Transport's get_to): depth first, the first neighbour leads down a long detour.
ROUTES = """
domain:
  predicates: {at: [x], road: [x, x]}
  primitives:
    drive:
      parameters: [?a, ?b]
      precondition: at(?a) and road(?a, ?b)
      add: [at(?b)]
      delete: [at(?a)]
  tasks: {get_to: [?l]}
  methods:
    - name: direct
      task: get_to(?b)
      precondition: at(?a) and road(?a, ?b)
      subtasks: [drive(?a, ?b)]
    - name: via
      task: get_to(?c)
      precondition: road(?b, ?c)
      subtasks: [get_to(?b), drive(?b, ?c)]
problems:
  p:
    init: [at(home), road(home, x1), road(d4, goal), road(x1, goal),
           road(x1, d1), road(d1, d2), road(d2, d3), road(d3, d4),
           road(d1, x1), road(d2, d1), road(d3, d2), road(d4, d3), road(x1, home), road(goal, x1), road(goal, d4)]
    tasks: [get_to(goal)]
"""


def test_left_recursive_chains_are_deepened_and_find_the_short_route_first():
    taskfile = load_task_text(textwrap.dedent(ROUTES))
    result = search(taskfile)
    assert result.ok and steps(result) == ["drive(home, x1)", "drive(x1, goal)"]
    assert result.stats["depth_cuts"] >= 1  # the detour by d4 was cut at depth 1, then x1 led straight there
    reference = plain(taskfile)
    assert reference.ok  # depth first finds a route too, the long way round
    assert len(reference.plan) > len(result.plan)


def test_an_unreachable_place_is_still_no_plan_after_every_depth():
    text = ROUTES.replace("tasks: [get_to(goal)]", "tasks: [get_to(island)]").replace(
        "init: [at(home),", "init: [at(home), road(island, island),")
    taskfile = load_task_text(textwrap.dedent(text))
    result = search(taskfile)
    assert result.status == "no_plan"
    assert plain(taskfile).status == "no_plan"


def test_a_chain_that_completes_only_deep_with_a_failing_continuation_is_exhausted():
    # every route reaches goal, but the task after it needs a fact no route gives: no plan, found after every
    # depth was tried, each decomposition's continuation tried once (the failure memo skips repeats)
    text = ROUTES.replace("tasks: [get_to(goal)]", "tasks: [get_to(goal), finish()]").replace(
        "  tasks: {get_to: [?l]}", "    finish: {precondition: at(nowhere)}\n  tasks: {get_to: [?l]}")
    taskfile = load_task_text(textwrap.dedent(text))
    result = search(taskfile)
    assert result.status == "no_plan" and plain(taskfile).status == "no_plan"


def _random_domain(rng: random.Random) -> str:
    """A small random domain: 4 objects, unary and nullary facts, a static graph ``e``, recursive methods.

    Some methods are left-recursive through the graph, as IPC Transport's routes (``t(?x)`` by ``t(?y)`` then a
    step, for an edge ``e(?y, ?x)``): the chains the deepening bounds.
    """
    objects = ["a", "b", "c", "d"]
    atoms = [f"p({o})" for o in objects] + [f"q({o})" for o in objects] + ["r()"]

    def literal() -> str:
        pred = rng.choice(["p", "q", "r"])
        arg = "" if pred == "r" else rng.choice(["?x", *objects])
        return ("not " if rng.random() < 0.3 else "") + f"{pred}({arg})"

    def atom() -> str:
        pred = rng.choice(["p", "q", "r"])
        return f"{pred}()" if pred == "r" else f"{pred}({rng.choice(['?x', *objects])})"

    lines = ["domain:", "  predicates: {p: [x], q: [x], r: [], e: [x, y]}", "  primitives:"]
    primitives = [f"act{i}" for i in range(4)]
    for name in primitives:
        pre = " and ".join(literal() for _ in range(rng.choice([0, 0, 1, 2])))
        add = ", ".join(dict.fromkeys(atom() for _ in range(rng.randint(1, 2))))
        delete = ", ".join(dict.fromkeys(atom() for _ in range(rng.randint(0, 1))))
        lines += [f"    {name}:", "      parameters: [?x]", f"      add: [{add}]"]
        lines += [f"      precondition: {pre}"] if pre else []
        lines += [f"      delete: [{delete}]"] if delete else []
    tasks = [f"t{i}" for i in range(3)]
    lines.append("  tasks: {" + ", ".join(f"{t}: [?x]" for t in tasks) + "}")
    lines.append("  methods:")
    for task in tasks:
        for index in range(rng.randint(1, 3)):
            pre = " and ".join(literal() for _ in range(rng.choice([0, 0, 1])))
            if rng.random() < 0.35:  # left recursion along an edge
                pre = " and ".join(filter(None, ["e(?y, ?x)", pre]))
                subs = [f"{task}(?y)", f"{rng.choice(primitives)}(?x)"]
            else:
                subs = [f"{rng.choice(tasks + primitives * 2)}({rng.choice(['?x', *objects])})"
                        for _ in range(rng.randint(0, 3))]
            lines += [f"    - name: {task}_m{index}", f"      task: {task}(?x)"]
            lines += [f"      precondition: {pre}"] if pre else []
            lines.append(f"      subtasks: [{', '.join(subs)}]")
    edges = [f"e({x}, {y})" for x in objects for y in objects if x != y and rng.random() < 0.5]
    init = ", ".join([*(a for a in atoms if rng.random() < 0.4), *edges])
    network = ", ".join(f"{rng.choice(tasks)}({rng.choice(objects)})" for _ in range(rng.randint(1, 3)))
    goal = ", ".join(dict.fromkeys(rng.choice(atoms) for _ in range(rng.randint(1, 2))))
    lines += ["problems:", f"  p: {{init: [{init}], tasks: [{network}], goal: [{goal}]}}"]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("seed", range(300))
def test_random_domains_are_solvable_exactly_when_the_plain_search_solves_them(seed):
    text = _random_domain(random.Random(seed))
    taskfile = load_task_text(text)
    reference = search(taskfile, goal_pruning=False, deepening=False, max_nodes=20_000)
    if reference.status == "budget_exhausted":
        pytest.skip("the plain search needs more than the budget")
    for options in ({}, {"goal_pruning": False}, {"deepening": False}):
        result = search(taskfile, max_nodes=200_000, **options)
        assert result.status == reference.status, (options, text)
        if result.ok and not result.stats["depth_cuts"]:
            # goal pruning only cuts branches that fail: without a depth cut the search order is the plain one
            assert steps(result) == steps(reference), (options, text)


def test_achiever_masks_cover_recursion_and_unbound_method_variables():
    from bt_meta.htn.achievers import GoalAchievers

    text = """
    domain:
      predicates: {on: [x, y], done: [x], link: [x, y]}
      primitives:
        put: {parameters: [?x, ?y], add: [on(?x, ?y)]}
        mark: {parameters: [?x], add: [done(?x)]}
      tasks: {chain: [?x], anywhere: [?x]}
      methods:
        - name: step
          task: chain(?x)
          precondition: link(?x, ?y)
          subtasks: [chain(?y), mark(?x)]
        - name: stop
          task: chain(?x)
          subtasks: []
        - name: somewhere
          task: anywhere(?x)
          precondition: link(?x, ?y)
          subtasks: [put(?x, ?y)]
    problems:
      p: {tasks: [chain(a)], goal: [done(a), done(c), on(a, b), on(b, a)]}
    """
    taskfile = load_task_text(textwrap.dedent(text))
    achievers = GoalAchievers(taskfile.domain, taskfile.problems["p"].goal)
    bits = achievers.bits
    # chain(a) recurses through chain(?y), any object: it can mark every block
    assert achievers.of_task(("chain", "a")) == bits[("done", "a")] | bits[("done", "c")]
    # ?y is bound by the precondition, not the head: any object, so on(a, b) but not on(b, a)
    assert achievers.of_task(("anywhere", "a")) == bits[("on", "a", "b")]
    assert achievers.of_task(("mark", "b")) == 0
    assert achievers.first(bits[("done", "c")] | bits[("on", "b", "a")]) == ("done", "c")
