"""The behaviour class of each leaf kind (one module per kind, as in BehaviorTree.ROS2 and py_trees_ros)."""

from __future__ import annotations

from bt_meta.ros2.leaves.action import RosActionLeaf
from bt_meta.ros2.leaves.publisher import RosPublisherLeaf
from bt_meta.ros2.leaves.service import RosServiceLeaf
from bt_meta.ros2.leaves.subscriber import RosSubscriberLeaf

__all__ = ["LEAF_CLASSES"]

LEAF_CLASSES = {"action": RosActionLeaf, "service": RosServiceLeaf, "topic_sub": RosSubscriberLeaf,
                "topic_pub": RosPublisherLeaf}
