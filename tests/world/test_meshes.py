"""Mesh objects in the catalogue (``shape: mesh``): a file shipped beside the catalogue (the wedge) or inside an
installed package (example-robot-data), loaded by pybullet (visual and collision) and by the collision checker
(coal, its convex hull), with grasp frames the skills use."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet
import pytest

from bt_meta.errors import ConfigError
from bt_meta.world.simulation.catalogue import load_catalogue, shipped_catalogue
from bt_meta.world.simulation.meshes import MeshError, read_vertices
from bt_meta.world.simulation.objects import Mesh

FEATURES = """\
    features:
      bottom: {point: [0, 0, -0.02], normal: [0, 0, -1]}
    grasp_frames:
      top: [0, 0, 0.024, 180, 0, 180]
"""


def test_the_shipped_wedge_is_a_mesh_with_a_grasp_frame_off_its_centroid():
    wedge = shipped_catalogue()["wedge"].model()
    (part,) = wedge.parts
    assert isinstance(part, Mesh) and Path(part.file).name == "wedge.obj" and len(part.vertices) == 6
    low, high = wedge.extent()
    assert low == pytest.approx([-0.04, -0.025, -0.02]) and high == pytest.approx([0.04, 0.025, 0.02])
    assert wedge.lowest_z(0.0, 0.0) == pytest.approx(0.02)
    (frame,) = wedge.grasp_frames()
    assert frame[:3] == pytest.approx((-0.02, 0.0, 0.024))  # over its thick end, not the slope


def test_a_mesh_from_an_installed_package_scaled(tmp_path: Path):
    path = tmp_path / "mine.yaml"
    path.write_text(textwrap.dedent("""\
        types:
          knob:
            shape: mesh
            mesh: {distribution: example-robot-data,
                   path: cmeel.prefix/share/example-robot-data/robots/panda_description/meshes/collision/link7.stl}
            scale: [0.5, 0.5, 0.5]
            mass: 0.1
        """) + FEATURES)
    (part,) = load_catalogue(path)["knob"].model().parts
    assert isinstance(part, Mesh) and part.scale == (0.5, 0.5, 0.5)
    raw = read_vertices(part.file)
    assert len(raw) > 4 and np.array(part.vertices) == pytest.approx(raw * 0.5)


@pytest.mark.parametrize(
    ("mesh", "needle", "message"),
    [
        ("meshes/nosuch.obj", "meshes/nosuch.obj", "type 'thing': mesh file {dir}/meshes/nosuch.obj does not exist"),
        ("{distribution: no-such-package, path: a.obj}", "{distribution",
         "type 'thing': distribution 'no-such-package' is not installed"),
        ("thing.ply", "thing.ply", "type 'thing': {dir}/thing.ply: a mesh is an OBJ or STL file, not .ply"),
        ("flat.obj", "flat.obj", "type 'thing': {dir}/flat.obj: the mesh has 3 vertices; a solid needs at least 4"),
    ],
)
def test_bad_meshes_fail_at_their_line(tmp_path: Path, mesh: str, needle: str, message: str):
    (tmp_path / "thing.ply").write_text("ply\n")
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    path = tmp_path / "mine.yaml"
    path.write_text(f"types:\n  thing:\n    shape: mesh\n    mesh: {mesh}\n    mass: 0.1\n" + FEATURES)
    with pytest.raises(ConfigError) as info:
        load_catalogue(path)
    column = path.read_text().splitlines()[3].index(needle) + 1
    assert str(info.value) == f"{path}:4:{column}: " + message.format(dir=tmp_path)


def test_a_mesh_needs_its_file(tmp_path: Path):
    path = tmp_path / "mine.yaml"
    path.write_text("types:\n  thing:\n    shape: mesh\n    mass: 0.1\n" + FEATURES)
    with pytest.raises(ConfigError, match=r"mine.yaml:3:5: type 'thing': missing key 'mesh'"):
        load_catalogue(path)
    with pytest.raises(MeshError, match=r"a mesh is an OBJ or STL file, not \.yaml"):
        read_vertices(tmp_path / "mine.yaml")


def test_the_wedge_in_pybullet_and_in_the_collision_checker():
    from bt_meta.world.kinematics.collision import CollisionChecker
    from bt_meta.world.kinematics.forward import Kinematics
    from bt_meta.world.simulation.sim import Simulation

    wedge = shipped_catalogue()["wedge"].model()
    with Simulation() as sim:
        sim.spawn("wedge", wedge, (0.7, -0.2, 0.0, 0.0, 0.0, 0.0), on_table=True)
        sim.settle(120)
        pose = sim.object_pose("wedge")
        assert pose[2] == pytest.approx(sim.table.top_z + 0.02, abs=2e-3)  # resting on its 8 x 5 cm bottom
        assert abs(pose[3]) < 0.02 and abs(pose[4]) < 0.02
        low, high = pybullet.getAABB(sim.body_id("wedge"), physicsClientId=sim.client)
        assert np.array(high) - np.array(low) == pytest.approx([0.08, 0.05, 0.04], abs=0.005)
        # a ray down onto the slope meets the mesh lower than onto the thick end: the shape, not a box
        def surface(x: float) -> float:
            hit = pybullet.rayTest([x, -0.2, 0.5], [x, -0.2, -0.5], physicsClientId=sim.client)[0]
            return 0.5 - hit[2] * 1.0
        assert surface(0.7 - 0.03) > surface(0.7 + 0.03) + 0.02

    kin = Kinematics(sim.robot)
    checker = CollisionChecker(kin)
    gripper = kin.frame_pose(kin.home, "right_gripper")
    checker.add_convex("wedge", np.array(wedge.parts[0].vertices), gripper)
    contact = checker.check(kin.home)
    assert contact is not None and "wedge" in (contact.first, contact.second)
    checker.remove("wedge")
    away = pin.SE3(np.eye(3), np.array([2.0, 0.0, 0.0]))  # far in front of the robot
    checker.add_convex("wedge", np.array(wedge.parts[0].vertices), away)
    assert checker.check(kin.home) is None


def test_a_model_of_more_than_16_parts_keeps_them_all_in_pybullet():
    """pybullet keeps at most 16 shapes per compound: the housing's 24 tube segments are a base and a link."""
    from bt_meta.world.simulation.objects import housing
    from bt_meta.world.simulation.sim import Simulation

    model = housing()
    assert len(model.parts) == 24
    with Simulation() as sim:
        sim.spawn("housing", model, (0.7, -0.1, 0.2, 0.0, 0.0, 0.0))
        centre = sim.object_transform("housing")[:3, 3]
        flange = centre + np.array([0.0, 0.0, 0.025])
        for degrees in range(0, 360, 30):  # the flange all round, 3.5 cm from the axis
            a = np.radians(degrees)
            start = flange + 0.06 * np.array([np.cos(a), np.sin(a), 0.0])
            hit = pybullet.rayTest(list(start), list(flange), physicsClientId=sim.client)[0]
            assert hit[0] == sim.body_id("housing"), degrees
            assert 0.06 * (1.0 - hit[2]) == pytest.approx(0.035, abs=0.002), degrees
        assert sim.object_pose("housing")[:3] == pytest.approx(tuple(centre))


def test_top_down_grasps_go_over_a_grasp_frame_that_points_down(tmp_path: Path):
    """The wedge is held over its thick end; object 2 standing on its magnet face (its `top` frame now points
    sideways) is held over its centroid."""
    from bt_meta.resources import trees_dir
    from bt_meta.world.simulation.sim_world import SimWorld

    scene = (trees_dir() / "scenes" / "letters_A.yaml").read_text(encoding="utf-8")
    extra = ("  - {name: wedge, type: wedge, pose: [0.70, -0.20, table, 0, 0, 90]}\n"
             "  - {name: side, type: magnet_active_side, pose: [0.80, -0.20, table, 0, -90, 0]}\n")
    scene = scene.replace("variants:", extra + "variants:", 1)
    path = tmp_path / "scene.yaml"
    path.write_text(scene)
    world = SimWorld.from_task_file(trees_dir() / "letters.yaml", "A", scene=path)
    try:
        wedge = world.sim.object_transform("wedge")
        expected = wedge[:3, :3] @ np.array([-0.02, 0.0, 0.024]) + wedge[:3, 3]  # yaw 90: the thick end at -y
        assert world.grasp_xy("wedge") == pytest.approx((expected[0], expected[1]), abs=1e-6)
        assert expected[1] == pytest.approx(wedge[1, 3] - 0.02, abs=1e-3)
        side = world.sim.object_transform("side")
        assert world.grasp_xy("side") == pytest.approx((side[0, 3], side[1, 3]), abs=1e-9)
    finally:
        world.close()


@pytest.mark.slow
def test_the_panda_places_the_wedge_holding_it_by_its_grasp_frame(tmp_path: Path):
    """A mesh object picked and placed by the Place skill, in the simulator: the hand goes down over the wedge's
    grasp frame (its thick end), not over its centroid."""
    from bt_meta.resources import trees_dir
    from bt_meta.world.base import RUNNING, SUCCESS
    from bt_meta.world.simulation.sim_world import SimWorld

    scene = (trees_dir() / "scenes" / "letters_A.yaml").read_text(encoding="utf-8")
    scene = scene.replace("{name: b0, type: megablok_1x1, colour: blue,", "{name: b0, type: wedge,")
    path = tmp_path / "scene.yaml"
    path.write_text(scene)
    world = SimWorld.from_task_file(trees_dir() / "letters.yaml", "A", robot="panda", scene=path)
    try:
        grasp_x, grasp_y = world.grasp_xy("b0")
        centre = world.sim.object_transform("b0")[:3, 3]
        assert np.hypot(grasp_x - centre[0], grasp_y - centre[1]) == pytest.approx(0.02, abs=1e-3)
        skill = world.skill("place")
        skill.start(["b0", "0", "0"])
        for _ in range(400):
            if skill.tick() != RUNNING:
                break
        record = skill.inner.record()
        assert skill.inner.outcome == SUCCESS, record.get("failure")
        descend = next(p for p in record["phases"] if p["phase"] == "descend")
        assert descend["target"][:2] == pytest.approx([grasp_x, grasp_y], abs=1e-3)
        assert record["placement_error"] < 0.01 and world.sim.held("arm") is None
    finally:
        world.close()
