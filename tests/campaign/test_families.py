"""Campaign families as data: the shipped family files, a user's task as it stands, and every mistake located."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from bt_meta.campaign.families import FamilyError, family, family_spec, load_family, shipped_families, task_family
from bt_meta.campaign.spec import SpecError
from bt_meta.cli import main
from bt_meta.htn import load_task_file
from bt_meta.judge.success import SuccessError
from bt_meta.resources import trees_dir
from bt_meta.world.simulation.sim_world import load_grounding


def _checks(chosen):
    task_file = load_task_file(chosen.task_path())
    grounding = load_grounding(task_file.domain.name, chosen.task_path())
    return [(c.kind, c.args) for c in chosen.success_check(task_file, task_file.problem(chosen.problem),
                                                           grounding).checks]


def test_the_four_shipped_families_are_files():
    assert shipped_families() == ["housing", "letters_A", "letters_H", "magnetic"]
    for name in shipped_families():
        chosen = family(name)
        assert chosen.file == (trees_dir() / "families" / f"{name}.yaml").resolve()
        assert chosen.task_path().is_file() and chosen.demonstration_list()


def test_success_checks_come_from_the_goal_and_the_family_file():
    assert _checks(family("magnetic")) == [("at_pose", ("staging",)), ("gripper", ("closed",)),
                                           ("attached", ("active_part", "reference_part"))]
    assert _checks(family("housing")) == [("inserted", ("housing", "housing_hole")), ("gripper", ("open",))]
    letters = _checks(family("letters_A"))
    assert letters[0] == ("at_cell", ("b5", "1.5", "1"))  # the goal, then every cell the plan fills, once
    assert sorted(letters) == sorted({("at_cell", (b, x, y)) for b, x, y in [
        ("b0", "0", "0"), ("b1", "0", "1"), ("b2", "3", "0"), ("b3", "3", "1"), ("b4", "1.5", "2"),
        ("b5", "1.5", "1")]})
    assert len(_checks(family("letters_H"))) == 8  # H's problem has no goal: the plan's cells


def test_a_task_as_it_stands_needs_no_family_file(tmp_path):
    chosen = task_family(trees_dir() / "magnetic_attach.yaml", "nominal")
    assert chosen.file is None and chosen.demonstration_list() == (("nominal", 1),)
    assert _checks(chosen) == [("at_pose", ("staging",)), ("gripper", ("closed",))]


def test_an_unknown_family_names_the_shipped_ones(capsys):
    code = main(["campaign", "generate", "kitting", "--n", "1", "-o", "/nonexistent/x"])
    err = capsys.readouterr().err
    assert code == 2 and "unknown family 'kitting'" in err and "letters_A" in err and "--task" in err


def _family_file(tmp_path, text, name="fam.yaml"):
    path = tmp_path / name
    path.write_text(f"task: {trees_dir() / 'magnetic_attach.yaml'}\nproblem: nominal\nscene: magnetic_attach\n{text}",
                    encoding="utf-8")
    return path


@pytest.mark.parametrize(("text", "error", "line", "column", "message"), [
    ("colour: red\n", FamilyError, 4, 1, "unknown key 'colour'"),
    ("grasped: [active, ghost]\n", FamilyError, 4, 19, "unknown object 'ghost'"),
    ("demonstrations:\n  - {problem: nope}\n", FamilyError, 5, 15, "no problem 'nope'"),
    ("demonstrations:\n  - {problem: nominal, times: 2}\n", FamilyError, 5, 24, "unknown key 'times'"),
    ("success:\n  predicates:\n    gripper_open: {check: gripper, args: [open]}\n", SuccessError, 6, 5,
     "unknown predicate 'gripper_open'"),
    ("success:\n  checks:\n    - {check: attached, args: [active_part, ghost]}\n", SuccessError, 6, 45,
     "unknown object 'ghost'"),
    ("success:\n  checks:\n    - {check: glued, args: [active_part]}\n", SuccessError, 6, 15,
     "unknown check kind 'glued'"),
    ("success:\n  checks:\n    - {check: attached, args: [active_part]}\n", SuccessError, 6, 31,
     "takes 2 argument(s)"),
    ("success:\n  extra: []\n", SuccessError, 5, 3, "unknown key 'extra'"),
])
def test_family_file_mistakes_are_located(tmp_path, capsys, text, error, line, column, message):
    path = _family_file(tmp_path, text)
    with pytest.raises(error) as caught:
        load_family(path)
    assert (caught.value.line, caught.value.column) == (line, column), str(caught.value)
    assert message in str(caught.value)
    code = main(["campaign", "generate", "--family", str(path), "--n", "1", "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and f"{path}:{line}:{column}:" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_a_goal_predicate_without_a_check_is_located_at_the_problem(tmp_path, capsys):
    task = trees_dir() / "housing_insertion.yaml"
    with pytest.raises(SuccessError) as caught:
        task_family(task, "nominal")
    assert "gripper_open" in str(caught.value) and caught.value.line is not None
    code = main(["campaign", "generate", "--task", str(task), "--problem", "nominal", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and f"{task}:{caught.value.line}:" in err and "success: predicates" in err


def test_perturbations_select_objects_by_name_type_or_role(tmp_path):
    path = _family_file(tmp_path, "perturbations:\n"
                        "  - shift: {objects: [{type: magnet_active}]}\n"
                        "  - turn: {objects: [{role: reference}, active]}\n"
                        "  - rotate: {objects: [{role: grasped}]}\n")
    spec = family_spec(load_family(path), roles={"grasped": ["active"]})
    assert [p.objects for p in spec.perturbations] == [("active",), ("reference", "active"), ("active",)]
    bad = _family_file(tmp_path, "perturbations:\n  - shift: {objects: [{role: spare}]}\n", "bad.yaml")
    with pytest.raises(SpecError) as caught:
        family_spec(load_family(bad), roles={"grasped": ["active"]})
    assert (caught.value.line, caught.value.column) == (5, 30) and "no object of role 'spare'" in str(caught.value)


def test_a_problem_without_a_plan_leaves_no_folder(tmp_path, capsys):
    """The letters problem whose bar is red has no plan symbolically: refused, and nothing is left behind."""
    out = tmp_path / "c"
    code = main(["campaign", "generate", "--task", str(trees_dir() / "letters.yaml"), "--problem",
                 "A_bar_other_colour", "--n", "2", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "has no plan" in err
    assert list(tmp_path.iterdir()) == []


def test_shipped_family_files_are_package_data():
    text = (Path(__file__).resolve().parents[2] / "setup.py").read_text(encoding="utf-8")
    assert '"families/*.yaml"' in text
    assert shutil.which("true")  # the environment runs commands (used by the slow tests)


def test_a_manifests_family_is_read_once_per_process_and_again_when_its_file_changes(tmp_path, monkeypatch):
    """An episode asks for its family to label its seed and for each run: one read serves while the files stay."""
    from bt_meta.campaign.families import family_of_manifest

    path = _family_file(tmp_path, "grasped: [active]\n")
    manifest = {"family": "fam", "family_file": str(path), "task_file": str(trees_dir() / "magnetic_attach.yaml"),
                "problem": "nominal", "shipped": False}
    first = family_of_manifest(manifest)
    assert family_of_manifest(dict(manifest)) is first and first.grasped == ("active",)
    assert family_of_manifest({"family": "letters_A"}) is family_of_manifest({"family": "letters_A"})
    path.write_text(path.read_text(encoding="utf-8").replace("grasped: [active]", "grasped: [reference]"),
                    encoding="utf-8")
    assert family_of_manifest(manifest).grasped == ("reference",)
    monkeypatch.setenv("BT_META_MODEL_CACHE", "0")
    assert family_of_manifest(manifest) is not family_of_manifest(manifest)
