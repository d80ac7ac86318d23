"""Sensing noise: seeded, zero when perfect, the documented depth model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bt_meta.sensing.noise import SensingNoise, corrupt_image, depth_sigma, pose_error


@dataclasses.dataclass(frozen=True)
class _Image:
    rgb: np.ndarray
    depth: np.ndarray | None
    pose: np.ndarray


def _image():
    rgb = np.full((24, 32, 3), 120, dtype=np.uint8)
    return _Image(rgb, np.full((24, 32), 1.0, dtype=np.float32), np.eye(4))


def test_depth_sigma_follows_the_published_model():
    noise = SensingNoise()
    assert depth_sigma(noise, 0.4) == pytest.approx(0.0012)
    assert depth_sigma(noise, 1.0) == pytest.approx(0.0012 + 0.0019 * 0.36)


def test_same_seed_same_frame_and_perfect_sensing_changes_nothing():
    noise = SensingNoise()
    calibration = pose_error(SensingNoise.rng(3, 1), noise.camera_translation_sigma, noise.camera_rotation_sigma_deg)
    a = corrupt_image(_image(), noise, SensingNoise.rng(3, 2, 0), calibration)
    b = corrupt_image(_image(), noise, SensingNoise.rng(3, 2, 0), calibration)
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)
    assert not np.array_equal(a.rgb, _image().rgb)
    assert 0.0005 < float(np.std(a.depth - 1.0)) < 0.005
    assert not np.allclose(a.pose, np.eye(4))
    perfect = SensingNoise.perfect()
    calibration = pose_error(SensingNoise.rng(3, 1), 0.0, 0.0)
    c = corrupt_image(_image(), perfect, SensingNoise.rng(3, 2, 0), calibration)
    assert np.array_equal(c.rgb, _image().rgb) and np.array_equal(c.depth, _image().depth)
    assert np.allclose(c.pose, np.eye(4))


def test_lighting_changes_brightness_between_frames():
    noise = dataclasses.replace(SensingNoise(), pixel_sigma=0.0)
    means = {float(corrupt_image(_image(), noise, SensingNoise.rng(0, 2, k), np.eye(4)).rgb.mean()) for k in range(5)}
    assert len(means) == 5 and min(means) < 120 < max(means)
