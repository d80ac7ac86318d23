"""The simulator served over ROS 2 (``bt-meta sim serve --ros2``): the pybullet simulation of a robot and a scene
behind the interfaces a ros2_control robot offers, so the ROS 2 world can be proven against it.

It builds the scene as the in-process world does (same robot, home pose and start joints, scene, variant, seed:
the same objects at the same poses), then serves one FollowJointTrajectory per arm controller and one
GripperCommand per gripper (:mod:`~bt_meta.ros2.trajectory_server`, :mod:`~bt_meta.ros2.gripper_server`),
publishes ``/joint_states`` and the ground-truth object poses after every executed point and at
``state_rate`` Hz (:mod:`~bt_meta.ros2.state_publishers`), and the top-view camera (checked at ``camera_rate`` Hz) while
subscribed (:mod:`~bt_meta.ros2.camera_publisher`). Everything runs on one thread (the physics is not shared).
SIGINT and SIGTERM end the spin between two callbacks (within 0.1 s of the last); the node and the simulation
are closed and :meth:`SimServer.serve` returns.

Offers:

* :class:`Faults` -- ``--fault`` specs: ``reject@N`` / ``abort@N[:CODE]`` for the N-th trajectory goal,
  ``no-feedback`` for trajectory goals that succeed without feedback (what mismatched definitions look like)
* :class:`SimServer` -- ``serve()`` until a signal
"""

from __future__ import annotations

import re
import signal
import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from bt_meta.errors import UserInputError

__all__ = ["Faults", "SimServer"]

_FAULT = re.compile(r"^(reject|abort)@([1-9][0-9]*)(?::(-?[0-9]+))?$")


@dataclass
class Faults:
    """Goal numbers (1-based, over every trajectory goal) -> ``"reject"`` or ``"abort:CODE"``: how the fault tests
    make a controller refuse or give up, which a healthy simulation never does."""

    trajectory: dict[int, str] = field(default_factory=dict)
    no_feedback: bool = False
    """Trajectory goals succeed but never send feedback: the client sees what a definitions mismatch shows."""

    @classmethod
    def parse(cls, specs: Iterable[str]) -> Faults:
        out = cls()
        for spec in specs:
            if spec == "no-feedback":
                out.no_feedback = True
                continue
            match = _FAULT.match(spec)
            if match is None:
                raise UserInputError(f"bad --fault {spec!r}: expected reject@N, abort@N[:CODE] or no-feedback",
                                     "--fault")
            kind, number, code = match.groups()
            out.trajectory[int(number)] = kind if code is None else f"{kind}:{code}"
        return out

    def trajectory_fault(self, number: int) -> str | None:
        return self.trajectory.get(number)


class SimServer:
    def __init__(self, robot: Any, scene: Any, *, variant: str | None = None, seed: int = 0,
                 start: Mapping[str, float] | None = None, config: Any = None, faults: Faults | None = None,
                 state_rate: float = 20.0, camera_rate: float = 20.0, reach: float = 0.03,
                 node_name: str = "bt_meta_sim") -> None:
        from bt_meta.ros2.config import default_config
        from bt_meta.world.simulation.sim import Simulation
        from bt_meta.world.simulation.sim_world import quiet_stdout

        self.config = config or default_config(robot)
        self.faults = faults or Faults()
        unknown = sorted(set(start or {}) - set(robot.home))
        if unknown:
            raise UserInputError(f"robot {robot.name!r} has no joints {', '.join(unknown)}", "--joint")
        with quiet_stdout():
            self.sim = Simulation(seed=seed, visuals="light", robot=robot)
        try:
            self.sim.set_joint_positions({**robot.home, **(start or {})})
            scene.build(self.sim, None if variant in (None, "nominal") else variant, seed=seed)
        except BaseException:
            self.sim.close()
            raise
        self.state_rate = state_rate
        self.camera_rate = camera_rate
        self.reach = reach
        self.node_name = node_name
        self._goals = 0

    # -- what the servers share ---------------------------------------------------------------------------------

    def trajectory_goals(self) -> int:
        return self._goals

    def count_goal(self) -> int:
        self._goals += 1
        return self._goals

    def drive(self, targets: Mapping[str, float], steps: int) -> None:
        """Motor targets, then ``steps`` physics steps, then the state topics."""
        self.sim.set_joint_targets(targets)
        if steps > 0:
            self.sim.step(steps)
        self.publishers.publish()

    # -- running ------------------------------------------------------------------------------------------------

    def serve(self, ready: Any = None) -> None:
        """Spin until SIGINT or SIGTERM (or ``rclpy`` shut down); ``ready()`` is called once everything is up."""
        from bt_meta.ros2.environment import import_rclpy
        from bt_meta.ros2.interfaces import load_control_msgs

        rclpy = import_rclpy()
        load_control_msgs()
        from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

        from bt_meta.ros2.camera_publisher import CameraPublisher
        from bt_meta.ros2.gripper_server import GripperServer
        from bt_meta.ros2.state_publishers import StatePublishers
        from bt_meta.ros2.trajectory_server import TrajectoryServer

        context = rclpy.Context()
        # SIGINT and SIGTERM only ask to stop: the spin below ends between two callbacks and the context is shut
        # down after it. Shutting it down in the handler broke the callback it interrupted (a publish on a shut
        # context raises RCLError: exit 1 instead of 0). rclpy's own handlers are not installed.
        from rclpy.signals import SignalHandlerOptions

        stop = threading.Event()
        previous = {signum: signal.signal(signum, lambda _signum, _frame: stop.set())
                    for signum in (signal.SIGINT, signal.SIGTERM)}
        rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node(self.node_name, context=context)
        executor = SingleThreadedExecutor(context=context)
        try:
            self.publishers = StatePublishers(node, self.sim, self.config)
            self.camera = CameraPublisher(node, self.sim, self.config)
            self.servers = []
            for name, arm in self.config.arms.items():
                self.servers.append(TrajectoryServer(node, self, arm, self.config.trajectory_action(name)))
                if arm.gripper_action is not None:
                    self.servers.append(GripperServer(node, self, name, arm.gripper_action, self.reach))
            node.create_timer(1.0 / self.state_rate, self.publishers.publish)
            if self.camera_rate > 0:
                node.create_timer(1.0 / self.camera_rate, self.camera.publish)
            self.publishers.publish()
            executor.add_node(node)
            if ready is not None:
                ready()
            try:
                while not stop.is_set() and context.ok():
                    executor.spin_once(timeout_sec=0.1)
            except (KeyboardInterrupt, ExternalShutdownException):
                pass
        finally:
            for server in getattr(self, "servers", []):
                server.handle.destroy()
            executor.shutdown()
            node.destroy_node()
            if context.ok():
                context.try_shutdown()
            for signum, handler in previous.items():
                signal.signal(signum, handler)
            self.sim.close()
