"""ROS 2: the simulator served over ROS 2 and a world that acts through ROS 2 (``pip install 'bt-meta[ros2]'``).

The same skills, monitors, memory and repairs drive a robot reached through ros2_control's interfaces
(``control_msgs/action/FollowJointTrajectory``, ``GripperCommand``, ``/joint_states``); IK, collision checks and
the model of the scene stay in-process. See docs/ros2.md.

Offers (one concept per module):

* :mod:`~bt_meta.ros2.errors` -- the typed errors (extra missing, server unreachable, connection lost)
* :mod:`~bt_meta.ros2.environment` -- localhost-only discovery by default, rclpy imported only here
* :mod:`~bt_meta.ros2.interfaces` -- control_msgs generated from the kept Jazzy definitions at first use
* :mod:`~bt_meta.ros2.config` -- the config YAML (controllers, joints, topics, frames) and its defaults
* :mod:`~bt_meta.ros2.messages` -- conversions between messages and numbers (stamps, poses, trajectories)
* :mod:`~bt_meta.ros2.trajectory_server` / :mod:`~bt_meta.ros2.gripper_server` -- the served simulator's action
  servers; :mod:`~bt_meta.ros2.state_publishers` / :mod:`~bt_meta.ros2.camera_publisher` -- its publishers;
  :mod:`~bt_meta.ros2.sim_server` -- the node that owns the simulation and ties them together
* :mod:`~bt_meta.ros2.action_clients` -- goals with timeouts, cancelled on the way out
* :mod:`~bt_meta.ros2.robot_state` -- the latest joint states and object poses, waited for by stamp
* :mod:`~bt_meta.ros2.world` -- :class:`~bt_meta.ros2.world.RosWorld`, the World acting through ROS 2
* :mod:`~bt_meta.ros2.mcap_recording` -- the run's ROS 2 messages as MCAP (``--record-mcap``)
* :mod:`~bt_meta.ros2.leaves` -- BehaviorTree.ROS2's action, service and topic leaves in tree XML
  (``--ros2-leaves``), one module per kind
"""
