"""docs/tutorial.md, run as written: its files are written, its commands run in order in an empty folder, each
ending with the exit status the tutorial states (0 unless a line says ``# exit N``)."""

from __future__ import annotations

import os
import re
import shlex
from pathlib import Path

import pytest

from bt_meta.cli import main

TUTORIAL = Path(__file__).resolve().parents[1] / "docs" / "tutorial.md"
BLOCK = re.compile(r"^```(?P<info>[^\n]*)\n(?P<body>.*?)^```$", re.M | re.S)


def tutorial_steps() -> list[tuple[str, str]]:
    """("file", path + text) and ("command", line) in the order the tutorial gives them."""
    steps: list[tuple[str, str]] = []
    for match in BLOCK.finditer(TUTORIAL.read_text(encoding="utf-8")):
        info, body = match["info"].split(), match["body"]
        if info[:1] == ["yaml"] and len(info) == 2 and info[1].startswith("file="):
            steps.append(("file", info[1][len("file="):] + "\n" + body))
        elif info[:1] == ["console"]:
            steps.extend(("command", line[2:]) for line in body.splitlines() if line.startswith("$ "))
    return steps


def test_the_tutorial_has_files_and_commands():
    steps = tutorial_steps()
    files = [text.split("\n", 1)[0] for kind, text in steps if kind == "file"]
    assert files == ["peg.yaml", "scene.yaml", "poses/peg_on_base.yaml"]
    commands = [text for kind, text in steps if kind == "command"]
    assert commands[:2] == ["mkdir mytask", "cd mytask"]
    assert any("--repair" in c and "run" in c for c in commands)


@pytest.mark.slow
def test_the_tutorial_runs_as_written(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("BT_META_MEMORY", raising=False)
    outputs: dict[str, str] = {}
    for kind, text in tutorial_steps():
        if kind == "file":
            name, body = text.split("\n", 1)
            Path(name).parent.mkdir(parents=True, exist_ok=True)
            Path(name).write_text(body, encoding="utf-8")
            continue
        stated = re.match(r"(?P<command>.*?)\s+#\s*exit (?P<code>\d+)$", text)
        command = stated["command"] if stated else text
        expected = int(stated["code"]) if stated else 0
        words = shlex.split(command)
        if words[0] == "mkdir":
            Path(words[1]).mkdir()
        elif words[0] == "cd":
            os.chdir(words[1])
        else:
            assert words[0] == "bt-meta", text
            code = main(words[1:])
            captured = capsys.readouterr()
            assert code == expected, f"{text}: exit {code}\n{captured.out[-2000:]}\n{captured.err[-2000:]}"
            outputs[command.strip()] = captured.out
    repaired = outputs["bt-meta run peg.yaml --variant peg_on_side --repair --record --memory memory.sqlite"]
    assert "repair applied: backtrack by pose_backtracking" in repaired and "SUCCESS after" in repaired
    failed = outputs["bt-meta run peg.yaml --variant peg_on_side --memory memory.sqlite"]
    assert "[unexpected_configuration]" in failed
    listing = outputs["bt-meta memory ls --memory memory.sqlite"]
    assert "peg_on_side  success" in listing and "nominal      success" in listing
    assert "repair attempt(s)" in outputs['bt-meta tick peg.yaml --repair --fault "Grasp#1=fail:physical"']
