"""The robot description loader: the shipped Baxter file, and located errors for bad files."""

from __future__ import annotations

from pathlib import Path

import pytest

from bt_meta.errors import ConfigError, KinematicsError
from bt_meta.resources import robots_dir
from bt_meta.world.robot.description import IKSettings, load_robot, read_urdf_summary

BAXTER_TEXT = (robots_dir() / "baxter.yaml").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def baxter():
    return load_robot("baxter")


def write_variant(tmp_path: Path, old: str, new: str) -> Path:
    assert old in BAXTER_TEXT, old
    path = tmp_path / "robot.yaml"
    path.write_text(BAXTER_TEXT.replace(old, new, 1), encoding="utf-8")
    return path


def position_of(path: Path, needle: str) -> tuple[int, int]:
    """1-based line and column of the first occurrence of ``needle`` in a file."""
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        if needle in line:
            return number, line.index(needle) + 1
    raise AssertionError(needle)


def test_baxter_files_come_from_example_robot_data(baxter):
    assert baxter.name == "baxter"
    assert baxter.urdf_path.is_file() and baxter.urdf_path.name == "baxter.urdf"
    assert baxter.srdf_path is not None and baxter.srdf_path.name == "baxter_manipulation.srdf"
    assert baxter.package_dirs[0].name == "share"
    assert "cmeel.prefix" in str(baxter.package_dirs[0])
    assert str(baxter.urdf_path).startswith(str(baxter.package_dirs[0]))
    assert baxter.srdf_joint_prefix == "baxter/"


def test_baxter_arms_frames_and_cameras(baxter):
    right = baxter.arms["right"]
    assert right.joints == ("right_s0", "right_s1", "right_e0", "right_e1", "right_w0", "right_w1", "right_w2")
    assert right.end_effector == "right_gripper"
    assert right.camera == "right_hand_camera_link"
    assert baxter.arms["left"].end_effector == "left_gripper"
    assert baxter.head_camera == "head_camera_link"
    assert baxter.head_joints == ("head_pan",)
    assert baxter.cameras == {
        "right_hand": "right_hand_camera_link",
        "left_hand": "left_hand_camera_link",
        "head": "head_camera_link",
    }
    assert baxter.arm("right") is right
    with pytest.raises(KinematicsError, match="no arm 'middle'; arms: right, left"):
        baxter.arm("middle")


def test_baxter_gripper_home_limits_and_ik(baxter):
    gripper = baxter.arms["right"].gripper
    assert gripper.joints == ("r_gripper_l_finger_joint", "r_gripper_r_finger_joint")
    assert gripper.open == (0.020833, -0.020833)
    assert gripper.opening == pytest.approx(0.0462)
    assert baxter.home["right_e1"] == 1.94 and baxter.home["left_e0"] == -1.19
    assert baxter.home["r_gripper_l_finger_joint"] == 0.0  # not listed: stays at 0
    assert len(baxter.home) == 19
    assert baxter.joint_limits["right_s0"] == pytest.approx((-1.70167993878, 1.70167993878))
    assert baxter.joint_limits["r_gripper_r_finger_joint"] == pytest.approx((-0.020833, 0.0))
    assert baxter.ik.position_tolerance == 1e-4 and baxter.ik.orientation_tolerance == 1e-3
    assert isinstance(baxter.ik, IKSettings)


def test_load_by_path_and_unknown_name(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text(BAXTER_TEXT.replace("name: baxter", "name: mine"), encoding="utf-8")
    assert load_robot(path).name == "mine"
    with pytest.raises(ConfigError, match=r"no robot description 'r2d2'; available: .*baxter"):
        load_robot("r2d2")
    with pytest.raises(ConfigError, match="not found"):
        load_robot(tmp_path / "missing.yaml")


def test_unknown_joint_is_located(tmp_path):
    path = write_variant(tmp_path, "right_w1, right_w2]", "right_w1, right_w9]")
    line, column = position_of(path, "right_w9")
    with pytest.raises(ConfigError) as caught:
        load_robot(path)
    error = caught.value
    assert (error.line, error.column) == (line, column)
    assert "arms.right.joints: unknown joint 'right_w9' (not in the URDF)" in str(error)
    assert str(error).startswith(f"{path}:{line}:{column}: ")


def test_fixed_joint_is_not_an_arm_joint(tmp_path):
    path = write_variant(tmp_path, "right_w1, right_w2]", "right_w1, right_endpoint]")
    with pytest.raises(ConfigError, match="joint 'right_endpoint' is fixed, not movable"):
        load_robot(path)


def test_unknown_frame_is_located(tmp_path):
    path = write_variant(tmp_path, "end_effector: right_gripper", "end_effector: right_griper")
    line, column = position_of(path, "right_griper")
    with pytest.raises(ConfigError) as caught:
        load_robot(path)
    assert (caught.value.line, caught.value.column) == (line, column)
    assert "unknown frame 'right_griper' (no such link or joint in the URDF)" in caught.value.message


def test_missing_key_is_located_at_its_mapping(tmp_path):
    path = write_variant(tmp_path, "    end_effector: right_gripper        # between", "    # between")
    with pytest.raises(ConfigError, match=r"arms\.right: missing key 'end_effector'") as caught:
        load_robot(path)
    assert caught.value.line == position_of(path, "joints: [right_s0")[0]
    path = write_variant(tmp_path, "base_frame: base\n", "")
    with pytest.raises(ConfigError, match="robot description: missing key 'base_frame'"):
        load_robot(path)


def test_unknown_key_wrong_type_and_bad_values(tmp_path):
    path = write_variant(tmp_path, "  seed: 0 ", "  sead: 0 ")
    with pytest.raises(ConfigError, match=r"ik: unknown key 'sead'; expected one of .*seed"):
        load_robot(path)
    path = write_variant(tmp_path, "  max_attempts: 40 ", "  max_attempts: many ")
    with pytest.raises(ConfigError, match=r"ik\.max_attempts must be a non-negative integer"):
        load_robot(path)
    path = write_variant(tmp_path, "  right_e1: 1.94", "  right_e1: 4.0")
    with pytest.raises(ConfigError, match=r"home.right_e1 = 4.0 is outside the joint limits \[-0.05, 2.618"):
        load_robot(path)
    path = write_variant(tmp_path, "  head_pan: 0.0", "  head_spin: 0.0")
    with pytest.raises(ConfigError, match="home: unknown joint 'head_spin'"):
        load_robot(path)
    path = write_variant(tmp_path, "open: [0.020833, -0.020833]", "open: [0.020833]")
    with pytest.raises(ConfigError, match="expected 2 values, one per gripper joint"):
        load_robot(path)
    path = write_variant(tmp_path, "joint_limits: {}", "joint_limits: {right_s0: [-3.0, 1.0]}")
    with pytest.raises(ConfigError, match="must be increasing and within the URDF limits"):
        load_robot(path)


def test_joint_limit_override_tightens(tmp_path):
    path = write_variant(tmp_path, "joint_limits: {}", "joint_limits: {right_s0: [-1.0, 1.0]}")
    assert load_robot(path).joint_limits["right_s0"] == (-1.0, 1.0)


def test_bad_yaml_and_missing_files(tmp_path):
    path = write_variant(tmp_path, "name: baxter", "name: [baxter")
    with pytest.raises(ConfigError, match="not valid YAML") as caught:
        load_robot(path)
    assert caught.value.line is not None
    path = write_variant(tmp_path, "distribution: example-robot-data", "distribution: no-such-distribution-xyz")
    with pytest.raises(ConfigError, match="'no-such-distribution-xyz' is not installed"):
        load_robot(path)
    path = write_variant(tmp_path, "urdf/baxter.urdf", "urdf/baxtr.urdf")
    with pytest.raises(ConfigError, match=r"files.urdf: file .*baxtr.urdf does not exist"):
        load_robot(path)
    empty = tmp_path / "empty.yaml"
    empty.write_text("", encoding="utf-8")
    with pytest.raises(ConfigError, match="empty"):
        load_robot(empty)


def test_share_relative_to_the_file_without_distribution(tmp_path, baxter):
    share = baxter.package_dirs[0]
    text = BAXTER_TEXT.replace("  distribution: example-robot-data\n", "").replace(
        "share: cmeel.prefix/share", f"share: {share}"
    )
    path = tmp_path / "local.yaml"
    path.write_text(text, encoding="utf-8")
    assert load_robot(path).urdf_path == baxter.urdf_path


def test_urdf_summary(baxter, tmp_path):
    summary = read_urdf_summary(baxter.urdf_path)
    assert len(summary.movable_joints) == 19
    assert summary.mimic["r_gripper_r_finger_joint"] == ("r_gripper_l_finger_joint", -1.0, 0.0)
    assert "right_gripper" in summary.frames
    bad = tmp_path / "bad.urdf"
    bad.write_text('<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY a "b">]>\n<robot name="x"/>', encoding="utf-8")
    with pytest.raises(ConfigError, match="DOCTYPE"):
        read_urdf_summary(bad)
    bad.write_text("<robot name='x'>\n<link name='a'>\n</robot>", encoding="utf-8")
    with pytest.raises(ConfigError, match="not well-formed") as caught:
        read_urdf_summary(bad)
    assert caught.value.line == 3


URDF_HEAD = '<?xml version="1.0"?>\n<robot name="two">\n  <link name="a"/>\n  <link name="b"/>\n'


@pytest.mark.parametrize(("body", "message", "where"), [
    ('  <joint name="j" type="revolute">\n    <parent link="a"/><child link="c"/>\n  </joint>\n',
     "joint 'j': its child link 'c' is not in the URDF", (5, 3)),
    ('  <joint name="j" type="hinge">\n    <parent link="a"/><child link="b"/>\n  </joint>\n',
     "joint 'j' has an unknown type 'hinge'", (5, 3)),
    ('  <link name="c"/>\n', "the links do not form one tree: 2 have no parent joint (a, c)", (2, 1)),
    ('  <joint name="j" type="fixed">\n    <parent link="a"/><child link="b"/>\n  </joint>\n'
     '  <link name="c"><visual><geometry>\n    <mesh filename="meshes/nothere.stl"/>\n  </geometry></visual></link>\n'
     '  <joint name="k" type="fixed"><parent link="a"/><child link="c"/></joint>\n',
     "mesh file 'meshes/nothere.stl' is not there", (9, 5)),
])
def test_a_urdf_the_models_would_not_load_is_located(tmp_path, body, message, where):
    urdf = tmp_path / "two.urdf"
    urdf.write_text(URDF_HEAD + body + "</robot>\n", encoding="utf-8")
    if "one tree" in message:  # a and b joined, c on its own
        urdf.write_text(URDF_HEAD + '  <joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint>\n'
                        + body + "</robot>\n", encoding="utf-8")
    with pytest.raises(ConfigError) as caught:
        read_urdf_summary(urdf)
    assert str(caught.value) == f"{urdf}:{where[0]}:{where[1]}: {message}"


@pytest.mark.parametrize(("old", "new", "needle", "message"), [
    ("end_effector: right_gripper", "end_effector: right_griper", "right_griper", "unknown frame 'right_griper'"),
    ("    camera: right_hand_camera_link ", "    camera_frame: right_hand_camera_link ", "camera_frame",
     "arms.right: unknown key 'camera_frame'"),
    ("base_frame: base\n", "base_frame: base\nbase_fram: base\n", "base_fram:", "unknown key 'base_fram'"),
])
def test_a_bad_robot_file_on_the_command_line_is_exit_2_at_its_line(tmp_path, capsys, old, new, needle, message):
    from bt_meta.cli import main
    from bt_meta.resources import trees_dir

    path = write_variant(tmp_path, old, new)
    line, column = position_of(path, needle)
    code = main(["run", str(trees_dir() / "letters.yaml"), "--problem", "A", "--robot", str(path)])
    err = capsys.readouterr().err
    assert code == 2 and f"{path}:{line}:{column}: " in err and message in err and "Traceback" not in err


def test_a_urdf_that_does_not_load_on_the_command_line_is_exit_2(tmp_path, capsys):
    from bt_meta.cli import main
    from bt_meta.resources import trees_dir

    share = tmp_path / "share"
    share.mkdir()
    source = load_robot("baxter").urdf_path.read_text(encoding="utf-8")
    broken = source.replace('<child link="right_gripper"/>', '<child link="right_griper"/>', 1)
    assert broken != source
    (share / "baxter.urdf").write_text(broken, encoding="utf-8")
    path = tmp_path / "robot.yaml"
    path.write_text(BAXTER_TEXT.replace("  distribution: example-robot-data\n", "").replace(
        "share: cmeel.prefix/share", f"share: {share}").replace(
        "urdf: example-robot-data/robots/baxter_description/urdf/baxter.urdf", "urdf: baxter.urdf").replace(
        "  srdf: example-robot-data/robots/baxter_description/srdf/baxter_manipulation.srdf\n", ""))
    code = main(["run", str(trees_dir() / "letters.yaml"), "--problem", "A", "--robot", str(path)])
    err = capsys.readouterr().err
    lines = broken.splitlines()
    child = next(n for n, text in enumerate(lines, 1) if "right_griper" in text)
    start = max(n for n, text in enumerate(lines[:child], 1) if "<joint " in text)  # the joint's start tag
    column = lines[start - 1].index("<joint") + 1
    assert code == 2 and f"{share / 'baxter.urdf'}:{start}:{column}: joint 'right_endpoint': its child link " \
        "'right_griper' is not in the URDF" in err


def test_turn_about_fingers_is_a_located_flag(tmp_path):
    old = "      opening: 0.0462                  # measured"
    path = write_variant(tmp_path, old, "      turn_about_fingers: sometimes\n" + old)
    with pytest.raises(ConfigError, match=r"arms\.right\.gripper\.turn_about_fingers must be true or false") as caught:
        load_robot(path)
    assert (caught.value.line, caught.value.column) == position_of(path, "sometimes")
    assert load_robot("panda").arm("arm").gripper.turn_about_fingers
    assert not load_robot("baxter").arm("right").gripper.turn_about_fingers
