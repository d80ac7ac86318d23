"""``--robot`` and ``--scene`` on the commands that build worlds (demo, experiment keypoints): what cannot work is
refused with the reason, exit 2, no traceback."""

from __future__ import annotations

import json
from pathlib import Path

from bt_meta.cli import main
from bt_meta.resources import trees_dir


def test_demo_refuses_a_scene_naming_why(tmp_path: Path, capsys):
    code = main(["demo", "--out", str(tmp_path / "out"), "--scene", str(trees_dir() / "scenes" / "letters_A.yaml")])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert "--scene: the demo builds the scenes of its three families" in err


def test_demo_refuses_a_memory_recorded_on_another_robot(tmp_path: Path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "memory.sqlite").write_bytes(b"")
    (out / "summary.json").write_text(json.dumps({"robot": "baxter"}))
    code = main(["demo", "--out", str(out), "--robot", "panda"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert f"{out / 'summary.json'}" in err and "recorded on the baxter, not the panda" in err


def test_demo_names_an_unknown_robot(tmp_path: Path, capsys):
    code = main(["demo", "--out", str(tmp_path / "out"), "--robot", "nosuch"])
    err = capsys.readouterr().err
    assert code == 2 and "no robot description 'nosuch'" in err and "Traceback" not in err


def test_keypoints_refuses_a_scene_without_its_two_parts(capsys):
    scene = trees_dir() / "scenes" / "letters_A.yaml"
    code = main(["experiment", "keypoints", "--scene", str(scene)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert f"{scene}" in err and "has no object 'active' or 'reference'" in err


def test_substitution_refuses_a_scene_naming_why(capsys):
    code = main(["experiment", "substitution", "--scene", str(trees_dir() / "scenes" / "letters_H.yaml")])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert "--scene: the substitution experiment runs letters A's own scene" in err


def test_a_scene_whose_catalogue_mesh_is_missing_is_exit_2(tmp_path: Path, capsys):
    (tmp_path / "mine.yaml").write_text(
        "types:\n  knob:\n    shape: mesh\n    mesh: knob.stl\n    mass: 0.1\n"
        "    features: {bottom: {point: [0, 0, 0], normal: [0, 0, -1]}}\n"
        "    grasp_frames: {top: [0, 0, 0.02, 180, 0, 180]}\n")
    scene = tmp_path / "scene.yaml"
    scene.write_text("scene: knobs\ncatalogue: [mine.yaml]\nobjects:\n"
                     "  - {name: k, type: knob, pose: [0.6, -0.3, table, 0, 0, 0]}\n")
    code = main(["run", str(trees_dir() / "letters.yaml"), "--problem", "A", "--scene", str(scene)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert f"{tmp_path / 'mine.yaml'}:4:11: type 'knob': mesh file {tmp_path / 'knob.stl'} does not exist" in err


def test_ablation_refuses_a_scene(capsys):
    code = main(["experiment", "ablation", "--scene", str(trees_dir() / "scenes" / "letters_A.yaml")])
    err = capsys.readouterr().err
    assert code == 2 and "--scene: the ablation runs its families' own scenes" in err and "Traceback" not in err
