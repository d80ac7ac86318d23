"""Cameras in the pybullet world: a fixed top view over the table and the eye-in-hand camera, RGB + depth.

Both are pinhole cameras with known intrinsics and the principal point at the image centre, so a pixel maps to
a ray exactly and a ray meets a plane (the table top) at one point: :meth:`Camera.pixel_to_plane` is how
perception turns a blob's pixel centroid into table coordinates. Pixel coordinates are continuous
``(u, v)``: ``u`` to the right, ``v`` down, the centre of pixel ``[row, col]`` is ``(col + 0.5, row + 0.5)``.
Rendered images follow that convention too: the projection matrix given to pybullet's TinyRenderer (which samples
pixels at integer screen coordinates, not at their centres) is offset so a point projects to the pixel whose
centre is nearest its ``(u, v)``. The camera frame is the optical one (x right, y down, z forward).

Offers:

* :class:`Intrinsics` -- width, height, fx, fy, cx, cy (``from_fov``)
* :class:`CameraImage` -- rgb (H, W, 3 uint8), depth (H, W float32, metres along the optical axis),
  segmentation (H, W int32 pybullet body ids, -1 background), the intrinsics and the camera pose it was taken at
* :class:`Camera` -- capture, pixel <-> point, pixel -> plane; :meth:`Camera.object_mask` by object name
* :class:`TopViewCamera` -- looks straight down on the table; hides the robot while rendering (the paper's
  top view comes from the wrist camera held over the table, which does not see the arm); ``table_to_pixel``
  and ``table_patch`` (a metric crop of the table, e.g. the 3 lb x 3 lb grid-map window)
* :class:`HandCamera` -- follows an arm's camera link (``right_hand_camera_link``)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pybullet

from bt_meta.world.simulation.sim import Simulation, SimulationError

__all__ = ["Camera", "CameraImage", "HandCamera", "Intrinsics", "TopViewCamera"]

# Optical frame (x right, y down, z forward) -> OpenGL camera frame (x right, y up, z backward).
_OPTICAL_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass(frozen=True)
class Intrinsics:
    width: int
    height: int
    fx: float
    fy: float

    @property
    def cx(self) -> float:
        return self.width / 2.0

    @property
    def cy(self) -> float:
        return self.height / 2.0

    @classmethod
    def from_fov(cls, width: int, height: int, fov_y_deg: float) -> Intrinsics:
        """Square pixels with the vertical field of view ``fov_y_deg``."""
        if width <= 0 or height <= 0 or not 0.0 < fov_y_deg < 180.0:
            raise SimulationError(f"bad camera size {width}x{height} or field of view {fov_y_deg}")
        f = (height / 2.0) / math.tan(math.radians(fov_y_deg) / 2.0)
        return cls(width, height, f, f)

    @property
    def fov_y_deg(self) -> float:
        return math.degrees(2.0 * math.atan((self.height / 2.0) / self.fy))

    def matrix(self) -> np.ndarray:
        """The 3x3 K matrix (OpenCV convention)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True, eq=False)
class CameraImage:
    rgb: np.ndarray
    depth: np.ndarray | None
    segmentation: np.ndarray | None
    intrinsics: Intrinsics
    pose: np.ndarray
    """4x4 optical-frame pose in the robot base frame when the image was taken."""


class Camera:
    """A pinhole camera in a :class:`~bt_meta.world.simulation.sim.Simulation`; subclasses say where it is."""

    def __init__(
        self, sim: Simulation, intrinsics: Intrinsics, *, near: float = 0.02, far: float = 3.0, hide_robot: bool
    ) -> None:
        if not 0.0 < near < far:
            raise SimulationError(f"camera clipping planes need 0 < near < far, got {near}, {far}")
        self.sim = sim
        self.intrinsics = intrinsics
        self.near = near
        self.far = far
        self.hide_robot = hide_robot
        self._projection = self._projection_matrix()

    def pose(self) -> np.ndarray:
        """4x4 pose of the optical frame in the robot base frame."""
        raise NotImplementedError

    # -- rendering -------------------------------------------------------------------------------------------

    def _projection_matrix(self) -> list[float]:
        """OpenGL projection that makes TinyRenderer's image follow :class:`Intrinsics` exactly.

        TinyRenderer samples pixel column ``i`` at screen x = ``i`` and row ``r`` at screen y = ``H - 1 - r`` (y up),
        not at pixel centres, so the textbook matrix renders everything (+0.5, -0.5) px off the pinhole model
        (measured: mean blob-centroid offset (+0.50, -0.50) px). The third column puts the principal point where
        the samples fall, i.e. the continuous point (u, v) is drawn at screen ((u - 0.5), (H - 0.5 - v))."""
        k, n, f = self.intrinsics, self.near, self.far
        w, h = k.width, k.height
        proj = np.array(
            [
                [2.0 * k.fx / w, 0.0, (w + 1.0 - 2.0 * k.cx) / w, 0.0],
                [0.0, 2.0 * k.fy / h, (2.0 * k.cy + 1.0 - h) / h, 0.0],
                [0.0, 0.0, -(f + n) / (f - n), -2.0 * f * n / (f - n)],
                [0.0, 0.0, -1.0, 0.0],
            ]
        )
        return list(proj.T.reshape(-1))  # pybullet takes OpenGL's column-major order

    def capture(self, *, depth: bool = True, segmentation: bool = True) -> CameraImage:
        """Render one frame (TinyRenderer: deterministic and headless)."""
        sim, k = self.sim, self.intrinsics
        pose = self.pose()
        view = np.linalg.inv(pose @ _OPTICAL_TO_GL)
        flags = 0 if segmentation else pybullet.ER_NO_SEGMENTATION_MASK
        if self.hide_robot:
            self._set_robot_alpha(0.0)
        try:
            _, _, rgba, depth_buffer, seg = pybullet.getCameraImage(
                k.width,
                k.height,
                list(view.T.reshape(-1)),
                self._projection,
                renderer=pybullet.ER_TINY_RENDERER,
                flags=flags,
                physicsClientId=sim.client,
            )
        finally:
            if self.hide_robot:
                self._set_robot_alpha(None)
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(k.height, k.width, 4)[:, :, :3].copy()
        depth_m = None
        if depth:
            d = np.asarray(depth_buffer, dtype=np.float64).reshape(k.height, k.width)
            depth_m = (self.far * self.near / (self.far - (self.far - self.near) * d)).astype(np.float32)
        seg_arr = np.asarray(seg, dtype=np.int32).reshape(k.height, k.width) if segmentation else None
        return CameraImage(rgb, depth_m, seg_arr, k, pose)

    def _set_robot_alpha(self, alpha: float | None) -> None:
        """Hide (alpha 0) or restore (``None``) the robot's visuals; hidden shapes cost nothing to render."""
        sim = self.sim
        if not hasattr(self, "_robot_colours"):
            data = pybullet.getVisualShapeData(sim.robot_id, physicsClientId=sim.client)
            # Per shape: a link with fixed links merged into it carries several shapes of different colours.
            colours: dict[tuple[int, int], list[float]] = {}
            shapes: dict[int, int] = {}
            for entry in data:
                shape = shapes[entry[1]] = shapes.get(entry[1], -1) + 1
                colours[(entry[1], shape)] = list(entry[7])
            self._robot_colours = colours
        for (link, shape), colour in self._robot_colours.items():
            rgba = colour if alpha is None else [colour[0], colour[1], colour[2], alpha]
            pybullet.changeVisualShape(sim.robot_id, link, shapeIndex=shape, rgbaColor=rgba,
                                       physicsClientId=sim.client)

    # -- geometry --------------------------------------------------------------------------------------------

    def point_to_pixel(self, point: Sequence[float], pose: np.ndarray | None = None) -> tuple[float, float, float]:
        """(u, v, depth) of a base-frame point; depth <= 0 means behind the camera."""
        pose = self.pose() if pose is None else pose
        p = np.linalg.inv(pose) @ np.array([point[0], point[1], point[2], 1.0])
        k = self.intrinsics
        if p[2] <= 0.0:
            return (math.nan, math.nan, float(p[2]))
        return (k.fx * p[0] / p[2] + k.cx, k.fy * p[1] / p[2] + k.cy, float(p[2]))

    def pixel_ray(self, u: float, v: float, pose: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(origin, unit direction) in the base frame of the ray through pixel (u, v)."""
        pose = self.pose() if pose is None else pose
        k = self.intrinsics
        d = np.array([(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0])
        direction = pose[:3, :3] @ d
        return pose[:3, 3].copy(), direction / np.linalg.norm(direction)

    def pixel_to_point(self, u: float, v: float, depth: float, pose: np.ndarray | None = None) -> np.ndarray:
        """The base-frame point at optical depth ``depth`` (m, along z, as in :attr:`CameraImage.depth`)."""
        pose = self.pose() if pose is None else pose
        k = self.intrinsics
        p = np.array([(u - k.cx) / k.fx * depth, (v - k.cy) / k.fy * depth, depth, 1.0])
        return (pose @ p)[:3]

    def pixel_to_plane(self, u: float, v: float, z: float | None = None, pose: np.ndarray | None = None) -> np.ndarray:
        """Where the ray through (u, v) meets the horizontal plane at height ``z`` (default: the table top)."""
        z = self.sim.table.top_z if z is None else z
        origin, direction = self.pixel_ray(u, v, pose)
        if abs(direction[2]) < 1e-12:
            raise SimulationError(f"pixel ({u}, {v}) looks parallel to the plane z = {z}")
        t = (z - origin[2]) / direction[2]
        if t <= 0.0:
            raise SimulationError(f"the plane z = {z} is behind the camera at pixel ({u}, {v})")
        return origin + t * direction

    def metres_per_pixel(self, z: float | None = None) -> float:
        """Ground resolution at the image centre on the plane at height ``z`` (default: the table top)."""
        z = self.sim.table.top_z if z is None else z
        centre = self.pixel_to_plane(self.intrinsics.cx, self.intrinsics.cy, z)
        return float(np.linalg.norm(self.pixel_to_plane(self.intrinsics.cx + 1.0, self.intrinsics.cy, z) - centre))

    def object_mask(self, image: CameraImage, name: str) -> np.ndarray:
        """Boolean mask of the pixels showing object ``name`` in an image captured with segmentation."""
        if image.segmentation is None:
            raise SimulationError("the image was captured without a segmentation mask")
        return (image.segmentation & 0xFFFFFF) == self.sim.body_id(name)


class TopViewCamera(Camera):
    """A camera straight above the table looking down: image up is +x (away from the robot), image right is -y
    (the robot's right), as seen standing behind the robot. The default 320x240 view at 1 m above the table covers
    0.8 m (y) x 0.6 m (x) around ``centre`` at 2.5 mm per pixel (a Mega Blok is ~24 pixels wide)."""

    def __init__(
        self,
        sim: Simulation,
        *,
        centre: tuple[float, float] | None = None,
        height: float = 1.0,
        intrinsics: Intrinsics | None = None,
        hide_robot: bool = True,
    ) -> None:
        intrinsics = intrinsics or Intrinsics(320, 240, 400.0, 400.0)
        if height <= 0.0:
            raise SimulationError(f"top-view camera height must be positive, got {height}")
        super().__init__(sim, intrinsics, near=0.05, far=height + 0.5, hide_robot=hide_robot)
        if centre is None:  # (0.70, -0.20) in the scene frame: the shipped scenes' objects
            dx, dy, _ = sim.robot.scene_offset
            centre = (0.70 + dx, -0.20 + dy)
        self.centre = centre
        self.height = height
        pose = np.eye(4)
        # optical x = -y_base, optical y = -x_base, optical z = -z_base
        pose[:3, :3] = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
        pose[:3, 3] = [centre[0], centre[1], sim.table.top_z + height]
        self._pose = pose

    def pose(self) -> np.ndarray:
        return self._pose.copy()

    def table_patch(
        self, image: CameraImage, centre: Sequence[float], size: float, pixels: int, z: float | None = None
    ) -> np.ndarray:
        """A square metric crop of the table plane (height ``z``, default the table top), resampled from ``image``:
        ``size`` metres wide centred on table point ``centre`` = (x, y), ``pixels`` x ``pixels``, oriented like
        the image (up = +x, right = -y). Exact under perspective, e.g. the paper's 3 lb x 3 lb grid-map crop."""
        import cv2

        if size <= 0.0 or pixels <= 0:
            raise SimulationError(f"a table patch needs a positive size and pixel count, got {size}, {pixels}")
        z = self.sim.table.top_z if z is None else z
        step = size / pixels
        offsets = (np.arange(pixels) + 0.5) * step - size / 2.0
        rows, cols = np.meshgrid(offsets, offsets, indexing="ij")
        xs = centre[0] - rows  # row 0 is the far edge (+x)
        ys = centre[1] - cols  # column 0 is the left edge (+y)
        points = np.stack([xs, ys, np.full_like(xs, z), np.ones_like(xs)], axis=-1)
        camera = points @ np.linalg.inv(image.pose).T
        k = image.intrinsics
        map_u = (k.fx * camera[..., 0] / camera[..., 2] + k.cx - 0.5).astype(np.float32)
        map_v = (k.fy * camera[..., 1] / camera[..., 2] + k.cy - 0.5).astype(np.float32)
        return cv2.remap(image.rgb, map_u, map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    def table_to_pixel(self, x: float, y: float, z: float | None = None) -> tuple[float, float]:
        """Pixel (u, v) of a table point (z defaults to the table top)."""
        z = self.sim.table.top_z if z is None else z
        u, v, _ = self.point_to_pixel((x, y, z))
        return (u, v)


class HandCamera(Camera):
    """The eye-in-hand camera of an arm, posed by its camera link (an optical frame in Baxter's URDF: z looks
    along the gripper). The robot stays visible (the gripper fingers can be in view)."""

    def __init__(
        self,
        sim: Simulation,
        arm: str | None = None,
        *,
        intrinsics: Intrinsics | None = None,
        hide_robot: bool = False,
    ) -> None:
        arm = arm or sim.robot.default_arm
        link = sim.robot.arm(arm).camera
        if link is None:
            raise SimulationError(f"arm {arm!r} has no camera in the robot description")
        super().__init__(
            sim, intrinsics or Intrinsics.from_fov(320, 240, 45.0), near=0.02, far=2.0, hide_robot=hide_robot
        )
        self.arm = arm
        self.link = link

    def pose(self) -> np.ndarray:
        return self.sim.link_transform(self.link)
