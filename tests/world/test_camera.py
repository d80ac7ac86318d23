"""Cameras: the top view shows blocks where they are; pixel <-> table conversions; the wrist camera follows the hand."""

from __future__ import annotations

import numpy as np
import pytest

from bt_meta.world.simulation.camera import HandCamera, Intrinsics, TopViewCamera
from bt_meta.world.simulation.objects import make_model
from bt_meta.world.simulation.sim import Simulation, SimulationError

pytestmark = pytest.mark.slow

BLOCKS = {
    "b0": ("megablok_1x2", "red", (0.55, -0.35, 0.0, 0.0, 0.0, 0.3)),
    "b1": ("megablok_1x1", "blue", (0.72, -0.05, 0.0, 0.0, 0.0, 0.0)),
    "b2": ("megablok_1x1", "red", (0.62, -0.20, 0.0, 0.0, 0.0, 0.7)),
}


@pytest.fixture(scope="module")
def sim():
    with Simulation(seed=0) as s:
        for name, (type_name, colour, pose) in BLOCKS.items():
            s.spawn(name, make_model(type_name, colour), pose, on_table=True)
        s.step(120)
        yield s


def top_face_centroid(cam: TopViewCamera, image, sim: Simulation, name: str) -> np.ndarray:
    """Table (x, y) of the blob's pixel centroid, cast onto the block's top face (as perception will)."""
    rows, cols = np.nonzero(cam.object_mask(image, name))
    u, v = cols.mean() + 0.5, rows.mean() + 0.5
    state = sim.object_state(name)
    z_top = state.pose[2] + sim.object_model(name).info["body_height"] / 2.0
    return cam.pixel_to_plane(u, v, z_top)[:2]


def test_top_view_shows_blocks_where_they_are(sim):
    cam = TopViewCamera(sim)
    image = cam.capture()
    assert image.rgb.shape == (240, 320, 3) and image.rgb.dtype == np.uint8
    assert image.depth is not None and image.depth.shape == (240, 320)
    for name, (_, colour, _pose) in BLOCKS.items():
        mask = cam.object_mask(image, name)
        assert mask.sum() > 300, name  # a block is ~24 px wide at 2.5 mm/px
        xy = top_face_centroid(cam, image, sim, name)
        assert np.linalg.norm(xy - np.array(sim.object_pose(name)[:2])) < 0.006, name
        mean = image.rgb[mask].mean(axis=0)
        channel = {"red": 0, "blue": 2}[colour]
        assert mean.argmax() == channel, (name, mean)  # what HSV thresholding will rely on


def test_top_view_orientation_and_round_trip(sim):
    cam = TopViewCamera(sim)
    u0, v0 = cam.table_to_pixel(0.70, -0.20)
    assert (u0, v0) == pytest.approx((160.0, 120.0))
    u_far, v_far = cam.table_to_pixel(0.80, -0.20)
    u_left, v_left = cam.table_to_pixel(0.70, -0.10)
    assert v_far < v0 and u_far == pytest.approx(u0)  # farther from the robot is up in the image
    assert u_left < u0 and v_left == pytest.approx(v0)  # the robot's left (+y) is left in the image
    for x, y in ((0.5, -0.55), (0.9, 0.15), (0.66, -0.31)):
        u, v = cam.table_to_pixel(x, y)
        assert cam.pixel_to_plane(u, v)[:2] == pytest.approx((x, y), abs=1e-9)
    assert cam.metres_per_pixel() == pytest.approx(0.0025)


def test_depth_is_metric(sim):
    cam = TopViewCamera(sim)
    image = cam.capture()
    u, v = cam.table_to_pixel(0.85, 0.10)  # bare table
    assert image.depth[int(v), int(u)] == pytest.approx(cam.height, abs=3e-3)
    point = cam.pixel_to_point(u, v, float(image.depth[int(v), int(u)]))
    assert point[2] == pytest.approx(sim.table.top_z, abs=3e-3)
    top = sim.object_state("b1").features["top"][0]
    u, v, d = cam.point_to_pixel(top)
    assert image.depth[int(v), int(u)] == pytest.approx(d, abs=3e-3)


def test_top_view_hides_the_robot_but_restores_it(sim):
    sim.set_joint_positions(sim.robot.home)
    cam = TopViewCamera(sim, centre=(0.55, -0.18), height=1.0)
    image = cam.capture()
    assert not np.any((image.segmentation & 0xFFFFFF) == sim.robot_id)  # the gripper hangs right below
    shown = TopViewCamera(sim, centre=(0.55, -0.18), height=1.0, hide_robot=False).capture()
    assert np.any((shown.segmentation & 0xFFFFFF) == sim.robot_id)


def test_hand_camera_follows_the_wrist_and_sees_the_table(sim):
    cam = HandCamera(sim, "right")
    pose = cam.pose()
    assert np.allclose(pose, sim.link_transform("right_hand_camera_link"))
    assert pose[2, 2] < -0.9  # at home the wrist camera looks down
    image = cam.capture()
    assert image.rgb.shape == (240, 320, 3)
    centre = cam.pixel_to_point(160.0, 120.0, float(image.depth[120, 160]))
    assert sim.table.top_z - 0.01 < centre[2] < sim.table.top_z + 0.06  # the table (or a block on it)
    u, v, d = cam.point_to_pixel(pose[:3, 3] + pose[:3, 2])  # one metre along the optical axis
    assert (u, v, d) == pytest.approx((160.0, 120.0, 1.0))


def test_camera_arguments_are_checked(sim):
    with pytest.raises(SimulationError, match="field of view"):
        Intrinsics.from_fov(320, 240, 0.0)
    with pytest.raises(SimulationError, match="height must be positive"):
        TopViewCamera(sim, height=-1.0)
    cam = TopViewCamera(sim)
    image = cam.capture(segmentation=False)
    with pytest.raises(SimulationError, match="without a segmentation mask"):
        cam.object_mask(image, "b0")
    with pytest.raises(SimulationError, match="behind the camera"):
        cam.pixel_to_plane(160.0, 120.0, z=cam.pose()[2, 3] + 1.0)


def test_table_patch_is_a_metric_crop_centred_on_the_block(sim):
    from bt_meta.world.simulation.objects import LB

    cam = TopViewCamera(sim)
    image = cam.capture()
    x, y = sim.object_pose("b1")[:2]
    z_top = sim.object_pose("b1")[2] + sim.object_model("b1").info["body_height"] / 2.0
    patch = cam.table_patch(image, (x, y), 3 * LB, 60, z=z_top)  # the paper's grid-map window, 3 lb
    assert patch.shape == (60, 60, 3)
    blue = (patch[..., 2] > 120) & (patch[..., 0] < 80)
    rows, cols = np.nonzero(blue)
    assert rows.mean() == pytest.approx(29.5, abs=1.5) and cols.mean() == pytest.approx(29.5, abs=1.5)
    # a 1x1 block covers the middle third of a 3 lb window, the cells around it are table
    assert blue[25:35, 25:35].all() and not blue[:15].any() and not blue[:, :15].any()
    # the 1x2 (long axis along x, turned 0.3 rad) stands upright in the patch: up is +x
    x, y = sim.object_pose("b0")[:2]
    red = cam.table_patch(image, (x, y), 3 * LB, 60, z=z_top)
    rows, cols = np.nonzero((red[..., 0] > 120) & (red[..., 2] < 80))
    assert rows.std() > 1.5 * cols.std()
    with pytest.raises(SimulationError, match="positive size"):
        cam.table_patch(image, (x, y), 0.0, 10)


def test_rendered_pixels_follow_the_pixel_centre_convention(sim):
    """A thin tile's blob centroid lands on its projection; TinyRenderer samples pixels at integer screen positions,
    so without the projection's half-pixel offset the mean error is (+0.5, -0.5) px."""
    import pybullet

    client, z = sim.client, sim.table.top_z + 0.0005
    for intrinsics in (None, Intrinsics(321, 241, 300.0, 310.0)):  # odd sizes: the offset is not a rounding accident
        cam = TopViewCamera(sim, intrinsics=intrinsics)
        step = cam.metres_per_pixel(z) / 4.0
        errors = []
        for i in range(4):  # sub-pixel positions, so quantisation averages out
            for j in range(4):
                x, y = 0.82 + i * step + j * 0.013, 0.02 + j * step - i * 0.011  # bare table
                shape = pybullet.createVisualShape(
                    pybullet.GEOM_BOX, halfExtents=[0.0123, 0.0171, 0.0005], physicsClientId=client
                )
                body = pybullet.createMultiBody(0.0, -1, shape, [x, y, z], physicsClientId=client)
                try:
                    image = cam.capture(depth=False)
                finally:
                    pybullet.removeBody(body, physicsClientId=client)
                rows, cols = np.nonzero((image.segmentation & 0xFFFFFF) == body)
                u, v, _ = cam.point_to_pixel((x, y, z + 0.0005))
                errors.append((cols.mean() + 0.5 - u, rows.mean() + 0.5 - v))
        mean = np.mean(errors, axis=0)
        assert np.all(np.abs(mean) < 0.15), (cam.intrinsics, mean)
        assert np.all(np.abs(errors) < 0.5), (cam.intrinsics, np.abs(errors).max(axis=0))
