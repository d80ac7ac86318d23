"""A missing part that the plan names only through the grounding (the magnetic plan moves to poses defined over
``active_part``), with a spare of its type on the table: the symbol is rebound to the spare, the run succeeds with
the spare joined, the refinement keeps the rebinding, and the next run needs zero attempts. Simulator, a small
hand-built scene: the shipped magnetic scene with the active part removed, a spare of its type (another colour)
and a distractor block of another type."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from bt_meta_plugins import classification_rules, object_substitution, refinement_predicates, retry_repair
from bt_meta_plugins._grounding_spares import entity_symbols, rebind_proposals

from bt_meta.meta import Limits, MetaExecutor, RefinementStore
from bt_meta.plugins import create_plugin_host
from bt_meta.resources import trees_dir

pytestmark = pytest.mark.slow

TASK_FILE = trees_dir() / "magnetic_attach.yaml"

SCENE = """
scene: spare_magnet
description: the magnetic attach scene; the active part is gone, a spare of its type and a block stand elsewhere
anchors:
  set_down_spot: [0.50, -0.28, table, 0, 0, 0]
objects:
  - {name: reference, type: magnet_reference, pose: [0.62, -0.10, table, 0, 0, 0]}
  - {name: active, type: magnet_active, pose: [0.58, -0.40, table, 0, 0, 0]}
variants:
  spare:
    remove: [active]
    add:
      - {name: block, type: megablok_1x1, colour: red, pose: [0.52, -0.36, table, 0, 0, 0]}
      - {name: other_magnet, type: magnet_active, colour: green, pose: [0.66, -0.45, table, 0, 0, 20]}
  far:
    override: {active: {pose: [0.98, 0.30, table, 0, 0, 0]}}
    add:
      - {name: other_magnet, type: magnet_active, colour: yellow, pose: [0.66, -0.45, table, 0, 0, 30]}
"""


def host() -> Any:
    return create_plugin_host(entry_points=False, plugins=[
        ("classification_rules", classification_rules), ("retry_repair", retry_repair),
        ("refinement_predicates", refinement_predicates),
        ("object_substitution", object_substitution.ObjectSubstitution(memory=None))])


def run(scene: Path, memory: Path, variant: str = "spare") -> tuple[Any, Any, list[Any]]:
    from bt_meta.campaign.episode import variant_world

    task_file, problem, world = variant_world(TASK_FILE, "nominal", scene, variant, seed=0)
    try:
        with RefinementStore.open(memory) as store:
            report = MetaExecutor(task_file.domain, problem, world, host(), task_file=task_file, refinements=store,
                                  limits=Limits(max_attempts=3, max_seconds=60), variant=variant).run()
        return report, problem, list(world.sim.attachments())
    finally:
        world.close()


def test_the_missing_part_s_symbol_is_rebound_to_a_spare_of_its_type_and_the_refinement_keeps_it(tmp_path):
    scene = tmp_path / "spare_magnet.yaml"
    scene.write_text(SCENE)
    memory = tmp_path / "memory.sqlite"
    report, _, joined = run(scene, memory)
    assert report.ok, report.stop_reason
    assert [(a.kind, a.step, a.proposal["action"]) for a in report.attempts] == [("unknown_entity", 0, "rebind")]
    proposal = report.attempts[0].proposal
    assert proposal["changes"] == {"symbols": {"active_part": "other_magnet"}, "from_step": 0}
    assert proposal["evidence"]["spares"] == ["other_magnet"]  # the block is of another type; colour not asked for
    assert report.rebound == {"active_part": "other_magnet"} and report.plan == report.initial_plan
    assert joined == [("other_magnet", "reference")]
    saved = report.refinement_saved
    assert saved is not None and saved["rebind"] == {"active_part": "other_magnet"}
    assert "pose_within(other_magnet, " in saved["precondition"]

    again, _, joined = run(scene, memory)
    assert again.ok and again.attempts == [] and again.refinements_used == [saved["method"]]
    assert again.rebound == {"active_part": "other_magnet"} and joined == [("other_magnet", "reference")]


def test_a_part_out_of_reach_where_it_lies_is_rebound_to_a_spare(tmp_path):
    """The active part lies beyond the arm's reach: the move above it (a pose over ``active_part``) has no IK
    solution and names it ``out_of_reach``; the symbol is rebound to the spare, which is joined."""
    scene = tmp_path / "far_magnet.yaml"
    scene.write_text(SCENE)
    report, _, joined = run(scene, tmp_path / "memory.sqlite", "far")
    assert report.ok, report.stop_reason
    assert [(a.kind, a.proposal["action"]) for a in report.attempts] == [("reachability", "rebind")]
    proposal = report.attempts[0].proposal
    assert proposal["changes"]["symbols"] == {"active_part": "other_magnet"}
    assert "out of reach where it lies" in proposal["description"]
    assert report.failures[0]["evidence"]["out_of_reach"] == "active"
    assert joined == [("other_magnet", "reference")]


def test_no_spare_of_the_missing_part_s_type_no_rebinding(tmp_path):
    from bt_meta.bt.failures import Failure, FailureKind
    from bt_meta.campaign.episode import variant_world

    scene = tmp_path / "no_spare.yaml"
    scene.write_text(SCENE.replace("      - {name: other_magnet, type: magnet_active, colour: green, "
                                   "pose: [0.66, -0.45, table, 0, 0, 20]}\n", ""))
    _, problem, world = variant_world(TASK_FILE, "nominal", scene, "spare", seed=0)
    try:
        assert entity_symbols(world, problem) == {"active_part": "active", "reference_part": "reference"}

        class Context:
            pass

        context = Context()
        context.world = world
        context.run = Context()
        context.run.problem = problem
        plan = [{"step": 0, "action": "MoveTo", "args": ["active_above"], "done": False}]
        failure = Failure(kind=FailureKind.UNKNOWN_ENTITY, message="no active", step=0, evidence={"plan": plan})
        assert rebind_proposals(failure, context) == []  # only the block: not a magnet_active
    finally:
        world.close()
