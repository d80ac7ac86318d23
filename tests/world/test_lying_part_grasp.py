"""A friction grasp of a part lying on its side closes on the part's widest section, where that section is widest
(issue 27): the housing lying down is held by its flange at the flange's axis -- not by its narrower body beside
it, 2 cm below the flange's top, on a slope, where it stood up tilted and fell back -- and the Panda stands it on its
narrow end. The cross-sections come from the pieces' collision shapes (fast); the re-grasp runs on a hand-built
scene (slow)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bt_meta.resources import trees_dir
from bt_meta.world.base import RUNNING, SUCCESS
from bt_meta.world.simulation.objects import Box, ObjectModel, housing, pose_to_matrix
from bt_meta.world.simulation.sections import square_contact, widest_section
from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

X = np.array([1.0, 0.0, 0.0])


def _lying_housing() -> tuple[ObjectModel, np.ndarray]:
    """The housing on its side, its axis along +y and tilted up 17 degrees toward the flange (as it rests: the
    flange is wider than the body), its centre at the origin."""
    model = housing()
    tilt = math.atan2(0.035 - 0.02, 0.05)
    return model, pose_to_matrix((0.0, 0.0, 0.0, -math.pi / 2.0 + tilt, 0.0, 0.0))


def test_the_section_of_a_lying_housing_is_its_flange_at_the_flange_axis():
    model, t = _lying_housing()
    section = widest_section(model, t, X, (0.0, 0.0))
    assert section is not None and section.moved
    flange_centre = t[:3, :3] @ np.array([0.0, 0.0, 0.025])  # the flange spans z 0.019..0.031 of the part
    assert section.y == pytest.approx(flange_centre[1], abs=0.004) and section.x == pytest.approx(0.0, abs=1e-3)
    assert section.width == pytest.approx(0.07, abs=0.003)
    assert section.low < flange_centre[2] < section.high and section.high - section.low < 0.025
    # above the band the pads would meet a slope; in it, a face square to them
    assert square_contact(model, t, X, (section.x, section.y), section.high + 0.004, section.high + 0.023) < 0.003
    middle = 0.5 * (section.low + section.high)
    assert square_contact(model, t, X, (section.x, section.y), middle - 0.0095, middle + 0.0095) > 0.008


def test_an_upright_part_keeps_its_grasp_point_and_its_widest_piece():
    model = housing()
    t = np.eye(4)
    section = widest_section(model, t, X, (0.0, 0.0))
    assert section is not None and not section.moved and (section.x, section.y) == (0.0, 0.0)
    assert (section.low, section.high) == pytest.approx((0.019, 0.031))  # the flange, as standing
    block = ObjectModel("stick", "green", (Box((0.12, 0.03, 0.03)),), 0.04, housing().features, "insert_end")
    section = widest_section(block, t, X, (0.0, 0.01))
    assert section is not None and not section.moved and (section.x, section.y) == (0.0, 0.01)
    assert square_contact(block, t, X, (0.0, 0.01), -0.0095, 0.0095) == pytest.approx(0.019, abs=0.001)


def _run(world: SimWorld, action: str, args: list[str]) -> None:
    skill = world.skill(action)
    skill.start(args)
    for _ in range(2000):
        status = skill.tick()
        if status != RUNNING:
            inner = getattr(skill, "inner", skill)
            assert status == SUCCESS, f"{action}{args}: {getattr(inner, 'failure', None)}"
            return
    raise AssertionError(f"{action}{args} did not finish")


@pytest.mark.slow
def test_the_panda_holds_a_lying_housing_by_its_flange_and_stands_it_up(tmp_path: Path):
    scene = (trees_dir() / "scenes" / "housing_insertion.yaml").read_text(encoding="utf-8")
    old = "{name: housing, type: housing, pose: [0.58, -0.38, table, 0, 0, 0]}"
    assert old in scene
    scene = scene.replace("scene: housing_insertion", "scene: lying_housing")
    (tmp_path / "scene.yaml").write_text(scene.replace(old, old.replace("table, 0, 0, 0", "table, 90, 0, 0")))
    with quiet_stdout():
        world = SimWorld.from_task_file(trees_dir() / "housing_insertion.yaml", "nominal", robot="panda",
                                        scene=tmp_path / "scene.yaml")
    try:
        sim = world.sim
        assert abs(float(sim.object_transform("housing")[2, 2])) < math.cos(math.radians(60.0))  # on its side
        for action, args in [("MoveTo", ["housing_above"]), ("MoveTo", ["housing_grasp"]),
                             ("CloseGripper", ["housing"])]:
            _run(world, action, args)
        hand = sim.link_transform(world.end_effector(world.default_arm))
        held = np.linalg.inv(sim.object_transform("housing")) @ hand
        assert 0.017 < float(held[2, 3]) < 0.033  # the fingers' middle on the flange (part z 0.019..0.031)
        assert abs(float(held[0, 3]) ** 2 + float(held[1, 3]) ** 2) < 0.006 ** 2  # at its axis, not above it
        for action, args in [("MoveTo", ["housing_above"]), ("MoveTo", ["turn_high"]), ("MoveTo", ["turn_low"]),
                             ("SetDownUpright", ["housing"]), ("MoveTo", ["turn_high"])]:
            _run(world, action, args)
        assert float(sim.object_transform("housing")[2, 2]) > math.cos(math.radians(10.0))  # standing, flange up
    finally:
        world.close()
