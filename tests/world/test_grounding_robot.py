"""A grounding file's ``robot:`` key and per-robot ``robot_pose``; paths in it are read beside the file."""

from __future__ import annotations

import json

import pytest

from bt_meta.cli import main
from bt_meta.errors import ConfigError
from bt_meta.resources import robots_dir, trees_dir
from bt_meta.world.simulation.sim_world import load_grounding

MAGNETS = trees_dir() / "magnetic_attach.yaml"
GROUNDING = (trees_dir() / "poses" / "magnetic_attach.yaml").read_text()


def test_robot_key_and_per_robot_poses(tmp_path):
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "my_panda.yaml").write_text((robots_dir() / "panda.yaml").read_text())
    path = tmp_path / "grounding.yaml"
    path.write_text(GROUNDING + "robot: robots/my_panda.yaml\nrobot_pose: {baxter: {left_s0: 0.8}, panda: {}}\n")
    grounding = load_grounding("magnetic_attach", path=path)
    assert grounding.robot == str(tmp_path / "robots" / "my_panda.yaml")  # beside the grounding file
    assert grounding.start_pose("baxter") == {"left_s0": 0.8} and grounding.start_pose("panda") == {}
    path.write_text(GROUNDING + "robot_pose: {left_s0: 0.8, panda: {}}\n")
    with pytest.raises(ConfigError, match="robot_pose mixes joint values and per-robot mappings"):
        load_grounding("magnetic_attach", path=path)


@pytest.mark.slow
def test_the_grounding_chooses_the_robot_and_the_command_line_wins(tmp_path, capsys):
    path = tmp_path / "grounding.yaml"
    path.write_text(GROUNDING + "robot: panda\n")
    args = ["run", str(MAGNETS), "--problem", "nominal", "--grounding", str(path), "--max-ticks", "1", "--json"]
    main(args)
    assert json.loads(capsys.readouterr().out)["robot"] == "panda"
    main([*args, "--robot", "baxter"])
    assert json.loads(capsys.readouterr().out)["robot"] == "baxter"


@pytest.mark.slow
def test_a_start_pose_for_joints_the_robot_lacks_is_a_located_error(tmp_path, capsys):
    path = tmp_path / "grounding.yaml"
    path.write_text(GROUNDING + "robot_pose: {left_s0: 0.8}\n")
    code = main(["run", str(MAGNETS), "--problem", "nominal", "--grounding", str(path), "--robot", "panda"])
    err = capsys.readouterr().err
    assert code == 2 and f"{path}: robot_pose: robot 'panda' has no joints left_s0" in err
