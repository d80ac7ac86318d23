"""Magnetic joins reach the ROS 2 world's model of the scene: the served simulator's object-pose message carries
them (one LINE_LIST marker per join) and the world's model joins and lets go as told. No ROS process: the messages
go from the publisher's builder straight into the subscriber's callback (the message packages are needed)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("visualization_msgs.msg", reason="needs the [ros2] extra: pip install 'bt-meta[ros2]'")

from bt_meta.htn import load_task_file
from bt_meta.resources import shipped_tree
from bt_meta.ros2.config import default_config
from bt_meta.ros2.robot_state import RobotState
from bt_meta.ros2.state_publishers import JOIN_NAMESPACE, StatePublishers
from bt_meta.ros2.world import RosWorld
from bt_meta.world.poses import matrix_to_pose
from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout


class _Node:
    """Stands in for an rclpy node: keeps what is published, ignores subscriptions."""

    def __init__(self) -> None:
        self.sent: dict[str, list] = {}

    def create_publisher(self, _type, topic, _depth):
        return SimpleNamespace(publish=lambda message: self.sent.setdefault(topic, []).append(message))

    def create_subscription(self, *_args, **_kwargs):
        return None


def _world() -> SimWorld:
    task_file = load_task_file(shipped_tree("magnetic_attach.yaml"))
    with quiet_stdout():
        return SimWorld(task_file.domain, task_file.problem("nominal"), load_grounding("magnetic_attach"))


def _put_active_on_reference(sim) -> None:
    """The active part's magnet (bottom face) on the reference's (top face): the attach rule holds."""
    pose = sim.object_transform("reference").copy()
    pose[2, 3] += 0.02 + 0.03  # the reference's half height + the active part's
    sim.move_object("active", matrix_to_pose(pose))


@pytest.fixture
def served_and_model():
    served, model = _world(), _world()
    yield served, model
    served.close()
    model.close()


def _deliver(served, model) -> RobotState:
    """Publish the served state, feed it to a RobotState, and set the model to it as the world does."""
    config = default_config(served.sim.robot)
    node = _Node()
    StatePublishers(node, served.sim, config).publish()
    state = RobotState(_Node(), config)
    state._on_joints(node.sent[config.joint_states][-1])
    state._on_objects(node.sent[config.object_poses][-1])
    RosWorld._sync(SimpleNamespace(sim=model.sim, connection=SimpleNamespace(state=state)))
    return state


def test_a_join_in_the_served_physics_reaches_the_model_and_so_does_letting_go(served_and_model):
    served, model = served_and_model
    _put_active_on_reference(served.sim)
    assert served.sim.try_attach("active", "reference")

    state = _deliver(served, model)
    assert state.joins() == {("active", "reference")}
    assert model.sim.attachments() == [("active", "reference")]
    assert model.sim.object_state("active").attached_to == ("reference",)
    assert np.allclose(model.sim.object_transform("active"), served.sim.object_transform("active"), atol=1e-9)

    assert served.sim.detach("active", "reference")
    assert _deliver(served, model).joins() == set()
    assert model.sim.attachments() == []


def test_join_markers_are_line_lists_between_the_joined_objects(served_and_model):
    served, _ = served_and_model
    _put_active_on_reference(served.sim)
    served.sim.try_attach("active", "reference")
    config = default_config(served.sim.robot)
    node = _Node()
    StatePublishers(node, served.sim, config).publish()
    markers = node.sent[config.object_poses][-1].markers
    joins = [m for m in markers if m.ns == JOIN_NAMESPACE]
    assert len(joins) == 1 and joins[0].type == joins[0].LINE_LIST
    assert joins[0].text.split("\n") == ["active", "reference"]
    ends = [[p.x, p.y, p.z] for p in joins[0].points]
    assert np.allclose(ends, [served.sim.object_transform(n)[:3, 3] for n in ("active", "reference")])
    assert sorted(m.ns for m in markers if m.type == m.CUBE) == sorted(served.sim.object_names())
