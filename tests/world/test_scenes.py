"""Scenes and variants as data: the shipped files load and settle; bad files fail at path:line:column."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

from bt_meta.errors import ConfigError
from bt_meta.htn.loader import load_task_file
from bt_meta.resources import trees_dir
from bt_meta.world.robot.description import available_robots, load_robot
from bt_meta.world.simulation.objects import LB
from bt_meta.world.simulation.scenes import load_scene, scene_names
from bt_meta.world.simulation.sim import Simulation

SHIPPED = ["housing_insertion", "letters_A", "letters_H", "magnetic_attach"]


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scene.yaml"
    path.write_text(textwrap.dedent(text).lstrip("\n"), encoding="utf-8")
    return path


def test_shipped_scenes_and_their_variants():
    assert scene_names() == SHIPPED
    letters = load_scene("letters_A")
    assert letters.variant_names == ("A_bar_other_colour", "A_two_1x1_same_colour", "A_two_1x1_different_colours")
    nominal = {o.name: o for o in letters.objects_for(None)}
    assert (nominal["b5"].type, nominal["b5"].colour) == ("megablok_1x2", "blue")
    assert all(nominal[f"b{i}"].type == "megablok_1x1" and nominal[f"b{i}"].colour == "blue" for i in range(5))
    red = {o.name: o for o in letters.objects_for("A_bar_other_colour")}
    assert (red["b5"].type, red["b5"].colour) == ("megablok_1x2", "red")
    assert red["b5"].position == nominal["b5"].position and red["b5"].rpy == nominal["b5"].rpy
    mixed = {o.name: o for o in letters.objects_for("A_two_1x1_different_colours")}
    assert {mixed["b5"].colour, mixed["b6"].colour} == {"red", "blue"} and mixed["b5"].type == "megablok_1x1"
    housing = load_scene("housing_insertion")
    upside = {o.name: o for o in housing.objects_for("housing_upside_down")}
    assert upside["housing"].rpy[0] == pytest.approx(math.pi) and upside["housing"].on_table
    assert {o.type for o in housing.objects_for("shaft_instead")} == {"task_board", "shaft"}
    magnets = load_scene("magnetic_attach")
    assert len(magnets.variant_names) >= 2
    assert {o.name for o in magnets.objects_for("nominal")} == {"active", "reference"}


# trees/letters.yaml problem -> (scene, variant): the blocks on the table are the problem's blocks.
LETTER_PROBLEMS = {
    "A": ("letters_A", None),
    "H": ("letters_H", None),
    "A_bar_other_colour": ("letters_A", "A_bar_other_colour"),
    "A_two_1x1_same_colour": ("letters_A", "A_two_1x1_same_colour"),
    "A_two_1x1_different_colours": ("letters_A", "A_two_1x1_different_colours"),
}


def test_letter_scenes_hold_the_blocks_of_the_letter_problems():
    problems = load_task_file(trees_dir() / "letters.yaml").problems
    assert set(LETTER_PROBLEMS) <= set(problems)
    for problem, (scene, variant) in LETTER_PROBLEMS.items():
        init = problems[problem].init
        shapes = {atom[1]: atom[2] for atom in init if atom[0] == "shape"}
        colours = {atom[1]: atom[2] for atom in init if atom[0] == "colour"}
        expected = {(b, shapes[b], colours[b]) for b in shapes}
        objects = load_scene(scene).objects_for(variant)
        assert {(o.name, o.model().shape, o.model().colour) for o in objects} == expected, problem


def test_letter_origin_anchor_maps_letter_cells_onto_the_free_table():
    scene = load_scene("letters_A")
    origin = scene.anchor_transform("letter_origin", table_top_z=-0.2)
    far_corner = origin @ np.array([3 * LB, 2 * LB, 0.0, 1.0])  # the letter's top-right cell
    assert np.allclose(origin[:3, 3], (0.55, 0.10, -0.2))
    assert np.allclose(origin[:3, 0], (0, -1, 0), atol=1e-12) and np.allclose(origin[:3, 1], (1, 0, 0), atol=1e-12)
    assert far_corner[:3] == pytest.approx((0.55 + 2 * LB, 0.10 - 3 * LB, -0.2))
    supply_y = max(o.position[1] for o in scene.objects)
    assert far_corner[1] - LB > supply_y + LB  # the letter never overlaps the supply
    with pytest.raises(ConfigError, match="no anchor 'corner'; anchors: letter_origin"):
        scene.anchor_transform("corner", -0.2)


def test_unknown_scene_and_variant():
    with pytest.raises(ConfigError, match="no scene 'nope'; shipped scenes: housing_insertion"):
        load_scene("nope")
    with pytest.raises(ConfigError, match="has no variant 'upside'; variants: A_bar_other_colour"):
        load_scene("letters_A").objects_for("upside")


GOOD_OBJECT = "  - {name: b0, type: megablok_1x1, colour: red, pose: [0.6, -0.3, table, 0, 0, 0]}"


@pytest.mark.parametrize(
    ("text", "line", "column", "message"),
    [
        (
            """
            scene: s
            objects:
              - {name: b0, type: brick, pose: [0.6, -0.3, table, 0, 0, 0]}
            """,
            3,
            22,
            "object 'b0': unknown type 'brick'; known: megablok_1x1",
        ),
        (
            """
            scene: s
            objects:
              - name: b0
                type: megablok_1x1
                pose: [0.6, -0.3, 0, 0]
            """,
            5,
            11,
            "pose must be [x, y, z, roll, pitch, yaw] (m, m, m or 'table', deg, deg, deg); got 4 values",
        ),
        (
            f"""
            scene: s
            objects:
            {GOOD_OBJECT}
              - {{name: b0, type: megablok_1x2, pose: [0.7, -0.3, table, 0, 0, 0]}}
            """,
            4,
            5,
            "duplicate object name 'b0' (first at line 3)",
        ),
        (
            """
            scene: s
            objects:
              - {name: b0, type: shaft, pose: [0.6, table, 0, 0, 0, 0]}
            """,
            3,
            41,
            "object 'b0' pose[1] must be a number, got 'table'",
        ),
        (
            """
            scene: s
            objects:
              - {name: b0, type: shaft, colour: purple, pose: [0.6, -0.3, table, 0, 0, 0]}
            """,
            3,
            37,
            "unknown colour 'purple'",
        ),
        (
            f"""
            scene: s
            objects:
            {GOOD_OBJECT}
            variants:
              v:
                override:
                  b9: {{pose: [0.6, -0.3, table, 0, 0, 0]}}
            """,
            7,
            7,
            "variant 'v': no object 'b9' to change; objects: b0",
        ),
        (
            f"""
            scene: s
            objects:
            {GOOD_OBJECT}
            variants:
              v:
                add:
                  - {{name: b0, type: shaft, pose: [0.7, -0.3, table, 0, 0, 0]}}
            """,
            7,
            9,
            "duplicate object name 'b0' (first at line 3)",
        ),
        (
            f"""
            scene: s
            objects:
            {GOOD_OBJECT}
            variants:
              v:
                replace:
                  b0:
                    - {{name: b5, type: megablok_1x1}}
                    - {{name: b6, type: megablok_1x1}}
            """,
            8,
            9,
            "only one replacement may omit its pose",
        ),
        (
            f"""
            scene: s
            objects:
            {GOOD_OBJECT}
            variants:
              v:
                recolour: {{b0: blue}}
            """,
            6,
            5,
            "unknown key 'recolour'; expected one of add, description, obstacles, override, remove, replace",
        ),
        (
            f"""
            scene: s
            objects:
            {GOOD_OBJECT}
            variants:
              v: {{description: nothing}}
            """,
            5,
            6,
            "variant 'v' changes nothing",
        ),
        (
            """
            objects: []
            """,
            1,
            1,
            "a scene file: missing key 'scene'",
        ),
        (
            """
            scene: s
            objects: [
            """,
            3,
            1,
            "not valid YAML",
        ),
    ],
)
def test_bad_scene_files_fail_at_their_line(tmp_path, text, line, column, message):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    error = info.value
    assert message in error.message
    assert (error.path, error.line, error.column) == (str(path), line, column), error.location_message()
    assert str(error).startswith(f"{path}:{line}:{column}: ")


@pytest.fixture(scope="module")
def sim():
    with Simulation(seed=0) as s:
        yield s


@pytest.mark.slow
@pytest.mark.parametrize(
    ("scene", "variant"),
    [(name, v) for name in SHIPPED for v in (None, *load_scene(name).variant_names)],
)
def test_every_scene_and_variant_builds_and_stays_put(sim, scene, variant):
    sim.clear_objects()
    spec = load_scene(scene)
    spec.build(sim, variant, settle_steps=0)
    objects = spec.objects_for(variant)
    assert set(sim.object_names()) == {o.name for o in objects}
    start = {o.name: np.array(sim.object_pose(o.name)) for o in objects}
    for obj in objects:
        assert start[obj.name][:2] == pytest.approx(obj.position[:2], abs=1e-9)
        if not obj.on_table:
            assert start[obj.name][2] == pytest.approx(obj.position[2], abs=1e-9)
    sim.step(480)
    for obj in objects:
        now = np.array(sim.object_pose(obj.name))
        assert np.abs(now[:3] - start[obj.name][:3]).max() < 1.5e-3, obj.name
    if scene == "magnetic_attach":
        assert sim.attachments() == []  # nothing joins before the robot acts
    sim.clear_objects()


@pytest.mark.slow
def test_jitter_is_seeded_and_off_table_objects_are_located(sim, tmp_path):
    path = write(
        tmp_path,
        """
        scene: s
        jitter: {position: 0.01, yaw: 5}
        objects:
          - {name: b0, type: megablok_1x1, pose: [0.6, -0.3, table, 0, 0, 0]}
          - {name: b1, type: megablok_1x1, pose: [0.6, -0.1, table, 0, 0, 0]}
        variants:
          off:
            override:
              b1: {pose: [2.0, -0.1, table, 0, 0, 0]}
        """,
    )
    spec = load_scene(path)

    def poses(seed: int) -> list[tuple[float, ...]]:
        sim.clear_objects()
        spec.build(sim, seed=seed, settle_steps=0)
        return [sim.object_pose("b0"), sim.object_pose("b1")]

    first, again, other = poses(1), poses(1), poses(2)
    assert first == again and first != other
    assert abs(first[0][0] - 0.6) <= 0.01 and first[0][0] != 0.6
    sim.clear_objects()
    with pytest.raises(
        ConfigError,
        match=r"object 'b1' at \(1\.99\d, -0\.09\d\) is off the table \(x 0\.450\.\.1\.050, y -0\.650\.\.0\.450\)",
    ) as info:
        spec.build(sim, "off")
    assert info.value.line == 9
    sim.clear_objects()


@pytest.mark.slow
@pytest.mark.parametrize("robot", available_robots())
def test_jitter_keeps_the_robots_scene_offset_for_every_object(robot, tmp_path):
    """Every object lands where the scene puts it in this robot's base frame, give or take the jitter.

    The jitter's draw once reused the offset's names, so every object after the first lost the offset.
    """
    path = write(
        tmp_path,
        """
        scene: s
        jitter: {position: 0.004, yaw: 2}
        objects:
          - {name: b0, type: megablok_1x1, pose: [0.60, -0.30, table, 0, 0, 0]}
          - {name: b1, type: megablok_1x1, pose: [0.60, -0.10, table, 0, 0, 0]}
          - {name: b2, type: megablok_1x2, pose: [0.70, 0.00, table, 0, 0, 90]}
          - {name: b3, type: megablok_1x1, pose: [0.55, 0.15, table, 0, 0, 0]}
        """,
    )
    spec = load_scene(path)
    description = load_robot(robot)
    dx, dy, _ = description.scene_offset
    with Simulation(seed=0, robot=description) as s:
        spec.build(s, seed=3, settle_steps=0)
        for obj in spec.objects:
            x, y, _, _, _, yaw = s.object_pose(obj.name)
            assert abs(x - (obj.position[0] + dx)) <= 0.004 + 1e-9, (robot, obj.name, x)
            assert abs(y - (obj.position[1] + dy)) <= 0.004 + 1e-9, (robot, obj.name, y)
            assert abs(math.remainder(yaw - obj.rpy[2], 2 * math.pi)) <= math.radians(2) + 1e-9


def test_a_grounding_naming_an_anchor_the_scene_lacks_is_refused_at_its_line(tmp_path):
    """The anchor is checked when the world is built, at the grounding's line, not in the middle of a repair."""
    from bt_meta.world.simulation.sim_world import load_grounding

    text = textwrap.dedent(
        """
        domain: d
        problems:
          p: {scene: scene.yaml}
        skills:
          MoveTo: {skill: move_to}
        frames:
          letter: {anchor: letter_origin, unit: 0.061}
        poses:
          turn_high: {anchor: set_down_spot, offset: [0, 0, 0.18]}
        """
    ).lstrip("\n")
    grounding_path = tmp_path / "grounding.yaml"
    grounding_path.write_text(text, encoding="utf-8")
    grounding = load_grounding("d", path=grounding_path)
    assert [(a, where) for a, where, _, _ in grounding.anchor_uses] == [
        ("letter_origin", "frames.letter"),
        ("set_down_spot", "poses.turn_high"),
    ]
    objects = "objects:\n  - {name: b0, type: megablok_1x1, pose: [0.6, -0.3, table, 0, 0, 0]}\n"
    both = write(tmp_path, "scene: both\nanchors:\n  letter_origin: [0.55, 0.10, table, 0, 0, -90]\n"
                           "  set_down_spot: [0.50, -0.28, table, 0, 0, 0]\n" + objects)
    grounding.check_anchors(load_scene(both))
    one = write(tmp_path, "scene: one\nanchors:\n  letter_origin: [0.55, 0.10, table, 0, 0, -90]\n" + objects)
    refused = r"poses\.turn_high names anchor .set_down_spot..*anchors: letter_origin"
    with pytest.raises(ConfigError, match=refused) as info:
        grounding.check_anchors(load_scene(one))
    line = text.splitlines().index("  turn_high: {anchor: set_down_spot, offset: [0, 0, 0.18]}") + 1
    column = text.splitlines()[line - 1].index("set_down_spot") + 1
    assert (info.value.path, info.value.line, info.value.column) == (str(grounding_path), line, column)


@pytest.mark.slow
def test_run_refuses_a_scene_without_the_groundings_anchor_before_any_motion(tmp_path):
    """``bt-meta run`` on a scene lacking an anchor the shipped grounding names: exit 2, the grounding's line."""
    import subprocess
    import sys

    scene = write(tmp_path, "scene: no_anchor\nobjects:\n"
                            + "".join(f"  - {{name: b{i}, type: megablok_1x1, pose: [0.6, {-0.3 + 0.08 * i:.2f}, table,"
                                      " 0, 0, 0]}\n" for i in range(5))
                            + "  - {name: b5, type: megablok_1x2, pose: [0.7, 0.0, table, 0, 0, 0]}\n")
    done = subprocess.run([sys.executable, "-m", "bt_meta.cli", "run", str(trees_dir() / "letters.yaml"), "--problem",
                           "A", "--scene", str(scene)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stdout + done.stderr
    grounding = trees_dir() / "poses" / "letters.yaml"
    line = next(n for n, text in enumerate(grounding.read_text().splitlines(), 1) if "anchor: letter_origin" in text)
    assert f"{grounding}:{line}:" in done.stderr and "letter_origin" in done.stderr, done.stderr
