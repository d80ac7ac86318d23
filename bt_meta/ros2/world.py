"""RosWorld: the World of a task-file problem acting on a robot through ROS 2 (``bt-meta run --world ros2``).

The narrowest seam: skills act on a world through a few methods that move the robot -- ``drive_arm`` (the next
joint targets of an arm), ``advance`` (let a tick pass), ``grasp`` and ``release`` -- and read the world through its
model of the scene (``world.sim``: object and link poses, contacts, shapes). A RosWorld is a
:class:`~bt_meta.world.simulation.sim_world.SimWorld` whose simulation is only that model, never stepped: the
moving methods go through ROS 2, and after each the model is set to the state the robot reports (joint states,
object poses, magnetic joins). So IK (mink), collision checks (coal, against the model of the scene), path
planning, perception and every skill, monitor and repair run in-process exactly as in the simulator.

* ``advance``: one ``FollowJointTrajectory`` goal per tick on the arm's controller, its point the arm's latest
  target one tick ahead (the controller holds it: the other arms keep theirs); then the world waits for joint
  states and object poses stamped at least a tick later than before, and copies them into the model.
* ``grasp``: the model says whether the object is within reach (as in-process); then ``GripperCommand`` closes
  the gripper and the grasp holds only if the gripper reports it closed on something (``stalled``).
* ``release``: ``GripperCommand`` opens it.

A goal rejected or aborted fails the skill (``physical``; evidence: action, ``error_code``, ``error_string``); a
result or state that does not come within the config's result timeout is a lost connection: the running goals are
cancelled and every later skill fails at once, so the run stops within that bound (and a failed run stores no
trace). With ``record_mcap`` the states received and the goals sent are written as MCAP
(:mod:`~bt_meta.ros2.mcap_recording`), with the camera frames perception used. Perception looks through the
robot's camera (``top_camera``, :mod:`~bt_meta.ros2.camera_subscriber`): a frame stamped after the last motion, not a
render of the model. What stays in-process, and why, is in docs/ros2.md.

Offers:

* :class:`RosWorld` -- the world
* :func:`bt_meta_make_world` -- hook implementation for ``--world ros2``
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pybullet

from bt_meta.bt.failures import FailureKind
from bt_meta.hookspecs import hookimpl
from bt_meta.ros2.action_clients import GoalFailed
from bt_meta.ros2.errors import ConnectionLost, ServerUnavailable
from bt_meta.world.poses import matrix_to_pose
from bt_meta.world.simulation.sim_world import SimWorld
from bt_meta.world.skills.base import SkillAbort

__all__ = ["START_TOLERANCE", "SYNC_TOLERANCE", "RosWorld", "bt_meta_make_world"]

START_TOLERANCE = 0.01
"""rad (or m): how far a joint may be from the grounding's start pose when the run starts."""
SYNC_TOLERANCE = 1e-9
"""Largest difference of a reported object pose (transform entries: m, rotation) still taken as the model's own."""
_GRIPPER_EFFORT = 50.0


class RosWorld(SimWorld):
    """A :class:`SimWorld` whose moves go through ROS 2 (see the module docstring)."""

    def __init__(self, domain: Any, problem: Any, grounding: Any, *, ros2_config: str | Path | None = None,
                 record_mcap: str | Path | None = None, **options: Any) -> None:
        from bt_meta.ros2.config import load_config
        from bt_meta.ros2.connection import Connection

        options.pop("gui", None)
        options.pop("realtime", None)
        super().__init__(domain, problem, grounding, **options)
        self.connection: Any = None
        self.recording: Any = None
        try:
            self.config = load_config(ros2_config, self.sim.robot)
            self._commanded = {arm: np.array([self.sim.joint_positions()[j] for j in spec.joints])
                               for arm, spec in self.config.arms.items()}
            self._driven = self.default_arm
            self._lost: str | None = None
            self._warned_feedback = False
            self.connection = Connection(self.config)
            if record_mcap is not None:
                from bt_meta.ros2.mcap_recording import McapRecording

                self.recording = McapRecording(record_mcap)
                self.connection.record(self.recording.write)
            self.connection.open()
            self._check_start()
            self._sync()
            from bt_meta.ros2.camera_subscriber import RosTopViewCamera

            self.top_camera = RosTopViewCamera(self, self.connection.camera)
            """What the camera perception plugin looks through: the robot's camera topics, not the model."""
        except BaseException:
            self.close()
            raise

    # -- the moving methods -------------------------------------------------------------------------------------

    def drive_arm(self, arm: str, values: np.ndarray) -> None:
        self._alive()
        spec = self.config.arms[arm]
        model = self.sim.robot.arm(arm).joints
        by_name = dict(zip(model, (float(v) for v in values), strict=True))
        self._commanded[arm] = np.array([by_name[j] for j in spec.joints])
        self._driven = arm

    def advance(self, ticks: int = 1) -> None:
        arm = self._driven
        client = self.connection.trajectory[arm]
        step_ns = round(self.tick_seconds * 1e9)
        for _ in range(ticks):
            self._alive()
            before = self.connection.state.stamp()
            try:
                client.follow([(self._commanded[arm], self.tick_seconds)], self.config.result_timeout)
            except GoalFailed as failure:
                raise SkillAbort(FailureKind.PHYSICAL, f"the robot refused a motion: {failure}",
                                 {"action": failure.action, "error_code": failure.code,
                                  "error_string": failure.text, "rejected": failure.code is None}) from None
            except ConnectionLost as lost:
                self._lose(str(lost))
            self._await_state(before + step_ns - round(self.sim.time_step * 0.5e9))
            self.total_ticks += 1
        if client.feedback_missing() and not self._warned_feedback:
            self._warned_feedback = True
            print(f"bt-meta: warning: {client.action}: {client.succeeded} goals succeeded without any feedback -- "
                  "the likely cause is control_msgs definitions of another ROS 2 distro than the robot's "
                  "(docs/ros2.md)", file=sys.stderr)

    def grasp(self, name: str, arm: str, reach: float) -> bool:
        self._alive()
        if not super().grasp(name, arm, reach):  # not within reach in the model: nothing is sent, as in-process
            return False
        before = self.connection.state.stamp()
        result = self._gripper(arm, 0.0)
        if not result.stalled:  # closed on nothing
            super().release(arm)
            self._await_state(before)
            return False
        self._await_state(before)
        return True

    def release(self, arm: str) -> str | None:
        self._alive()
        if self.sim.held(arm) is None:
            return None
        gripper = self.sim.robot.arm(arm).gripper
        before = self.connection.state.stamp()
        self._gripper(arm, float(gripper.opening) if gripper is not None else 1.0)
        name = super().release(arm)
        self._await_state(before)
        return name

    # -- internals ----------------------------------------------------------------------------------------------

    def _gripper(self, arm: str, position: float) -> Any:
        client = self.connection.gripper.get(arm)
        if client is None:
            raise SkillAbort(FailureKind.INTERNAL, f"the ROS 2 config gives the {arm} arm no gripper_action")
        try:
            return client.command(position, _GRIPPER_EFFORT, self.config.result_timeout)
        except GoalFailed as failure:
            raise SkillAbort(FailureKind.PHYSICAL, f"the gripper refused: {failure}",
                             {"action": failure.action, "error_code": failure.code}) from None
        except ConnectionLost as lost:
            self._lose(str(lost))

    def _await_state(self, stamp: int) -> None:
        if not self.connection.state.wait_until(stamp, self.config.result_timeout):
            self._lose(f"no {self.config.joint_states} / {self.config.object_poses} stamped after the last goal "
                       f"within {self.config.result_timeout:g} s")
        self._sync()

    def _lose(self, why: str) -> None:
        self._lost = f"{why} (after {self.total_ticks} ticks)"
        self.connection.cancel_all()
        raise ConnectionLost(f"lost the robot: {self._lost}")

    def _alive(self) -> None:
        if self._lost is not None:
            raise ConnectionLost(f"lost the robot earlier: {self._lost}")

    def _check_start(self) -> None:
        """The robot must stand in the grounding's start pose: a run never moves it there unasked."""
        measured = self.connection.state.joints()
        expected = self.sim.joint_positions()
        missing = sorted(set(expected) - set(measured))
        if missing:
            raise ServerUnavailable(f"{self.config.joint_states} lacks joints of robot {self.sim.robot.name!r}: "
                                    f"{', '.join(missing)}", self.config.path or "--ros2")
        off = {name: (measured[name], value) for name, value in expected.items()
               if abs(measured[name] - value) > START_TOLERANCE}
        if off:
            shown = ", ".join(f"{n} is {m:.3f}, expected {e:.3f}" for n, (m, e) in sorted(off.items()))
            raise ServerUnavailable(f"the robot is not in the start pose of the grounding file: {shown}; move it "
                                    "there first (sim serve: --joint NAME=VALUE)", self.grounding.path)

    def _sync(self) -> None:
        """Set the model of the scene to the state the robot reported."""
        measured = self.connection.state.joints()
        sim = self.sim
        sim.set_joint_positions({n: v for n, v in measured.items() if n in sim.robot.home})
        names = set(sim.object_names())
        for name, pose in self.connection.state.objects().items():
            # only a real move: re-applying a pose that differs by the messages' float noise resets the body
            if name in names and np.abs(sim.object_transform(name) - pose).max() > SYNC_TOLERANCE:
                sim.move_object(name, matrix_to_pose(pose))
        # the joins the robot reports (the model is never stepped, so it never joins anything itself): after the
        # poses, so a new join holds the objects as they now stand
        reported = {pair for pair in self.connection.state.joins() if set(pair) <= names}
        known = set(sim.attachments())
        for first, second in sorted(known - reported):
            sim.detach(first, second)
        for first, second in sorted(reported - known):
            sim.join(first, second)
        pybullet.performCollisionDetection(physicsClientId=sim.client)

    def observe(self) -> dict[str, Any]:
        self._alive()
        return super().observe()

    def close(self) -> None:
        try:
            if self.connection is not None:
                self.connection.close()
                self.connection = None
        finally:
            try:
                if self.recording is not None:  # after the connection: no message arrives any more
                    self.recording.close()
            finally:
                super().close()


@hookimpl
def bt_meta_make_world(name: str, domain: Any, problem: Any, options: dict[str, Any]) -> RosWorld | None:
    if name != "ros2":
        return None
    from bt_meta.world.simulation.sim_world import load_grounding

    grounding = load_grounding(domain.name, options.get("task_file"), options.get("grounding"))
    return RosWorld(domain, problem, grounding, ros2_config=options.get("ros2"), variant=options.get("variant"),
                    seed=int(options.get("seed", 0)), robot=options.get("robot"), scene=options.get("scene"))
