"""``--scene FILE`` on run: another scene for the problem; a bad scene is a located error before anything runs."""

from __future__ import annotations

import json

import pytest

from bt_meta.cli import main
from bt_meta.resources import trees_dir

MAGNETS = str(trees_dir() / "magnetic_attach.yaml")


@pytest.mark.slow
def test_scene_option_builds_the_given_scene(tmp_path, capsys):
    scene = tmp_path / "elsewhere.yaml"
    scene.write_text((trees_dir() / "scenes" / "magnetic_attach.yaml").read_text()
                     .replace("scene: magnetic_attach", "scene: elsewhere")
                     .replace("[0.58, -0.40, table, 0, 0, 0]", "[0.66, -0.42, table, 0, 0, 0]"))
    code = main(["run", MAGNETS, "--problem", "nominal", "--scene", str(scene), "--max-ticks", "1", "--json"])
    result = json.loads(capsys.readouterr().out)
    assert code == 1 and result["scene"] == "elsewhere"  # still running after one tick
    assert result["objects"]["active"]["pose"][:2] == pytest.approx([0.66, -0.42], abs=0.01)


def test_a_bad_scene_file_is_exit_2(tmp_path, capsys):
    scene = tmp_path / "bad.yaml"
    scene.write_text("scene: bad\nobjects:\n  - {name: x, type: cone, pose: [0, 0, table, 0, 0, 0]}\n")
    code = main(["run", MAGNETS, "--problem", "nominal", "--scene", str(scene)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert f"{scene}:3:21: object 'x': unknown type 'cone'" in err
    code = main(["run", MAGNETS, "--problem", "nominal", "--scene", str(tmp_path / "missing.yaml")])
    assert code == 2 and "scene file not found" in capsys.readouterr().err
