"""The served simulator's camera: ``sensor_msgs/Image`` (rgb8) and ``sensor_msgs/CameraInfo`` of the fixed top
view over the table, rendered only while someone subscribes (a render costs 14-20 ms).

Offers:

* :class:`CameraPublisher` -- ``publish()`` renders and sends one frame when the image topic has subscribers
"""

from __future__ import annotations

from typing import Any

from bt_meta.ros2.messages import to_stamp

__all__ = ["FRAME", "CameraPublisher"]

FRAME = "top_view_camera_optical"
"""frame_id of the images: the top view's optical frame (x right, y down, z forward), posed over the table."""


class CameraPublisher:
    def __init__(self, node: Any, sim: Any, config: Any) -> None:
        from sensor_msgs.msg import CameraInfo, Image

        from bt_meta.world.simulation.camera import TopViewCamera

        self.sim = sim
        self.camera = TopViewCamera(sim)
        self.image = node.create_publisher(Image, config.camera_image, 2)
        self.info = node.create_publisher(CameraInfo, config.camera_info, 2)

    def publish(self) -> bool:
        if self.image.get_subscription_count() == 0 and self.info.get_subscription_count() == 0:
            return False
        from sensor_msgs.msg import CameraInfo, Image
        from std_msgs.msg import Header

        frame = self.camera.capture(depth=False, segmentation=False)
        header = Header(stamp=to_stamp(self.sim.steps * self.sim.time_step), frame_id=FRAME)
        height, width = frame.rgb.shape[:2]
        self.image.publish(Image(header=header, height=height, width=width, encoding="rgb8", is_bigendian=0,
                                 step=3 * width, data=frame.rgb.astype("uint8").tobytes()))
        k = frame.intrinsics.matrix()
        info = CameraInfo(header=header, height=height, width=width, distortion_model="plumb_bob",
                          d=[0.0] * 5, k=[float(v) for v in k.ravel()],
                          r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                          p=[float(k[0, 0]), 0.0, float(k[0, 2]), 0.0, 0.0, float(k[1, 1]), float(k[1, 2]), 0.0,
                             0.0, 0.0, 1.0, 0.0])
        self.info.publish(info)
        return True
