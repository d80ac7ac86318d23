"""Labels of a user's own stacking task (tests/data/usertask_stack) decided like the physics: the kind of a limit
is the obstacle the step meets on each robot, not a default (issue 31 item 6)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parent.parent / "data" / "usertask_stack"

ON_ITS_SIDE = """    override:
      top: {pose: [0.5862, -0.3985, table, 90.0, 0.0, 0.0]}
"""


def _label(tmp_path: Path, robot: str, change: str):
    from bt_meta.campaign.families import task_family
    from bt_meta.campaign.labeller import Labeller
    from bt_meta.world.simulation.scenes import load_scene

    shutil.copytree(DATA, tmp_path / "stack")
    scene_path = tmp_path / "stack" / "scene.yaml"
    variant = tmp_path / "v.yaml"
    variant.write_text(scene_path.read_text(encoding="utf-8") + "variants:\n  perturbed:\n" + change,
                       encoding="utf-8")
    with Labeller(task_family(tmp_path / "stack" / "stack.yaml", "nominal"), load_scene(str(scene_path)),
                  start_seed=None, robot=robot) as labeller:
        return labeller.label(variant, "perturbed")


@pytest.mark.slow
@pytest.mark.parametrize(("robot", "kind"), [("panda", "collision"), ("baxter", "reachability")])
def test_a_block_on_its_side_is_a_limit_of_the_kind_its_own_step_meets(tmp_path: Path, robot: str, kind: str):
    # No turn in the domain: the place stands the block up on the way, held as picked (the wrist turned a quarter).
    # Above the base the Panda has solutions that all run into the table or its own fingers; the Baxter has none.
    label = _label(tmp_path, robot, ON_ITS_SIDE)
    assert label.expected == f"limit:{kind}", label.reason
    assert label.evidence["kind"] == kind and "held as it lies" in label.reason


@pytest.mark.slow
def test_a_shifted_block_is_nominal(tmp_path: Path):
    label = _label(tmp_path, "panda", "    override:\n      top: {pose: [0.60, -0.38, table, 0, 0, 20]}\n")
    assert label.expected == "nominal_equivalent", label.reason


@pytest.mark.slow
def test_a_plain_run_says_whether_the_goal_holds_in_the_simulator(tmp_path: Path, capsys):
    """``bt-meta run --json`` outside a campaign: ``achieved`` / ``truth`` are the campaigns' judge of the task's
    goal on the simulator's true state (they were missing: a user could not see whether the block was stacked)."""
    import json

    from bt_meta.cli import main

    shutil.copytree(DATA, tmp_path / "stack")
    assert main(["run", str(tmp_path / "stack" / "stack.yaml"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "SUCCESS" and out["achieved"] is True, out.get("truth")
    assert "cell (0, 0) of stack" in out["truth"]


KIT = Path(__file__).resolve().parent.parent / "data" / "usertask_kit"

LOW_PEG = """  peg:
    description: A 2.4 cm wide, 3 cm tall cylinder no slot takes (lower than the pin)
    shape: cylinder
    radius: 0.012
    length: 0.03
    mass: 0.03
    colour: white
    features:
      bottom: {point: [0, 0, -0.015], normal: [0, 0, -1]}
    grasp_frames:
      top: [0, 0, 0.019, 180, 0, 180]
"""


@pytest.mark.slow
@pytest.mark.parametrize(("radius", "expected"), [(0.047, "limit:collision"), (0.06, "nominal_equivalent")])
def test_the_grasp_check_holds_the_fingers_as_the_pick_does(tmp_path: Path, radius: float, expected: str):
    """The pin ringed by eight pegs lower than it: the Panda's pick goes down with its end-effector below the pin's
    top and its fingers still open 8 cm, so at 4.7 cm every grasp yaw puts a finger into a peg (the run fails
    ``collision`` at the grasp); at 6 cm they clear. Checked 4 mm over the pin's top, the fingers missed the pegs
    and the variant was labelled ``nominal_equivalent``."""
    import math

    from bt_meta.campaign.families import task_family
    from bt_meta.campaign.labeller import Labeller
    from bt_meta.world.simulation.scenes import load_scene

    shutil.copytree(KIT, tmp_path / "kit")
    parts = tmp_path / "kit" / "parts.yaml"
    parts.write_text(parts.read_text(encoding="utf-8") + LOW_PEG, encoding="utf-8")
    pegs = "".join(f"      - {{name: peg{k}, type: peg, colour: white, pose: [{0.52 + radius * math.cos(a):.4f}, "
                   f"{-0.42 + radius * math.sin(a):.4f}, table, 0, 0, 0]}}\n"
                   for k, a in enumerate(math.radians(22.5 + 45 * k) for k in range(8)))
    scene_path = tmp_path / "kit" / "scene.yaml"
    scene_path.write_text(scene_path.read_text(encoding="utf-8") + "variants:\n  ringed:\n    add:\n" + pegs,
                          encoding="utf-8")
    with Labeller(task_family(tmp_path / "kit" / "kit.yaml", "nominal"), load_scene(str(scene_path)),
                  start_seed=None, robot="panda") as labeller:
        label = labeller.label(scene_path, "ringed")
    assert label.expected == expected, label.reason
    if expected.startswith("limit"):
        assert "panda_leftfinger" in label.reason or "panda_rightfinger" in label.reason
