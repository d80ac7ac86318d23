"""The served simulator's ``control_msgs/action/GripperCommand`` servers, one per arm with a gripper.

``command.position`` is the finger gap (m): at or below :data:`CLOSED` the gripper closes -- it holds the nearest
object within reach as the in-process world's grasp does (:meth:`~bt_meta.world.simulation.sim.Simulation.grasp`:
by a constraint, or by the fingers' friction where the robot's gripper says so) and reports ``stalled`` (closed on
something) or ``reached_goal`` (closed on nothing); above it, the gripper lets go of what it holds.

Offers:

* :class:`GripperServer` -- the action server of one arm's gripper
* :data:`CLOSED` -- the largest gap that counts as a close command
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["CLOSED", "GripperServer"]

CLOSED = 1e-3


class GripperServer:
    def __init__(self, node: Any, server: Any, arm: str, action: str, reach: float) -> None:
        from control_msgs.action import GripperCommand
        from rclpy.action import ActionServer

        self.server = server
        self.arm = arm
        self.reach = reach
        self.handle = ActionServer(node, GripperCommand, action, execute_callback=self.execute)

    def execute(self, handle: Any) -> Any:
        from control_msgs.action import GripperCommand

        sim = self.server.sim
        gripper = sim.robot.arm(self.arm).gripper
        opening = float(gripper.opening) if gripper is not None else 0.0
        wanted = float(handle.request.command.position)
        held = sim.held(self.arm)
        if wanted <= CLOSED:
            if held is None:
                held = self._close()
            result = GripperCommand.Result(position=0.0 if held is None else opening, stalled=held is not None,
                                           reached_goal=held is None)
        else:
            if held is not None:
                sim.release(self.arm)
            result = GripperCommand.Result(position=opening, stalled=False, reached_goal=True)
        self.server.publishers.publish()
        handle.succeed()
        return result

    def _close(self) -> str | None:
        sim = self.server.sim
        gripper = sim.link_transform(sim.robot.arm(self.arm).end_effector)[:3, 3]
        held = {sim.held(arm) for arm in sim.robot.arms}
        names = [n for n in sim.object_names() if n not in held]
        for name in sorted(names, key=lambda n: float(np.linalg.norm(sim.object_transform(n)[:3, 3] - gripper))):
            if sim.grasp(name, self.arm, max_distance=self.reach):
                return name
        return None
