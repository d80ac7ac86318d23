"""The pybullet world: robot placement, table reach, objects at rest, grasp by constraint, magnetic attach."""

from __future__ import annotations

import math

import numpy as np
import pybullet
import pytest

from bt_meta.world.kinematics.forward import Kinematics, pose_matrix
from bt_meta.world.simulation.objects import OBJECT_TYPES, make_model, pose_to_matrix
from bt_meta.world.simulation.scenes import load_scene
from bt_meta.world.simulation.sim import Simulation, SimulationError

pytestmark = pytest.mark.slow

DOWN = (math.pi, 0.0, 0.0)  # gripper z (approach) pointing at the table


@pytest.fixture(scope="module")
def sim():
    with Simulation(seed=0) as s:
        yield s


@pytest.fixture
def world(sim):
    """The module's simulation, emptied and with the arm at home before and after each test."""
    sim.clear_objects()
    sim.set_joint_positions(sim.robot.home)
    yield sim
    for arm in sim.robot.arms:
        sim.release(arm)
    sim.clear_objects()
    sim.set_joint_positions(sim.robot.home)


def reach(sim: Simulation, position, rpy=DOWN, arm: str = "right") -> float:
    """Teleport the arm to a pybullet IK solution for the pose; return the remaining position error (m)."""
    end = sim.link_index(sim.robot.arm(arm).end_effector)
    quat = pybullet.getQuaternionFromEuler(rpy)
    best = math.inf
    for _ in range(4):
        q = pybullet.calculateInverseKinematics(
            sim.robot_id,
            end,
            list(position),
            quat,
            maxNumIterations=300,
            residualThreshold=1e-6,
            physicsClientId=sim.client,
        )
        values = dict(zip(sim.movable_joints, q, strict=True))
        sim.set_joint_positions({j: values[j] for j in sim.robot.arm(arm).joints})
        best = np.linalg.norm(np.array(sim.gripper_pose(arm)[:3]) - np.array(position))
        if best < 1e-4:
            break
    return float(best)


def relative(sim: Simulation, name: str, arm: str = "right") -> np.ndarray:
    return np.linalg.inv(sim.link_transform(sim.robot.arm(arm).end_effector)) @ sim.object_transform(name)


def test_robot_base_is_the_pinocchio_world(world):
    kin = Kinematics(world.robot)
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = kin.random_q(rng)
        values = kin.q_to_dict(q)
        world.set_joint_positions(values)
        for frame in ("right_gripper", "left_gripper", "right_hand_camera_link", "head_camera_link"):
            expected = pose_matrix(kin.frame_pose(q, frame))
            assert np.allclose(world.link_transform(frame), expected, atol=1e-5), frame


def test_home_pose_is_applied(world):
    q = world.joint_positions(list(world.robot.home))
    for joint, value in world.robot.home.items():
        assert q[joint] == pytest.approx(value, abs=1e-9)


def test_table_area_is_reachable_pointing_down(world):
    (x_lo, _), _ = world.table.bounds
    assert x_lo > 0.42  # clear of the pedestal
    for x in (0.5, 0.6, 0.7):
        for y in (-0.5, -0.3, -0.1, 0.1):
            err = reach(world, (x, y, world.table.top_z + 0.03))
            assert err < 1e-3, (x, y, err)


@pytest.mark.parametrize("type_name", sorted(OBJECT_TYPES))
def test_objects_rest_where_spawned(world, type_name):
    for i, roll in enumerate((0.0, math.pi)):
        if type_name == "task_board" and roll:
            continue
        world.spawn(f"o{i}", make_model(type_name), (0.55 + 0.18 * i, -0.3, 0.0, roll, 0.0, 0.4), on_table=True)
    start = {n: world.object_pose(n) for n in world.object_names()}
    world.step(480)
    for name, pose in start.items():
        now = world.object_pose(name)
        assert np.allclose(now[:3], pose[:3], atol=1e-3), (name, now, pose)
        rot = pose_to_matrix(now)[:3, :3].T @ pose_to_matrix(pose)[:3, :3]
        assert math.acos(min(1.0, (np.trace(rot) - 1) / 2)) < 0.01
        if world.object_model(name).mass > 0:  # static bodies (the board) make no contacts with the static table
            assert "table" in world.contacts(name)


def test_object_state_reports_features_in_base_frame(world):
    world.spawn("up", make_model("magnet_active"), (0.6, -0.3, 0, 0, 0, 0), on_table=True)
    world.spawn("down", make_model("magnet_active"), (0.6, -0.1, 0, math.pi, 0, 0), on_table=True)
    states = world.object_states()
    assert set(states) == {"up", "down"}
    up, down = states["up"], states["down"]
    assert np.allclose(up.an, (0, 0, -1), atol=1e-6) and np.allclose(down.an, (0, 0, 1), atol=1e-6)
    assert up.ap[2] == pytest.approx(world.table.top_z, abs=1e-3)  # the magnet face rests on the table
    assert down.ap[2] == pytest.approx(world.table.top_z + 0.06, abs=1e-3)
    assert up.an_object == (0.0, 0.0, -1.0) and up.type == "magnet_active" and up.colour == "yellow"
    assert up.as_dict()["pose"] == list(up.pose)


def test_grasp_holds_while_the_arm_moves_and_release_drops(world):
    assert reach(world, (0.6, -0.3, world.table.top_z + 0.15)) < 1e-3
    grip = world.gripper_pose()
    block = make_model("megablok_1x1", "red")
    top = block.feature("top").point[2]
    world.spawn("b", block, (grip[0], grip[1], grip[2] - top, 0, 0, 0))
    assert world.grasp("b")
    assert world.held() == "b" and world.object_state("b").held_by == "right"
    before = relative(world, "b")
    start = world.joint_positions(world.robot.arm("right").joints)
    target = {
        j: v + (0.3 if j in ("right_s0", "right_w2") else -0.15 if j == "right_e1" else 0.0) for j, v in start.items()
    }
    world.set_joint_targets(target)
    world.step(360)
    moved = world.gripper_pose()
    assert np.linalg.norm(np.array(moved[:3]) - np.array(grip[:3])) > 0.05  # the arm really moved
    drift = relative(world, "b")
    assert np.linalg.norm(drift[:3, 3] - before[:3, 3]) < 1e-4
    assert np.allclose(world.grasp_transform(), drift)
    assert world.target_error(list(target)) < 1e-3
    assert world.release() == "b" and world.held() is None
    world.step(480)
    z_rest = world.table.top_z + block.lowest_z(0, 0)
    assert world.object_pose("b")[2] == pytest.approx(z_rest, abs=2e-3)


def test_grasp_refuses_far_objects_and_double_grasps(world):
    world.spawn("far", make_model("megablok_1x1"), (0.6, -0.3, 0, 0, 0, 0), on_table=True)
    assert not world.grasp("far")  # the gripper is at home, high above the table
    assert world.held() is None
    assert world.release() is None


def test_magnetic_attach_joins_only_when_aligned(world):
    active, reference = make_model("magnet_active"), make_model("magnet_reference")
    world.spawn("ref", reference, (0.62, -0.1, 0, 0, 0, 0), on_table=True)
    ref_ap, _ = world.feature("ref")
    # misaligned: magnet 3 cm beside the reference's
    world.spawn("act", active, (ref_ap[0] + 0.03, ref_ap[1], ref_ap[2] + 0.03 + 0.0005, 0, 0, 0))
    world.step(60)
    assert world.attachments() == []
    relation = world.attachment_relation("act", "ref")
    assert relation.distance > 0.01 and not relation.aligned
    # misaligned: right place, magnet facing sideways
    world.move_object("act", (ref_ap[0], ref_ap[1], ref_ap[2] + 0.02 + 0.0005, math.pi / 2, 0, 0))
    world.step(1)
    assert world.attachments() == []
    assert world.attachment_relation("act", "ref").angle == pytest.approx(math.pi / 2, abs=0.05)
    # aligned: points coincide, normals oppose -- join, and a sideways magnet never joined
    world.move_object("act", (ref_ap[0] + 0.002, ref_ap[1], ref_ap[2] + 0.03 + 0.0005, 0, 0, 0.3))
    world.step(1)
    assert world.attachments() == [("act", "ref")]
    assert world.object_state("act").attached_to == ("ref",)
    relation = world.attachment_relation("act", "ref")
    assert relation.aligned and relation.angle == pytest.approx(math.pi, abs=0.01)
    assert world.detach("act", "ref") and world.attachments() == []


def test_magnetic_attach_by_the_arm_lifts_the_reference(world):
    """Carry the active part down onto the reference, then lift: the joined reference comes along (the paper's
    staging-pose verification)."""
    world.spawn("ref", make_model("magnet_reference"), (0.62, -0.1, 0, 0, 0, 0), on_table=True)
    world.step(10)
    ref_ap, _ = world.feature("ref")
    high = (ref_ap[0], ref_ap[1], ref_ap[2] + 0.06 + 0.05)
    assert reach(world, high) < 1e-3
    q_high = world.joint_positions(world.robot.arm("right").joints)
    world.spawn("act", make_model("magnet_active"), (high[0], high[1], high[2] - 0.03, 0, 0, 0))
    assert world.grasp("act")
    end = world.link_index("right_gripper")
    q = pybullet.calculateInverseKinematics(
        world.robot_id,
        end,
        [high[0], high[1], high[2] - 0.049],
        pybullet.getQuaternionFromEuler(DOWN),
        maxNumIterations=300,
        residualThreshold=1e-6,
        physicsClientId=world.client,
    )
    low = dict(zip(world.movable_joints, q, strict=True))
    world.set_joint_targets({j: low[j] for j in world.robot.arm("right").joints})
    world.step(240)
    assert world.attachments() == [("act", "ref")]
    world.set_joint_targets(q_high)
    world.step(240)
    assert world.object_pose("ref")[2] > world.table.top_z + 0.02 + 0.04


def test_bad_requests_raise_simulation_errors(world):
    with pytest.raises(SimulationError, match="no object named 'ghost'"):
        world.object_pose("ghost")
    world.spawn("x", make_model("shaft"), (0.6, -0.3, 0, 0, 0, 0), on_table=True)
    with pytest.raises(SimulationError, match="already exists"):
        world.spawn("x", make_model("shaft"), (0.6, -0.2, 0, 0, 0, 0))
    with pytest.raises(SimulationError, match="6 finite numbers"):
        world.move_object("x", (0.6, -0.3, 0.0))
    with pytest.raises(SimulationError, match="no movable joint 'elbow'"):
        world.set_joint_targets({"elbow": 0.0})
    with pytest.raises(SimulationError, match="visuals"):
        Simulation(visuals="fancy")


def test_same_seed_same_world():
    def run() -> list[tuple[float, ...]]:
        with Simulation(seed=7) as s:
            s.spawn("a", make_model("megablok_1x2"), (0.6, -0.3, -0.1, 0.3, 0.2, 0.1))  # dropped, tumbles
            s.spawn("b", make_model("housing"), (0.6, -0.2, -0.05, 1.0, 0.0, 0.0))
            s.step(300)
            return [s.object_pose("a"), s.object_pose("b")]

    assert run() == run()


def test_own_client_is_closed():
    s = Simulation()
    client = s.client
    s.close()
    s.close()  # idempotent
    assert not pybullet.isConnected(physicsClientId=client)


def move_in_line(sim: Simulation, target, waypoints: int = 8, steps: int = 60) -> float:
    """Drive the right arm along a straight line (pybullet IK per waypoint, pointing down); final error (m)."""
    end = sim.link_index("right_gripper")
    start = np.array(sim.gripper_pose()[:3])
    joints = sim.robot.arm("right").joints
    for k in range(1, waypoints + 1):
        point = start + (np.asarray(target) - start) * k / waypoints
        q = pybullet.calculateInverseKinematics(
            sim.robot_id,
            end,
            list(point),
            pybullet.getQuaternionFromEuler(DOWN),
            maxNumIterations=300,
            residualThreshold=1e-6,
            physicsClientId=sim.client,
        )
        values = dict(zip(sim.movable_joints, q, strict=True))
        sim.set_joint_targets({j: values[j] for j in joints})
        sim.step(steps)
    return float(np.linalg.norm(np.array(sim.gripper_pose()[:3]) - np.asarray(target)))


@pytest.mark.parametrize("variant", [None, "housing_upside_down"])
def test_housing_goes_into_the_board_narrow_end_first_only(world, variant):
    load_scene("housing_insertion").build(world, variant)
    state = world.object_state("housing")
    top = max(point[2] for point, _ in state.features.values())
    x, y = state.pose[:2]
    assert move_in_line(world, (x, y, top + 0.1)) < 1e-3
    assert move_in_line(world, (x, y, top + 0.002)) < 1e-3
    assert world.grasp("housing")
    insert_end, _ = world.feature("housing", "insert_end")
    offset = np.array(world.gripper_pose()[:3]) - insert_end
    hole, _ = world.feature("board")
    move_in_line(world, (x, y, top + 0.15))
    move_in_line(world, hole + offset + (0.0, 0.0, 0.1))
    move_in_line(world, hole + offset + (0.0, 0.0, 0.001), waypoints=10, steps=80)
    insert_end, _ = world.feature("housing", "insert_end")
    if variant is None:
        assert np.linalg.norm(insert_end - hole) < 2e-3  # down at the bottom of the hole
    else:
        assert np.linalg.norm(insert_end - hole) > 0.03  # the flange meets the socket: it never gets in


def test_gripper_fingers_and_robot_contacts(world):
    world.set_gripper("right", "open")
    world.step(120)
    fingers = world.robot.arm("right").gripper
    q = world.joint_positions(fingers.joints)
    assert [q[j] for j in fingers.joints] == pytest.approx(list(fingers.open), abs=1e-3)
    with pytest.raises(SimulationError, match="'open' or 'closed'"):
        world.set_gripper("right", "ajar")
    assert world.robot_contacts() == []
    world.spawn("b", make_model("megablok_1x1"), (0.6, -0.3, 0, 0, 0, 0), on_table=True)
    top = world.object_state("b").features["top"][0]
    assert reach(world, (0.6, -0.3, top[2] - 0.025)) < 1e-3  # open fingertips 2.5 cm into the block
    world.step(1)
    touching = world.robot_contacts()
    assert any(other == "b" for _, other in touching) and all(link.startswith("r_gripper") for link, _ in touching)
    assert world.grasp_transform() is None


def test_a_removed_held_object_leaves_no_collision_hole(world):
    """pybullet reuses body ids: the next object must collide with the hand again."""
    world.spawn("x", make_model("megablok_1x1"), (0.6, -0.3, 0, 0, 0, 0), on_table=True)
    top = world.object_state("x").features["top"][0]
    assert reach(world, (0.6, -0.3, top[2] - 0.025)) < 1e-3
    assert world.grasp("x")
    old_id = world.body_id("x")
    world.remove("x")
    world.spawn("y", make_model("megablok_1x1"), (0.6, -0.3, 0, 0, 0, 0), on_table=True)
    assert world.body_id("y") == old_id  # the id was reused
    world.step(1)
    assert any(other == "y" for _, other in world.robot_contacts())


@pytest.mark.parametrize(("variant", "joins"), [(None, True), ("active_on_side", False), ("active_upside_down", False)])
def test_nominal_magnetic_attach_motion_joins_only_in_the_nominal_scene(world, variant, joins):
    """Replay the nominal gripper motion (top grasp, carry the grasp point 6.2 cm above the reference's magnet):
    it attaches the upright part, and misses with the variant poses (paper, section 7.5, Figure 10)."""
    load_scene("magnetic_attach").build(world, variant)
    state = world.object_state("active")
    top = pybullet.getAABB(world.body_id("active"), physicsClientId=world.client)[1][2]
    x, y = state.pose[:2]
    assert move_in_line(world, (x, y, top + 0.1)) < 1e-3
    assert move_in_line(world, (x, y, top + 0.002)) < 1e-3
    assert world.grasp("active")
    move_in_line(world, (x, y, top + 0.15))
    ref_ap, _ = world.feature("reference")
    move_in_line(world, ref_ap + np.array([0.0, 0.0, 0.15]))
    move_in_line(world, ref_ap + np.array([0.0, 0.0, 0.062]), waypoints=10)
    world.release()
    world.step(120)
    assert (world.attachments() == [("active", "reference")]) is joins


def test_teleporting_the_arm_carries_what_it_holds(world):
    assert reach(world, (0.6, -0.3, world.table.top_z + 0.15)) < 1e-3
    grip = world.gripper_pose()
    world.spawn("ref", make_model("magnet_reference"), (0.6, -0.1, 0, 0, 0, 0), on_table=True)
    world.spawn("act", make_model("magnet_active"), (grip[0], grip[1], grip[2] - 0.03, 0, 0, 0))
    assert world.grasp("act")
    world.move_object("ref", (grip[0], grip[1], grip[2] - 0.06 - 0.02, 0, 0, 0))  # magnets touching
    assert world.try_attach("act", "ref")
    held = world.grasp_transform()
    joined = np.linalg.inv(world.object_transform("act")) @ world.object_transform("ref")
    world.set_joint_positions(world.robot.home)
    assert np.allclose(world.grasp_transform(), held, atol=1e-9)
    assert np.allclose(np.linalg.inv(world.object_transform("act")) @ world.object_transform("ref"), joined, atol=1e-9)
    world.step(60)
    assert np.allclose(world.grasp_transform()[:3, 3], held[:3, 3], atol=2e-4)
    world.home()
    assert world.held() is None
