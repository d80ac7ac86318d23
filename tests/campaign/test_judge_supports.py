"""The judge's ``at_cell`` on a frame with a ``support:`` (issue 31: trays and stacking): a cell is filled by a part
resting on the support under it -- on the tray's floor, on top of the block it is stacked on -- not by the support
itself nor by a part on the table beside or under it. Hand-built scenes, the parts laid by hand."""

from __future__ import annotations

from pathlib import Path

import pytest

from bt_meta.judge.checks import evaluate
from bt_meta.world.base import RUNNING
from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

TASK = """\
domain:
  name: stacking
  types: [block]
  predicates: {available: [block], at: [block, object, object], hand_empty: []}
  primitives:
    put:
      parameters: [?b - block, ?x, ?y]
      precondition: available(?b) and hand_empty()
      add: [at(?b, ?x, ?y)]
      delete: [available(?b)]
problems:
  nominal:
    objects: {block: [top]}
    init: [hand_empty(), available(top)]
    tasks: [put(top, 0, 0)]
    goal: [at(top, 0, 0)]
"""

SCENE = """\
scene: supports
objects:
  - {name: base_block, type: megablok_1x1, colour: blue, pose: [0.60, -0.10, table, 0, 0, 0]}
  - {name: top, type: megablok_1x1, colour: red, pose: [0.58, -0.38, table, 0, 0, 0]}
obstacles:
  - {name: tray, shape: box, size: [0.20, 0.20, 0.02], pose: [0.62, 0.12, table, 0, 0, 0]}
anchors:
  stack_spot: [0.60, -0.10, table, 0, 0, 0]
  slot: [0.62, 0.12, table, 0, 0, 0]
variants:
  no_top:
    remove: [top]
    add: [{name: spare, type: megablok_1x1, colour: red, pose: [0.66, -0.42, table, 0, 0, 0]}]
  top_on_side:
    override: {top: {pose: [0.58, -0.38, table, 90, 0, 0]}}
"""


def _world(tmp_path: Path, frame: str) -> SimWorld:
    (tmp_path / "poses").mkdir()
    (tmp_path / "task.yaml").write_text(TASK)
    (tmp_path / "scene.yaml").write_text(SCENE)
    frames = {"stack": "{anchor: stack_spot, unit: 0.061, support: base_block}",
              "tray": "{anchor: slot, unit: 0.061, support: tray}"}
    (tmp_path / "poses" / "stacking.yaml").write_text(
        "domain: stacking\nproblems:\n  nominal: {scene: ../scene.yaml}\n"
        f"skills:\n  put: {{skill: place, frame: {frame}}}\nframes:\n  {frame}: {frames[frame]}\n")
    with quiet_stdout():
        return SimWorld.from_task_file(tmp_path / "task.yaml", "nominal", robot="baxter")


def _lay(world: SimWorld, name: str, z: float) -> None:
    x, y, yaw = world.ground_cell(next(iter(world.grounding.frames)), "0", "0")
    world.sim.move_object(name, [x, y, z, 0.0, 0.0, yaw])
    world.sim.settle(60)


@pytest.mark.slow
def test_a_stacked_cell_needs_the_part_on_top_not_the_block_under_it(tmp_path: Path):
    world = _world(tmp_path, "stack")
    try:
        ok, why = evaluate("at_cell", ("top", "0", "0"), {}, world)
        assert not ok, why  # only base_block is there: nothing is stacked yet
        _lay(world, "top", world.sim.object_pose("base_block")[2] + 0.06)
        ok, why = evaluate("at_cell", ("top", "0", "0"), {}, world)
        assert ok, why
    finally:
        world.close()


@pytest.mark.slow
def test_a_tray_slot_is_filled_by_a_part_on_the_tray_floor(tmp_path: Path):
    world = _world(tmp_path, "tray")
    try:
        assert not evaluate("at_cell", ("top", "0", "0"), {}, world)[0]
        _lay(world, "top", world.sim.object_pose("top")[2] + 0.022)
        ok, why = evaluate("at_cell", ("top", "0", "0"), {}, world)
        assert ok, why
    finally:
        world.close()


@pytest.mark.slow
def test_the_labeller_does_not_take_the_support_for_what_blocks_the_place(tmp_path: Path):
    """The block a part is stacked on lies on the place the task puts something: it is the frame's support, so the
    nominal scene is nominal_equivalent, not ``limit:collision`` (every variant of a user's stacking task was)."""
    from bt_meta.campaign.families import task_family
    from bt_meta.campaign.labeller import Labeller
    from bt_meta.world.simulation.scenes import load_scene

    _world(tmp_path, "stack").close()
    scene = load_scene(str(tmp_path / "scene.yaml"))
    with Labeller(task_family(tmp_path / "task.yaml", "nominal"), scene, start_seed=None) as labeller:
        label = labeller.label(scene.path, None)
    assert label.expected == "nominal_equivalent", label.reason


@pytest.mark.slow
def test_the_labeller_needs_the_domain_to_turn_a_block_it_stacks(tmp_path: Path):
    """A block on its side on a frame's cell is only repairable when the domain can turn it (the letters'
    turn_over / Reorient); this one cannot: a limit, not ``repairable``. A missing block with a spare is."""
    from bt_meta.campaign.families import task_family
    from bt_meta.campaign.labeller import Labeller
    from bt_meta.world.simulation.scenes import load_scene

    _world(tmp_path, "stack").close()
    tray = "obstacles:\n  - {name: tray, shape: box, size: [0.20, 0.20, 0.02], pose: [0.62, 0.12, table, 0, 0, 0]}\n"
    assert tray in SCENE
    (tmp_path / "scene.yaml").write_text(SCENE.replace(tray, ""))  # no obstacle: the turn alone decides
    scene = load_scene(str(tmp_path / "scene.yaml"))
    with Labeller(task_family(tmp_path / "task.yaml", "nominal"), scene, start_seed=None) as labeller:
        turned = labeller.label(scene.path, "top_on_side")
        assert turned.expected == "limit:reachability", turned.reason
        assert labeller.label(scene.path, "no_top").expected == "repairable"


@pytest.mark.slow
def test_the_support_is_never_put_onto_itself(tmp_path: Path):
    """With the block to stack missing, the block it goes on is no spare for it: placed onto itself, the stacking
    "succeeded" with nothing stacked (a false success). The place skill refuses it, and the spare is used."""
    import json
    import os
    import subprocess
    import sys

    world = _world(tmp_path, "stack")
    try:
        skill = world.skill("put")
        skill.start(["base_block", "0", "0"])
        for _ in range(50):
            if skill.tick() != RUNNING:
                break
        assert skill.inner.failure is not None and "support" in skill.inner.failure.message
    finally:
        world.close()
    command = [str(Path(sys.executable).with_name("bt-meta")), "run", str(tmp_path / "task.yaml"),
               "--variant", "no_top", "--repair", "--json"]
    done = subprocess.run(command, capture_output=True, text=True, env=dict(os.environ), timeout=120)
    out = json.loads(done.stdout)
    assert out["status"] == "SUCCESS", out.get("attempts")
    assert [a["proposal"]["changes"]["symbols"] for a in out["attempts"]] == [{"top": "spare"}]
