"""The served simulator's state topics: ``sensor_msgs/JointState`` on ``/joint_states`` and the ground-truth object
poses (simulation only) as ``visualization_msgs/MarkerArray``, both stamped with the simulation's clock.

One marker per object: ``ns`` is the object's name, ``pose`` its pose in the base frame, ``scale`` its bounding
box, type CUBE (RViz and Foxglove show them). A perception node on a robot publishes the same message. Then one
marker per magnetic join (:data:`JOIN_NAMESPACE`): a LINE_LIST from one joined object to the other, ``text`` the
two names on two lines -- the message is the whole state, so a join that is not in it does not exist (the world's
model of the scene learns the joins from it, :mod:`bt_meta.ros2.robot_state`).

Offers:

* :class:`StatePublishers` -- ``publish()`` sends both with the current simulation time
* :data:`JOIN_NAMESPACE` -- the ``ns`` of the join markers
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bt_meta.ros2.messages import pose_message, to_stamp

__all__ = ["JOIN_NAMESPACE", "StatePublishers"]

JOIN_NAMESPACE = "bt_meta/joined"
"""``ns`` of a join marker (a LINE_LIST: told apart from an object's CUBE marker by its type too)."""


class StatePublishers:
    def __init__(self, node: Any, sim: Any, config: Any) -> None:
        from sensor_msgs.msg import JointState
        from visualization_msgs.msg import MarkerArray

        self.node = node
        self.sim = sim
        self.config = config
        self.joints = node.create_publisher(JointState, config.joint_states, 10)
        self.objects = node.create_publisher(MarkerArray, config.object_poses, 10)

    def stamp(self) -> Any:
        return to_stamp(self.sim.steps * self.sim.time_step)

    def publish(self) -> None:
        from geometry_msgs.msg import Point
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Header
        from visualization_msgs.msg import Marker, MarkerArray

        header = Header(stamp=self.stamp(), frame_id=self.config.base_frame)
        positions = self.sim.joint_positions()
        self.joints.publish(JointState(header=header, name=list(positions),
                                       position=[float(v) for v in positions.values()]))
        markers = []
        for index, name in enumerate(self.sim.object_names()):
            low, high = self.sim.object_model(name).extent()
            marker = Marker(header=header, ns=name, id=index, type=Marker.CUBE, action=Marker.ADD,
                            pose=pose_message(self.sim.object_transform(name)))
            marker.scale.x, marker.scale.y, marker.scale.z = (float(v) for v in (high - low))
            marker.color.r, marker.color.g, marker.color.b, marker.color.a = 0.8, 0.8, 0.8, 1.0
            markers.append(marker)
        for index, (first, second) in enumerate(self.sim.attachments()):
            marker = Marker(header=header, ns=JOIN_NAMESPACE, id=index, type=Marker.LINE_LIST, action=Marker.ADD,
                            text=f"{first}\n{second}", pose=pose_message(np.eye(4)),
                            points=[Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))
                                    for p in (self.sim.object_transform(n)[:3, 3] for n in (first, second))])
            marker.scale.x = 0.005  # line width
            marker.color.r, marker.color.g, marker.color.b, marker.color.a = 1.0, 0.6, 0.0, 1.0
            markers.append(marker)
        self.objects.publish(MarkerArray(markers=markers))
