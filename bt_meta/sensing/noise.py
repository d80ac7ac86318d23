"""Sensing noise models: what makes a simulated camera and pose sensor as fallible as a real one.

Every parameter is a field of :class:`SensingNoise` with its unit; docs/campaigns.md ("Perceived world") states
where each default comes from. The models:

* **pixel noise** -- zero-mean Gaussian per pixel and channel, ``pixel_sigma`` digital numbers (0-255)
* **lighting** -- a per-frame brightness gain drawn from ``lighting_gain`` and a per-channel white-balance gain
  within ``white_balance``: the scene gets brighter, darker, warmer or colder between frames
* **depth noise** -- axial, Gaussian, growing with distance as measured for a structured-light RGB-D camera:
  ``sigma_z(z) = depth_a + depth_b (z - depth_z0)^2`` metres (z in metres)
* **camera pose error** -- the extrinsic calibration is off: the pose perception *believes* the camera has differs
  from the true one by a translation (``camera_translation_sigma`` per axis) and a rotation
  (``camera_rotation_sigma_deg`` about a random axis), drawn once per episode
* **occlusion by the arm** -- the arm is rendered in the top view (``occlusion``) and hides what lies under it
* **object pose sensing** (parts that are not blocks) -- the true pose seen through the same camera error and
  depth noise, plus ``pose_rotation_sigma_deg`` of orientation noise

All draws take a seed (:meth:`SensingNoise.rng`): the same seed gives the same frames.

Offers:

* :class:`SensingNoise` -- the parameters; :meth:`SensingNoise.perfect` has them all zero
* :func:`corrupt_image` -- a noisy copy of a :class:`~bt_meta.world.simulation.camera.CameraImage` (rgb, depth)
  and the pose perception believes it was taken from
* :func:`depth_sigma` -- the axial depth noise at a distance
* :func:`pose_error` -- a seeded rigid error transform
* :func:`sense_pose` -- a noisy 4x4 object pose
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from bt_meta.world.poses import axis_angle_matrix

__all__ = ["SensingNoise", "corrupt_image", "depth_sigma", "pose_error", "sense_pose"]


@dataclass(frozen=True)
class SensingNoise:
    pixel_sigma: float = 2.5
    """DN (0-255) per channel."""
    lighting_gain: tuple[float, float] = (0.75, 1.25)
    """Range of the per-frame brightness gain."""
    white_balance: float = 0.05
    """Per-channel gain within 1 +- this."""
    depth_a: float = 0.0012
    depth_b: float = 0.0019
    depth_z0: float = 0.4
    """sigma_z(z) = depth_a + depth_b (z - depth_z0)^2, metres."""
    camera_translation_sigma: float = 0.00028
    """m per axis, drawn once per episode (docs/campaigns.md: a published hand-eye calibration's error bound)."""
    camera_rotation_sigma_deg: float = 0.25
    """degrees about a random axis, drawn once per episode (the same source)."""
    pose_rotation_sigma_deg: float = 2.0
    """degrees of orientation noise of a sensed object pose (per observation)."""
    occlusion: bool = True
    """Render the arm in the top view (it hides what lies under it)."""

    @classmethod
    def perfect(cls) -> SensingNoise:
        return cls(pixel_sigma=0.0, lighting_gain=(1.0, 1.0), white_balance=0.0, depth_a=0.0, depth_b=0.0,
                   camera_translation_sigma=0.0, camera_rotation_sigma_deg=0.0, pose_rotation_sigma_deg=0.0,
                   occlusion=False)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @staticmethod
    def rng(seed: int, *stream: int) -> np.random.Generator:
        return np.random.default_rng([int(seed), *stream])


def depth_sigma(noise: SensingNoise, z: np.ndarray | float) -> np.ndarray | float:
    return noise.depth_a + noise.depth_b * (np.asarray(z) - noise.depth_z0) ** 2


def pose_error(rng: np.random.Generator, translation_sigma: float, rotation_sigma_deg: float) -> np.ndarray:
    """A rigid transform with Gaussian translation (per axis) and a rotation of Gaussian angle about a random axis."""
    out = np.eye(4)
    out[:3, :3] = axis_angle_matrix(rng.normal(size=3), math.radians(float(rng.normal(0.0, rotation_sigma_deg))))
    out[:3, 3] = rng.normal(0.0, translation_sigma, size=3)
    return out


def corrupt_image(image: Any, noise: SensingNoise, rng: np.random.Generator, calibration: np.ndarray) -> Any:
    """A copy of ``image`` with lighting, pixel and depth noise; its ``pose`` is the one perception believes
    (true pose composed with the episode's ``calibration`` error)."""
    rgb = image.rgb.astype(np.float32)
    lo, hi = noise.lighting_gain
    gain = float(rng.uniform(lo, hi)) * (1.0 + rng.uniform(-noise.white_balance, noise.white_balance, size=3))
    rgb = rgb * gain.astype(np.float32)
    if noise.pixel_sigma > 0.0:
        rgb = rgb + rng.normal(0.0, noise.pixel_sigma, size=rgb.shape).astype(np.float32)
    rgb = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    depth = image.depth
    if depth is not None and (noise.depth_a > 0.0 or noise.depth_b > 0.0):
        depth = (depth + rng.normal(size=depth.shape) * depth_sigma(noise, depth)).astype(np.float32)
    return dataclasses.replace(image, rgb=rgb, depth=depth, pose=np.asarray(image.pose) @ calibration)


def sense_pose(transform: np.ndarray, noise: SensingNoise, rng: np.random.Generator, calibration: np.ndarray,
               distance: float) -> np.ndarray:
    """A sensed object pose: the true one seen through the camera error, with depth noise along z and
    orientation noise."""
    out = calibration @ np.asarray(transform, dtype=float)
    out[2, 3] += float(rng.normal(0.0, float(depth_sigma(noise, distance))))
    if noise.pose_rotation_sigma_deg > 0.0:
        axis = rng.normal(size=3)  # drawn before the angle, as ever: the seeded noise streams stay the same
        angle = math.radians(float(rng.normal(0.0, noise.pose_rotation_sigma_deg)))
        out[:3, :3] = axis_angle_matrix(axis, angle) @ out[:3, :3]
    return out
