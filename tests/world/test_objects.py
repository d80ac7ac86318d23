"""Object models as data: proportions, features, the attach rule and pose conversions (no simulator)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bt_meta.world.simulation.objects import (
    LB,
    OBJECT_TYPES,
    AttachmentFeature,
    ObjectModelError,
    attachment_relation,
    housing,
    make_model,
    matrix_to_pose,
    megablok,
    pose_to_matrix,
    task_board,
)


def test_megablok_proportions():
    one, two = megablok("1x1", "red"), megablok("1x2", "blue")
    lo, hi = one.extent()
    assert hi[0] - lo[0] == pytest.approx(LB) and hi[1] - lo[1] == pytest.approx(LB)
    lo2, hi2 = two.extent()
    assert hi2[0] - lo2[0] == pytest.approx(2 * LB) and hi2[1] - lo2[1] == pytest.approx(LB)
    assert one.info["body_height"] == pytest.approx(0.6 * LB)
    assert one.shape == "1x1" and two.shape == "1x2" and two.colour == "blue"
    assert one.feature().name == "bottom" and one.feature().normal == (0.0, 0.0, -1.0)
    assert one.lowest_z(0.0, 0.0) == pytest.approx(0.3 * LB)  # origin is the body centre
    assert one.lowest_z(math.pi, 0.0) == pytest.approx(0.3 * LB + 0.2 * LB)  # upside down it stands on its stud


def test_housing_fits_the_board_only_narrow_end_first():
    h, board = housing(), task_board()
    half = board.info["hole_half_width"]
    assert h.info["body_radius"] / math.cos(math.pi / 12) < half < h.info["flange_radius"]
    assert h.feature("insert_end").normal == (0.0, 0.0, -1.0) and h.feature("bore").normal == (0.0, 0.0, 1.0)
    assert board.mass == 0.0 and board.feature().name == "hole"


def test_every_type_builds_with_its_default_colour_and_a_named_one():
    for type_name in OBJECT_TYPES:
        assert make_model(type_name).type == type_name
        assert make_model(type_name, "white").colour == "white"


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: make_model("brick"), "unknown object type 'brick'"),
        (lambda: make_model("shaft", "purple"), "unknown colour 'purple'"),
        (lambda: megablok("2x2", "red"), "1x1 or 1x2, not '2x2'"),
        (lambda: AttachmentFeature("x", (0, 0, 0), (0, 0, 0)), "normal is zero"),
        (lambda: housing().feature("lid"), "no attachment feature 'lid'"),
    ],
)
def test_errors_name_the_problem(call, message):
    with pytest.raises(ObjectModelError, match=message):
        call()


def test_attach_rule_needs_coincident_points_and_opposed_normals():
    ok = attachment_relation((0, 0, 0), (0, 0, -1), (0.005, 0, 0), (0, 0, 1))
    assert ok.aligned and ok.distance == pytest.approx(0.005) and ok.angle == pytest.approx(math.pi)
    far = attachment_relation((0, 0, 0.02), (0, 0, -1), (0, 0, 0), (0, 0, 1))
    assert not far.aligned
    sideways = attachment_relation((0, 0, 0), (0, 1, 0), (0, 0, 0), (0, 0, 1))
    assert not sideways.aligned and sideways.angle == pytest.approx(math.pi / 2)
    tilted = attachment_relation((0, 0, 0), (0, math.sin(0.2), -math.cos(0.2)), (0, 0, 0), (0, 0, 1))
    assert tilted.aligned  # 0.2 rad (11.5 deg) from opposed is within the 15 degree tolerance


def test_pose_round_trip_and_gimbal_lock():
    rng = np.random.default_rng(0)
    for _ in range(50):
        pose = (*rng.uniform(-1, 1, 3), *rng.uniform(-3, 3, 1), *rng.uniform(-1.5, 1.5, 1), *rng.uniform(-3, 3, 1))
        assert np.allclose(pose_to_matrix(matrix_to_pose(pose_to_matrix(pose))), pose_to_matrix(pose), atol=1e-9)
        assert np.allclose(matrix_to_pose(pose_to_matrix(pose)), pose, atol=1e-9)
    locked = pose_to_matrix((0, 0, 0, 0.3, math.pi / 2, 0.2))
    assert np.allclose(pose_to_matrix(matrix_to_pose(locked)), locked, atol=1e-9)


def test_a_pose_of_the_wrong_length_is_named():
    from bt_meta.world.poses import PoseError

    with pytest.raises(PoseError, match="6 numbers"):
        pose_to_matrix((1, 2, 3))


def test_the_skills_do_not_import_the_simulation_package():
    """The skills speak poses (bt_meta.world.poses); the simulation's World imports the skills: no circle."""
    import ast
    from pathlib import Path

    import bt_meta.world.skills

    for path in sorted(Path(bt_meta.world.skills.__file__).parent.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        imported = [node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module]
        assert not [m for m in imported if m.startswith("bt_meta.world.simulation")], path.name
