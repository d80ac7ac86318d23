"""Object substitution (section 6.4): grid-map vs symbolic matching in a memory of A and H, and in the simulator.

The fast tests write the traces of the nominal letters A and H directly (the grid-maps are the 6 x 6 occupancy
the simulator's camera records after each placement) and hand the plugin a failure at A's bar step with a world
that reports what it shows. The slow test records A and H in the simulator and runs A's variants through the
meta-executor. The plugin is registered explicitly, as the ``bt_meta`` entry point will register it.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import bt_meta_plugins.object_substitution as substitution
import numpy as np
import pytest

from bt_meta.bt.failures import Failure, FailureKind
from bt_meta.errors import ConfigError
from bt_meta.htn import load_task_file, plan
from bt_meta.memory import Episode, EpisodicMemory, Expectation, GridMap, State, Step, Trace
from bt_meta.meta.proposals import PlanState, apply_proposal
from bt_meta.resources import trees_dir

LETTERS = trees_dir() / "letters.yaml"

# The placed block's grid-map after each step, as the top camera records it (row 0 = far side of the window).
LEG_1 = "...... ...... ..bb.. ..bb.. ...... ......"
LEG_2 = "...... ...... ..bb.. ..bb.. ..bb.. ..bb.."
A_BAR = "...... ...... bbbbbb bbbbbb b....b b....b"
A_APEX = "...... ...... ..bb.. ..bb.. bbbbbb bbbbbb"
H_BAR_LEFT = "bb.... bb.... bbbb.. bbbb.. bb.... bb...."
H_BAR_RIGHT = "....bb ....bb bbbbbb bbbbbb ....bb ....bb"

A_STEPS = [  # block, x, y, shape, parent task, parent node, grid
    ("b0", "0", "0", "1x1", "draw_leg", "n1", LEG_1), ("b1", "0", "1", "1x1", "draw_leg", "n1", LEG_2),
    ("b2", "3", "0", "1x1", "draw_leg", "n4", LEG_1), ("b3", "3", "1", "1x1", "draw_leg", "n4", LEG_2),
    ("b5", "1.5", "1", "1x2", "draw_A_bar", "n7", A_BAR), ("b4", "1.5", "2", "1x1", "draw_apex", "n9", A_APEX)]
H_STEPS = [
    ("b0", "0", "0", "1x1", "draw_tall_leg", "n1", LEG_1), ("b1", "0", "1", "1x1", "draw_tall_leg", "n1", LEG_2),
    ("b2", "0", "2", "1x1", "draw_tall_leg", "n1", LEG_2), ("b3", "3", "0", "1x1", "draw_tall_leg", "n5", LEG_1),
    ("b4", "3", "1", "1x1", "draw_tall_leg", "n5", LEG_2), ("b5", "3", "2", "1x1", "draw_tall_leg", "n5", LEG_2),
    ("b6", "1", "1", "1x1", "draw_H_bar", "n9", H_BAR_LEFT), ("b7", "2", "1", "1x1", "draw_H_bar", "n9", H_BAR_RIGHT)]


def grid(text: str) -> np.ndarray:
    return np.array([[1 if c == "b" else 0 for c in row] for row in text.split()], dtype=np.uint8)


def letter_trace(task_file: Any, problem: str, steps: list[tuple[str, ...]], started: float) -> Trace:
    out, expectations = [], []
    for i, (block, x, y, shape, parent, node, text) in enumerate(steps):
        at = ("at", block, x, y)
        state = State(facts=(at,), grid_maps=(GridMap(grid(text), object_name=block, colour="blue", shape=shape),))
        out.append(Step(i, "place", (block, x, y), node_id=f"n{20 + i}", parent_task=parent, parent_node=node,
                        state=state))
        expectations.append(Expectation(i, "place", (block, x, y), parent, facts=(at,), grid_map_index=0))
    initial = State(facts=tuple(sorted(task_file.problem(problem).state)))
    episode = Episode(f"draw_{problem}", str(LETTERS), problem, started=started, outcome="success")
    return Trace(episode, tuple(out), initial, tuple(expectations))


@pytest.fixture(scope="module")
def task_file():
    return load_task_file(LETTERS)


@pytest.fixture(scope="module")
def letters_memory(task_file, tmp_path_factory):
    path = tmp_path_factory.mktemp("substitution") / "memory.sqlite"
    with EpisodicMemory.open(path) as memory:
        memory.write(letter_trace(task_file, "A", A_STEPS, 1000.0))
        memory.write(letter_trace(task_file, "H", H_STEPS, 2000.0))
    memory = EpisodicMemory.open(path, readonly=True)
    yield memory
    memory.close()


class SeenWorld:
    """What a world offers the plugin: the objects it reports (with shape and colour) and its symbolic state."""

    def __init__(self, state: Any, objects: dict[str, tuple[str, str]]) -> None:
        self.state = state
        self.objects = objects

    def observe(self) -> dict[str, Any]:
        return {"objects": {n: {"name": n, "shape": s, "colour": c} for n, (s, c) in self.objects.items()}}

    def symbolic_state(self) -> Any:
        return self.state

    def apply_symbolic(self, add, delete) -> None:
        self.state = self.state.apply(add=add, delete=delete)


NOMINAL = {f"b{i}": ("1x1", "blue") for i in range(5)}
VARIANT_OBJECTS = {
    "two_1x1_same_colour": {**NOMINAL, "b5": ("1x1", "red"), "b6": ("1x1", "red")},
    "two_1x1_different_colours": {**NOMINAL, "b5": ("1x1", "red"), "b6": ("1x1", "blue")},
    "other_colour_renamed": {**NOMINAL, "r5": ("1x2", "red")},
    "same_kind_renamed": {**NOMINAL, "c5": ("1x2", "blue")},
}


def bar_failure(task_file: Any, memory: Any, objects: dict[str, tuple[str, str]], *,
                kind: FailureKind = FailureKind.UNEXPECTED_CONFIGURATION, placed: bool = True):
    """A's plan failed at the bar step: b5 was put at (1.5, 1) (``placed``) and the grid-map monitor objected."""
    problem = task_file.problem("A")
    tree = plan(task_file.domain, problem).tree
    plan_state = PlanState(tree, cursor=4)
    state = problem.state
    for node in plan_state.steps()[: 5 if placed else 4]:
        state = task_file.domain.primitives["place"].ground(node.task[1:]).apply(state)
    world = SeenWorld(state, objects)
    effects = ([("at", "b5", "1.5", "1")], [("available", "b5")])
    context = SimpleNamespace(action="place", args=("b5", "1.5", "1"), step=4, node_id="n8", world=world,
                              effects=effects, run=SimpleNamespace(problem=problem, memory=memory))
    maps = [{"object": "b5", "cells": 4, "expected": {"colour": "blue", "shape": "1x2"},
             "observed": {"colour": objects.get("b5", ("", ""))[1], "shape": objects.get("b5", ("", ""))[0],
                          "block_seen": "b5" in objects}}]
    failure = Failure(kind=kind, message="grid-maps differ", step=4, node_id="n8", action="place",
                      args=("b5", "1.5", "1"),
                      evidence={"plan": plan_state.describe(), "mismatches": [{"kind": "gridmap",
                                                                                "evidence": {"maps": maps}}]})
    return failure, context, plan_state, world


def run_steps(task_file: Any, plan_state: PlanState, state: Any) -> Any:
    """Apply the plan from its cursor symbolically; every precondition must hold."""
    for node in plan_state.steps()[plan_state.cursor:]:
        ground = task_file.domain.primitives[node.task[0]].ground(node.task[1:])
        assert ground.holds(state), f"{node.task} does not apply in {sorted(state)}"
        state = ground.apply(state)
    return state


@pytest.mark.parametrize("variant", ["two_1x1_same_colour", "two_1x1_different_colours"])
def test_gridmap_matcher_splices_h_bar_for_two_1x1(task_file, letters_memory, variant):
    failure, context, plan_state, world = bar_failure(task_file, letters_memory, VARIANT_OBJECTS[variant])
    plugin = substitution.ObjectSubstitution(letters_memory, matcher="gridmap")
    proposals = plugin.bt_meta_propose_repairs(failure, context)
    best = proposals[0]
    assert best.action == "splice"
    assert best.changes == {"start": 4, "end": 5, "actions": [["place", "b5", "1", "1"], ["place", "b6", "2", "1"]]}
    match = best.evidence["match"]
    assert (match["task"], match["parent_task"], match["call"], match["distance"], match["rank"]) == \
        ("draw_H", "draw_H_bar", "place(b7, 2, 1)", 8, 2)
    assert best.evidence["vector"]["missing"] == ["b5 (blue 1x2)"]
    assert 0.3 < best.score < 1 and all(p.score <= best.score for p in proposals)
    # the unknown entities are anchored: perceived shape and colour, available again for the repair
    state = world.symbolic_state()
    colour = VARIANT_OBJECTS[variant]["b6"][1]
    assert {("block", "b6"), ("available", "b6"), ("shape", "b6", "1x1"), ("colour", "b6", colour),
            ("available", "b5"), ("shape", "b5", "1x1"), ("colour", "b5", "red")} <= set(state)
    assert ("shape", "b5", "1x2") not in state and ("at", "b5", "1.5", "1") not in state
    # the splice applies and the repaired plan runs symbolically from the anchored state
    repaired, change = apply_proposal(best, plan_state, failed_step=4, failed_node="n8", domain=task_file.domain,
                                      problem=task_file.problem("A"), state=state)
    assert change == "steps 4..4 replaced by place(b5, 1, 1), place(b6, 2, 1)"
    final = run_steps(task_file, repaired, state)
    assert {("at", "b5", "1", "1"), ("at", "b6", "2", "1"), ("at", "b4", "1.5", "2")} <= set(final)


@pytest.mark.parametrize("variant", ["two_1x1_same_colour", "two_1x1_different_colours"])
def test_symbolic_matcher_finds_no_decomposition_for_two_1x1(task_file, letters_memory, variant):
    failure, context, _, world = bar_failure(task_file, letters_memory, VARIANT_OBJECTS[variant])
    before = world.symbolic_state()
    plugin = substitution.ObjectSubstitution(letters_memory, matcher="symbolic")
    assert plugin.bt_meta_propose_repairs(failure, context) is None
    assert world.symbolic_state() == before  # nothing proposed, nothing anchored
    vector = substitution.mismatch_vector(failure, context)
    retrieval = plugin.retrieve(vector, failure.evidence["plan"], letters_memory, "draw_A")
    assert retrieval.found is None
    by_task = {m.decomposition.parent_task: m for m in retrieval.matches}
    assert by_task["draw_A_bar"].distance == 0 and by_task["draw_A_bar"].rank == 1
    # H's bar is among the symbolic candidates, but its facts say blue 1x1 blocks
    assert "needs blue 1x1, blue 1x1" in by_task["draw_H_bar"].reason
    # the apex (one blue 1x1) is symbolically nearer than H's bar: symbols do not see the form
    assert by_task["draw_apex"].distance < by_task["draw_H_bar"].distance


def test_one_for_one_substitute_and_the_colour_rule(task_file, letters_memory):
    # a red 1x2 under another name: the grid-map matcher reuses A's own bar with it; the symbolic one cannot
    renamed = VARIANT_OBJECTS["other_colour_renamed"]
    failure, context, plan_state, world = bar_failure(task_file, letters_memory, renamed,
                                                      kind=FailureKind.UNKNOWN_ENTITY, placed=False)
    proposals = substitution.ObjectSubstitution(letters_memory).bt_meta_propose_repairs(failure, context)
    assert (proposals[0].action, proposals[0].changes) == ("substitute", {"mapping": {"b5": "r5"}, "from_step": 4})
    assert proposals[0].evidence["match"]["distance"] == 0
    # the tiling of the same cells comes after it, saying the red bar is not the methods' blue
    assert [(p.action, p.evidence.get("other_colour")) for p in proposals[1:]] == [("splice", ["r5"])]
    assert proposals[1].score < proposals[0].score
    state = world.symbolic_state()
    assert {("block", "r5"), ("available", "r5"), ("colour", "r5", "red")} <= set(state)
    repaired, _ = apply_proposal(proposals[0], plan_state, failed_step=4, failed_node="n8", domain=task_file.domain,
                                 problem=task_file.problem("A"), state=state)
    assert ("at", "r5", "1.5", "1") in run_steps(task_file, repaired, state)
    failure, context, _, _ = bar_failure(task_file, letters_memory, VARIANT_OBJECTS["other_colour_renamed"],
                                         placed=False)
    assert substitution.ObjectSubstitution(letters_memory, matcher="symbolic").bt_meta_propose_repairs(
        failure, context) is None
    # a blue 1x2 under another name: now the symbols match too
    failure, context, _, _ = bar_failure(task_file, letters_memory, VARIANT_OBJECTS["same_kind_renamed"],
                                         placed=False)
    proposals = substitution.ObjectSubstitution(letters_memory, matcher="symbolic").bt_meta_propose_repairs(
        failure, context)
    assert proposals[0].action == "substitute" and proposals[0].changes["mapping"] == {"b5": "c5"}


def test_rotations_let_legs_tie_with_h_bar(task_file, letters_memory):
    """With quarter turns the legs' columns look like the bar (distance 8, as H's bar): orientation is off by
    default because both letters are drawn in one table frame."""
    failure, context, _, _ = bar_failure(task_file, letters_memory, VARIANT_OBJECTS["two_1x1_same_colour"])
    vector = substitution.mismatch_vector(failure, context)
    turned = substitution.ObjectSubstitution(letters_memory, rotations=True, k=10).retrieve(
        vector, failure.evidence["plan"], letters_memory, "draw_A")
    assert [m.distance for m in turned.matches[:3]] == [0, 8, 8]
    assert turned.found is not None and turned.found.decomposition.parent_task in {"draw_leg", "draw_tall_leg"}


def test_nothing_to_do(task_file, letters_memory, tmp_path, monkeypatch):
    plugin = substitution.ObjectSubstitution(letters_memory)
    failure, context, _, _ = bar_failure(task_file, letters_memory, {**NOMINAL, "b5": ("1x2", "blue")},
                                         kind=FailureKind.COLLISION)
    failure.evidence["mismatches"] = []
    assert plugin.bt_meta_propose_repairs(failure, context) is None  # a collision with the entities as assumed
    failure, context, _, _ = bar_failure(task_file, letters_memory, VARIANT_OBJECTS["two_1x1_same_colour"],
                                         kind=FailureKind.COLLISION)
    proposals = plugin.bt_meta_propose_repairs(failure, context)  # the step's block is not the one planned
    assert proposals and proposals[0].action == "splice"
    failure, context, _, _ = bar_failure(task_file, letters_memory, {**NOMINAL, "b5": ("1x2", "blue")})
    failure.evidence["mismatches"] = []
    assert plugin.bt_meta_propose_repairs(failure, context) is None  # nothing missing
    monkeypatch.setenv("BT_META_MEMORY", str(tmp_path / "absent.sqlite"))
    failure, context, _, _ = bar_failure(task_file, None, VARIANT_OBJECTS["two_1x1_same_colour"])
    # no memory: no remembered decomposition; only the geometry's tiling, with the two red 1x1 (not blue)
    proposals = substitution.ObjectSubstitution().bt_meta_propose_repairs(failure, context)
    assert [(p.evidence["matcher"], bool(p.evidence["other_colour"])) for p in proposals] == [("tiling", True)]
    assert substitution.ObjectSubstitution(colours="require").bt_meta_propose_repairs(failure, context) is None
    # H's P_a has no place(b5, 1.5, 1): no query, so no match
    failure, context, _, _ = bar_failure(task_file, letters_memory, VARIANT_OBJECTS["two_1x1_same_colour"])
    vector = substitution.mismatch_vector(failure, context)
    retrieval = plugin.retrieve(vector, failure.evidence["plan"], letters_memory, "draw_H")
    assert retrieval.matches == [] and retrieval.note == "P_a has no execution of place(b5, 1.5, 1) in draw_H"


def test_settings_errors_and_environment(letters_memory, monkeypatch):
    with pytest.raises(ConfigError, match="matcher must be one of gridmap, symbolic, got 'visual'"):
        substitution.ObjectSubstitution(matcher="visual")
    with pytest.raises(ConfigError, match="level must be one of task, step, got 'leaf'"):
        substitution.ObjectSubstitution(level="leaf")
    with pytest.raises(ConfigError, match="k, max_proposals and candidates must be >= 1"):
        substitution.ObjectSubstitution(k=0)
    monkeypatch.setenv("BT_META_SUBSTITUTION_MATCHER", "symbolic")
    assert substitution.ObjectSubstitution().matcher == "symbolic"
    monkeypatch.setenv("BT_META_SUBSTITUTION_MATCHER", "nearest")
    with pytest.raises(ConfigError, match=r"\$BT_META_SUBSTITUTION_MATCHER: .*got 'nearest'"):
        substitution.ObjectSubstitution()
    try:
        assert substitution.configure(memory=letters_memory, matcher="gridmap", k=2).k == 2
    finally:
        substitution.configure()


def test_module_plugin_registers_and_answers_the_hook(task_file, letters_memory):
    from bt_meta.plugins import PluginHost

    host = PluginHost()
    host.register(substitution, "object_substitution", source="test")
    failure, context, _, _ = bar_failure(task_file, letters_memory, VARIANT_OBJECTS["two_1x1_same_colour"])
    try:
        substitution.configure(memory=letters_memory)
        result = host.call("bt_meta_propose_repairs", failure=failure, context=context)
        assert not result.errors
        assert result.values[0][0].action == "splice"
    finally:
        substitution.configure()


def test_experiment_rejects_unknown_matchers(capsys):
    from bt_meta.cli import main

    assert main(["experiment", "substitution", "--matchers", "gridmap,visual"]) == 2
    assert "--matchers: expected a comma-separated subset of gridmap, symbolic, got 'gridmap,visual'" in \
        capsys.readouterr().err
    assert main(["experiment", "substitution", "--variants", "A_upside_down"]) == 2
    assert "--variants: expected a comma-separated subset of A_bar_other_colour, A_two_1x1_same_colour, " \
        "A_two_1x1_different_colours, got 'A_upside_down'" in capsys.readouterr().err


@pytest.mark.slow
def test_simulator_two_1x1_same_colour_repaired_by_gridmap_substitution_not_by_symbols(tmp_path):
    from bt_meta.experiments import substitution as experiment

    result = experiment.run(variants=["A_two_1x1_same_colour"], memory_path=tmp_path / "memory.sqlite")
    assert result["recorded"] == {"A": "episode 1", "H": "episode 2"}
    row = result["rows"][0]
    assert row["retrieval"]["vector"] == {"step": None, "missing": ["b5 (blue 1x2)"],
                                          "unknown": ["b5 (red 1x1)", "b6 (red 1x1)"]}
    found = row["retrieval"]["matchers"]["gridmap"]["found"]
    assert (found["task"], found["parent_task"], found["rank"]) == ("draw_H", "draw_H_bar", 2)
    assert row["retrieval"]["matchers"]["symbolic"]["found"] is None
    grid_run = row["runs"]["gridmap"]
    # the monitor's grid-map mismatch at the bar step -> splice with the two 1x1 blocks -> SUCCESS
    assert grid_run["monitor"]["step"] == 4 and "expected blue 1x2, seen red 1x1" in grid_run["monitor"]["message"]
    assert [(r["action"], r["outcome"]) for r in grid_run["repairs"]] == [("splice", "repaired")]
    assert grid_run["status"] == "success"
    assert ["place", "b5", "1", "1"] in grid_run["plan"] and ["place", "b6", "2", "1"] in grid_run["plan"]
    expected = sorted(tuple(c) for c in result["expected_cells"])
    seen = sorted((round(u * 2) / 2, round(v * 2) / 2) for u, v in grid_run["letter_cells"])
    assert seen == expected  # every block where the letter wants it, nothing else in the letter's area
    symbolic_run = row["runs"]["symbolic"]
    assert symbolic_run["status"] == "failed" and symbolic_run["repairs"] == []
    assert symbolic_run["stop_reason"] == "no repair proposed for unknown_entity at step 4"
