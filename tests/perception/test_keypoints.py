"""Keypoint relations R_p, R_n: exact values, every object-state form, means over traces, tolerances."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bt_meta.memory import ObjectState, State
from bt_meta.perception.keypoints import (
    KeypointError,
    expected_relation,
    judge,
    keypoints_of,
    pairs_from_states,
    relation,
)


def test_relation_of_aligned_magnets_is_zero_distance_and_opposed_normals():
    active = {"name": "a", "ap": [0.6, -0.1, -0.16], "an": [0, 0, -1]}
    reference = {"name": "r", "ap": [0.6, -0.1, -0.16], "an": [0, 0, 1]}
    r = relation(active, reference)
    assert r.r_p == pytest.approx(0.0) and r.r_n == pytest.approx(math.pi)


def test_relation_values_are_exact():
    active = {"ap": [0.03, 0.04, 0.0], "an": [0, 1, 0]}
    reference = {"ap": [0.0, 0.0, 0.0], "an": [0, 0, 2]}  # normals are normalised
    r = relation(active, reference)
    assert r.r_p == pytest.approx(0.05) and r.r_n == pytest.approx(math.pi / 2)


def test_memory_object_state_normal_is_turned_into_the_base_frame():
    # AN (0, 0, -1) in the object frame of an object rolled by 90 degrees points along +y in the base frame.
    state = ObjectState("a", (0, 0, 0, math.pi / 2, 0, 0), (0.0, 0.0, 0.0), (0.0, 0.0, -1.0))
    _, an = keypoints_of(state)
    assert np.allclose(an, [0, 1, 0], atol=1e-12)
    # a dict with an_object is turned the same way; with only "an" it is taken as base frame
    _, an_dict = keypoints_of({"ap": [0, 0, 0], "pose": [0, 0, 0, math.pi / 2, 0, 0], "an_object": [0, 0, -1]})
    assert np.allclose(an_dict, [0, 1, 0], atol=1e-12)
    assert np.allclose(keypoints_of({"ap": [0, 0, 0], "an": [0, 0, -1]})[1], [0, 0, -1])


def test_means_over_traces_and_judging():
    states = [
        State(objects=(ObjectState("a", (0,) * 6, (0.0, 0.0, d), (0.0, 0.0, -1.0)),
                       ObjectState("r", (0,) * 6, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))))
        for d in (0.002, 0.004, 0.006)
    ]
    states.append(State(objects=(ObjectState("r", (0,) * 6),)))  # a trace without the active object is skipped
    pairs = pairs_from_states(states, "a", "r")
    assert len(pairs) == 3
    expected = expected_relation(pairs)
    assert expected.r_p == pytest.approx(0.004) and expected.n == 3
    assert expected.r_n == pytest.approx(math.pi)
    assert expected.r_p_std == pytest.approx(np.std([0.002, 0.004, 0.006]))
    nominal = relation({"ap": [0, 0, 0.005], "an": [0, 0, -1]}, {"ap": [0, 0, 0], "an": [0, 0, 1]})
    assert judge(nominal, expected).matched
    on_side = relation({"ap": [0, 0.02, 0.02], "an": [0, 1, 0]}, {"ap": [0, 0, 0], "an": [0, 0, 1]})
    verdict = judge(on_side, expected)
    assert not verdict.matched and verdict.failed == ("r_p", "r_n")
    assert verdict.delta_n == pytest.approx(math.pi / 2)
    only_p = judge(on_side, expected, angle_tolerance=None)
    assert only_p.failed == ("r_p",)
    assert judge(on_side, expected, position_tolerance=None, angle_tolerance=None).matched


def test_errors_name_what_is_missing():
    with pytest.raises(KeypointError, match="at least one past trace"):
        expected_relation([])
    with pytest.raises(KeypointError, match="'x' has no attachment point"):
        keypoints_of({"name": "x", "an": [0, 0, 1]})
    with pytest.raises(KeypointError, match="'x' has no attachment normal"):
        keypoints_of({"name": "x", "ap": [0, 0, 0]})
    with pytest.raises(KeypointError, match="zero attachment normal"):
        keypoints_of({"ap": [0, 0, 0], "an": [0, 0, 0]})
    with pytest.raises(KeypointError, match="3 finite numbers"):
        keypoints_of({"ap": [0, 0], "an": [0, 0, 1]})


@pytest.mark.slow
def test_simulator_states_separate_upright_from_on_side():
    from bt_meta.world.simulation.objects import magnetic_part
    from bt_meta.world.simulation.sim import Simulation

    with Simulation(seed=0) as sim:
        sim.spawn("reference", magnetic_part("reference"), (0.62, -0.10, 0, 0, 0, 0), on_table=True)
        sim.spawn("active", magnetic_part("active"), (0.58, -0.40, 0, 0, 0, 0), on_table=True)
        sim.settle(60)
        upright = relation(sim.object_state("active"), sim.object_state("reference"))
        # the memory's form (AN in the object frame) gives the same relation
        states = {n: sim.object_state(n) for n in ("active", "reference")}
        stored = [ObjectState(s.name, s.pose, s.ap, s.an_object) for s in states.values()]
        assert relation(stored[0], stored[1]).r_n == pytest.approx(upright.r_n, abs=1e-9)
        sim.move_object("active", sim.resting_pose(sim.object_model("active"), (0.58, -0.40, 0, math.pi / 2, 0, 0)))
        sim.settle(60)
        on_side = relation(sim.object_state("active"), sim.object_state("reference"))
    assert upright.r_n == pytest.approx(math.pi, abs=0.01)
    assert on_side.r_n == pytest.approx(math.pi / 2, abs=0.02)


def test_the_offset_in_the_reference_s_frame_tells_a_part_beside_the_reference_from_a_joined_one():
    """Joined: the attachment points 1 cm apart along the normal. Put down 1.2 cm beside the reference (it had
    moved from where the absolute poses expect it; generated magnetic s1 0031): as far apart, sideways -- R_p
    agrees, the offset does not. Both shifted and turned together, nothing changes."""
    turned = math.radians(30.0)
    pose = [0.6, -0.1, -0.18, 0.0, 0.0, turned]
    reference = {"ap": [0.6, -0.1, -0.16], "an": [0, 0, 1], "pose": pose}
    joined = {"ap": [0.6, -0.1, -0.15], "an": [0, 0, -1]}
    expected = expected_relation([(joined, reference)] * 3)
    assert expected.offset == pytest.approx((0.0, 0.0, 0.01))
    beside = relation({"ap": [0.612, -0.1, -0.16], "an": [0, 0, -1]}, reference)
    assert beside.r_p == pytest.approx(expected.r_p, abs=0.003)  # the paper's R_p cannot tell
    verdict = judge(beside, expected)
    assert not verdict.matched and verdict.failed == ("r_p",)
    assert verdict.delta_offset == pytest.approx(0.0156, abs=1e-3)
    # the pair shifted and turned about the vertical: the offset in the reference's frame is the same
    moved = {"ap": [0.7, 0.0, -0.16], "an": [0, 0, 1], "pose": [0.7, 0.0, -0.18, 0.0, 0.0, turned + 0.5]}
    assert judge(relation({"ap": [0.7, 0.0, -0.15], "an": [0, 0, -1]}, moved), expected).matched
    # a reference without a pose: no offset, the paper's R_p alone
    assert relation(joined, {"ap": [0.6, -0.1, -0.16], "an": [0, 0, 1]}).offset is None
