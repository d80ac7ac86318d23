"""The perturbation spec: shipped defaults load, every mistake is located at path:line:column (CLI exit 2)."""

from __future__ import annotations

import pytest

from bt_meta.campaign.families import family, family_spec, shipped_families
from bt_meta.campaign.spec import KINDS, SpecError, load_spec
from bt_meta.cli import main


@pytest.mark.parametrize("name", shipped_families())
def test_every_family_ships_a_default_spec_that_loads(name):
    spec = family_spec(family(name))
    assert spec.family == name
    assert {p.kind for p in spec.perturbations} <= set(KINDS)
    assert spec.perturbations


def _write(tmp_path, text):
    path = tmp_path / "spec.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def _error(tmp_path, text, names=("b0", "b5"), family=None):
    with pytest.raises(SpecError) as caught:
        load_spec(_write(tmp_path, text), names, family=family)
    return caught.value


def test_unknown_perturbation_is_located(tmp_path):
    error = _error(tmp_path, "perturbations:\n  - shift: {probability: 0.5}\n  - wobble: {probability: 1}\n")
    assert (error.line, error.column) == (3, 5)
    assert "unknown perturbation 'wobble'" in error.message and "shift" in error.message


def test_unknown_object_is_located(tmp_path):
    error = _error(tmp_path, "perturbations:\n  - remove: {objects: [b0, b9]}\n")
    assert (error.line, error.column) == (2, 28)
    assert "unknown object 'b9'" in error.message and "b0, b5" in error.message


def test_unknown_parameter_colour_and_type_are_located(tmp_path):
    error = _error(tmp_path, "perturbations:\n  - shift: {distnce: [0, 1]}\n")
    assert error.line == 2 and "unknown key 'distnce'" in error.message
    error = _error(tmp_path, "perturbations:\n  - colour: {colours: [red, mauve]}\n")
    assert error.line == 2 and "unknown colour 'mauve'" in error.message
    error = _error(tmp_path, "perturbations:\n  - distractor: {types: [teapot]}\n")
    assert "unknown object type 'teapot'" in error.message


def test_bad_numbers_and_family_mismatch(tmp_path):
    assert "between 0 and 1" in _error(tmp_path, "perturbations:\n  - remove: {probability: 2}\n").message
    assert "lo <= hi" in _error(tmp_path, "perturbations:\n  - shift: {distance: [0.05, 0.01]}\n").message
    error = _error(tmp_path, "family: magnetic\nperturbations:\n  - remove: {}\n", family="letters_A")
    assert (error.line, error.column) == (1, 9) and "not 'letters_A'" in error.message


def test_cli_reports_a_bad_spec_with_its_location_and_exit_2(tmp_path, capsys):
    spec = _write(tmp_path, "perturbations:\n  - turn: {probability: 0.5}\n  - explode: {}\n")
    code = main(["campaign", "generate", "letters_A", "--n", "1", "--spec", str(spec), "-o", str(tmp_path / "C")])
    err = capsys.readouterr().err
    assert code == 2
    assert f"{spec}:3:5: unknown perturbation 'explode'" in err
    assert "Traceback" not in err


def test_cli_unknown_family_exits_2(tmp_path, capsys):
    assert main(["campaign", "generate", "letters_Z", "-o", str(tmp_path / "C")]) == 2
    assert "unknown family 'letters_Z'" in capsys.readouterr().err


def test_obstacles_parameters_are_checked_and_located(tmp_path):
    spec = load_spec(_write(tmp_path, "perturbations:\n  - obstacles: {shapes: [post, shelf], size: [0.02, 0.05]}\n"),
                     ["b0"])
    (obstacles,) = spec.perturbations
    assert obstacles.params["shapes"] == ("post", "shelf") and obstacles.params["size"] == (0.02, 0.05)
    error = _error(tmp_path, "perturbations:\n  - obstacles: {shapes: [box, teapot]}\n")
    assert (error.line, error.column) == (2, 31) and "unknown obstacle shape 'teapot'" in error.message
    error = _error(tmp_path, "perturbations:\n  - obstacles: {height: [0, 0.1]}\n")
    assert error.line == 2 and "0 < lo <= hi" in error.message
