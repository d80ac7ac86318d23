"""The served simulator's camera: ``sensor_msgs/Image`` (rgb8), its depth (32FC1, metres along the optical axis)
and ``sensor_msgs/CameraInfo`` of the fixed top view over the table, rendered only while someone subscribes (a
render costs 14-20 ms).

A frame is rendered once the simulation has moved since the last one and then rested for a timer period (no
goal ran in between: the world is waiting, e.g. for a frame taken after its last motion), and otherwise once a
second (a late subscriber's first frame); never during a run of goals (a render would delay each) and never twice
for the same state in between.

Offers:

* :class:`CameraPublisher` -- ``publish()`` renders and sends one frame when a camera topic has subscribers
"""

from __future__ import annotations

import time
from typing import Any

from bt_meta.ros2.messages import to_stamp

__all__ = ["FRAME", "REPEAT_SECONDS", "CameraPublisher"]

FRAME = "top_view_camera_optical"
"""frame_id of the images: the top view's optical frame (x right, y down, z forward), posed over the table."""
REPEAT_SECONDS = 1.0
"""A frame of an unchanged state is sent again after this long (wall clock)."""


class CameraPublisher:
    def __init__(self, node: Any, sim: Any, config: Any) -> None:
        from sensor_msgs.msg import CameraInfo, Image

        from bt_meta.world.simulation.camera import TopViewCamera

        self.sim = sim
        self.camera = TopViewCamera(sim)
        self.image = node.create_publisher(Image, config.camera_image, 2)
        self.info = node.create_publisher(CameraInfo, config.camera_info, 2)
        self.depth = node.create_publisher(Image, config.camera_depth, 2)
        self._last: tuple[int, float] | None = None  # (sim steps, wall time) of the last frame sent
        self._seen = -1  # sim steps at the last check

    def publish(self) -> bool:
        publishers = (self.image, self.info, self.depth)
        if all(p.get_subscription_count() == 0 for p in publishers):
            return False
        now = time.monotonic()
        steps = self.sim.steps
        if steps != self._seen:  # moved since the last check: wait until it rests (the next check)
            self._seen = steps
            if self._last is not None:
                return False
        if self._last is not None and self._last[0] == steps and now - self._last[1] < REPEAT_SECONDS:
            return False
        from sensor_msgs.msg import CameraInfo, Image
        from std_msgs.msg import Header

        with_depth = self.depth.get_subscription_count() > 0
        frame = self.camera.capture(depth=with_depth, segmentation=False)
        self._last = (self.sim.steps, now)
        header = Header(stamp=to_stamp(self.sim.steps * self.sim.time_step), frame_id=FRAME)
        height, width = frame.rgb.shape[:2]
        k = frame.intrinsics.matrix()
        info = CameraInfo(header=header, height=height, width=width, distortion_model="plumb_bob",
                          d=[0.0] * 5, k=[float(v) for v in k.ravel()],
                          r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                          p=[float(k[0, 0]), 0.0, float(k[0, 2]), 0.0, 0.0, float(k[1, 1]), float(k[1, 2]), 0.0,
                             0.0, 0.0, 1.0, 0.0])
        # info and depth before the image: a reader that waits for the image finds the others of its stamp
        self.info.publish(info)
        if frame.depth is not None:
            self.depth.publish(Image(header=header, height=height, width=width, encoding="32FC1",
                                     is_bigendian=0, step=4 * width,
                                     data=frame.depth.astype("<f4").tobytes()))
        self.image.publish(Image(header=header, height=height, width=width, encoding="rgb8", is_bigendian=0,
                                 step=3 * width, data=frame.rgb.astype("uint8").tobytes()))
        return True
