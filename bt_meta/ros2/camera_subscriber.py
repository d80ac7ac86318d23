"""The ROS 2 world's camera: the top view from ``sensor_msgs/Image`` + ``CameraInfo`` (+ a depth image), handed to
the perception plugins as the same :class:`~bt_meta.world.simulation.camera.CameraImage` the in-process camera
renders.

:class:`RosTopViewCamera` is a :class:`~bt_meta.world.simulation.camera.TopViewCamera` of the world's model (so the
geometry -- pixel to table, metric crops -- is the same code) whose ``capture`` does not render: it waits for a frame
stamped at or after the robot state the world last synced to (the state after the last motion goal), takes the
intrinsics from its ``CameraInfo`` and the pose from the top view's placement over the table (the served
simulator's camera; docs/ros2.md). No frame in time is a :class:`~bt_meta.ros2.errors.ConnectionLost` naming the
topic that is missing. ROS carries no segmentation: asking for one is an error saying so.

Offers:

* :class:`CameraFrames` -- the subscriptions: the latest image, depth and info, ``wait(stamp, timeout, depth)``
* :class:`RosTopViewCamera` -- ``capture(depth, segmentation)`` from the frames
* :func:`decode_image` -- a ``sensor_msgs/Image`` as a numpy array (rgb8/bgr8/rgba8/bgra8/mono8, 32FC1, 16UC1)
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from bt_meta.ros2.errors import ConnectionLost
from bt_meta.ros2.messages import nanoseconds
from bt_meta.world.simulation.camera import CameraImage, Intrinsics, TopViewCamera

__all__ = ["CameraFrames", "RosTopViewCamera", "decode_image"]

_COLOUR = {"rgb8": (3, (0, 1, 2)), "bgr8": (3, (2, 1, 0)), "rgba8": (4, (0, 1, 2)), "bgra8": (4, (2, 1, 0)),
           "mono8": (1, (0, 0, 0))}


def decode_image(message: Any) -> np.ndarray:
    """(H, W, 3) uint8 for colour encodings; (H, W) float32 metres for depth (32FC1 m, 16UC1 mm; 0 -> NaN)."""
    height, width, step, encoding = int(message.height), int(message.width), int(message.step), message.encoding
    data = np.frombuffer(bytes(message.data), dtype=np.uint8)
    if data.size < height * step:
        raise ValueError(f"{encoding} image of {height}x{width} with step {step} carries {data.size} bytes")
    rows = data[:height * step].reshape(height, step)
    if encoding in _COLOUR:
        channels, order = _COLOUR[encoding]
        pixels = rows[:, :width * channels].reshape(height, width, channels)
        return np.ascontiguousarray(pixels[:, :, list(order)])
    if encoding in ("32FC1", "16UC1"):
        size = 4 if encoding == "32FC1" else 2
        kind = ("f" if size == 4 else "u") + str(size)
        dtype = np.dtype((">" if message.is_bigendian else "<") + kind)
        values = rows[:, :width * size].copy().view(dtype).reshape(height, width).astype(np.float32)
        if encoding == "16UC1":
            values = np.where(values == 0, np.nan, values / 1000.0).astype(np.float32)
        return values
    raise ValueError(f"unsupported image encoding {encoding!r} (rgb8, bgr8, rgba8, bgra8, mono8, 32FC1, 16UC1)")


class CameraFrames:
    """The latest image, depth image and camera info received, each with its stamp (ns)."""

    def __init__(self, node: Any, config: Any) -> None:
        from sensor_msgs.msg import CameraInfo, Image

        self.config = config
        self.tap: Any = None
        """``tap(topic, message)`` sees each frame handed to perception (the MCAP recording), else ``None``."""
        self._condition = threading.Condition()
        self._latest: dict[str, Any] = {}
        self._recorded = -1
        self._subscriptions = [
            node.create_subscription(Image, config.camera_image, lambda m: self._on("image", m), 2),
            node.create_subscription(Image, config.camera_depth, lambda m: self._on("depth", m), 2),
            node.create_subscription(CameraInfo, config.camera_info, lambda m: self._on("info", m), 2),
        ]

    def topic(self, kind: str) -> str:
        return {"image": self.config.camera_image, "depth": self.config.camera_depth,
                "info": self.config.camera_info}[kind]

    def _on(self, kind: str, message: Any) -> None:
        with self._condition:
            self._latest[kind] = message
            self._condition.notify_all()

    def _stamp(self, kind: str) -> int:
        message = self._latest.get(kind)
        return -1 if message is None else nanoseconds(message.header.stamp)

    def wait(self, stamp: int, timeout: float, *, depth: bool) -> dict[str, Any]:
        """The latest image, info (and depth) once all are stamped at or after ``stamp`` (ns) and the image's
        companions are of its stamp; else ConnectionLost naming each topic that gave no such message."""
        kinds = ("image", "info", "depth") if depth else ("image", "info")
        deadline = time.monotonic() + timeout
        with self._condition:
            while True:
                image = self._stamp("image")
                if image >= stamp and all(self._stamp(k) == image for k in kinds):
                    got = {k: self._latest[k] for k in kinds}
                    break
                left = deadline - time.monotonic()
                if left <= 0:
                    got = None
                    break
                self._condition.wait(min(left, 0.1))
            if got is not None:
                fresh = image != self._recorded
                self._recorded = image
        if got is not None:
            if fresh and self.tap is not None:  # the frames perception used, each once (not every frame sent)
                for kind in kinds:
                    self.tap(self.topic(kind), got[kind])
            return got
        with self._condition:
            late = [f"{self.topic(k)} ({'nothing received' if self._stamp(k) < 0 else 'none stamped after it'})"
                    for k in kinds if self._stamp(k) < stamp]
            if not late:  # every topic is fresh, but not of one stamp
                late = [f"{self.topic(k)} (not of the image's stamp)" for k in kinds if self._stamp(k) != image]
        raise ConnectionLost(f"no camera frame taken after the last motion within the {timeout:g} s camera "
                             f"timeout: {'; '.join(late)}")


class RosTopViewCamera(TopViewCamera):
    """The top view over the table as ROS 2 delivers it; see the module docstring."""

    def __init__(self, world: Any, frames: CameraFrames) -> None:
        super().__init__(world.sim)
        self.world = world
        self.frames = frames

    def capture(self, *, depth: bool = True, segmentation: bool = True) -> CameraImage:
        if segmentation:
            raise ConnectionLost(f"{self.frames.config.camera_image}: ROS 2 images carry no segmentation mask "
                                 "(a perception plugin that needs one cannot run on --world ros2)")
        self.world._alive()
        after = self.world.connection.state.stamp()  # the state the world synced to after its last motion
        got = self.frames.wait(after, self.frames.config.camera_timeout, depth=depth)
        info = got["info"]
        k = np.asarray(info.k, dtype=float).reshape(3, 3)
        intrinsics = Intrinsics(int(info.width), int(info.height), float(k[0, 0]), float(k[1, 1]))
        if abs(k[0, 2] - intrinsics.cx) > 1e-6 or abs(k[1, 2] - intrinsics.cy) > 1e-6:
            raise ConnectionLost(f"{self.frames.config.camera_info}: principal point ({k[0, 2]:g}, {k[1, 2]:g}) is "
                                 f"not the image centre ({intrinsics.cx:g}, {intrinsics.cy:g}); perception needs "
                                 "a centred pinhole (rectify the image first)")
        self.intrinsics = intrinsics
        try:
            rgb = decode_image(got["image"])
            depth_m = decode_image(got["depth"]) if depth else None
        except ValueError as error:
            raise ConnectionLost(f"{self.frames.config.camera_image}: {error}") from None
        if rgb.shape[:2] != (intrinsics.height, intrinsics.width) or (
                depth_m is not None and depth_m.shape != rgb.shape[:2]):
            raise ConnectionLost(f"camera image {rgb.shape[1]}x{rgb.shape[0]} does not match its info "
                                 f"{intrinsics.width}x{intrinsics.height} (or the depth image's size)")
        return CameraImage(rgb, depth_m, None, intrinsics, self.pose())
