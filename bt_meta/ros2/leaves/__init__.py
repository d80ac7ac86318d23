"""ROS leaves in tree XML: BehaviorTree.ROS2's action, service, topic-subscriber and topic-publisher nodes, with
its port names and defaults, declared in YAML or Python instead of C++ (docs/ros2.md, "ROS leaves in tree XML").

Offers (one concept per module):

* :mod:`~bt_meta.ros2.leaves.registration` -- :func:`load_leaves_file` (``ros2_leaves:`` YAML), :func:`ros_leaf`
  (Python), the node types they make
* :mod:`~bt_meta.ros2.leaves.fields` -- interface types by name, field paths and the port types they carry
* :mod:`~bt_meta.ros2.leaves.runtime` -- the process's shared rclpy node and executor thread
* :mod:`~bt_meta.ros2.leaves.base` -- what every leaf does (ports, outputs, ``success_if``, failures)
* :mod:`~bt_meta.ros2.leaves.action`, :mod:`~bt_meta.ros2.leaves.service`,
  :mod:`~bt_meta.ros2.leaves.subscriber`, :mod:`~bt_meta.ros2.leaves.publisher` -- one leaf kind each
"""

from __future__ import annotations

from bt_meta.ros2.leaves.registration import load_leaves_file, ros_leaf

__all__ = ["load_leaves_file", "ros_leaf"]
